"""Episodes: what each environment draws, and the rows of many environments reset at once.

An episode is the nominal scene with a drawn primary imbalance and phase, initial ball angles,
scaled ball drag and rolling resistance, and, where a preset randomises them, a scaled critical
speed (through the supported mass: :func:`loaded_rotor_mass`) and support damping (the
preset's ``randomize`` ranges), or the values given as reset options.  With a noisy
synchronous-vibration observation it also draws the key of its sensor noise
(:mod:`abb_gym.physics.sensors`).

* :func:`draw` takes one environment's values from its own generator in a fixed order, with
  one ``rng.random`` call (the numbers ``rng.uniform`` would give one by one: ``low + (high -
  low) u``), then the noise key (``rng.integers``, only when the observation is noisy), then
  applies the reset options.  A randomised parameter added later takes its number after the
  existing ones, so presets that leave it off draw the same episodes as before.
* :func:`prepare` computes what resetting many rows at once writes: the packed parameters,
  the initial state, the drive rows and the bookkeeping of the compiled step, with numpy over
  the rows plus one compiled call for the stiff rates that set each episode's integration
  step; it changes nothing, so a reset it rejects leaves every row as it was.
  :func:`commit` then writes it (``EnvSetup.reset_rows`` does both).  The single
  environment resets through the same functions with one row, so a single environment and a
  sub-environment of the vector environment stay alike bit for bit.  It reproduces exactly
  what packing the episode's Scene would give (``tests/test_episodes.py`` checks the packed
  parameters, the reference length and the integration step against :meth:`Episode.scene`).
* :class:`EpisodeTable` keeps the values of every row; :class:`Episode` is one row's view,
  whose Scene is built only when asked for (building and validating a Scene costs ~0.3 ms, the
  reset of a row without it a few microseconds).

**Angles** (``imbalance_phase``, ``ball_angles``, given or drawn) are reduced to [-pi, pi] with
the exact IEEE remainder: an angle and the same angle plus any multiple of 2 pi (as floats:
``1e16`` and ``np.mod(1e16, 2 pi)``) give the same machine bit for bit, and the compiled
sin/cos, accurate to ``|x| <= 1.6e6`` rad (:mod:`abb_gym.physics.elementary`), never see a
huge one.  Angles already in [-pi, pi] (every shipped scene and preset) are left as they are.

**Stiff episodes.**  Under RK4 an episode's step is bounded by its stiff rate (the ball drag
and rolling resistance, :func:`abb_gym.physics.steps.default_step`).  An episode whose
stiff rate forces a step more than :data:`MAX_STIFFNESS` times shorter than the step its
rotation needs (``ball_drag_scale=1e6`` on yoshida_odd: a 2e-9 s step, 5 million RK4 steps and
seconds of work per control interval) is refused with a ValueError that says what to use
(``integrator="etdrk4"``, which integrates the drag exactly at the ordinary step, or smaller
scales): at reset for reset options, and when the environment is made for a preset whose
``randomize`` ranges allow such an episode, so that an automatic reset never fails.  An
explicit ``integration_step`` is the user's choice and is not checked.  The check takes the
corners of every range the step depends on: drag, rolling resistance, critical speed (a lighter
machine has a faster natural frequency) and support damping.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Mapping, Sequence

import numpy as np

from ..physics import drive_law as dl
from ..physics import model as mdl
from ..physics import rotor, runup, sensors
from ..physics.scene import Scene, SceneError, reference_length
from ..physics.steps import default_step, stiff_rates
from .config import PresetError
from .layout import (N_ST, S_ACC, S_AOP, S_AREF, S_DTMAX, S_MARK, S_NKEY, S_NSEG,
                     S_PEN_RATE, S_PEN_TERM, S_UBEST, S_USCALE, S_XS, S_YS)

__all__ = ["RESET_OPTIONS", "MAX_STIFFNESS", "Episode", "EpisodeTable", "Pending", "draw",
           "prepare", "commit", "check_preset_stiffness", "check_preset_machines",
           "reduce_angle", "episode_scene", "packed_rows", "loaded_rotor_mass", "draw_ball_angles"]

RESET_OPTIONS = ("imbalance", "imbalance_ratio", "imbalance_phase", "ball_angles",
                 "ball_drag_scale", "rolling_resistance_scale", "critical_speed_scale",
                 "support_damping_scale")

# Largest ratio of the step an episode's rotation needs to the step its stiff rate forces on
# RK4 (module docstring).  The shipped scenes and presets need at most 15 (washer's rolling
# resistance; yoshida_odd about 2; tests/test_env_inputs.py keeps a margin of 5).  A ratio of
# 100 already costs a hundred times the ordinary work (on yoshida_odd about 1 ms per control
# interval of one environment, 1 s per episode); far beyond it the work grows without bound.
MAX_STIFFNESS = 100.0

TWO_PI = 2.0 * math.pi


def reduce_angle(angle):
    """``angle`` [rad] (a float or an array) reduced to [-pi, pi] by the exact IEEE remainder
    modulo the float 2 pi; angles already in [-pi, pi] come back unchanged, bit for bit."""
    if np.ndim(angle) == 0:
        return math.remainder(float(angle), TWO_PI)
    a = np.asarray(angle, float)
    out = a.copy()
    # only the angles outside [-pi, pi] change (math.remainder returns the others as they
    # are), so only they pay for the Python loop: the drawn ones never do
    far = np.abs(a) > math.pi
    if far.any():
        out[far] = [math.remainder(v, TWO_PI) for v in a[far]]
    return out


def loaded_rotor_mass(scene: Scene, critical_speed_scale):
    """Rotor mass [kg] that scales the critical speeds ``sqrt(k / M)`` of ``scene`` by
    ``critical_speed_scale`` s (a number or an array): the supported mass becomes ``M / s^2``
    and the rotor (with its load) carries all of the change, ``M / s^2 - sum m_i``; exactly the
    scene's rotor mass for s = 1."""
    s = np.asarray(critical_speed_scale, float)
    loaded = scene.total_mass / (s * s) - float(sum(scene.ball_mass))
    out = np.where(s == 1.0, scene.rotor_mass, loaded)
    return float(out) if out.ndim == 0 else out


def _polar_inertia(scene: Scene, rotor_mass):
    """The loaded rotor's polar inertia [kg m^2]: proportional to its mass (a load spread like
    the rotor), exactly the scene's at the scene's mass."""
    m = np.asarray(rotor_mass, float)
    out = np.where(m == scene.rotor_mass, scene.rotor_polar_inertia,
                   scene.rotor_polar_inertia * (m / scene.rotor_mass))
    return float(out) if out.ndim == 0 else out


def episode_scene(scene: Scene, imbalance: float, drag: float, roll: float,
                  critical_speed_scale: float = 1.0, damping_scale: float = 1.0) -> Scene:
    """The nominal ``scene`` with primary imbalance ``imbalance`` [kg m] (through the rotor
    eccentricity), ball drag and rolling resistance scaled by ``drag`` and ``roll``, critical
    speeds scaled by ``critical_speed_scale`` (through the rotor mass,
    :func:`loaded_rotor_mass`; its polar inertia in proportion) and support damping by
    ``damping_scale``."""
    changes: dict[str, Any] = {}
    mass = scene.rotor_mass
    if critical_speed_scale != 1.0:
        mass = loaded_rotor_mass(scene, critical_speed_scale)
        changes["rotor_mass"] = mass
        changes["rotor_polar_inertia"] = _polar_inertia(scene, mass)
    if imbalance != scene.imbalance or mass != scene.rotor_mass:
        changes["rotor_eccentricity"] = imbalance / mass
    if damping_scale != 1.0:
        changes["support_damping_x"] = scene.support_damping_x * damping_scale
        changes["support_damping_y"] = scene.support_damping_y * damping_scale
    if drag != 1.0:
        changes["ball_drag"] = [v * drag for v in scene.ball_drag]
    if roll != 1.0:
        changes["ball_rolling_resistance"] = [v * roll for v in scene.ball_rolling_resistance]
    return scene.replace(**changes) if changes else scene


@dataclass
class Episode:
    """Parameters of one episode: imbalance [kg m] and its phase [rad], initial ball angles
    [rad], ball drag and rolling-resistance scales [-], the integration step bound [s], the
    rotor's rest position (static sag) [m], the critical-speed and support-damping scales [-]
    and the key of the sensor noise."""

    nominal: Scene
    imbalance: float
    imbalance_phase: float
    ball_angles: np.ndarray
    ball_drag_scale: float
    rolling_resistance_scale: float
    integration_step: float
    static_deflection: tuple[float, float] = (0.0, 0.0)
    critical_speed_scale: float = 1.0
    support_damping_scale: float = 1.0
    noise_key: int = 0

    @cached_property
    def scene(self) -> Scene:
        """The episode as a Scene (built on first use)."""
        return episode_scene(self.nominal, self.imbalance, self.ball_drag_scale,
                             self.rolling_resistance_scale, self.critical_speed_scale,
                             self.support_damping_scale)

    def as_info(self) -> dict[str, Any]:
        return {"imbalance": self.imbalance, "imbalance_phase": self.imbalance_phase,
                "initial_ball_angles": self.ball_angles.copy(),
                "ball_drag_scale": self.ball_drag_scale,
                "rolling_resistance_scale": self.rolling_resistance_scale,
                "critical_speed_scale": self.critical_speed_scale,
                "support_damping_scale": self.support_damping_scale,
                "integration_step": self.integration_step,
                "static_deflection": np.array(self.static_deflection)}


class EpisodeTable:
    """The current episode of every row (arrays over rows; :meth:`episode` gives one)."""

    def __init__(self, scene: Scene, n: int):
        nb = scene.ball_count
        self.scene = scene
        self.started = np.zeros(n, dtype=bool)
        self.imbalance = np.full(n, scene.imbalance)
        self.imbalance_phase = np.zeros(n)
        self.ball_angles = np.zeros((n, nb))
        self.ball_drag_scale = np.ones(n)
        self.rolling_resistance_scale = np.ones(n)
        self.critical_speed_scale = np.ones(n)
        self.support_damping_scale = np.ones(n)
        self.noise_key = np.zeros(n, dtype=np.int64)
        self.integration_step = np.zeros(n)
        self.reference_length = np.full(n, scene.reference_length)
        self.static_deflection = np.tile(np.array(rotor.static_deflection(scene)), (n, 1))

    def episode(self, i: int) -> Episode | None:
        """Row ``i``'s episode (None before its first reset)."""
        if not self.started[i]:
            return None
        return Episode(self.scene, float(self.imbalance[i]), float(self.imbalance_phase[i]),
                       self.ball_angles[i].copy(), float(self.ball_drag_scale[i]),
                       float(self.rolling_resistance_scale[i]), float(self.integration_step[i]),
                       (float(self.static_deflection[i, 0]),
                        float(self.static_deflection[i, 1])),
                       float(self.critical_speed_scale[i]), float(self.support_damping_scale[i]),
                       int(self.noise_key[i]))

    def info(self, rows) -> dict[str, np.ndarray]:
        """The episode parameters of ``rows`` as arrays over all rows (0 elsewhere): the keys
        of :meth:`Episode.as_info`."""
        rows = np.asarray(rows, dtype=np.int64)
        n = self.imbalance.shape[0]
        out: dict[str, np.ndarray] = {}
        for key, values in (("imbalance", self.imbalance),
                            ("imbalance_phase", self.imbalance_phase),
                            ("initial_ball_angles", self.ball_angles),
                            ("ball_drag_scale", self.ball_drag_scale),
                            ("rolling_resistance_scale", self.rolling_resistance_scale),
                            ("critical_speed_scale", self.critical_speed_scale),
                            ("support_damping_scale", self.support_damping_scale),
                            ("integration_step", self.integration_step)):
            arr = np.zeros_like(values)
            arr[rows] = values[rows]
            out[key] = arr
        sag = np.zeros((n, 2))
        sag[rows] = self.static_deflection[rows]
        out["static_deflection"] = sag
        return out


def _show(value: Any) -> str:
    """A short one-line picture of a given option (arrays by shape, long text cut)."""
    if isinstance(value, np.ndarray) and value.size > 4:
        return f"an array of shape {value.shape}"
    text = " ".join(repr(value).split())
    return text if len(text) <= 80 else text[:77] + "..."


def _is_number(value: Any) -> bool:
    """True for a real number (Python or NumPy, or a 0-d numeric array); not for bools or text,
    which ``float()`` would take as 1.0 or parse."""
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    return isinstance(value, (int, float, np.integer, np.floating)) \
        and not isinstance(value, (bool, np.bool_))


def _opt_number(name: str, value: Any, lo: float | None, unit: str, inclusive: bool = True
                ) -> float:
    if not _is_number(value):
        raise ValueError(f"reset option {name!r} must be a number [{unit}] (got "
                         f"{_show(value)})")
    v = float(value)
    if not math.isfinite(v) or (lo is not None and (v < lo or (v == lo and not inclusive))):
        rng = "finite" if lo is None else f"{'>=' if inclusive else '>'} {lo:g}"
        raise ValueError(f"reset option {name!r} must be {rng} [{unit}] (got {_show(value)})")
    return v


def _uniform(lo_hi: Sequence[float], u):
    lo, hi = float(lo_hi[0]), float(lo_hi[1])
    return lo + (hi - lo) * u


def draw_ball_angles(setup: Any, rng: np.random.Generator) -> np.ndarray:
    """Initial ball angles [rad], one per ball, drawn as the preset draws them (uniform in its
    ``randomize.ball_angles`` range) from ``rng``: the balls of a machine started somewhere else
    (:func:`abb_gym.baselines.oracle.balls_elsewhere`).  ValueError if the preset fixes the
    angles (``ball_angles: null``): then there is nowhere else to start them."""
    span = setup.config.randomize.ball_angles
    if span is None:
        raise ValueError(f"preset {setup.config.name!r} fixes the initial ball angles "
                         f"(randomize.ball_angles is null): there is nowhere else to start the "
                         f"balls")
    return _uniform(span, rng.random(setup.scene.ball_count))


def draw(setup: Any, rng: np.random.Generator, options: Mapping[str, Any] | None
         ) -> tuple[float, float, np.ndarray, float, float, float, float, int]:
    """One environment's episode values ``(imbalance, phase, ball angles, drag scale, rolling
    resistance scale, critical-speed scale, support-damping scale, noise key)``: the preset's
    random draws from ``rng`` (:func:`_preset_draws`), then ``options``
    (:data:`RESET_OPTIONS`) in their place."""
    sc = setup.scene
    nb = sc.ball_count
    cap = sc.balancing_capacity
    drawn = [v[0] for v in _preset_draws(setup, [rng])]
    imbalance, phase, drag, roll, crit, damp = (float(drawn[k]) for k in (0, 1, 3, 4, 5, 6))
    angles = drawn[2].copy()
    key = int(drawn[7])
    if options is not None and not isinstance(options, Mapping):
        raise ValueError(f"options must be a dict with keys from {list(RESET_OPTIONS)} (got "
                         f"{_show(options)})")
    if options:
        unknown = sorted(set(options) - set(RESET_OPTIONS), key=str)  # keys of any type
        if unknown:
            raise ValueError(f"unknown reset option(s) {unknown}; allowed: "
                             f"{list(RESET_OPTIONS)}")
        if "imbalance" in options and "imbalance_ratio" in options:
            raise ValueError("reset options 'imbalance' and 'imbalance_ratio' exclude each other")
        if "imbalance" in options:
            imbalance = _opt_number("imbalance", options["imbalance"], 0.0, "kg m")
        if "imbalance_ratio" in options:
            imbalance = _opt_number("imbalance_ratio", options["imbalance_ratio"], 0.0,
                                    "-") * cap
        if "imbalance_phase" in options:
            phase = _opt_number("imbalance_phase", options["imbalance_phase"], None, "rad")
        if "ball_angles" in options:
            given = options["ball_angles"]
            try:
                a = np.asarray(given)
                ok = a.dtype.kind in "fiu"
                a = a.astype(float) if ok else a
            except (TypeError, ValueError):  # ragged or unreadable
                ok = False
            if ok and a.ndim == 0:
                a = np.full(nb, float(a))
            if not ok or a.shape != (nb,) or not np.all(np.isfinite(a)):
                raise ValueError(f"reset option 'ball_angles' must be {nb} finite angles [rad] "
                                 f"(got {_show(given)})")
            angles = a.copy()
        if "ball_drag_scale" in options:
            drag = _opt_number("ball_drag_scale", options["ball_drag_scale"], 0.0, "-",
                               inclusive=False)
        if "rolling_resistance_scale" in options:
            roll = _opt_number("rolling_resistance_scale", options["rolling_resistance_scale"],
                               0.0, "-")
        if "critical_speed_scale" in options:
            crit = _opt_number("critical_speed_scale", options["critical_speed_scale"], 0.0,
                               "-", inclusive=False)
            _check_machine(sc, crit, "reset option 'critical_speed_scale'", ValueError)
        if "support_damping_scale" in options:
            damp = _opt_number("support_damping_scale", options["support_damping_scale"], 0.0,
                               "-")
            _check_machine(sc, crit, "reset option 'support_damping_scale'", ValueError,
                           damp)
    # angles far beyond 2 pi: the same machine as their remainder (module docstring)
    return (float(imbalance), reduce_angle(phase), reduce_angle(angles), float(drag),
            float(roll), float(crit), float(damp), key)


def _no_options(options: Sequence[Any] | None) -> bool:
    return options is None or all(o is None or (isinstance(o, Mapping) and not o)
                                  for o in options)


def draw_rows(setup: Any, rngs: Sequence[np.random.Generator],
              options: Sequence[Mapping[str, Any] | None] | None = None
              ) -> tuple[np.ndarray, ...]:
    """:func:`draw` for many environments, row ``k`` from ``rngs[k]`` with ``options[k]``, as
    arrays over rows ``(imbalance, phase, ball angles (rows x balls), drag scale, rolling
    resistance scale, critical-speed scale, support-damping scale, noise key)``.

    Without reset options (the autoreset of a vector environment) the values are mapped onto
    the preset's ranges for all rows at once (:func:`_preset_draws`, which :func:`draw`
    reads too); each generator still gives its own draws in the same order, so every seeded
    episode is unchanged.  With options, row by row through :func:`draw`."""
    if not _no_options(options):
        values = [draw(setup, rng, None if options is None else options[k])
                  for k, rng in enumerate(rngs)]
        return tuple(np.array(v) for v in zip(*values))
    return _preset_draws(setup, rngs)


def _preset_draws(setup: Any, rngs: Sequence[np.random.Generator]) -> tuple[np.ndarray, ...]:
    """The preset's random draws of every row, as arrays over rows (:func:`draw_rows`'
    layout): row ``k`` takes one ``rngs[k].random`` call for the randomised fields (imbalance
    ratio, phase, ball angles, drag scale, rolling-resistance scale, critical-speed scale,
    support-damping scale: those that are randomised, in this order; the scene's values for
    the others), then the noise key if the observation is noisy; angles reduced to
    [-pi, pi]."""
    sc = setup.scene
    rz = setup.config.randomize
    nb = sc.ball_count
    n = len(rngs)
    imbalance = np.full(n, float(sc.imbalance))
    phase = np.zeros(n)
    angles = np.tile(np.asarray(sc.ball_angles0, dtype=float), (n, 1))
    drag, roll, crit, damp = (np.ones(n) for _ in range(4))
    count = sum(1 for r in (rz.imbalance_ratio, rz.imbalance_phase, rz.ball_drag_scale,
                            rz.rolling_resistance_scale, rz.critical_speed_scale,
                            rz.support_damping_scale) if r is not None)
    count += nb if rz.ball_angles is not None else 0
    if count and n:
        u = np.array([rng.random(count) for rng in rngs])
        k = 0
        if rz.imbalance_ratio is not None:
            imbalance = _uniform(rz.imbalance_ratio, u[:, k]) * sc.balancing_capacity
            k += 1
        if rz.imbalance_phase is not None:
            phase = _uniform(rz.imbalance_phase, u[:, k])
            k += 1
        if rz.ball_angles is not None:
            angles = _uniform(rz.ball_angles, u[:, k:k + nb])
            k += nb
        if rz.ball_drag_scale is not None:
            drag = _uniform(rz.ball_drag_scale, u[:, k])
            k += 1
        if rz.rolling_resistance_scale is not None:
            roll = _uniform(rz.rolling_resistance_scale, u[:, k])
            k += 1
        if rz.critical_speed_scale is not None:
            crit = _uniform(rz.critical_speed_scale, u[:, k])
            k += 1
        if rz.support_damping_scale is not None:
            damp = _uniform(rz.support_damping_scale, u[:, k])
    sync = setup.config.sync_vibration
    if sync.enabled and sync.noise > 0.0:
        key = np.array([int(rng.integers(0, sensors.KEY_BOUND)) for rng in rngs],
                       dtype=np.int64)
    else:
        key = np.zeros(n, dtype=np.int64)
    return (imbalance, reduce_angle(phase), reduce_angle(angles), drag, roll, crit, damp,
            key)


def _check_machine(scene: Scene, crit: float, where: str, error: type[ValueError],
                   damp: float = 1.0) -> None:
    """Raise ``error`` naming ``where`` unless the scene with critical-speed scale ``crit`` and
    support-damping scale ``damp`` is a valid machine (a rotor mass left, within the scene's
    bounds) whose rest position, under gravity, lies inside the housing clearance."""
    if crit == 1.0 and damp == 1.0:
        return
    balls = float(sum(scene.ball_mass))
    if loaded_rotor_mass(scene, crit) <= 0.0:
        raise error(f"{where}: with critical_speed_scale={crit:g} the supported mass "
                    f"M / s^2 = {scene.total_mass / crit ** 2:g} kg would not even carry the "
                    f"balls ({balls:g} kg): no rotor mass left; use a smaller scale (below "
                    f"{math.sqrt(scene.total_mass / balls):.4g})")
    try:
        sc = episode_scene(scene, scene.imbalance, 1.0, 1.0, crit, damp)
    except SceneError as exc:
        raise error(f"{where}: the machine with critical_speed_scale={crit:g} and "
                    f"support_damping_scale={damp:g} is not a valid scene: {exc}") from None
    sag = math.hypot(*rotor.static_deflection(sc))
    if sag >= scene.housing_clearance:
        raise error(f"{where}: with critical_speed_scale={crit:g} the supported mass "
                    f"{sc.total_mass:g} kg sags {sag:g} m under gravity, beyond the housing "
                    f"clearance {scene.housing_clearance:g} m; use a larger scale")


def rotor_eccentricity(scene: Scene, imbalance: np.ndarray, rotor_mass=None) -> np.ndarray:
    """The episodes' rotor eccentricity [m] (:func:`episode_scene`: the nominal one where the
    imbalance and the rotor mass are the nominal ones); ``rotor_mass`` [kg]: each episode's
    (default the scene's)."""
    if rotor_mass is None:
        return np.where(imbalance != scene.imbalance, imbalance / scene.rotor_mass,
                        scene.rotor_eccentricity)
    return np.where((imbalance != scene.imbalance) | (rotor_mass != scene.rotor_mass),
                    imbalance / rotor_mass, scene.rotor_eccentricity)


def _ones(values, n: int) -> np.ndarray:
    return np.ones(n) if values is None else np.asarray(values, float)


def packed_rows(scene: Scene, imbalance: np.ndarray, drag: np.ndarray, roll: np.ndarray,
                critical: np.ndarray | None = None, damping: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """(p, b) of the episodes' scenes, (R, N_PARAMS) and (R, n, N_BALL_PARAMS): what
    ``model.pack_parameters(episode_scene(scene, imbalance[r], drag[r], roll[r], critical[r],
    damping[r]))`` gives, bit for bit, without building the scenes (the few entries an
    episode changes are computed the way the Scene and :func:`model.pack_parameters` compute
    them).  ``critical``, ``damping``: the critical-speed and support-damping scales (default
    1)."""
    p0, b0 = mdl.pack_parameters(scene)
    r = imbalance.shape[0]
    p = np.repeat(p0[None], r, axis=0)
    b = np.repeat(b0[None], r, axis=0)
    critical = _ones(critical, r)
    damping = _ones(damping, r)
    if np.any(critical != 1.0):
        mass = np.asarray(loaded_rotor_mass(scene, critical), float).reshape(r)
        p[:, mdl.P_MASS] = mass + float(sum(scene.ball_mass))          # Scene.total_mass
        p[:, mdl.P_J] = _polar_inertia(scene, mass)
        p[:, mdl.P_U0] = mass * rotor_eccentricity(scene, imbalance, mass)
    else:
        p[:, mdl.P_U0] = scene.rotor_mass * rotor_eccentricity(scene, imbalance)
    scaled = damping != 1.0
    p[scaled, mdl.P_CX] = scene.support_damping_x * damping[scaled]
    p[scaled, mdl.P_CY] = scene.support_damping_y * damping[scaled]
    a = scene.arrays()
    scaled = drag != 1.0
    b[scaled, :, mdl.B_BETA] = (a["ball_drag"][None, :] * drag[scaled, None]
                                * scene.race_radius ** 2)
    scaled = roll != 1.0
    rr = a["ball_rolling_resistance"][None, :] * roll[scaled, None]
    b[scaled, :, mdl.B_MUR] = rr / a["ball_radius"]
    p[scaled, mdl.P_ROLL] = np.where((rr > 0).any(axis=1), 1.0, 0.0)  # Scene.effects
    return p, b


@dataclass
class Pending:
    """What :func:`commit` writes into the rows ``rows`` of the buffers and the table: arrays
    over ``rows`` computed by :func:`prepare`."""

    rows: np.ndarray
    p: np.ndarray
    b: np.ndarray
    s: np.ndarray
    st: np.ndarray
    d: np.ndarray
    imbalance: np.ndarray
    phase: np.ndarray
    angles: np.ndarray
    drag: np.ndarray
    roll: np.ndarray
    step: np.ndarray
    reference_length: np.ndarray
    critical: np.ndarray
    damping: np.ndarray
    key: np.ndarray
    static_deflection: np.ndarray


def _stiff_message(setup: Any, drag: float, roll: float, step: float, needed: float,
                   where: str, machine: str = "") -> str:
    per = setup.control_interval / step
    return (f"{where}: an episode with ball_drag_scale={drag:g} and rolling_resistance_scale="
            f"{roll:g}{machine} is too stiff for integrator='rk4': its ball drag and rolling "
            f"resistance force a {step:.3g} s step at the top speed {setup.max_speed:.4g} rad/s "
            f"(from operating_speed = {setup.operating_speed:.4g} rad/s) ({per:.3g} RK4 steps "
            f"per {setup.control_interval:g} s "
            f"control interval, {needed / step:.3g} x shorter than the {needed:.3g} s its "
            f"rotation needs; at most {MAX_STIFFNESS:g} x is allowed); use integrator='etdrk4' "
            f"(integrates the stiff drag exactly at the ordinary step) or smaller scales")


def _machine_rates(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each packed episode's ``critical_speeds[1]`` [rad/s] and :func:`explicit_rate` [1/s]
    without a drive (what :func:`default_step` reads from a Scene, computed the same way)."""
    mass = p[:, mdl.P_MASS]
    return (np.sqrt(p[:, mdl.P_KY] / mass),
            np.maximum(p[:, mdl.P_CX], p[:, mdl.P_CY]) / mass)


def _steps(setup: Any, p: np.ndarray, method: str, rate, varied: bool) -> np.ndarray:
    """:func:`default_step` of each packed episode (``varied``: their masses or support
    damping differ from the scene's)."""
    sc = setup.scene
    if not varied:
        return default_step(sc, setup.max_speed, method, rate=rate)
    crit, other = _machine_rates(p)
    return default_step(sc, setup.max_speed, method, rate=rate, critical_speed=crit,
                        other_rate=other)


def _rk4_steps(setup: Any, p: np.ndarray, b: np.ndarray, drag, roll, where: str,
               error: type[ValueError] = ValueError, critical=None, damping=None
               ) -> np.ndarray:
    """The RK4 step of each packed episode [s] (drag and rolling-resistance scales ``drag``,
    ``roll``; critical-speed and support-damping scales ``critical``, ``damping``); raises
    ``error`` if the stiffest needs a step more than :data:`MAX_STIFFNESS` times shorter than
    its rotation alone does (module docstring)."""
    n = p.shape[0]
    critical = _ones(critical, n)
    damping = _ones(damping, n)
    varied = bool(np.any(critical != 1.0) or np.any(damping != 1.0))
    rate = stiff_rates(p, b, setup.max_speed)
    step = np.broadcast_to(np.asarray(_steps(setup, p, "rk4", rate, varied), float), (n,))
    needed = np.broadcast_to(np.asarray(_steps(setup, p, "rk4", np.zeros(n) if varied else 0.0,
                                               varied), float), (n,))
    k = int(np.argmax(needed / step))
    if needed[k] > MAX_STIFFNESS * step[k]:
        machine = (f", critical_speed_scale={critical[k]:g} and support_damping_scale="
                   f"{damping[k]:g}" if varied else "")
        raise error(_stiff_message(setup, drag[k], roll[k], step[k], needed[k], where,
                                   machine))
    return step


def _corners(value) -> list[float]:
    return [1.0] if value is None else [float(v) for v in np.atleast_1d(value)]


def check_preset_machines(setup: Any) -> None:
    """Raise PresetError naming the field if a corner of the preset's critical-speed and
    support-damping ranges is not a machine (no rotor mass left, a field out of the scene's
    bounds, or under gravity a static sag beyond the housing clearance)."""
    cfg = setup.config
    rz = cfg.randomize
    where = f"environment preset {cfg.name!r}: field 'randomize.%s'"
    # (each scale on its own: neither changes what makes the other one valid)
    for crit in _corners(rz.critical_speed_scale):
        _check_machine(setup.scene, crit, where % "critical_speed_scale", PresetError)
    for damp in _corners(rz.support_damping_scale):
        _check_machine(setup.scene, 1.0, where % "support_damping_scale", PresetError, damp)


def check_preset_stiffness(setup: Any) -> None:
    """Raise PresetError (a ValueError) if the preset's ``randomize`` ranges allow an episode
    too stiff for RK4 (module docstring): checked at the corners of the drag,
    rolling-resistance, critical-speed and support-damping ranges: the stiff rate grows with
    the first two scales, the rotation's step shrinks as the machine gets lighter (a higher
    critical speed) and, with heavy damping, as c / M grows."""
    cfg = setup.config
    if cfg.integrator != "rk4" or cfg.integration_step is not None:
        return
    rz = cfg.randomize
    corners = np.array([(dv, rv, cv, sv) for dv in _corners(rz.ball_drag_scale)
                        for rv in _corners(rz.rolling_resistance_scale)
                        for cv in _corners(rz.critical_speed_scale)
                        for sv in _corners(rz.support_damping_scale)])
    sc = setup.scene
    imbalance = np.full(len(corners), sc.imbalance)
    p, b = packed_rows(sc, imbalance, corners[:, 0], corners[:, 1], corners[:, 2],
                       corners[:, 3])
    _rk4_steps(setup, p, b, corners[:, 0], corners[:, 1],
               f"environment preset {cfg.name!r} (its randomize ranges allow it)", PresetError,
               corners[:, 2], corners[:, 3])


def prepare(setup: Any, table: EpisodeTable, rows, imbalance, phase, angles, drag, roll,
            critical=None, damping=None, key=None) -> Pending:
    """The start of the episodes of ``rows`` (rotor at rest), computed without changing
    anything: the values are arrays over ``rows`` (``angles``: (R, n); ``critical``,
    ``damping`` the critical-speed and support-damping scales, default 1; ``key`` the noise
    keys, default 0).  Raises ValueError for an episode too stiff for RK4 (module
    docstring)."""
    sc = setup.scene
    nb = sc.ball_count
    nq = 3 + nb
    rows = np.asarray(rows, dtype=np.int64)
    n = len(rows)
    imbalance = np.asarray(imbalance, float)
    phase = np.asarray(phase, float)
    angles = np.asarray(angles, float).reshape(n, nb)
    drag = np.asarray(drag, float)
    roll = np.asarray(roll, float)
    critical = _ones(critical, n)
    damping = _ones(damping, n)
    key = np.zeros(n, dtype=np.int64) if key is None else np.asarray(key, np.int64)
    varied = bool(np.any(critical != 1.0) or np.any(damping != 1.0))
    p, b = packed_rows(sc, imbalance, drag, roll, critical, damping)
    step = setup.config.integration_step
    if step is None:
        if setup.config.integrator == "rk4":
            step = _rk4_steps(setup, p, b, drag, roll, "reset", ValueError, critical, damping)
        else:
            step = _steps(setup, p, setup.config.integrator, np.zeros(n), varied)
    step = np.array(np.broadcast_to(np.asarray(step, float), (n,)))
    mass = p[:, mdl.P_MASS]
    if varied:
        sag = np.column_stack(np.broadcast_arrays(*rotor.static_deflection(sc, mass)))
        sag = np.array(np.broadcast_to(sag, (n, 2)))
    else:
        sag = np.tile(np.array(rotor.static_deflection(sc)), (n, 1))
    xs = sag[:, 0]
    ys = sag[:, 1]
    s = np.zeros((len(rows), 2 * nq))
    s[:, 0] = xs
    s[:, 1] = ys
    s[:, 2] = phase
    s[:, 3:nq] = angles
    u0 = p[:, mdl.P_U0]
    u_ref = rotor.imbalance_scale(sc, u0)
    if varied:
        # the reward's scales: this episode's machine with its balancer off
        a_peak, a_op = rotor.reference_amplitudes(sc, setup.operating_speed, u_ref, mass=mass,
                                                  damping_scale=damping)
    else:
        a_peak, a_op = rotor.reference_amplitudes(sc, setup.operating_speed, u_ref)
    st = np.zeros((len(rows), N_ST))
    acc = np.zeros(runup.N_ACC)
    runup.reset(acc)
    st[:, S_ACC:S_ACC + runup.N_ACC] = acc
    st[:, S_XS] = xs
    st[:, S_YS] = ys
    st[:, S_AREF] = a_peak
    st[:, S_AOP] = a_op
    st[:, S_USCALE] = u_ref
    st[:, S_UBEST] = rotor.best_residual(sc, u0)
    st[:, S_DTMAX] = step
    st[:, S_NSEG] = 1.0
    # the reference mark: the rotor starts with its imbalance at angle `phase` from the
    # fixed x axis and its mark on it, so the imbalance lies `phase` from the mark
    st[:, S_MARK] = phase
    st[:, S_NKEY] = key
    w = setup.config.reward
    clear = sc.housing_clearance
    st[:, S_PEN_RATE] = w.vibration * clear / a_peak + w.time + w.effort * setup.effort_bound
    st[:, S_PEN_TERM] = w.residual * clear / a_op
    d = np.zeros((len(rows), setup.n_rows, dl.N_DRIVE))
    setup.actions.reset_rows(d, phase, setup)
    extra = mdl.spec_of(p, d) & ~setup.spec
    if extra:
        raise RuntimeError(f"episodes of scene {sc.name!r} need kernel effects {extra} beyond "
                           f"the environment's {setup.spec}")
    if varied:
        rotor_mass = (np.asarray(loaded_rotor_mass(sc, critical), float).reshape(n)
                      if np.any(critical != 1.0) else None)
        ref = reference_length(rotor_eccentricity(sc, imbalance, rotor_mass),
                               sc.race_eccentricity, sc.balancing_capacity, mass)
    else:
        ref = reference_length(rotor_eccentricity(sc, imbalance), sc.race_eccentricity,
                               sc.balancing_capacity, sc.total_mass)
    return Pending(rows, p, b, s, st, d, imbalance, phase, angles, drag, roll, step, ref,
                   critical, damping, key, sag)


def commit(bufs: Any, table: EpisodeTable, pending: Pending) -> None:
    """Write what :func:`prepare` computed into the buffers ``bufs`` and the ``table`` (cannot
    fail: every array has its shape already)."""
    rows = pending.rows
    bufs.p[rows] = pending.p
    bufs.b[rows] = pending.b
    bufs.s[rows] = pending.s
    bufs.st[rows] = pending.st
    bufs.d[rows] = pending.d
    bufs.act[rows] = 0.0
    table.started[rows] = True
    table.imbalance[rows] = pending.imbalance
    table.imbalance_phase[rows] = pending.phase
    table.ball_angles[rows] = pending.angles
    table.ball_drag_scale[rows] = pending.drag
    table.rolling_resistance_scale[rows] = pending.roll
    table.critical_speed_scale[rows] = pending.critical
    table.support_damping_scale[rows] = pending.damping
    table.noise_key[rows] = pending.key
    table.static_deflection[rows] = pending.static_deflection
    table.integration_step[rows] = pending.step
    table.reference_length[rows] = pending.reference_length
