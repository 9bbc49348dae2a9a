"""Scenes: validated, SI-unit parameter sets for one balancer machine.

A scene is one YAML file in ``configs/scenes/`` (or any path), grouped into sections.  Every
key of a section becomes the field ``<prefix>_<key>`` of :class:`Scene`
(``rotor.mass`` -> ``rotor_mass``; the ``balls`` section uses the prefix ``ball``), and any
field can be overridden by keyword::

    scene = load_scene("yoshida_odd", ball_mass=2e-3, support_stiffness=2000.0)

Units are SI throughout and angles are radians.  Per-ball fields accept one number (same for
every ball) or a list of ``ball_count`` numbers.

Fields (unit, allowed range):

==============================  ==========  ==========================================================
field                           unit        meaning
==============================  ==========  ==========================================================
rotor_mass                      kg          rotor and housing mass without the balls, > 0
rotor_eccentricity              m           offset of the rotor's mass centre (primary imbalance
                                            m0*e0 = rotor_mass * rotor_eccentricity), >= 0
rotor_polar_inertia             kg m^2      polar inertia of the spinning part (used with a motor), > 0
bearing_drag                    N m s       viscous drag torque on the rotor spin, >= 0
support_stiffness_x, _y         N/m         linear support springs, > 0
support_damping_x, _y           N s/m       linear support dampers, >= 0
race_radius                     m           radius of the ball-centre track, > 0
race_eccentricity               m           offset E of the race centre from the rotor centre, >= 0
race_eccentricity_angle         rad         angle gamma of that offset, measured from the imbalance
ball_count                      -           number of balls, >= 1
ball_mass                       kg          per ball, > 0
ball_radius                     m           per ball, > 0 and < race_radius
ball_inertia_factor             -           spin inertia J = factor * m * r^2 (0.4 solid sphere,
                                            0 point mass), in [0, 1]
ball_drag                       N s/m       race drag force per relative orbit speed, >= 0
                                            (Spannan's torque coefficient beta = ball_drag * R^2)
ball_rolling_resistance         m           rolling-resistance offset beta_b (Yoshida eq. 2-8), >= 0
ball_angles0                    rad         default initial ball angles relative to the rotor,
                                            measured from the imbalance
rolling_regularization_speed    m/s         tanh width replacing sign() in rolling resistance, > 0
drive_torque_limit              N m         motor torque limit, > 0
drive_max_acceleration          rad/s^2     largest commanded rotor acceleration, > 0
drive_operating_speed           rad/s       target operating speed, > 0
housing_clearance               m           largest whirl radius the housing allows, > 0
==============================  ==========  ==========================================================

Effects are switched on by their parameters: a scene whose rolling resistance and race
eccentricity are zero runs a kernel path that never evaluates those terms (see
:attr:`Scene.effects`).
"""
from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import yaml

__all__ = ["Scene", "load_scene", "list_scenes", "scenes_dir", "SceneError"]


class SceneError(ValueError):
    """A scene file or override is invalid; the message names the field and its allowed range."""


# name -> (unit, lower bound, lower bound inclusive, upper bound or None, per-ball)
_NUMERIC_FIELDS: dict[str, tuple[str, float | None, bool, float | None, bool]] = {
    "rotor_mass": ("kg", 0.0, False, None, False),
    "rotor_eccentricity": ("m", 0.0, True, None, False),
    "rotor_polar_inertia": ("kg m^2", 0.0, False, None, False),
    "bearing_drag": ("N m s", 0.0, True, None, False),
    "support_stiffness_x": ("N/m", 0.0, False, None, False),
    "support_stiffness_y": ("N/m", 0.0, False, None, False),
    "support_damping_x": ("N s/m", 0.0, True, None, False),
    "support_damping_y": ("N s/m", 0.0, True, None, False),
    "race_radius": ("m", 0.0, False, None, False),
    "race_eccentricity": ("m", 0.0, True, None, False),
    "race_eccentricity_angle": ("rad", None, True, None, False),
    "ball_mass": ("kg", 0.0, False, None, True),
    "ball_radius": ("m", 0.0, False, None, True),
    "ball_inertia_factor": ("-", 0.0, True, 1.0, True),
    "ball_drag": ("N s/m", 0.0, True, None, True),
    "ball_rolling_resistance": ("m", 0.0, True, None, True),
    "ball_angles0": ("rad", None, True, None, True),
    "rolling_regularization_speed": ("m/s", 0.0, False, None, False),
    "drive_torque_limit": ("N m", 0.0, False, None, False),
    "drive_max_acceleration": ("rad/s^2", 0.0, False, None, False),
    "drive_operating_speed": ("rad/s", 0.0, False, None, False),
    "housing_clearance": ("m", 0.0, False, None, False),
}
_SECTION_PREFIX = {"rotor": "rotor", "support": "support", "race": "race", "balls": "ball",
                   "drive": "drive", "housing": "housing"}
# keys that set two fields at once (isotropic support)
_SHORTCUTS = {"support_stiffness": ("support_stiffness_x", "support_stiffness_y"),
              "support_damping": ("support_damping_x", "support_damping_y")}
# fields whose YAML section key does not follow the prefix rule
_SPECIAL_KEYS = {("rotor", "bearing_drag"): "bearing_drag",
                 ("balls", "rolling_regularization_speed"): "rolling_regularization_speed",
                 ("balls", "count"): "ball_count"}
_DEFAULTS: dict[str, Any] = {
    "description": "",
    "source": "",
    "bearing_drag": 0.0,
    "race_eccentricity": 0.0,
    "race_eccentricity_angle": 0.0,
    "ball_inertia_factor": 0.4,
    "ball_rolling_resistance": 0.0,
    "ball_angles0": 0.0,
    "rolling_regularization_speed": 1e-3,
}


@dataclass(frozen=True)
class Scene:
    """One balancer machine in SI units; see the module docstring for every field and range."""

    name: str
    rotor_mass: float
    rotor_eccentricity: float
    rotor_polar_inertia: float
    support_stiffness_x: float
    support_stiffness_y: float
    support_damping_x: float
    support_damping_y: float
    race_radius: float
    ball_count: int
    ball_mass: tuple[float, ...]
    ball_radius: tuple[float, ...]
    ball_drag: tuple[float, ...]
    drive_torque_limit: float
    drive_max_acceleration: float
    drive_operating_speed: float
    housing_clearance: float
    bearing_drag: float = 0.0
    race_eccentricity: float = 0.0
    race_eccentricity_angle: float = 0.0
    ball_inertia_factor: tuple[float, ...] = (0.4,)
    ball_rolling_resistance: tuple[float, ...] = (0.0,)
    ball_angles0: tuple[float, ...] = (0.0,)
    rolling_regularization_speed: float = 1e-3
    description: str = ""
    source: str = ""

    def __post_init__(self) -> None:
        _validate(self)

    # ------------------------------------------------------------------ derived quantities
    @property
    def total_mass(self) -> float:
        """M = rotor mass + ball masses [kg] (the mass on the support springs)."""
        return self.rotor_mass + float(sum(self.ball_mass))

    @property
    def imbalance(self) -> float:
        """Primary imbalance m0*e0 = rotor_mass * rotor_eccentricity [kg m]."""
        return self.rotor_mass * self.rotor_eccentricity

    @property
    def critical_speeds(self) -> tuple[float, float]:
        """Undamped critical speeds sqrt(k_x/M), sqrt(k_y/M) [rad/s]."""
        m = self.total_mass
        return math.sqrt(self.support_stiffness_x / m), math.sqrt(self.support_stiffness_y / m)

    @property
    def critical_speed(self) -> float:
        """The lower undamped critical speed [rad/s]; the one a run-up passes first."""
        return min(self.critical_speeds)

    @property
    def balancing_capacity(self) -> float:
        """Largest imbalance the balls can cancel with all balls clumped, sum m_i R [kg m]."""
        return float(sum(self.ball_mass)) * self.race_radius

    @property
    def reference_length(self) -> float:
        """Length that normalises the whirl radius (Yoshida plots W_r/e) [m].

        The rotor eccentricity when there is one, otherwise the race eccentricity, otherwise the
        ball imbalance spread over the total mass."""
        if self.rotor_eccentricity > 0:
            return self.rotor_eccentricity
        if self.race_eccentricity > 0:
            return self.race_eccentricity
        return self.balancing_capacity / self.total_mass

    @property
    def effects(self) -> frozenset[str]:
        """Optional effects this scene switches on (each costs run time only when listed)."""
        on = set()
        if any(b > 0 for b in self.ball_rolling_resistance):
            on.add("rolling_resistance")
        if self.race_eccentricity > 0:
            on.add("race_eccentricity")
        if (self.support_stiffness_x != self.support_stiffness_y
                or self.support_damping_x != self.support_damping_y):
            on.add("orthotropic_support")
        return frozenset(on)

    def replace(self, **overrides: Any) -> "Scene":
        """A copy with some fields changed (validated like a loaded scene)."""
        data = self.to_dict()
        _apply_overrides(data, overrides, self.name)
        return _build(data, self.name)

    def to_dict(self) -> dict[str, Any]:
        """Flat field dictionary; per-ball fields as lists (JSON- and YAML-safe)."""
        out = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            out[f.name] = list(v) if isinstance(v, tuple) else v
        return out

    def arrays(self) -> dict[str, np.ndarray]:
        """Per-ball fields as float64 arrays of length ``ball_count``."""
        return {name: np.asarray(getattr(self, name), dtype=np.float64)
                for name, spec in _NUMERIC_FIELDS.items() if spec[4]}


# ---------------------------------------------------------------------------- validation
def _check_number(scene_name: str, name: str, value: Any) -> float:
    unit, lo, lo_incl, hi, _ = _NUMERIC_FIELDS[name]
    rng = _range_text(name)
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise SceneError(f"scene {scene_name!r}: field {name!r} must be a number {rng} "
                         f"(got {value!r})") from None
    if not math.isfinite(v):
        raise SceneError(f"scene {scene_name!r}: field {name!r} must be finite {rng} (got {v})")
    if lo is not None and (v < lo or (v == lo and not lo_incl)):
        raise SceneError(f"scene {scene_name!r}: field {name!r} must be {rng} (got {v} {unit})")
    if hi is not None and v > hi:
        raise SceneError(f"scene {scene_name!r}: field {name!r} must be {rng} (got {v} {unit})")
    return v


def _range_text(name: str) -> str:
    unit, lo, lo_incl, hi, _ = _NUMERIC_FIELDS[name]
    parts = []
    if lo is not None:
        parts.append(f"{'>=' if lo_incl else '>'} {lo:g}")
    if hi is not None:
        parts.append(f"<= {hi:g}")
    return (" and ".join(parts) + f" [{unit}]") if parts else f"[{unit}]"


def _validate(s: Scene) -> None:
    for name, spec in _NUMERIC_FIELDS.items():
        if spec[4]:
            values = getattr(s, name)
            if len(values) != s.ball_count:
                raise SceneError(f"scene {s.name!r}: field {name!r} has {len(values)} values; "
                                 f"it needs one or ball_count = {s.ball_count}")
            for v in values:
                _check_number(s.name, name, v)
        else:
            _check_number(s.name, name, getattr(s, name))
    for r in s.ball_radius:
        if r >= s.race_radius:
            raise SceneError(f"scene {s.name!r}: field 'ball_radius' must be < race_radius = "
                             f"{s.race_radius:g} m (got {r:g} m)")
    if s.race_eccentricity >= s.race_radius:
        raise SceneError(f"scene {s.name!r}: field 'race_eccentricity' must be < race_radius = "
                         f"{s.race_radius:g} m (got {s.race_eccentricity:g} m)")


def _as_ball_tuple(scene_name: str, name: str, value: Any, count: int) -> tuple[float, ...]:
    if isinstance(value, (list, tuple, np.ndarray)):
        vals = [float(v) if isinstance(v, (int, float, np.floating, np.integer)) else v
                for v in value]
        if len(vals) == 1:
            vals = vals * count
    else:
        vals = [value] * count
    if len(vals) != count:
        raise SceneError(f"scene {scene_name!r}: field {name!r} has {len(vals)} values; it needs "
                         f"one or ball_count = {count}")
    return tuple(_check_number(scene_name, name, v) for v in vals)


def _build(data: Mapping[str, Any], scene_name: str) -> Scene:
    valid = {f.name for f in dataclasses.fields(Scene)}
    unknown = sorted(set(data) - valid)
    if unknown:
        raise SceneError(f"scene {scene_name!r}: unknown field(s) {unknown}; allowed: "
                         f"{sorted(valid)}")
    full = {**_DEFAULTS, **data}
    missing = sorted(valid - set(full))
    if missing:
        raise SceneError(f"scene {scene_name!r}: missing field(s) {missing}")
    count = full["ball_count"]
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise SceneError(f"scene {scene_name!r}: field 'ball_count' must be an integer >= 1 "
                         f"(got {count!r})")
    kwargs: dict[str, Any] = {"ball_count": int(count)}
    for name in valid - {"ball_count"}:
        v = full[name]
        if name in _NUMERIC_FIELDS:
            if _NUMERIC_FIELDS[name][4]:
                v = _as_ball_tuple(scene_name, name, v, int(count))
            else:
                v = _check_number(scene_name, name, v)
        elif not isinstance(v, str):
            raise SceneError(f"scene {scene_name!r}: field {name!r} must be text (got {v!r})")
        kwargs[name] = v
    return Scene(**kwargs)


def _apply_overrides(data: dict[str, Any], overrides: Mapping[str, Any], scene_name: str) -> None:
    for key, value in overrides.items():
        if key in _SHORTCUTS:
            for target in _SHORTCUTS[key]:
                data[target] = value
        else:
            data[key] = value
    if "ball_count" in overrides:
        # per-ball lists of the old length cannot follow a new count; a single value can
        for name, spec in _NUMERIC_FIELDS.items():
            v = data.get(name)
            if spec[4] and name not in overrides and isinstance(v, (list, tuple)) \
                    and len(set(v)) == 1:
                data[name] = v[0]


def _flatten_yaml(raw: Mapping[str, Any], scene_name: str) -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in raw.items():
        if key in _SECTION_PREFIX:
            if not isinstance(value, Mapping):
                raise SceneError(f"scene {scene_name!r}: section {key!r} must be a mapping")
            for sub, v in value.items():
                name = _SPECIAL_KEYS.get((key, sub), f"{_SECTION_PREFIX[key]}_{sub}")
                if name in _SHORTCUTS:
                    for target in _SHORTCUTS[name]:
                        flat[target] = v
                else:
                    flat[name] = v
        else:
            flat[key] = value
    return flat


# ---------------------------------------------------------------------------- loading
def scenes_dir() -> Path:
    """Folder of the named scenes: ``$ABB_GYM_CONFIGS/scenes`` or the checkout's ``configs/scenes``."""
    root = os.environ.get("ABB_GYM_CONFIGS")
    base = Path(root) if root else Path(__file__).resolve().parents[2] / "configs"
    return base / "scenes"


def list_scenes() -> list[str]:
    """Names of the scenes shipped in ``configs/scenes``."""
    return sorted(p.stem for p in scenes_dir().glob("*.yaml"))


def load_scene(name_or_path: str | os.PathLike | Scene, **overrides: Any) -> Scene:
    """Load a scene by name (``configs/scenes/<name>.yaml``) or path and apply overrides.

    Overrides are flat field names (see the module docstring), plus ``support_stiffness`` and
    ``support_damping`` which set both axes.  A Scene passed in is copied with the overrides.
    Raises :class:`SceneError` (a ValueError) naming the field and the allowed range.
    """
    if isinstance(name_or_path, Scene):
        return name_or_path.replace(**overrides) if overrides else name_or_path
    text = str(name_or_path)
    path = Path(text)
    if not (text.endswith((".yaml", ".yml")) or path.exists()):
        path = scenes_dir() / f"{text}.yaml"
        if not path.exists():
            raise SceneError(f"unknown scene {text!r}; available: {', '.join(list_scenes())} "
                             f"(or give a path to a YAML file)")
    if not path.exists():
        raise SceneError(f"scene file {str(path)!r} does not exist")
    try:
        raw = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise SceneError(f"scene file {str(path)!r} is not valid YAML: {exc}") from None
    if not isinstance(raw, Mapping):
        raise SceneError(f"scene file {str(path)!r} must hold a mapping of sections")
    scene_name = str(raw.get("name", path.stem))
    data = _flatten_yaml(raw, scene_name)
    data.setdefault("name", path.stem)
    _apply_overrides(data, overrides, scene_name)
    return _build(data, scene_name)
