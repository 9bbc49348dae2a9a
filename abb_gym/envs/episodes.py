"""Episodes: what each environment draws, and the rows of many environments reset at once.

An episode is the nominal scene with a drawn primary imbalance and phase, initial ball angles,
and scaled ball drag and rolling resistance (the preset's ``randomize`` ranges), or the values
given as reset options.

* :func:`draw` takes one environment's values from its own generator in a fixed order, with
  one ``rng.random`` call (the numbers ``rng.uniform`` would give one by one: ``low + (high -
  low) u``), then applies the reset options.
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
and rolling resistance, :func:`abb_gym.physics.simulate.default_step`).  An episode whose
stiff rate forces a step more than :data:`MAX_STIFFNESS` times shorter than the step its
rotation needs (``ball_drag_scale=1e6`` on yoshida_odd: a 2e-9 s step, 5 million RK4 steps and
seconds of work per control interval) is refused with a ValueError that says what to use
(``integrator="etdrk4"``, which integrates the drag exactly at the ordinary step, or smaller
scales): at reset for reset options, and when the environment is made for a preset whose
``randomize`` ranges allow such an episode, so that an automatic reset never fails.  An
explicit ``integration_step`` is the user's choice and is not checked.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Mapping, Sequence

import numpy as np

from ..physics import drive_law as dl
from ..physics import model as mdl
from ..physics import rotor, runup
from ..physics.scene import Scene, reference_length
from ..physics.simulate import default_step, stiff_rates
from .config import PresetError
from .layout import (N_ST, S_ACC, S_AOP, S_AREF, S_DTMAX, S_NSEG, S_PEN_RATE, S_PEN_TERM,
                     S_UBEST, S_USCALE, S_XS, S_YS)

__all__ = ["RESET_OPTIONS", "MAX_STIFFNESS", "Episode", "EpisodeTable", "Pending", "draw",
           "prepare", "commit", "check_preset_stiffness", "reduce_angle",
           "episode_scene", "packed_rows"]

RESET_OPTIONS = ("imbalance", "imbalance_ratio", "imbalance_phase", "ball_angles",
                 "ball_drag_scale", "rolling_resistance_scale")

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
    return np.array([math.remainder(v, TWO_PI) for v in a.ravel()]).reshape(a.shape)


def episode_scene(scene: Scene, imbalance: float, drag: float, roll: float) -> Scene:
    """The nominal ``scene`` with primary imbalance ``imbalance`` [kg m] (through the rotor
    eccentricity) and ball drag and rolling resistance scaled by ``drag`` and ``roll``."""
    changes: dict[str, Any] = {}
    if imbalance != scene.imbalance:
        changes["rotor_eccentricity"] = imbalance / scene.rotor_mass
    if drag != 1.0:
        changes["ball_drag"] = [v * drag for v in scene.ball_drag]
    if roll != 1.0:
        changes["ball_rolling_resistance"] = [v * roll for v in scene.ball_rolling_resistance]
    return scene.replace(**changes) if changes else scene


@dataclass
class Episode:
    """Parameters of one episode: imbalance [kg m] and its phase [rad], initial ball angles
    [rad], ball drag and rolling-resistance scales [-], the integration step bound [s] and the
    rotor's rest position (static sag) [m]."""

    nominal: Scene
    imbalance: float
    imbalance_phase: float
    ball_angles: np.ndarray
    ball_drag_scale: float
    rolling_resistance_scale: float
    integration_step: float
    static_deflection: tuple[float, float] = (0.0, 0.0)

    @cached_property
    def scene(self) -> Scene:
        """The episode as a Scene (built on first use)."""
        return episode_scene(self.nominal, self.imbalance, self.ball_drag_scale,
                             self.rolling_resistance_scale)

    def as_info(self) -> dict[str, Any]:
        return {"imbalance": self.imbalance, "imbalance_phase": self.imbalance_phase,
                "initial_ball_angles": self.ball_angles.copy(),
                "ball_drag_scale": self.ball_drag_scale,
                "rolling_resistance_scale": self.rolling_resistance_scale,
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
        self.integration_step = np.zeros(n)
        self.reference_length = np.full(n, scene.reference_length)
        self.static_deflection = rotor.static_deflection(scene)

    def episode(self, i: int) -> Episode | None:
        """Row ``i``'s episode (None before its first reset)."""
        if not self.started[i]:
            return None
        return Episode(self.scene, float(self.imbalance[i]), float(self.imbalance_phase[i]),
                       self.ball_angles[i].copy(), float(self.ball_drag_scale[i]),
                       float(self.rolling_resistance_scale[i]), float(self.integration_step[i]),
                       self.static_deflection)

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
                            ("integration_step", self.integration_step)):
            arr = np.zeros_like(values)
            arr[rows] = values[rows]
            out[key] = arr
        sag = np.zeros((n, 2))
        sag[rows] = self.static_deflection
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


def draw(setup: Any, rng: np.random.Generator, options: Mapping[str, Any] | None
         ) -> tuple[float, float, np.ndarray, float, float]:
    """One environment's episode values ``(imbalance, phase, ball angles, drag scale, rolling
    resistance scale)``: the preset's random draws from ``rng`` (imbalance ratio, phase, ball
    angles, drag scale, rolling-resistance scale: those that are randomised, in this order),
    then ``options`` (:data:`RESET_OPTIONS`) in their place."""
    sc = setup.scene
    rz = setup.config.randomize
    nb = sc.ball_count
    cap = sc.balancing_capacity
    imbalance = sc.imbalance
    phase = 0.0
    angles = np.asarray(sc.ball_angles0, dtype=float).copy()
    drag = 1.0
    roll = 1.0
    count = sum(1 for r in (rz.imbalance_ratio, rz.imbalance_phase, rz.ball_drag_scale,
                            rz.rolling_resistance_scale) if r is not None)
    count += nb if rz.ball_angles is not None else 0
    if count:
        u = rng.random(count)
        k = 0
        if rz.imbalance_ratio is not None:
            imbalance = float(_uniform(rz.imbalance_ratio, u[k])) * cap
            k += 1
        if rz.imbalance_phase is not None:
            phase = float(_uniform(rz.imbalance_phase, u[k]))
            k += 1
        if rz.ball_angles is not None:
            angles = _uniform(rz.ball_angles, u[k:k + nb])
            k += nb
        if rz.ball_drag_scale is not None:
            drag = float(_uniform(rz.ball_drag_scale, u[k]))
            k += 1
        if rz.rolling_resistance_scale is not None:
            roll = float(_uniform(rz.rolling_resistance_scale, u[k]))
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
    # angles far beyond 2 pi: the same machine as their remainder (module docstring)
    return float(imbalance), reduce_angle(phase), reduce_angle(angles), float(drag), float(roll)


def rotor_eccentricity(scene: Scene, imbalance: np.ndarray) -> np.ndarray:
    """The episodes' rotor eccentricity [m] (:func:`episode_scene`: the nominal one where the
    imbalance is the nominal one)."""
    return np.where(imbalance != scene.imbalance, imbalance / scene.rotor_mass,
                    scene.rotor_eccentricity)


def packed_rows(scene: Scene, imbalance: np.ndarray, drag: np.ndarray, roll: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """(p, b) of the episodes' scenes, (R, N_PARAMS) and (R, n, N_BALL_PARAMS): what
    ``model.pack_parameters(episode_scene(scene, imbalance[r], drag[r], roll[r]))`` gives, bit
    for bit, without building the scenes (the few entries an episode changes are computed
    the way the Scene and :func:`model.pack_parameters` compute them)."""
    p0, b0 = mdl.pack_parameters(scene)
    r = imbalance.shape[0]
    p = np.repeat(p0[None], r, axis=0)
    b = np.repeat(b0[None], r, axis=0)
    p[:, mdl.P_U0] = scene.rotor_mass * rotor_eccentricity(scene, imbalance)  # Scene.imbalance
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


def _stiff_message(setup: Any, drag: float, roll: float, step: float, needed: float,
                   where: str) -> str:
    per = setup.control_interval / step
    return (f"{where}: an episode with ball_drag_scale={drag:g} and rolling_resistance_scale="
            f"{roll:g} is too stiff for integrator='rk4': its ball drag and rolling resistance "
            f"force a {step:.3g} s step at the top speed {setup.max_speed:.4g} rad/s (from "
            f"operating_speed = {setup.operating_speed:.4g} rad/s) ({per:.3g} RK4 steps per "
            f"{setup.control_interval:g} s "
            f"control interval, {needed / step:.3g} x shorter than the {needed:.3g} s its "
            f"rotation needs; at most {MAX_STIFFNESS:g} x is allowed); use integrator='etdrk4' "
            f"(integrates the stiff drag exactly at the ordinary step) or smaller scales")


def _rk4_steps(setup: Any, p: np.ndarray, b: np.ndarray, drag, roll, where: str,
               error: type[ValueError] = ValueError) -> np.ndarray:
    """The RK4 step of each packed episode [s] (drag and rolling-resistance scales ``drag``,
    ``roll``); raises ``error`` if the stiffest needs a step more than :data:`MAX_STIFFNESS`
    times shorter than its rotation alone does (module docstring)."""
    sc = setup.scene
    rate = stiff_rates(p, b, setup.max_speed)
    step = np.broadcast_to(np.asarray(default_step(sc, setup.max_speed, "rk4", rate=rate),
                                      float), (p.shape[0],))
    needed = float(default_step(sc, setup.max_speed, "rk4", rate=0.0))
    k = int(np.argmin(step))
    if needed > MAX_STIFFNESS * step[k]:
        raise error(_stiff_message(setup, drag[k], roll[k], step[k], needed, where))
    return step


def check_preset_stiffness(setup: Any) -> None:
    """Raise PresetError (a ValueError) if the preset's ``randomize`` ranges allow an episode
    too stiff for RK4 (module docstring): checked at the corners of the drag and
    rolling-resistance ranges, where the stiff rate, which grows with both scales, is
    largest."""
    cfg = setup.config
    if cfg.integrator != "rk4" or cfg.integration_step is not None:
        return
    rz = cfg.randomize
    drags = [1.0] if rz.ball_drag_scale is None else np.atleast_1d(rz.ball_drag_scale)
    rolls = ([1.0] if rz.rolling_resistance_scale is None
             else np.atleast_1d(rz.rolling_resistance_scale))
    corners = np.array([(float(dv), float(rv)) for dv in drags for rv in rolls])
    sc = setup.scene
    imbalance = np.full(len(corners), sc.imbalance)
    p, b = packed_rows(sc, imbalance, corners[:, 0], corners[:, 1])
    _rk4_steps(setup, p, b, corners[:, 0], corners[:, 1],
               f"environment preset {cfg.name!r} (its randomize ranges allow it)", PresetError)


def prepare(setup: Any, table: EpisodeTable, rows, imbalance, phase, angles, drag, roll
            ) -> Pending:
    """The start of the episodes of ``rows`` (rotor at rest), computed without changing
    anything: the values are arrays over ``rows`` (``angles``: (R, n)).  Raises ValueError for
    an episode too stiff for RK4 (module docstring)."""
    sc = setup.scene
    nb = sc.ball_count
    nq = 3 + nb
    rows = np.asarray(rows, dtype=np.int64)
    imbalance = np.asarray(imbalance, float)
    phase = np.asarray(phase, float)
    angles = np.asarray(angles, float).reshape(len(rows), nb)
    drag = np.asarray(drag, float)
    roll = np.asarray(roll, float)
    p, b = packed_rows(sc, imbalance, drag, roll)
    step = setup.config.integration_step
    if step is None:
        if setup.config.integrator == "rk4":
            step = _rk4_steps(setup, p, b, drag, roll, "reset")
        else:
            step = default_step(sc, setup.max_speed, setup.config.integrator,
                                rate=np.zeros(len(rows)))
    step = np.array(np.broadcast_to(np.asarray(step, float), (len(rows),)))
    xs, ys = table.static_deflection
    s = np.zeros((len(rows), 2 * nq))
    s[:, 0] = xs
    s[:, 1] = ys
    s[:, 2] = phase
    s[:, 3:nq] = angles
    u0 = p[:, mdl.P_U0]
    u_ref = rotor.imbalance_scale(sc, u0)
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
    ref = reference_length(rotor_eccentricity(sc, imbalance), sc.race_eccentricity,
                           sc.balancing_capacity, sc.total_mass)
    return Pending(rows, p, b, s, st, d, imbalance, phase, angles, drag, roll, step, ref)


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
    table.integration_step[rows] = pending.step
    table.reference_length[rows] = pending.reference_length
