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
gravity_acceleration            m/s^2       gravity in the balancing plane (horizontal-axis rotor),
                                            in [0, 100]; 0 = vertical axis (off)
gravity_angle                   rad         direction of gravity in the fixed x-y frame
                                            (default -pi/2: along -y, so y is "up")
contact_stiffness               N/m         ball-ball penalty stiffness, >= 0; 0 = no contact
contact_damping_ratio           -           damping ratio of the contact oscillation, in [0, 10]
                                            (default 0.5: restitution 0.16)
fluid_preset                    -           balancer fluid name (abb_gym.physics.fluids.FLUIDS),
                                            or empty
fluid_temperature               K           fluid temperature, in [250, 400] (default 298.15);
                                            only the Table 6.1 oils have a temperature law
fluid_density                   kg/m^3      explicit density, >= 0 (0 = from the preset)
fluid_viscosity                 m^2/s       explicit kinematic viscosity, >= 0 (0 = from the preset)
fluid_drag_law                  -           "linear" (ball_drag only, default), "stokes",
                                            "jan_chen_1997" or "spannan_2021" (fluids module)
fluid_stokes_drag               -           c_d Re of the Stokes regime, >= 0 (0 = the law's own)
fluid_drag_plateau              -           c_d above Re = 2e4 for "spannan_2021", >= 0 (0 = 0.6)
fluid_virtual_mass              -           virtual-mass coefficient c_vm (eq. 5.23; 2 for a
                                            sphere at a wall), in [0, 10]; 0 = off
friction_kinetic                -           kinetic race friction coefficient mu_k, in [0, 1]
friction_static                 -           static (adherence) coefficient mu_s, 0 or >= mu_k
friction_regularization_speed   m/s         tanh width u_reg of the friction law, > 0 (1e-4);
                                            small values make the balls stick
friction_stribeck_speed         m/s         speed over which mu_s falls to mu_k, > 0 (1e-3)
==============================  ==========  ==========================================================

YAML sections ``gravity``, ``contact``, ``fluid`` and ``friction`` map to the fields with those
prefixes (``fluid: {preset: S0.65, drag_law: spannan_2021}``).

Effects are switched on by their parameters, every one off by default: a scene whose rolling
resistance, race eccentricity, gravity, contact stiffness, fluid drag law, virtual mass and
friction are zero/"linear" runs a kernel path that never evaluates those terms (see
:attr:`Scene.effects`; the physics and when each effect matters are documented in
:mod:`abb_gym.physics.model`, :mod:`~abb_gym.physics.fluids`, :mod:`~abb_gym.physics.friction`
and :mod:`~abb_gym.physics.contact`).
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

from . import fluids as _fluids

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
    # extended physics (each 0 = off; see the module docstring)
    "gravity_acceleration": ("m/s^2", 0.0, True, 100.0, False),
    "gravity_angle": ("rad", None, True, None, False),
    "contact_stiffness": ("N/m", 0.0, True, None, False),
    "contact_damping_ratio": ("-", 0.0, True, 10.0, False),
    "fluid_temperature": ("K", 250.0, True, 400.0, False),
    "fluid_density": ("kg/m^3", 0.0, True, 2.0e4, False),
    "fluid_viscosity": ("m^2/s", 0.0, True, 1.0, False),
    "fluid_stokes_drag": ("-", 0.0, True, 1.0e5, False),
    "fluid_drag_plateau": ("-", 0.0, True, 100.0, False),
    "fluid_virtual_mass": ("-", 0.0, True, 10.0, False),
    "friction_kinetic": ("-", 0.0, True, 1.0, False),
    "friction_static": ("-", 0.0, True, 1.0, False),
    "friction_regularization_speed": ("m/s", 0.0, False, None, False),
    "friction_stribeck_speed": ("m/s", 0.0, False, None, False),
}
# text fields with a fixed set of values (checked in _validate)
_TEXT_FIELDS = ("description", "source", "fluid_preset", "fluid_drag_law")
_SECTION_PREFIX = {"rotor": "rotor", "support": "support", "race": "race", "balls": "ball",
                   "drive": "drive", "housing": "housing", "gravity": "gravity",
                   "contact": "contact", "fluid": "fluid", "friction": "friction"}
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
    "gravity_acceleration": 0.0,
    "gravity_angle": -0.5 * math.pi,
    "contact_stiffness": 0.0,
    "contact_damping_ratio": 0.5,
    "fluid_preset": "",
    "fluid_temperature": _fluids.T_NOMINAL,
    "fluid_density": 0.0,
    "fluid_viscosity": 0.0,
    "fluid_drag_law": "linear",
    "fluid_stokes_drag": 0.0,
    "fluid_drag_plateau": 0.0,
    "fluid_virtual_mass": 0.0,
    "friction_kinetic": 0.0,
    "friction_static": 0.0,
    "friction_regularization_speed": 1e-4,
    "friction_stribeck_speed": 1e-3,
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
    gravity_acceleration: float = 0.0
    gravity_angle: float = -0.5 * math.pi
    contact_stiffness: float = 0.0
    contact_damping_ratio: float = 0.5
    fluid_preset: str = ""
    fluid_temperature: float = _fluids.T_NOMINAL
    fluid_density: float = 0.0
    fluid_viscosity: float = 0.0
    fluid_drag_law: str = "linear"
    fluid_stokes_drag: float = 0.0
    fluid_drag_plateau: float = 0.0
    fluid_virtual_mass: float = 0.0
    friction_kinetic: float = 0.0
    friction_static: float = 0.0
    friction_regularization_speed: float = 1e-4
    friction_stribeck_speed: float = 1e-3
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
        if self.gravity_acceleration > 0:
            on.add("gravity")
        if self.contact_stiffness > 0:
            on.add("ball_contact")
        if self.fluid_drag_law != "linear":
            on.add("fluid_drag")
        if self.fluid_virtual_mass > 0:
            on.add("virtual_mass")
        if self.friction_kinetic > 0 or self.friction_static > 0:
            on.add("friction")
        if self.friction_static > self.friction_kinetic:
            on.add("stiction")
        return frozenset(on)

    @property
    def fluid_state(self) -> tuple[float, float]:
        """(density [kg/m^3], kinematic viscosity [m^2/s]) of the balancer fluid.

        Explicit ``fluid_density``/``fluid_viscosity`` win; otherwise the preset's values at
        ``fluid_temperature``; (0, 0) without a fluid."""
        rho, nu = 0.0, 0.0
        if self.fluid_preset:
            rho, nu = _fluids.fluid_properties(self.fluid_preset, self.fluid_temperature)
        return (self.fluid_density or rho, self.fluid_viscosity or nu)

    def fluid_linear_drag(self, cdre: float | None = None) -> np.ndarray:
        """Per-ball Stokes-regime race drag C (pi/4) rho nu r [N s/m] of this scene's fluid
        (Spannan eq. 5.26 divided by R^2): the ``ball_drag`` of the equivalent linear law.
        ``cdre`` None takes the drag law's own c_d Re."""
        rho, nu = self.fluid_state
        law = self.fluid_drag_law if self.fluid_drag_law != "linear" else "stokes"
        c = _fluids.law_coefficients(law, self.fluid_stokes_drag, self.fluid_drag_plateau)[1] \
            if cdre is None else cdre
        return _fluids.stokes_drag_coefficient(c, rho, nu, self.arrays()["ball_radius"])

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
    _validate_extended(s)


def _validate_extended(s: Scene) -> None:
    """Cross-field rules of the extended-physics fields (fluid, friction, contact)."""
    name = s.name
    if s.fluid_drag_law not in _fluids.DRAG_LAWS:
        raise SceneError(f"scene {name!r}: field 'fluid_drag_law' must be one of "
                         f"{list(_fluids.DRAG_LAWS)} (got {s.fluid_drag_law!r})")
    if s.fluid_preset and _fluids.canonical_fluid_name(s.fluid_preset) is None:
        raise SceneError(f"scene {name!r}: field 'fluid_preset' must be one of "
                         f"{list(_fluids.FLUIDS)} or empty (got {s.fluid_preset!r})")
    try:
        rho, nu = s.fluid_state
    except ValueError as exc:
        raise SceneError(f"scene {name!r}: field 'fluid_temperature' = {s.fluid_temperature:g} K "
                         f"does not fit fluid {s.fluid_preset!r}: {exc}") from None
    try:
        _fluids.law_coefficients(s.fluid_drag_law, s.fluid_stokes_drag, s.fluid_drag_plateau)
    except ValueError as exc:
        raise SceneError(f"scene {name!r}: field 'fluid_stokes_drag'/'fluid_drag_plateau': "
                         f"{exc}") from None
    if (s.fluid_drag_law != "linear" or s.fluid_virtual_mass > 0) and rho <= 0:
        raise SceneError(f"scene {name!r}: fluid_drag_law {s.fluid_drag_law!r} and "
                         f"fluid_virtual_mass need a fluid: set field 'fluid_preset' (one of "
                         f"{list(_fluids.FLUIDS)}) or 'fluid_density' > 0 [kg/m^3]")
    if s.fluid_drag_law != "linear" and nu <= 0:
        raise SceneError(f"scene {name!r}: fluid_drag_law {s.fluid_drag_law!r} needs field "
                         f"'fluid_viscosity' > 0 [m^2/s] or a 'fluid_preset'")
    if 0 < s.friction_static < s.friction_kinetic:
        raise SceneError(f"scene {name!r}: field 'friction_static' must be >= friction_kinetic "
                         f"= {s.friction_kinetic:g} (or 0 for no static peak) "
                         f"(got {s.friction_static:g})")
    if s.contact_stiffness > 0:
        big_r = s.race_radius
        width = sum(2.0 * math.asin(r / big_r) for r in s.ball_radius)
        if width > 2.0 * math.pi:
            raise SceneError(f"scene {name!r}: with ball contact the balls must fit in the race: "
                             f"field 'ball_count' x 'ball_radius' occupy {width:.3f} rad > 2 pi")
        for i in range(s.ball_count):
            for j in range(i + 1, s.ball_count):
                d = (s.ball_angles0[j] - s.ball_angles0[i] + math.pi) % (2 * math.pi) - math.pi
                chord = 2.0 * big_r * math.sin(0.5 * abs(d))
                reach = s.ball_radius[i] + s.ball_radius[j]
                if chord < reach * (1.0 - 1e-9):
                    raise SceneError(
                        f"scene {name!r}: field 'ball_angles0' puts balls {i} and {j} into "
                        f"each other (centre distance {chord:.4g} m < r_i + r_j = {reach:.4g} m); "
                        f"with ball contact the angles must differ by at least "
                        f"{2 * math.asin(min(1.0, reach / (2 * big_r))):.4g} rad")


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
        elif name == "fluid_preset" and v:
            v = _fluids.canonical_fluid_name(v) or v
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
