"""Scenes: validated, SI-unit parameter sets for one balancer machine.

A scene is one YAML file in ``configs/scenes/`` (or a user folder, or any path: see
:mod:`abb_gym.resources`), grouped into sections.  Every field has two names, accepted
everywhere a scene field is named (a YAML file, ``load_scene`` and ``Scene.replace``
keywords, ``abb-gym simulate --set``, the axes and ``--set`` of ``abb-gym stability-map``):
its YAML path (``balls.drag``) and its flat name (``ball_drag``), both in the table below.
Two shortcuts set both axes of the support: ``support.stiffness`` (``support_stiffness``)
and ``support.damping`` (``support_damping``)::

    scene = load_scene("yoshida_odd", ball_mass=2e-3, support_stiffness=2000.0)
    scene = load_scene("yoshida_odd", **{"balls.mass": 2e-3, "support.stiffness": 2000.0})

Units are SI throughout and angles are radians.  Per-ball fields accept one number (same for
every ball) or a list of ``ball_count`` numbers; ``support.stiffness`` and ``support.damping``
set both axes.  Fields, units and allowed ranges (declared once on :class:`Scene`; the bounds
keep every value in the range where the compiled model is meaningful and finite):

{table}

Cross-field rules: every ball radius < ``race_radius``, the race eccentricity <
``race_radius``, each rolling resistance <= its ball's radius, the rotor and race
eccentricities 0 or >= 1e-12 m (either may divide the whirl as the reference length),
``friction_static`` 0 or >= ``friction_kinetic``, a non-linear drag law or a virtual mass needs
a fluid, and with ball contact the balls must fit in the race without overlapping at their
initial angles.

The bounds keep every accepted scene usable by the compiled model: no division by zero, no
subnormal scale (the drive's smallest acceleration, speed and torque, the rotor's inertia and
the housing clearance are bounded away from 0), and every remaining stiffness (heavy drag,
tiny balls, stiff contact or support damping) is caught by the step rules and work bound of
:func:`~abb_gym.physics.simulate.simulate`, which then names a method that can take it.

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
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .. import resources
from ..configuration import ConfigError, check, declare, fields_table, locate, read_yaml, specs
from . import fluids as _fluids

__all__ = ["Scene", "load_scene", "list_scenes", "scenes_dir", "SceneError", "FIELD_NAMES",
           "resolve_field", "field_spec"]

ANGLE_LIMIT = 1.0e3  # rad: beyond it, rounding of the angle changes the machine
# m: smallest non-zero eccentricity.  Either one can be the reference length that divides the
# whirl (W_r/e); a subnormal one would make that ratio infinite.  1e-12 m is far below any
# balancing tolerance (the shipped scenes have 1e-5 to 1e-3 m).
MIN_ECCENTRICITY = 1.0e-12


def reference_length(rotor_eccentricity, race_eccentricity, capacity, total_mass):
    """:attr:`Scene.reference_length` [m] from its ingredients; ``rotor_eccentricity`` may be an
    array (the episodes of many environments)."""
    if race_eccentricity > 0:
        fallback = race_eccentricity
    else:
        fallback = capacity / total_mass
    return np.where(np.asarray(rotor_eccentricity) > 0, rotor_eccentricity, fallback)


class SceneError(ConfigError):
    """A scene file or override is invalid; the message names the field and its allowed range."""


def _angle(doc: str, default: Any = 0.0, yaml: str | None = None, per_ball: bool = False):
    return declare(default, unit="rad", ge=-ANGLE_LIMIT, le=ANGLE_LIMIT, doc=doc, yaml=yaml,
                   per_ball=per_ball)


@dataclass(frozen=True)
class Scene:
    """One balancer machine in SI units; see the module docstring for every field and range."""

    name: str = declare(kind="text", doc="scene name")
    rotor_mass: float = declare(unit="kg", ge=1e-4, le=1e5, yaml="rotor.mass",
                                doc="rotor and housing mass without the balls")
    rotor_eccentricity: float = declare(unit="m", ge=0.0, le=1.0, yaml="rotor.eccentricity",
                                        doc="offset of the rotor's mass centre (primary "
                                            "imbalance m0 e0 = rotor_mass * eccentricity)")
    rotor_polar_inertia: float = declare(unit="kg m^2", ge=1e-12, le=1e5,
                                         yaml="rotor.polar_inertia",
                                         doc="polar inertia of the spinning part (with a motor)")
    support_stiffness_x: float = declare(unit="N/m", ge=1e-3, le=1e12,
                                         yaml="support.stiffness_x", doc="support spring, x")
    support_stiffness_y: float = declare(unit="N/m", ge=1e-3, le=1e12,
                                         yaml="support.stiffness_y", doc="support spring, y")
    support_damping_x: float = declare(unit="N s/m", ge=0.0, le=1e9, yaml="support.damping_x",
                                       doc="support damper, x")
    support_damping_y: float = declare(unit="N s/m", ge=0.0, le=1e9, yaml="support.damping_y",
                                       doc="support damper, y")
    race_radius: float = declare(unit="m", ge=1e-4, le=10.0, yaml="race.radius",
                                 doc="radius of the ball-centre track")
    ball_count: int = declare(kind="integer", ge=1, le=64, yaml="balls.count",
                              doc="number of balls")
    ball_mass: tuple[float, ...] = declare(unit="kg", ge=1e-7, le=1e3, yaml="balls.mass",
                                           per_ball=True, doc="per ball")
    ball_radius: tuple[float, ...] = declare(unit="m", ge=1e-5, le=1.0, yaml="balls.radius",
                                             per_ball=True, doc="per ball, < race_radius")
    ball_drag: tuple[float, ...] = declare(unit="N s/m", ge=0.0, le=1e6, yaml="balls.drag",
                                           per_ball=True,
                                           doc="race drag per relative orbit speed (Spannan's "
                                               "torque coefficient = ball_drag R^2)")
    drive_torque_limit: float = declare(unit="N m", ge=1e-9, le=1e6, yaml="drive.torque_limit",
                                        doc="motor torque limit")
    drive_max_acceleration: float = declare(unit="rad/s^2", ge=1e-3, le=1e6,
                                            yaml="drive.max_acceleration",
                                            doc="largest commanded rotor acceleration")
    drive_operating_speed: float = declare(unit="rad/s", ge=1e-3, le=1e5,
                                           yaml="drive.operating_speed",
                                           doc="target operating speed")
    housing_clearance: float = declare(unit="m", ge=1e-7, le=10.0, yaml="housing.clearance",
                                       doc="largest whirl radius the housing allows")
    bearing_drag: float = declare(0.0, unit="N m s", ge=0.0, le=1e6, yaml="rotor.bearing_drag",
                                  doc="viscous drag torque on the rotor spin")
    race_eccentricity: float = declare(0.0, unit="m", ge=0.0, le=1.0,
                                       yaml="race.eccentricity",
                                       doc="offset E of the race centre, < race_radius")
    race_eccentricity_angle: float = _angle("angle gamma of that offset, from the imbalance",
                                            yaml="race.eccentricity_angle")
    ball_inertia_factor: tuple[float, ...] = declare((0.4,), ge=0.0, le=1.0, per_ball=True,
                                                     yaml="balls.inertia_factor",
                                                     doc="spin inertia J = factor m r^2 (0.4 "
                                                         "solid sphere, 0 point mass)")
    ball_rolling_resistance: tuple[float, ...] = declare((0.0,), unit="m", ge=0.0, le=1e-2,
                                                         per_ball=True,
                                                         yaml="balls.rolling_resistance",
                                                         doc="rolling-resistance offset beta_b "
                                                             "(Yoshida eq. 2-8)")
    ball_angles0: tuple[float, ...] = _angle("default initial ball angles from the imbalance",
                                             default=(0.0,), yaml="balls.angles0",
                                             per_ball=True)
    rolling_regularization_speed: float = declare(1e-3, unit="m/s", ge=1e-9, le=10.0,
                                                  yaml="balls.rolling_regularization_speed",
                                                  doc="tanh width replacing sign() in the "
                                                      "rolling resistance")
    gravity_acceleration: float = declare(0.0, unit="m/s^2", ge=0.0, le=100.0,
                                          yaml="gravity.acceleration",
                                          doc="gravity in the balancing plane (horizontal "
                                              "axis); 0 = vertical axis (off)")
    gravity_angle: float = _angle("direction of gravity in the fixed frame (-pi/2: along -y)",
                                  default=-0.5 * math.pi, yaml="gravity.angle")
    contact_stiffness: float = declare(0.0, unit="N/m", ge=0.0, le=1e12,
                                       yaml="contact.stiffness",
                                       doc="ball-ball penalty stiffness; 0 = no contact")
    contact_damping_ratio: float = declare(0.5, ge=0.0, le=10.0, yaml="contact.damping_ratio",
                                           doc="damping ratio of the contact (0.5: "
                                               "restitution 0.16)")
    fluid_preset: str = declare("", kind="text", yaml="fluid.preset",
                                doc="balancer fluid (abb_gym.physics.fluids.FLUIDS) or empty")
    fluid_temperature: float = declare(_fluids.T_NOMINAL, unit="K", ge=250.0, le=400.0,
                                       yaml="fluid.temperature",
                                       doc="fluid temperature (Table 6.1 oils only)")
    fluid_density: float = declare(0.0, unit="kg/m^3", ge=0.0, le=2.0e4, yaml="fluid.density",
                                   doc="explicit density (0 = from the preset)")
    fluid_viscosity: float = declare(0.0, unit="m^2/s", ge=0.0, le=1.0,
                                     yaml="fluid.viscosity",
                                     doc="explicit kinematic viscosity (0 = from the preset)")
    fluid_drag_law: str = declare("linear", kind="choice", choices=tuple(_fluids.DRAG_LAWS),
                                  yaml="fluid.drag_law",
                                  doc="race drag law (linear = ball_drag only)")
    fluid_stokes_drag: float = declare(0.0, ge=0.0, le=1.0e5, yaml="fluid.stokes_drag",
                                       doc="c_d Re of the Stokes regime (0 = the law's own)")
    fluid_drag_plateau: float = declare(0.0, ge=0.0, le=100.0, yaml="fluid.drag_plateau",
                                        doc="c_d above Re = 2e4, spannan_2021 (0 = 0.6)")
    fluid_virtual_mass: float = declare(0.0, ge=0.0, le=10.0, yaml="fluid.virtual_mass",
                                        doc="virtual-mass coefficient (2: sphere at a wall); "
                                            "0 = off")
    friction_kinetic: float = declare(0.0, ge=0.0, le=1.0, yaml="friction.kinetic",
                                      doc="kinetic race friction coefficient")
    friction_static: float = declare(0.0, ge=0.0, le=1.0, yaml="friction.static",
                                     doc="static (adherence) coefficient, 0 or >= kinetic")
    friction_regularization_speed: float = declare(1e-4, unit="m/s", ge=1e-9, le=10.0,
                                                   yaml="friction.regularization_speed",
                                                   doc="tanh width of the friction law; small "
                                                       "values make the balls stick")
    friction_stribeck_speed: float = declare(1e-3, unit="m/s", ge=1e-9, le=10.0,
                                             yaml="friction.stribeck_speed",
                                             doc="speed over which mu_s falls to mu_k")
    description: str = declare("", kind="text", doc="what the machine is")
    source: str = declare("", kind="text", doc="where the values come from")

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
        return float(reference_length(self.rotor_eccentricity, self.race_eccentricity,
                                      self.balancing_capacity, self.total_mass))

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
                for name, spec in _SPECS.items() if spec.per_ball}


_SPECS = specs(Scene)
__doc__ = __doc__.replace("{table}", fields_table(Scene, [n for n in _SPECS if n != "name"],
                                                  title="YAML path", flat_names=True))
_DEFAULTS = {f.name: f.default for f in dataclasses.fields(Scene)
             if f.default is not dataclasses.MISSING}
# YAML path -> field; support.stiffness and support.damping set both axes
_BY_PATH = {(spec.yaml or name): name for name, spec in _SPECS.items()}
_SHORTCUTS = {"support_stiffness": ("support_stiffness_x", "support_stiffness_y"),
              "support_damping": ("support_damping_x", "support_damping_y")}
_SECTIONS = {path.split(".")[0] for path in _BY_PATH if "." in path}


def _field_names() -> dict[str, tuple[str, ...]]:
    names: dict[str, tuple[str, ...]] = {}
    for name, spec in _SPECS.items():
        names[name] = (name,)
        if spec.yaml:
            names[spec.yaml] = (name,)
    for short, targets in _SHORTCUTS.items():
        section, _, key = short.partition("_")
        names[short] = names[f"{section}.{key}"] = targets
    return names


#: every accepted name of a scene field -> the field(s) it sets: the flat name
#: (``ball_drag``), the YAML path (``balls.drag``) and the two-axis support shortcuts, all
#: derived from the declarations on :class:`Scene`
FIELD_NAMES: dict[str, tuple[str, ...]] = _field_names()


def resolve_field(name: Any, where: str = "scene") -> tuple[str, ...]:
    """The field(s) a scene field name sets (:data:`FIELD_NAMES`: ``"balls.drag"`` and
    ``"ball_drag"`` both give ``("ball_drag",)``); an unknown name is a :class:`SceneError`
    naming the closest ones."""
    if isinstance(name, str) and name in FIELD_NAMES:
        return FIELD_NAMES[name]
    import difflib
    close = difflib.get_close_matches(str(name), list(FIELD_NAMES), n=3, cutoff=0.6)
    hint = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
    raise SceneError(f"{where}: unknown field(s) [{name!r}]{hint} (a scene field is named by "
                     f"its YAML path, e.g. 'balls.drag', or its flat name, e.g. 'ball_drag': "
                     f"see abb_gym.physics.scene)")


def field_spec(name: str) -> tuple[str, Any]:
    """(flat name, :class:`~abb_gym.configuration.Spec`) of the scene field ``name`` (either
    spelling; a support shortcut gives its x axis), e.g. for an axis label with a unit."""
    field = resolve_field(name)[0]
    return field, _SPECS[field]


# ---------------------------------------------------------------------------- validation
def _validate(s: Scene) -> None:
    for name, spec in _SPECS.items():
        value = getattr(s, name)
        if spec.per_ball:
            if not isinstance(value, tuple) or len(value) != s.ball_count:
                raise SceneError(f"scene {s.name!r}: field {name!r} needs one value or "
                                 f"ball_count = {s.ball_count} values (got {value!r})")
            for v in value:
                check(f"scene {s.name!r}", name, v, spec, SceneError)
        else:
            check(f"scene {s.name!r}", name, value, spec, SceneError)
    for r in s.ball_radius:
        if r >= s.race_radius:
            raise SceneError(f"scene {s.name!r}: field 'ball_radius' must be < race_radius = "
                             f"{s.race_radius:g} m (got {r:g} m)")
    for name in ("rotor_eccentricity", "race_eccentricity"):
        value = getattr(s, name)
        if 0.0 < value < MIN_ECCENTRICITY:
            raise SceneError(f"scene {s.name!r}: field {name!r} must be 0 or >= "
                             f"{MIN_ECCENTRICITY:g} m (got {value:g} m): it may set the "
                             f"reference length that divides the whirl")
    for r, beta in zip(s.ball_radius, s.ball_rolling_resistance):
        if beta > r:
            # the normal force acts inside the contact patch, whose size is below the radius
            raise SceneError(f"scene {s.name!r}: field 'ball_rolling_resistance' must be <= "
                             f"the ball radius {r:g} m (the lever arm of the race normal "
                             f"force lies inside the ball; got {beta:g} m)")
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
    # a 0-d array is one value (list() of it raises TypeError); anything else that is not a
    # list is one value too, which check() then accepts or refuses naming the field
    is_list = isinstance(value, (list, tuple)) or (isinstance(value, np.ndarray)
                                                   and value.ndim > 0)
    vals = list(value) if is_list else [value]
    if len(vals) == 1:
        vals = vals * count
    if len(vals) != count:
        raise SceneError(f"scene {scene_name!r}: field {name!r} has {len(vals)} values; it needs "
                         f"one or ball_count = {count}")
    return tuple(check(f"scene {scene_name!r}", name, v, _SPECS[name], SceneError) for v in vals)


def _build(data: Mapping[str, Any], scene_name: str) -> Scene:
    valid = set(_SPECS)
    unknown = sorted(set(data) - valid, key=str)  # a YAML key may be a number
    if unknown:
        raise SceneError(f"scene {scene_name!r}: unknown field(s) {unknown}; allowed: "
                         f"{sorted(valid)}")
    full = {**_DEFAULTS, **data}
    missing = sorted(valid - set(full))
    if missing:
        raise SceneError(f"scene {scene_name!r}: missing field(s) {missing}")
    where = f"scene {scene_name!r}"
    count = check(where, "ball_count", full["ball_count"], _SPECS["ball_count"], SceneError)
    kwargs: dict[str, Any] = {"ball_count": count}
    for name in valid - {"ball_count"}:
        v = full[name]
        if _SPECS[name].per_ball:
            v = _as_ball_tuple(scene_name, name, v, count)
        else:
            v = check(where, name, v, _SPECS[name], SceneError)
            if name == "fluid_preset" and v:
                v = _fluids.canonical_fluid_name(v) or v
        kwargs[name] = v
    return Scene(**kwargs)


def _apply_overrides(data: dict[str, Any], overrides: Mapping[str, Any], scene_name: str) -> None:
    """``overrides`` (by either name of a field, :data:`FIELD_NAMES`) written into ``data``;
    one field given twice (``ball_drag`` and ``balls.drag``) is refused."""
    given: dict[str, str] = {}
    for key, value in overrides.items():
        for target in resolve_field(key, f"scene {scene_name!r}"):
            if target in given:
                raise SceneError(f"scene {scene_name!r}: field {target!r} is given twice "
                                 f"(as {given[target]!r} and {key!r})")
            given[target] = key
            data[target] = value
    if "ball_count" in given:
        # per-ball lists of the old length cannot follow a new count; a single value can
        for name, spec in _SPECS.items():
            v = data.get(name)
            if spec.per_ball and name not in given and isinstance(v, (list, tuple)) \
                    and _uniform(v):
                data[name] = v[0]


def _uniform(values: list | tuple) -> bool:
    """True if every entry is the same plain number (entries of any other kind, which may not
    even compare, are left for the field check to refuse)."""
    if not values or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                             for v in values):
        return False
    return all(v == values[0] for v in values)


def _flatten_yaml(raw: Mapping[str, Any], scene_name: str) -> dict[str, Any]:
    """YAML sections -> fields by the declared paths (``rotor.mass`` -> ``rotor_mass``)."""
    flat: dict[str, Any] = {}
    for key, value in raw.items():
        if key in _SECTIONS:
            if not isinstance(value, Mapping):
                raise SceneError(f"scene {scene_name!r}: section {key!r} must be a mapping")
            for sub, v in value.items():
                path = f"{key}.{sub}"
                if not isinstance(sub, str):
                    raise SceneError(f"scene {scene_name!r}: key {sub!r} in section {key!r} "
                                     f"must be a field name; allowed: "
                                     f"{sorted(p for p in _BY_PATH if p.startswith(key + '.'))}")
                shortcut = f"{key}_{sub}"
                if shortcut in _SHORTCUTS:
                    for target in _SHORTCUTS[shortcut]:
                        flat[target] = v
                elif path in _BY_PATH:
                    flat[_BY_PATH[path]] = v
                else:
                    raise SceneError(f"scene {scene_name!r}: unknown key {path!r}; allowed in "
                                     f"section {key!r}: "
                                     f"{sorted(p for p in _BY_PATH if p.startswith(key + '.'))}")
        elif isinstance(key, str) and key in FIELD_NAMES:  # a flat name at the top level
            for target in FIELD_NAMES[key]:
                flat[target] = value
        else:
            flat[key] = value  # refused by _build, with the other unknown keys
    return flat


# ---------------------------------------------------------------------------- loading
def scenes_dir() -> Path:
    """Folder of the shipped scenes (``configs/scenes``, package data in a wheel)."""
    return resources.shipped_folder("scenes")


def list_scenes() -> list[str]:
    """Names of the scenes on the search path (user folders and the shipped ones)."""
    return resources.names("scenes")


def load_scene(name_or_path: str | os.PathLike | Scene, **overrides: Any) -> Scene:
    """Load a scene by name (on the search path of :mod:`abb_gym.resources`) or path and
    apply overrides.

    Overrides name a field by its flat name or its YAML path (``ball_drag=2.0`` or
    ``**{"balls.drag": 2.0}``: :data:`FIELD_NAMES`), plus ``support_stiffness`` and
    ``support_damping`` which set both axes.  A Scene passed in is copied with the overrides.
    Raises :class:`SceneError` (a ValueError) naming the field and the allowed range.
    """
    if isinstance(name_or_path, Scene):
        return name_or_path.replace(**overrides) if overrides else name_or_path
    if not isinstance(name_or_path, (str, os.PathLike)):
        raise SceneError(f"scene must be a scene name, a path or a Scene (got "
                         f"{name_or_path!r})")
    path = locate("scenes", name_or_path, "scene", SceneError)
    raw = read_yaml(path, "scene", SceneError)
    scene_name = str(raw.get("name", path.stem))
    data = _flatten_yaml(raw, scene_name)
    data.setdefault("name", path.stem)
    _apply_overrides(data, overrides, scene_name)
    return _build(data, scene_name)
