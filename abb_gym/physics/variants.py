"""Machine variants: a scene with its load, imbalance, race drag, rolling resistance, support
damping or fluid temperature changed, as a Scene and as packed kernel rows.

An environment's episode is its nominal scene changed in a few of these quantities (the
episode parameters of :mod:`abb_gym.envs.episode_parameters`).  This module is the one place
that knows how each change maps onto the scene and onto the packed parameters of
:func:`abb_gym.physics.model.pack_parameters`:

* :func:`variant_scene` builds the changed Scene (validated, ~0.3 ms);
* :func:`packed_variants` writes the packed rows of many variants at once, without building
  their scenes (a few microseconds per row), computing each changed entry the way the Scene
  and :func:`~abb_gym.physics.model.pack_parameters` compute it, so that
  ``packed_variants(scene, n, **values)[r]`` equals ``pack_parameters(variant_scene(scene,
  **values[r]))`` bit for bit (``tests/test_episodes.py`` holds the two together).

The changes are declared once, in :data:`CHANGES` (a value equal to the nominal one leaves the
scene as it is); the list below is generated from them:

"""
from __future__ import annotations

import math
from typing import Any, Callable, NamedTuple

import numpy as np

from . import model as mdl
from . import rotor
from .scene import Scene, SceneError, reference_length

__all__ = ["CHANGES", "loaded_rotor_mass", "loaded_polar_inertia", "rotor_eccentricity",
           "variant_scene", "packed_variants", "check_machine", "machine_rates",
           "RATE_CHANGES", "rates_vary", "References", "references"]

#: ball columns that depend on the balancer fluid's state (density, viscosity)
FLUID_COLUMNS = np.array([mdl.B_VM, mdl.B_KLIN, mdl.B_KQUAD, mdl.B_REU, mdl.B_MEFF, mdl.B_CI,
                          mdl.B_II, mdl.B_INV])


class Change(NamedTuple):
    """One change a variant may make: its unit, its nominal value on a scene, what it does and
    whether it alters the machine's mass or support damping (``rates``: the rates that bound a
    fixed step, :func:`machine_rates`, and its reference amplitudes)."""

    unit: str
    nominal: Callable[[Scene], float]
    doc: str
    rates: bool = False


def _one(scene: Scene) -> float:
    return 1.0


#: the changes a variant may make, by name (the episode parameters of the same name)
CHANGES: dict[str, Change] = {
    "imbalance": Change("kg m", lambda scene: scene.imbalance, "primary imbalance U0, through "
                        "the rotor eccentricity ``U0 / rotor mass``"),
    "ball_drag_scale": Change("-", _one, "factor on every ball's race drag"),
    "rolling_resistance_scale": Change("-", _one,
                                       "factor on every ball's rolling-resistance offset"),
    "critical_speed_scale": Change(
        "-", _one, "factor s on the critical speeds ``sqrt(k / M)`` through the supported mass "
        "``M / s^2`` (a load: laundry, sample tubes); the rotor carries the change, its polar "
        "inertia in proportion to its mass (a load spread like the rotor)", rates=True),
    "support_damping_scale": Change("-", _one, "factor on the support damping (both axes)",
                                    rates=True),
    "fluid_temperature": Change("K", lambda scene: scene.fluid_temperature,
                                "the balancer fluid's temperature (its viscosity and density: "
                                ":func:`abb_gym.physics.fluids.fluid_properties`)"),
}

#: the changes that alter a machine's mass or support damping, and so the rates that bound a
#: fixed step (:func:`machine_rates`) and its reference amplitudes
RATE_CHANGES = tuple(name for name, change in CHANGES.items() if change.rates)


if __doc__:
    __doc__ += "\n".join(f"* ``{name}`` [{change.unit}]: {change.doc}"
                         for name, change in CHANGES.items()) + "\n"


def _check_names(values: dict[str, Any]) -> None:
    unknown = sorted(set(values) - set(CHANGES))
    if unknown:
        raise ValueError(f"unknown machine change(s) {unknown}; allowed: {list(CHANGES)}")


class _Values(NamedTuple):
    """The changes of one variant (floats) or of many (arrays over them), each its nominal
    value where it is not given (or None)."""

    imbalance: Any    # [kg m]
    drag: Any         # factor on the race drag
    rolling: Any      # factor on the rolling resistance
    critical: Any     # factor s on the critical speeds
    damping: Any      # factor on the support damping
    temperature: Any  # [K] the fluid's


def _values(scene: Scene, values: dict[str, Any], n: int | None = None) -> _Values:
    """``values`` (change name -> value) as :class:`_Values`: floats, or with ``n`` arrays of
    ``n`` variants (one number broadcast)."""
    _check_names(values)

    def value(name: str):
        given = values.get(name)
        if n is None:
            return float(CHANGES[name].nominal(scene) if given is None else given)
        if given is None:
            return np.full(n, float(CHANGES[name].nominal(scene)))
        column = np.asarray(given, float)
        # (read only here; np.broadcast_to costs microseconds per reset and column)
        return column if column.shape == (n,) else np.broadcast_to(column, (n,))

    return _Values(value("imbalance"), value("ball_drag_scale"), value("rolling_resistance_scale"),
                   value("critical_speed_scale"), value("support_damping_scale"),
                   value("fluid_temperature"))


def _at_temperature(scene: Scene, temperature: float) -> dict[str, float]:
    """The Scene change that puts the fluid of ``scene`` at ``temperature`` [K] (none at the
    scene's own temperature)."""
    return ({} if temperature == scene.fluid_temperature
            else {"fluid_temperature": float(temperature)})


def loaded_rotor_mass(scene: Scene, scale):
    """Rotor mass [kg] that scales the critical speeds ``sqrt(k / M)`` of ``scene`` by
    the factor ``scale`` s (a number or an array): the supported mass becomes ``M / s^2``
    and the rotor (with its load) carries all of the change, ``M / s^2 - sum m_i``; exactly the
    scene's rotor mass for s = 1."""
    s = np.asarray(scale, float)
    loaded = scene.total_mass / (s * s) - float(sum(scene.ball_mass))
    out = np.where(s == 1.0, scene.rotor_mass, loaded)
    return float(out) if out.ndim == 0 else out


def loaded_polar_inertia(scene: Scene, rotor_mass):
    """The loaded rotor's polar inertia [kg m^2]: proportional to its mass (a load spread like
    the rotor), exactly the scene's at the scene's mass."""
    m = np.asarray(rotor_mass, float)
    out = np.where(m == scene.rotor_mass, scene.rotor_polar_inertia,
                   scene.rotor_polar_inertia * (m / scene.rotor_mass))
    return float(out) if out.ndim == 0 else out


def rotor_eccentricity(scene: Scene, imbalance: np.ndarray, rotor_mass=None) -> np.ndarray:
    """The variants' rotor eccentricity [m] (the nominal one where the imbalance and the rotor
    mass are the nominal ones); ``rotor_mass`` [kg]: each variant's (default the scene's)."""
    if rotor_mass is None:
        return np.where(imbalance != scene.imbalance, imbalance / scene.rotor_mass,
                        scene.rotor_eccentricity)
    return np.where((imbalance != scene.imbalance) | (rotor_mass != scene.rotor_mass),
                    imbalance / rotor_mass, scene.rotor_eccentricity)


def variant_scene(scene: Scene, **values: float) -> Scene:
    """``scene`` with the changes ``values`` (names of :data:`CHANGES`; module docstring);
    raises SceneError if the changed scene is not valid."""
    v = _values(scene, values)
    changes: dict[str, Any] = {}
    mass = scene.rotor_mass
    if v.critical != 1.0:
        mass = loaded_rotor_mass(scene, v.critical)
        changes["rotor_mass"] = mass
        changes["rotor_polar_inertia"] = loaded_polar_inertia(scene, mass)
    if v.imbalance != scene.imbalance or mass != scene.rotor_mass:
        changes["rotor_eccentricity"] = v.imbalance / mass
    if v.damping != 1.0:
        changes["support_damping_x"] = scene.support_damping_x * v.damping
        changes["support_damping_y"] = scene.support_damping_y * v.damping
    if v.drag != 1.0:
        changes["ball_drag"] = [x * v.drag for x in scene.ball_drag]
    if v.rolling != 1.0:
        changes["ball_rolling_resistance"] = [x * v.rolling
                                              for x in scene.ball_rolling_resistance]
    changes.update(_at_temperature(scene, v.temperature))
    return scene.replace(**changes) if changes else scene


def packed_variants(scene: Scene, n: int, **values) -> tuple[np.ndarray, np.ndarray]:
    """``(p, b)`` of ``n`` variants of ``scene``, shapes (n, N_PARAMS) and (n, balls,
    N_BALL_PARAMS): ``values`` maps change names (:data:`CHANGES`) to arrays over the variants
    (or one number; a missing or None change is the nominal value).  Equal bit for bit to
    packing each :func:`variant_scene` (module docstring)."""
    p0, b0 = mdl.pack_parameters(scene)
    p = np.repeat(p0[None], n, axis=0)
    b = np.repeat(b0[None], n, axis=0)
    v = _values(scene, values, n)
    if np.any(v.critical != 1.0):
        mass = np.asarray(loaded_rotor_mass(scene, v.critical), float).reshape(n)
        p[:, mdl.P_MASS] = mass + float(sum(scene.ball_mass))          # Scene.total_mass
        p[:, mdl.P_J] = loaded_polar_inertia(scene, mass)
        p[:, mdl.P_U0] = mass * rotor_eccentricity(scene, v.imbalance, mass)
    else:
        p[:, mdl.P_U0] = scene.rotor_mass * rotor_eccentricity(scene, v.imbalance)
    scaled = v.damping != 1.0
    p[scaled, mdl.P_CX] = scene.support_damping_x * v.damping[scaled]
    p[scaled, mdl.P_CY] = scene.support_damping_y * v.damping[scaled]
    a = scene.arrays()
    scaled = v.drag != 1.0
    b[scaled, :, mdl.B_BETA] = (a["ball_drag"][None, :] * v.drag[scaled, None]
                                * scene.race_radius ** 2)
    scaled = v.rolling != 1.0
    rr = a["ball_rolling_resistance"][None, :] * v.rolling[scaled, None]
    b[scaled, :, mdl.B_MUR] = rr / a["ball_radius"]
    p[scaled, mdl.P_ROLL] = np.where((rr > 0).any(axis=1), 1.0, 0.0)  # Scene.effects
    for t in np.unique(v.temperature):
        warmer = _at_temperature(scene, t)
        if warmer:
            # the fluid's columns (viscosity and density) as pack_parameters computes them for
            # the scene at that temperature; the drag and rolling-resistance columns are not
            # the fluid's and keep their scaling
            rows = v.temperature == t
            b_t = mdl.pack_parameters(scene.replace(**warmer))[1]
            b[np.ix_(rows, np.arange(b.shape[1]), FLUID_COLUMNS)] = b_t[:, FLUID_COLUMNS]
    return p, b


def rates_vary(values: dict[str, Any]) -> bool:
    """Whether the variants ``values`` (change name -> array) differ from the nominal scene in
    a change of :data:`RATE_CHANGES`."""
    return any(values.get(name) is not None and bool(np.any(np.asarray(values[name]) != 1.0))
               for name in RATE_CHANGES)


class References(NamedTuple):
    """What normalises the rewards and metrics of each packed variant (arrays over them)."""

    imbalance_scale: np.ndarray      # [kg m]: rotor.imbalance_scale
    best_residual: np.ndarray        # [kg m]: rotor.best_residual
    peak_amplitude: np.ndarray       # [m]: rotor.reference_amplitudes, peak over [0, w_op]
    operating_amplitude: np.ndarray  # [m]: the same at w_op
    static_deflection: np.ndarray    # (n, 2) [m]: the rest position
    reference_length: np.ndarray     # [m]: Scene.reference_length


def references(scene: Scene, p: np.ndarray, operating_speed: float, **values) -> References:
    """The :class:`References` of the packed variants ``p`` of ``scene`` (``values``: their
    changes, as given to :func:`packed_variants`), each equal to what the functions of
    :mod:`abb_gym.physics.rotor` give for its :func:`variant_scene`."""
    n = p.shape[0]
    v = _values(scene, values, n)
    varied = rates_vary(values)
    mass = p[:, mdl.P_MASS]
    if varied:
        sag = np.column_stack(np.broadcast_arrays(*rotor.static_deflection(scene, mass)))
        sag = np.array(np.broadcast_to(sag, (n, 2)))
    else:
        sag = np.tile(np.array(rotor.static_deflection(scene)), (n, 1))
    u0 = p[:, mdl.P_U0]
    u_ref = rotor.imbalance_scale(scene, u0)
    if varied:
        # the machine of each variant with its balancer off
        a_peak, a_op = rotor.reference_amplitudes(scene, operating_speed, u_ref, mass=mass,
                                                  damping_scale=v.damping)
        rotor_mass = (np.asarray(loaded_rotor_mass(scene, v.critical), float).reshape(n)
                      if np.any(v.critical != 1.0) else None)
        ref = reference_length(rotor_eccentricity(scene, v.imbalance, rotor_mass),
                               scene.race_eccentricity, scene.balancing_capacity, mass)
    else:
        a_peak, a_op = rotor.reference_amplitudes(scene, operating_speed, u_ref)
        ref = reference_length(rotor_eccentricity(scene, v.imbalance), scene.race_eccentricity,
                               scene.balancing_capacity, scene.total_mass)
    return References(np.broadcast_to(np.asarray(u_ref, float), (n,)),
                      np.broadcast_to(np.asarray(rotor.best_residual(scene, u0), float), (n,)),
                      np.broadcast_to(np.asarray(a_peak, float), (n,)),
                      np.broadcast_to(np.asarray(a_op, float), (n,)), sag,
                      np.broadcast_to(np.asarray(ref, float), (n,)))


def machine_rates(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each packed variant's ``critical_speeds[1]`` [rad/s] and
    :func:`~abb_gym.physics.simulate.explicit_rate` [1/s] without a drive (what
    :func:`~abb_gym.physics.simulate.default_step` reads from a Scene, computed the same
    way)."""
    mass = p[:, mdl.P_MASS]
    return (np.sqrt(p[:, mdl.P_KY] / mass),
            np.maximum(p[:, mdl.P_CX], p[:, mdl.P_CY]) / mass)


def check_machine(scene: Scene, where: str, error: type[ValueError], **values: float) -> None:
    """Raise ``error`` naming ``where`` unless the variant of ``scene`` with the changes
    ``values`` (names of :data:`CHANGES`) is a valid machine (a rotor mass left, within the
    scene's bounds) whose rest position, under gravity, lies inside the housing clearance."""
    v = _values(scene, values)
    # the changes that make this variant, in the errors' words
    given = [f"{name}={float(x):g}" for name, x in values.items()
             if x is not None and float(x) != CHANGES[name].nominal(scene)]
    if not given:
        return
    machine = " and ".join(given)
    balls = float(sum(scene.ball_mass))
    if loaded_rotor_mass(scene, v.critical) <= 0.0:
        raise error(f"{where}: with {machine} the supported mass M / s^2 = "
                    f"{scene.total_mass / v.critical ** 2:g} kg would not even carry the balls "
                    f"({balls:g} kg): no rotor mass left; use a smaller scale (below "
                    f"{math.sqrt(scene.total_mass / balls):.4g})")
    try:
        sc = variant_scene(scene, **values)
    except (SceneError, ValueError) as exc:
        raise error(f"{where}: the machine with {machine} is not a valid scene: {exc}") from None
    sag = math.hypot(*rotor.static_deflection(sc))
    if sag >= scene.housing_clearance:
        raise error(f"{where}: with {machine} the supported mass {sc.total_mass:g} kg sags "
                    f"{sag:g} m under gravity, beyond the housing clearance "
                    f"{scene.housing_clearance:g} m; use a larger scale")
