"""Hand-designed baselines as policies of the environments (the policy protocol of
:mod:`abb_gym.evaluation.registry`).

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
(Yoshida's scaling rule), from ``baselines/<scene>.yaml`` on the search path of
:mod:`abb_gym.resources` (the tuner's result; a user folder first, then the shipped
``configs/baselines``) when it exists, or explicitly.  ``baseline:NAME`` policy strings
resolve through :func:`load_baseline` (registered as an ``abb_gym.policies`` entry point).
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from .. import resources
from ..configuration import ConfigError, read_yaml
from ..envs.actions import dwell_action
from ..physics import drive_law as dl
from ..physics.drives import SpeedProfile
from ..physics.rotor import spinning_inertia
from ..physics.scene import Scene
from .families import FAMILY_NAMES, build_family

__all__ = ["BaselinePolicy", "ClosedLoopPolicy", "SpeedReferencePolicy", "tuned_parameters",
           "tuned_file", "oracle_starts", "make_baseline", "load_baseline", "dwell_action",
           "FAMILY_NAMES"]



def tuned_file(scene_name: str):
    """The tuned-parameter file of a scene on the search path, or None."""
    return resources.find("baselines", scene_name)


def _tuned_entry(scene_name: str, family: str):
    """(the scene's ``baselines/<scene>.yaml`` or None, ``family``'s entry there or {})."""
    path = tuned_file(scene_name)
    if path is None:
        return None, {}
    data = read_yaml(path, "tuned baselines")
    families = data.get("families") or {} if isinstance(data, dict) else data
    if not isinstance(families, dict):
        raise ConfigError(f"{path}: families must be a mapping of family name to its entry "
                          f"(got {families!r:.80})")
    entry = families.get(family) or {}
    if not isinstance(entry, dict):
        raise ConfigError(f"{path}: families.{family} must be a mapping with params (and "
                          f"optionally oracle_starts) (got {entry!r:.80})")
    if "params" in entry and not isinstance(entry["params"], dict):
        raise ConfigError(f"{path}: families.{family}.params must be a mapping of parameter "
                          f"name to value (got {entry['params']!r:.80})")
    return path, entry


def tuned_parameters(scene_name: str, family: str) -> dict[str, Any] | None:
    """Tuned parameters of ``family`` for a scene from ``baselines/<scene>.yaml``."""
    _, entry = _tuned_entry(scene_name, family)
    if "params" not in entry:
        return None
    # validated against the family's declared parameters (unit, bounds)
    return build_family(family, **dict(entry["params"])).to_params()


def oracle_starts(scene_name: str, family: str) -> list[dict[str, Any]]:
    """Further starts of the per-machine oracle for a scene's ``family``: the ``oracle_starts``
    list of its entry in ``baselines/<scene>.yaml`` (parameters of earlier tunings), each
    validated like the tuned parameters; [] if none (:mod:`abb_gym.baselines.oracle`)."""
    path, entry = _tuned_entry(scene_name, family)
    starts = entry.get("oracle_starts") or []
    if not isinstance(starts, list) or not all(isinstance(x, dict) for x in starts):
        raise ConfigError(f"{path}: families.{family}.oracle_starts must be a list of "
                          f"parameter mappings (got {starts!r:.80})")
    return [build_family(family, **dict(x)).to_params() for x in starts]


class SpeedReferencePolicy:
    """Turns a speed reference into the environment's action.

    * RunUpSpeed: the constant acceleration that lands the rotor exactly on the reference at
      the end of the interval, ``a = (w_ref(t + dt) - w) / dt``, in units of
      ``drive_max_acceleration``; on a profile whose breakpoints fall on control instants
      this is the profile itself, so the run equals ``simulate`` with that profile.
    * RunUpTorque: a speed-tracking controller within the scene's torque limit: the same
      deadbeat acceleration times the spinning inertia (rotor plus balls rolling with it,
      :func:`abb_gym.physics.rotor.spinning_inertia`), plus the bearing drag,
      ``T = J_spin a + b_0 w``, clipped to the limit.
    """

    name = "baseline"
    params: dict[str, Any] = {}
    #: the evaluation's hint (:mod:`abb_gym.evaluation.registry`): these policies read the
    #: observation or the environment, never ``info``
    reads_info = False

    def _bind(self, env) -> None:
        self._env = env.unwrapped
        setup = env.unwrapped.setup
        self.setup = setup
        self.kind = setup.kind
        self.dt = setup.control_interval
        self.alpha_max = setup.max_acceleration
        self.torque_limit = setup.torque_limit
        self.inertia = spinning_inertia(setup.scene)
        self.bearing_drag = setup.scene.bearing_drag

    def _actions(self, reference: np.ndarray, w: np.ndarray) -> np.ndarray:
        accel = (reference - w) / self.dt
        if self.kind == "speed":
            u = accel / self.alpha_max
        else:
            u = (self.inertia * accel + self.bearing_drag * w) / self.torque_limit
        return np.clip(u, -1.0, 1.0).astype(np.float32)[:, None]


class BaselinePolicy(SpeedReferencePolicy):
    """Open loop: a speed profile per sub-environment (one for all, or a list), executed
    through the environment's action (DwellProfile: the action that encodes it)."""

    def __init__(self, name: str, profiles_: Sequence[SpeedProfile] | SpeedProfile,
                 params: Mapping[str, Any] | None = None):
        self.name = name
        self._profiles = profiles_
        self.params = dict(params or {})

    def _profile(self, i: int) -> SpeedProfile:
        if isinstance(self._profiles, SpeedProfile):
            return self._profiles
        return self._profiles[i]

    def acts_on(self, setup: Any) -> bool:
        """Whether the environment of ``setup`` can execute every profile: always for speed and
        torque; on DwellProfile only ramp - dwell - ramp profiles its action encodes."""
        if setup.kind != "dwell":
            return True
        profiles = ([self._profiles] if isinstance(self._profiles, SpeedProfile)
                    else list(self._profiles))
        try:
            for profile in profiles:
                dwell_action(setup, profile)
        except ValueError:
            return False
        return True

    def reset(self, env, mask: np.ndarray) -> None:
        self._bind(env)
        n = env.num_envs
        tables = [self._profile(i).segment_table(math.inf)[1] for i in range(n)]
        self._n_rows = np.array([len(r) for r in tables], dtype=np.int64)
        self._tables = np.zeros((n, int(self._n_rows.max()), dl.N_DRIVE))
        for i, rows in enumerate(tables):
            self._tables[i, :len(rows)] = rows

    def act(self, obs: np.ndarray, info: dict) -> np.ndarray:
        n = obs.shape[0]
        if self.kind == "dwell":
            return np.stack([dwell_action(self.setup, self._profile(i)) for i in range(n)])
        # an open-loop drive knows the time and its own speed exactly (from the environment,
        # so that it works with any info level)
        t = self._env.times
        w = self._env.rotor_speeds
        reference = dl.prescribed_speeds(t + self.dt, self._tables, self._n_rows)
        return self._actions(reference, w)


class ClosedLoopPolicy(SpeedReferencePolicy):
    """Closed loop: a controller of :mod:`abb_gym.baselines.closed_loop` per sub-environment
    (one parameter set for all, or a list), which sees only the observation."""

    def __init__(self, name: str, families: Sequence[Any] | Any,
                 params: Mapping[str, Any] | None = None):
        self.name = name
        self._families = families
        self.params = dict(params or {})
        self._controller = None

    @staticmethod
    def acts_on(setup: Any) -> bool:
        """Whether the environment of ``setup`` lets the controller react: not DwellProfile,
        whose one action is decided before the run."""
        return setup.kind != "dwell"

    def reset(self, env, mask: np.ndarray) -> None:
        self._bind(env)
        if not self.acts_on(self.setup):
            raise ValueError(f"{self.name} is a closed-loop baseline; DwellProfile decides "
                             f"before the run and observes nothing to react to")
        if self._controller is None:
            fams = (list(self._families) if isinstance(self._families, (list, tuple))
                    else [self._families] * env.num_envs)
            self._controller = type(fams[0]).controller(fams, self.setup)
        self._controller.reset(np.asarray(mask, bool))

    def act(self, obs: np.ndarray, info: dict) -> np.ndarray:
        obs = np.asarray(obs, float)
        w = obs[:, 0] * self.setup.operating_speed  # the measured speed
        return self._actions(self._controller.references(obs), w)


def make_baseline(family: str, scene: Scene, operating_speed: float | None = None,
                  params: Mapping[str, Any] | None = None, use_tuned: bool = True):
    """Baseline policy of ``family`` for ``scene``: explicit ``params``, else the tuned ones,
    else the family defaults."""
    sc = scene if operating_speed is None else scene.replace(
        drive_operating_speed=operating_speed)
    if params is None and use_tuned:
        params = tuned_parameters(scene.name, family)
    params = dict(params or {})
    label = f"baseline:{family}" + (" (tuned)" if params else " (default)")
    fam = build_family(family, **params)
    if fam.closed_loop:
        return ClosedLoopPolicy(label, fam, params)
    return BaselinePolicy(label, fam.profile(sc), params)


class _LazyBaseline:
    """Resolved at the first reset, when the environment's operating speed is known."""

    reads_info = False  # neither policy it resolves to reads info

    def __init__(self, family: str, scene: Scene):
        self.family = family
        self.scene = scene
        self._inner = None
        self.name = f"baseline:{family}"
        self.params: dict[str, Any] = {}

    def _resolve(self, setup: Any):
        if self._inner is None:
            self._inner = make_baseline(self.family, setup.scene, setup.operating_speed)
            self.name = self._inner.name
            self.params = self._inner.params
        return self._inner

    def acts_on(self, setup: Any) -> bool:
        """See :meth:`BaselinePolicy.acts_on` and :meth:`ClosedLoopPolicy.acts_on`."""
        return self._resolve(setup).acts_on(setup)

    def reset(self, env, mask):
        self._resolve(env.unwrapped.setup).reset(env, mask)

    def act(self, obs, info):
        return self._inner.act(obs, info)


def load_baseline(name: str, env_id: str | None = None, scene: Any = None, **_: Any):
    """The policy of ``baseline:NAME`` (the ``abb_gym.policies`` entry point): a family
    (:data:`FAMILY_NAMES`, tuned parameters where there are) or ``laundry_oracle``
    (:mod:`abb_gym.baselines.laundry`)."""
    from .laundry import ORACLE_NAME, LaundryOracle
    if name == ORACLE_NAME:
        return LaundryOracle()
    if name not in FAMILY_NAMES:
        raise ValueError(f"unknown baseline {name!r}; available: "
                         f"{', '.join((*FAMILY_NAMES, ORACLE_NAME))}")
    return _LazyBaseline(name, scene)
