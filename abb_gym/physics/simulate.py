"""The plain simulation API: ``simulate(scene, drive, t_end) -> Trajectory``.

The step rules and work bounds it applies are in :mod:`abb_gym.physics.steps`, the result
type in :mod:`abb_gym.physics.trajectory`."""
from __future__ import annotations

import math
import time
from typing import Any, Sequence

import numpy as np

from . import drive_limits as limits
from . import integrators as integ
from . import model as mdl
from .methods import COMPILED_METHODS, FIXED_STEP, METHOD_IDS, METHODS
from .drives import MotorDrive, SpeedProfile, _finite, is_sequence
from .scene import ANGLE_LIMIT, Scene, load_scene
from .specialise import resolve_kernel
from .steps import (SCIPY_RHS_PER_STEP, check_work, default_max_steps, default_step,
                    drive_max_speed, output_times)
from .trajectory import Trajectory, state_names

__all__ = ["simulate", "SimulationError", "initial_state", "state_scale", "METHODS"]


class SimulationError(FloatingPointError):
    """The state became non-finite; the message says when and in which variable."""

    def __init__(self, message: str, time: float, variable: str):
        super().__init__(message)
        self.time = time
        self.variable = variable


def _vector(name: str, value: Any, n: int, unit: str, limit: float | None = None
            ) -> np.ndarray:
    """``value`` as ``n`` finite floats, or a ValueError naming ``name``, the count and the
    unit (text, None, booleans and nested lists are refused, not converted)."""
    what = f"{name} must be {n} finite numbers [{unit}]"
    if isinstance(value, np.ndarray) and value.dtype.kind in "fiu":
        arr = value.astype(float)
        if arr.shape != (n,):
            raise ValueError(f"{what} (got shape {arr.shape})")
        if not np.all(np.isfinite(arr)) or (limit is not None and np.any(np.abs(arr) > limit)):
            raise ValueError(f"{what}{f' in [-{limit:g}, {limit:g}]' if limit else ''} "
                             f"(got {arr})")
        return arr
    if not is_sequence(value):
        raise ValueError(f"{what} (got {value!r:.80})")
    items = list(value)
    if len(items) != n:
        raise ValueError(f"{what} (got {len(items)} entries)")
    return np.array([_finite(f"{name}[{i}]", v, unit=unit, limit=limit)
                     for i, v in enumerate(items)], dtype=float)


def initial_state(scene: Scene, drive, ball_angles0=None, ball_speeds0=None,
                  x0: Sequence[float] = (0.0, 0.0), v0: Sequence[float] = (0.0, 0.0)) -> np.ndarray:
    """First-order state at t = 0 (rotor angle and speed from the drive).

    ``ball_angles0`` [rad, within +-ANGLE_LIMIT] default to the scene's, ``ball_speeds0``
    (relative to the rotor) [rad/s] to 0; ``x0`` [m] and ``v0`` [m/s] are two numbers each.
    Bad input raises ValueError naming the argument."""
    n = scene.ball_count
    angles = np.asarray(scene.ball_angles0, float) if ball_angles0 is None else _vector(
        "ball_angles0", ball_angles0, n, "rad", limit=ANGLE_LIMIT)
    speeds = np.zeros(n) if ball_speeds0 is None else _vector("ball_speeds0", ball_speeds0, n,
                                                             "rad/s")
    x0 = _vector("x0", x0, 2, "m")
    v0 = _vector("v0", v0, 2, "m/s")
    th0, w0 = drive.initial_rotor_state()
    nq = 3 + n
    s = np.zeros(2 * nq)
    s[0:2] = x0
    s[2] = th0
    s[3:nq] = angles
    s[nq:nq + 2] = v0
    s[nq + 2] = w0
    s[nq + 3:] = speeds
    return s


MIN_T_END = 1e-9  # [s] shorter runs show nothing, and a subnormal span breaks solve_ivp
RTOL_RANGE = (1e-13, 1.0)  # below ~100 machine epsilons no step meets the tolerance


def is_conservative(scene: Scene, drive) -> bool:
    """No damping anywhere and a free rotor: the total energy must stay constant."""
    return (isinstance(drive, MotorDrive) and drive.torque == 0 and drive.speed_gain == 0
            and scene.support_damping_x == 0 and scene.support_damping_y == 0
            and scene.bearing_drag == 0 and not any(scene.ball_drag)
            and not any(scene.ball_rolling_resistance))


def state_scale(scene: Scene) -> np.ndarray:
    """Typical magnitude of each state entry (lengths: the reference length; angles: 1)."""
    nq = 3 + scene.ball_count
    scale = np.ones(2 * nq)
    scale[[0, 1, nq, nq + 1]] = scene.reference_length
    return scale


def simulate(scene: Scene | str, drive: SpeedProfile | MotorDrive | None = None,
             t_end: float | None = None, *,
             ball_angles0=None, ball_speeds0=None, x0=(0.0, 0.0), v0=(0.0, 0.0),
             method: str = "rk4", dt: float | None = None, output_dt: float | None = None,
             rtol: float | None = None, atol: float | None = None,
             energy_tolerance: float = 1e-3, kernel: str | None = None,
             max_steps: int | None = None, drive_limits: str = "warn") -> Trajectory:
    """Simulate a run of ``scene`` under ``drive`` from t = 0 to ``t_end`` [s].

    Every argument is checked before any work: numbers must be real numbers (not text, None or
    booleans) in range (t_end >= 1e-9 s; dt, output_dt, energy_tolerance > 0; rtol in
    [1e-13, 1]; atol >= 0, one number or one per state entry; ball angles within +-1000 rad).

    Parameters
    ----------
    scene : Scene or scene name
    drive : SpeedProfile (prescribed rotor angle) or MotorDrive (rotor spin as a DOF); default
        the scene's nominal run-up, a ramp at half ``drive.max_acceleration`` held at
        ``drive.operating_speed`` (:func:`~abb_gym.physics.drive_limits.nominal_drive`)
    t_end : end time [s], > 0; default: until a speed profile holds its speed, plus the 1 s
        settling window (:func:`~abb_gym.physics.drive_limits.default_t_end`; a motor needs
        one)
    drive_limits : a drive beyond the scene's drive limits (speed above
        ``drive.operating_speed``, acceleration above ``drive.max_acceleration``, torque above
        ``drive.torque_limit``): "warn" (default, a
        :class:`~abb_gym.physics.drive_limits.DriveLimitWarning`), "raise" (ValueError before
        the run; for a motor's speed, after it) or "ignore" (:mod:`abb_gym.physics.drive_limits`
        says why the API warns)
    ball_angles0, ball_speeds0 : initial ball angles [rad] (default: the scene's) and relative
        speeds [rad/s] (default 0)
    x0, v0 : initial deflection [m] and velocity [m/s] of the rotor centre
    method : compiled "rk4" (fixed step, default), "etdrk4" (fixed step, exponential: the
        stiff ball drag integrated exactly), "ros2" (fixed step, L-stable Rosenbrock, any
        stiffness), "dopri5" (adaptive 5(4)), or a ``solve_ivp`` method ("DOP853", "Radau",
        "RK45", "LSODA", "BDF") through the same compiled right-hand side
    dt : step of "rk4"/"etdrk4"/"ros2", first trial step of "dopri5" [s]; default
        :func:`default_step`
    output_dt : sampling interval of the result [s]; default 1 ms (it also caps the step)
    rtol, atol : tolerances of "dopri5" (default 1e-6) and of ``solve_ivp`` (default 1e-10);
        atol [state units: m, rad, m/s, rad/s] defaults to rtol x the state scale (reference
        length for x, y; 1 for angles)
    energy_tolerance : in a conservative run (no damping, free rotor) a relative growth of the
        total energy beyond this (> 0; ``inf``: no check) raises :class:`SimulationError`
    kernel : compiled methods only: "generic" (default through "auto": compiled once for every
        scene) or "specialised" (compiled once per method, ball count and set of effects,
        about 20 s; some 20 % faster per step, for many runs of one kind of scene); default
        ``$ABB_GYM_KERNEL``.  Both give the same trajectory bit for bit.
    max_steps : bound on the steps of the run, checked before it starts: exact for the
        fixed-step methods, an estimate from below for the adaptive ones (``solve_ivp`` also
        stops after 12 x max_steps right-hand sides).  Default :func:`default_max_steps`,
        about 30 s of computing (RK4 with two balls: 1.8e7 steps).  The result holds at most
        :func:`max_output_samples` samples (2e6 with two balls, 160 MB).

    Raises
    ------
    ValueError
        For bad input, naming the argument and its allowed range, and for a run beyond
        ``max_steps`` or the output bound, saying how to proceed.
    SimulationError
        If the state becomes non-finite, the adaptive step underflows, or an undamped run
        gains energy.
    """
    scene = load_scene(scene) if not isinstance(scene, Scene) else scene
    drive_limits = limits.check_mode(drive_limits)
    if drive is None:
        drive = limits.nominal_drive(scene)
    if not isinstance(drive, (SpeedProfile, MotorDrive)):
        raise ValueError(f"drive must be a SpeedProfile or MotorDrive (got {type(drive).__name__})")
    if t_end is None:
        t_end = limits.default_t_end(drive)
    t_end = _finite("t_end", t_end, positive=True, unit="s")
    if t_end < MIN_T_END:
        raise ValueError(f"t_end must be >= {MIN_T_END:g} s (got {t_end!r}): a shorter run "
                         f"turns even a 1e5 rad/s rotor by 1e-4 rad, and solve_ivp fails on it")
    if not (isinstance(method, str) and method in METHODS):
        raise ValueError(f"method must be one of {METHODS} (got {method!r:.80})")
    specialised = resolve_kernel(kernel, 1) == "specialised"
    if dt is not None:
        dt = _finite("dt", dt, positive=True, unit="s")
    if output_dt is not None:
        output_dt = _finite("output_dt", output_dt, positive=True, unit="s")
    rtol = (1e-6 if method in COMPILED_METHODS else 1e-10) if rtol is None else _finite(
        "rtol", rtol, positive=True)
    if not RTOL_RANGE[0] <= rtol <= RTOL_RANGE[1]:
        raise ValueError(f"rtol must be a number in [{RTOL_RANGE[0]:g}, {RTOL_RANGE[1]:g}] "
                         f"(got {rtol!r}): no step meets a tighter relative tolerance in "
                         f"double precision, and a looser one controls nothing")
    if not (isinstance(energy_tolerance, (int, float, np.floating, np.integer))
            and energy_tolerance == math.inf):  # inf switches the check off
        energy_tolerance = _finite("energy_tolerance", energy_tolerance, positive=True)
    if max_steps is None:
        max_steps = default_max_steps(method, scene.ball_count)
    elif isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer)) \
            or max_steps < 1:
        raise ValueError(f"max_steps must be a positive integer (got {max_steps!r:.80})")
    s0 = initial_state(scene, drive, ball_angles0, ball_speeds0, x0, v0)
    if atol is None:
        atol_arr = rtol * state_scale(scene)
    else:
        atol_arr = (_vector("atol", atol, len(s0), "state units") if is_sequence(atol)
                    else np.full(len(s0), _finite("atol", atol, nonneg=True)))
        if np.any(atol_arr < 0):
            raise ValueError(f"atol must be >= 0 in every state entry (got {atol_arr})")
    t_out = output_times(t_end, output_dt, scene.ball_count)
    # the fastest motion is the rotor plus the fastest ball relative to it
    max_speed = drive_max_speed(drive, t_end, scene) + float(
        np.max(np.abs(s0[6 + scene.ball_count:]), initial=0.0))
    if not math.isfinite(max_speed):
        raise ValueError(f"the drive reaches a non-finite rotor speed by t_end = {t_end:g} s; "
                         f"use smaller accelerations or a shorter t_end")
    seg_t, seg_d = drive.segment_table(t_end, scene)
    default_dt = method in COMPILED_METHODS and dt is None
    if default_dt:
        dt = default_step(scene, max_speed, method, drive=drive)
        if not dt >= 0:  # NaN; 0 (underflow) is left to the step count
            raise ValueError(f"no default dt can be formed for this scene and drive (got "
                             f"{dt!r}); pass dt [s]")
    check_work(scene, drive, method, t_end, t_out, len(seg_t), dt, default_dt, max_speed,
               max_steps, rtol)
    limits.enforce(scene, limits.drive_excess(scene, drive, t_end), drive_limits)
    p, b = mdl.pack_parameters(scene)
    out = np.empty((len(t_out), len(s0)))
    start = time.perf_counter()
    if method in COMPILED_METHODS:
        # "auto" is the general kernel: compiled once for every scene (a specialisation per
        # scene pays off only over many runs)
        run = integ.run if specialised else integ.run.generic
        status, t_fail, bad, work = run(
            METHOD_IDS[method], s0, t_out, seg_t, seg_d, p, b, float(dt), float(rtol),
            atol_arr, out, b.shape[0], mdl.spec_of(p, seg_d) | mdl.SPEC_ONE_LANE)
        if method in FIXED_STEP:
            # the step actually taken: an output interval is split into equal steps <= dt
            interval = t_out[1] - t_out[0]
            dt = interval / max(1, math.ceil(interval / dt - 1e-9))
        else:
            dt = None
    else:
        status, t_fail, bad, work = integ.scipy_run(s0, t_out, seg_t, seg_d, p, b, method,
                                                    rtol, atol_arr, out,
                                                    max_nfev=SCIPY_RHS_PER_STEP * max_steps)
        dt = None
    wall = time.perf_counter() - start
    if status == integ.STATUS_WORK_LIMIT:
        raise SimulationError(
            f"simulation of scene {scene.name!r} with {method}: solve_ivp evaluated the "
            f"right-hand side {work:,} times by t = {t_fail:.6g} s of t_end = {t_end:.6g} s, "
            f"more than {SCIPY_RHS_PER_STEP} x max_steps = {max_steps:,} allows (the scene is "
            f"stiffer or the tolerance tighter than estimated); use a compiled method "
            f"('dopri5', 'etdrk4', 'ros2'), a larger rtol, a shorter t_end or a larger max_steps",
            t_fail, "work")
    if status != integ.STATUS_OK:
        name = state_names(scene.ball_count)[bad]
        what = ("the adaptive step fell below 1e-14 s" if status == integ.STATUS_STEP_UNDERFLOW
                else f"the state became non-finite in {name!r}")
        raise SimulationError(
            f"simulation of scene {scene.name!r} with {method}"
            f"{f' (dt = {dt:.3g} s)' if dt else ''}: {what} at t = {t_fail:.6g} s; "
            f"reduce the step, or use 'etdrk4' (stiff drag) or 'ros2' (any stiffness)",
            t_fail, name)
    if is_conservative(scene, drive):
        energy = np.array([mdl.total_energy(s, p, b) for s in out])
        growth = (energy - energy[0]) / max(abs(energy[0]), 1e-300)
        k = int(np.argmax(growth))
        if growth[k] > energy_tolerance:
            raise SimulationError(
                f"simulation of scene {scene.name!r} with {method}: the undamped run gained "
                f"{growth[k]:.3g} of its energy by t = {t_out[k]:.6g} s (tolerance "
                f"{energy_tolerance:g}); the integrator is unstable at this step",
                float(t_out[k]), "energy")
    torque = None
    if isinstance(drive, MotorDrive):
        speed = out[:, 3 + scene.ball_count + 2]
        torque = drive.torque_at(t_out, speed, scene)
        # a speed profile's speed was checked before the run; a motor's is known now
        excess = limits.speed_excess(scene, t_out, speed)
        limits.enforce(scene, [excess] if excess else [], drive_limits)
    return Trajectory(scene=scene, t=t_out, states=out, method=method, step=dt, wall_time=wall,
                      work=int(work), motor_torque=torque)
