"""Hand-designed baselines as policies of the environments (see :mod:`.policies`).

* RunUpSpeed: each interval commands the constant acceleration that lands the rotor exactly on
  the profile's speed at the end of the interval, ``a = (w_ref(t + dt) - w) / dt``, in units
  of ``drive_max_acceleration``.  On a profile whose breakpoints fall on control instants this
  is the profile itself, so the run equals ``simulate`` with that profile.
* RunUpTorque: a speed-tracking controller within the scene's torque limit: the same
  deadbeat acceleration, times the spinning inertia (rotor plus balls rolling with it), plus
  the bearing drag, ``T = J_spin a + b_0 w``, clipped to the limit.
* DwellProfile: the action that encodes the dwell parameters (its inverse mapping).

``BaselinePolicy`` holds one profile per sub-environment, so one vector environment can sweep
a baseline family over its parameters.  Baseline parameters come from the family defaults
(Yoshida's scaling rule), from ``configs/baselines/<scene>.yaml`` (the tuner's result) when it
exists, or explicitly.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import yaml

from ..baselines import profiles
from ..physics.drives import SpeedProfile
from ..physics.scene import Scene
from .policies import register_loader

BASELINES_DIR = Path(__file__).resolve().parents[2] / "configs" / "baselines"


def tuned_parameters(scene_name: str, family: str) -> dict[str, Any] | None:
    """Tuned parameters of ``family`` for a scene from ``configs/baselines/<scene>.yaml``."""
    path = BASELINES_DIR / f"{scene_name}.yaml"
    if not path.exists():
        return None
    data = yaml.safe_load(path.read_text()) or {}
    entry = (data.get("families") or {}).get(family)
    return dict(entry["params"]) if entry and "params" in entry else None


def spinning_inertia(scene: Scene) -> float:
    """Polar inertia [kg m^2] of the rotor with the balls rolling along at the race."""
    a = scene.arrays()
    ball_spin = a["ball_inertia_factor"] * a["ball_mass"] * a["ball_radius"] ** 2
    return scene.rotor_polar_inertia + float(np.sum(ball_spin + a["ball_mass"]
                                                    * scene.race_radius ** 2))


class BaselinePolicy:
    """A speed profile per sub-environment, executed through the environment's action."""

    def __init__(self, name: str, profiles_: Sequence[SpeedProfile] | SpeedProfile,
                 params: Mapping[str, Any] | None = None):
        self.name = name
        self._profiles = profiles_
        self.params = dict(params or {})

    def _profile(self, i: int) -> SpeedProfile:
        if isinstance(self._profiles, SpeedProfile):
            return self._profiles
        return self._profiles[i]

    def reset(self, env, mask: np.ndarray) -> None:
        setup = env.unwrapped.setup
        self.kind = setup.kind
        self.dt = setup.control_interval
        self.alpha_max = setup.max_acceleration
        self.torque_limit = setup.torque_limit
        self.inertia = spinning_inertia(setup.scene)
        self.bearing_drag = setup.scene.bearing_drag
        self.setup = setup

    def act(self, obs: np.ndarray, info: dict) -> np.ndarray:
        n = obs.shape[0]
        if self.kind == "dwell":
            return np.stack([dwell_action(self.setup, self._profile(i)) for i in range(n)])
        t = np.asarray(info["time"], float)
        w = np.asarray(info["rotor_speed"], float)
        target = np.array([float(self._profile(i).speed(t[i] + self.dt)) for i in range(n)])
        accel = (target - w) / self.dt
        if self.kind == "speed":
            u = accel / self.alpha_max
        else:
            u = (self.inertia * accel + self.bearing_drag * w) / self.torque_limit
        return np.clip(u, -1.0, 1.0).astype(np.float32)[:, None]


def dwell_action(setup, profile: SpeedProfile) -> np.ndarray:
    """The DwellProfile action that encodes ``profile``'s dwell (inverse of its mapping).

    The profile must be ramp - dwell - ramp at the environment's run-up acceleration; other
    shapes raise ValueError."""
    dw = setup.config.dwell
    segs = profile.segments
    alpha = setup.dwell_acceleration
    if len(segs) < 2 or abs(segs[0][1] - alpha) > 1e-9 * alpha:
        raise ValueError("a DwellProfile action needs a ramp at the environment's run-up "
                         f"acceleration {alpha:g} rad/s^2 followed by a dwell")
    w_s = segs[0][0] * alpha
    t_c, a_c = segs[1]

    def unlerp(rng, v):
        return 2.0 * (v - rng[0]) / (rng[1] - rng[0]) - 1.0

    a = np.array([unlerp(dw.speed_range, w_s / setup.scene.critical_speed),
                  unlerp(dw.time_range, t_c / setup.nominal_runup_time),
                  unlerp(dw.accel_range, a_c / alpha)])
    return np.clip(a, -1.0, 1.0).astype(np.float32)


def make_baseline(family: str, scene: Scene, operating_speed: float | None = None,
                  params: Mapping[str, Any] | None = None, use_tuned: bool = True
                  ) -> BaselinePolicy:
    """Baseline policy of ``family`` for ``scene``: explicit ``params``, else the tuned ones,
    else the family defaults."""
    sc = scene if operating_speed is None else scene.replace(
        drive_operating_speed=operating_speed)
    if params is None and use_tuned:
        params = tuned_parameters(scene.name, family)
    params = dict(params or {})
    label = f"baseline:{family}" + (" (tuned)" if params else " (default)")
    return BaselinePolicy(label, profiles.build(family, sc, **params), params)


class _LazyBaseline:
    """Resolved at the first reset, when the environment's operating speed is known."""

    def __init__(self, family: str, scene: Scene):
        self.family = family
        self.scene = scene
        self._inner: BaselinePolicy | None = None
        self.name = f"baseline:{family}"

    def reset(self, env, mask):
        if self._inner is None:
            setup = env.unwrapped.setup
            self._inner = make_baseline(self.family, setup.scene, setup.operating_speed)
            self.name = self._inner.name
            self.params = self._inner.params
        self._inner.reset(env, mask)

    def act(self, obs, info):
        return self._inner.act(obs, info)


def _load_baseline(name: str, env_id: str, scene: Any) -> _LazyBaseline:
    if name not in profiles.FAMILIES:
        raise ValueError(f"unknown baseline {name!r}; available: {', '.join(profiles.FAMILIES)}")
    return _LazyBaseline(name, scene)


register_loader("baseline", _load_baseline)
