"""Step sizes and work bounds: the rules that set the fixed step of the compiled methods and
bound the work of a run before it starts.

:func:`default_step` is the one step rule.  :func:`~abb_gym.physics.simulate.simulate`, the
batched kernel (:mod:`abb_gym.physics.batch`) and the environments' episodes all take their
step from it, so a run of the simulation API and an episode of an environment on the same
machine are stepped alike.  The rates it bounds the step by (:func:`stiff_rate`,
:func:`explicit_rate`, :func:`contact_frequency`) are those of the equations in
:mod:`abb_gym.physics.model`.  The work bounds (:func:`check_work`, :func:`output_times`) are
checked before anything is allocated or compiled code runs, and say how to proceed.
"""
from __future__ import annotations

import math

import numpy as np
from .._numba import njit

from . import drive_law as dl
from . import model as mdl
from .methods import FIXED_STEP
from .drives import MotorDrive, SpeedProfile
from .scene import Scene

__all__ = ["default_step", "stiff_rate", "stiff_rates", "explicit_rate", "contact_frequency",
           "ROTATION_PER_STEP", "drive_max_speed", "default_max_steps", "step_cost",
           "max_output_samples", "output_times", "check_work", "WORK_BUDGET",
           "SCIPY_RHS_PER_STEP"]


def stiff_rate(scene: Scene, max_speed: float) -> float:
    """Largest relaxation rate of a ball's relative motion at rotor speed ``max_speed`` [1/s].

    rate = (c_b + c_roll) / (m (1 + I/(m r^2))) with the slope of the smoothed rolling
    resistance c_roll = (beta_b / r) m R Omega^2 / u* (:func:`model.drag_rates` at rest
    relative to the rotor).  The first term is set by the race drag, the second grows with the
    rotor speed: together they bound the step of the explicit methods (RK4: h * rate < 2.79).
    """
    p, b = mdl.pack_parameters(scene)
    return float(stiff_rates(p[None], b[None], max_speed)[0])


def stiff_rates(p: np.ndarray, b: np.ndarray, max_speed: float) -> np.ndarray:
    """:func:`stiff_rate` [1/s] of many packed parameter sets at once: ``p`` (R, N_PARAMS),
    ``b`` (R, n, N_BALL_PARAMS) (the episodes of a vector environment)."""
    d = np.zeros(dl.N_DRIVE)
    d[dl.D_W0] = max_speed
    return _stiff_rates(np.ascontiguousarray(p, float), np.ascontiguousarray(b, float), d,
                        mdl.spec_of(p, d))


@njit(cache=True)
def _stiff_rates(p, b, d, spec):
    ns = 2 * (3 + b.shape[1])
    out = np.empty(p.shape[0])
    s = np.zeros(ns)
    lam = np.zeros(ns)
    for r in range(p.shape[0]):
        mdl.drag_rates(0.0, s, p[r], b[r], d, lam, spec)
        out[r] = lam.max()
    return out


# rotation of the fastest motion per step [rad]; ETDRK4 integrates the stiff ball drag
# exactly, so only accuracy bounds its step.  The second-order ROS2 needs 8x smaller steps
# than RK4 for the same 1 % / 1 deg: at 0.4 rad it was 8 % off the peak whirl of the Yoshida
# ramp at 1 ms output and 28 % at 10 ms (against DOP853; tests/test_bad_input.py checks every
# method's default)
ROTATION_PER_STEP = {"rk4": 0.4, "etdrk4": 1.0, "ros2": 0.05}


def contact_frequency(scene: Scene) -> float:
    """Upper bound [rad/s] of the ball-ball contact frequency, sqrt(4 k_c / m_min)."""
    return math.sqrt(4.0 * scene.contact_stiffness / min(scene.ball_mass))


def explicit_rate(scene: Scene, drive=None) -> float:
    """Largest relaxation rate [1/s] outside the ball equations, which ETDRK4 too integrates
    explicitly: the support damping c/M (overdamped: the fast root of M s^2 + c s + k) and,
    with a :class:`MotorDrive`, the rotor spin (bearing drag + speed gain + the torque limit
    over the no-load speed) / rotor_polar_inertia (the balls' share of the inertia left out,
    which can only raise the rate).  For the shipped scenes it is a few 1/s; a support damping
    of 1e9 N s/m on a 0.1 kg rotor makes it 1e10 1/s, where only ROS2 and Radau take usable
    steps."""
    rate = max(scene.support_damping_x, scene.support_damping_y) / scene.total_mass
    if isinstance(drive, MotorDrive):
        slope = drive.speed_gain + scene.bearing_drag
        if drive.no_load_speed:
            slope += drive.limit(scene) / drive.no_load_speed
        rate = max(rate, slope / scene.rotor_polar_inertia)
    return rate


def default_step(scene: Scene, max_speed: float, method: str = "rk4", rate=None, drive=None,
                 critical_speed=None, other_rate=None):
    """Default step [s] of the fixed-step methods for a run reaching ``max_speed`` [rad/s]
    (``rate``: the :func:`stiff_rate` if known, or an array of them: an array of steps;
    ``drive``: the run's drive, for :func:`explicit_rate`).  ``critical_speed`` (the scene's
    ``critical_speeds[1]``) and ``other_rate`` (:func:`explicit_rate`) may be given, as numbers
    or arrays, for machines that differ from ``scene`` in mass or support damping (the
    episodes of a randomised preset): the steps are then those of each such scene.

    The step turns the fastest rotation (the higher critical speed or ``max_speed``) by at most
    :data:`ROTATION_PER_STEP` (0.4 rad for RK4, 1.0 rad for ETDRK4, 0.05 rad for the
    second-order ROS2).  For the explicit RK4 it also keeps h * :func:`stiff_rate` <= 1.5,
    inside RK4's real-axis stability limit of 2.79; "etdrk4" treats that rate exactly and the
    L-stable "ros2" is stable at any step, but both keep h * (contact frequency) <= 1 when
    balls can collide, and RK4 and ETDRK4 keep h * :func:`explicit_rate` <= 1.5 (heavy
    support damping, a stiff motor).  Against DOP853 (rtol 1e-12) on the Yoshida ramp RK4
    takes 1.25 ms steps (0.001 % of the peak whirl, 1e-3 deg of final ball angle), ETDRK4
    3.3 ms (0.1 %, 0.05 deg), ROS2 0.21 ms (0.02 %, 0.04 deg); ``tests/test_bad_input.py``
    checks the stated 1 % and 1 deg there and on spannan_cfrp.  It does not hold for the final
    ball angles of lu_hung_odd3 with ETDRK4 and ROS2 (three balls: their balanced positions
    form a family, so the final angles keep every error of the path).  The output
    interval also caps the step.
    """
    if critical_speed is None:
        omega = max(scene.critical_speeds[1], abs(max_speed), 1e-9)
    else:
        omega = np.maximum(np.maximum(np.asarray(critical_speed, float), abs(max_speed)), 1e-9)
    h = ROTATION_PER_STEP.get(method, 0.4) / omega
    if method == "rk4":
        rate = stiff_rate(scene, max_speed) if rate is None else rate
        h = np.where(np.asarray(rate) > 0, np.minimum(h, 1.5 / np.maximum(rate, 1e-300)), h)
    elif scene.contact_stiffness > 0:
        h = np.minimum(h, 1.0 / contact_frequency(scene))
    if method in ("rk4", "etdrk4"):
        other = explicit_rate(scene, drive) if other_rate is None else other_rate
        if np.ndim(other) == 0:
            if other > 0:
                h = np.minimum(h, 1.5 / other)
        else:
            other = np.asarray(other, float)
            pos = other > 0
            h = np.where(pos, np.minimum(h, 1.5 / np.where(pos, other, 1.0)), h)
    return float(h) if np.ndim(h) == 0 else h


# Bounds on the work of one call, checked before anything is allocated or compiled code runs
# (a step of 1e-15 s would otherwise run for days, an output interval of 1e-15 s would ask
# for terabytes); ``simulate(max_steps=...)`` raises the step bound for a run that needs it.
WORK_BUDGET = 30.0  # [s] of computing a call may take by default (by :func:`step_cost`)
MAX_OUTPUT_BYTES = 160e6  # the result's states: 2e6 samples at two balls, 1.5e5 at 64
SCIPY_RHS_PER_STEP = 12  # solve_ivp stops after 12 x max_steps right-hand sides (DOP853's)


def max_output_samples(n_balls: int) -> int:
    """Most samples a result of ``n_balls`` balls may hold (:data:`MAX_OUTPUT_BYTES`)."""
    return int(MAX_OUTPUT_BYTES / (8 * (6 + 2 * n_balls)))


def step_cost(method: str, n_balls: int) -> float:
    """Wall time of one step [s] of ``method`` with ``n_balls`` balls (generic kernel, one core
    of the development machine; measured at 2, 12 and 64 balls, rounded up).  A right-hand
    side costs about (0.25 + 0.08 n) us; RK4 takes 4, ETDRK4 and DOPRI5 about 6; ROS2 forms
    and factorises a Jacobian of 2 (3 + n) rows every step; ``solve_ivp`` pays a Python call
    per right-hand side (15 us for DOP853, 50 us with Radau's linear algebra)."""
    rhs = (0.25 + 0.08 * n_balls) * 1e-6
    if method == "rk4":
        return 4.0 * rhs
    if method in ("etdrk4", "dopri5"):
        return 6.0 * rhs
    if method == "ros2":
        return (2.0 + 0.07 * (6 + 2 * n_balls) ** 2) * 1e-6
    return SCIPY_RHS_PER_STEP * 50e-6  # Radau/BDF: their Newton and Jacobian work per call


def default_max_steps(method: str, n_balls: int) -> int:
    """The steps :data:`WORK_BUDGET` buys: the default ``max_steps`` of :func:`simulate`
    (RK4, two balls: 1.8e7; ROS2, two balls: 3.3e6; ``solve_ivp``: 5e4)."""
    return max(1000, int(WORK_BUDGET / step_cost(method, n_balls)))


# largest step [x 1/rate] of the explicit adaptive methods, the reach of their stability
# regions along the negative real axis (DOPRI5 and RK45 3.3, DOP853 about 6): taken as the
# largest step they can take, so that the estimated step count stays a lower bound
EXPLICIT_STABILITY = {"dopri5": 3.3, "RK45": 3.3, "DOP853": 6.0}


def output_times(t_end: float, output_dt: float | None, n_balls: int) -> np.ndarray:
    """The sampling times [s] of a run's result on [0, ``t_end``], ``output_dt`` apart
    (default 1 ms, coarser for a run that would exceed 200 000 samples); a ValueError saying
    how to proceed if they exceed :func:`max_output_samples`."""
    limit = max_output_samples(n_balls)
    if output_dt is None:
        output_dt = max(1e-3, t_end / min(200_000, limit - 1))
    ratio = t_end / output_dt
    if ratio > limit - 1:
        gb = 8.0 * (6 + 2 * n_balls) * min(ratio, 1e300) / 1e9
        raise ValueError(
            f"output_dt = {output_dt:.3g} s over t_end = {t_end:.6g} s asks for {ratio:.3g} "
            f"output samples ({gb:.3g} GB); at most {limit:,} are returned with "
            f"{n_balls} balls: use output_dt >= {t_end / (limit - 1):.3g} s or a shorter t_end")
    n = max(1, int(round(ratio)))
    return np.linspace(0.0, t_end, n + 1)


def _fastest_rotation(scene: Scene, max_speed: float) -> float:
    """The fastest rotation of a run [rad/s]: the higher critical speed or the top speed."""
    return max(scene.critical_speeds[1], abs(max_speed), 1e-9)


def check_work(scene: Scene, drive, method: str, t_end: float, t_out: np.ndarray,
               n_segments: int,
               dt: float | None, default_dt: bool, max_speed: float, max_steps: int,
               rtol: float) -> None:
    """Raise ValueError, saying how to proceed, if the run needs more than ``max_steps``
    steps: counted exactly for the fixed-step methods (as the kernel splits each output
    interval), estimated from below for the adaptive ones (no accurate step turns the fastest
    rotation by more than pi, no explicit step exceeds its stability limit)."""
    intervals = len(t_out) - 1
    interval = float(t_out[1] - t_out[0])  # a Python float: overflow is inf, not a warning
    rate = 0.0
    if method in FIXED_STEP:
        ratio = interval / dt if dt > 0 else math.inf
        steps = intervals * max(1, math.ceil(ratio - 1e-9)) + n_segments \
            if ratio <= max_steps else math.inf
        what = f"{method} with dt = {dt:.3g} s"
    else:
        omega = _fastest_rotation(scene, max_speed)
        # no accurate step turns the fastest rotation by more than pi; DOPRI5's error per step
        # ~ (omega h)^5 must stay near rtol (measured on the Yoshida ramp: 3 rtol^(1/5) rad a
        # step, 4 taken here so that the estimate stays below the steps actually taken)
        h = math.pi / omega
        if method == "dopri5":
            h = min(h, 4.0 * rtol ** 0.2 / omega)
        if method in EXPLICIT_STABILITY:
            rate = max(stiff_rate(scene, max_speed), explicit_rate(scene, drive),
                       contact_frequency(scene) if scene.contact_stiffness > 0 else 0.0)
            if rate > 0:
                h = min(h, EXPLICIT_STABILITY[method] / rate)
        steps = max(float(intervals), t_end / h if h > 0 else math.inf) + n_segments
        what = f"{method} (at least {h:.3g} s steps)"
    if steps <= max_steps:
        return
    omega = _fastest_rotation(scene, max_speed)
    if method in FIXED_STEP and not default_dt:
        how = "use a larger dt or a shorter t_end"
    elif method in FIXED_STEP:
        rate = stiff_rate(scene, max_speed) if method == "rk4" else 0.0
        other = explicit_rate(scene, drive) if method != "ros2" else 0.0
        rotation = ROTATION_PER_STEP[method] / omega
        if other > 0 and 1.5 / other < rotation and other >= rate:
            how = (f"the default dt is set by the support damping or the motor drive (rate "
                   f"{other:.3g} 1/s, {method} needs dt <= 1.5/rate): use method='ros2', "
                   f"which no rate limits, or a shorter t_end")
        elif method == "rk4" and rate > 0 and 1.5 / rate < rotation:
            how = (f"the default dt is set by the stiff ball drag, rolling resistance or "
                   f"friction (rate {rate:.3g} 1/s, rk4 needs dt <= 1.5/rate): use "
                   f"method='etdrk4' or 'ros2', which that rate does not limit, or a shorter "
                   f"t_end")
        elif scene.contact_stiffness > 0 and 1.0 / contact_frequency(scene) < rotation:
            how = (f"the default dt is set by the ball contact (contact_stiffness = "
                   f"{scene.contact_stiffness:g} N/m): use a softer contact or a shorter t_end")
        else:
            how = (f"the default dt turns the fastest rotation ({omega:.3g} rad/s) by "
                   f"{ROTATION_PER_STEP[method]} rad a step: use a shorter t_end, or a larger "
                   f"dt (less accurate)")
    elif rate > 0 and EXPLICIT_STABILITY[method] / rate < math.pi / omega:
        how = (f"the stiff scene (rate {rate:.3g} 1/s) holds an explicit method's step below "
               f"{EXPLICIT_STABILITY[method] / rate:.3g} s: use method='ros2' or 'Radau' "
               f"('etdrk4' if the ball drag sets the rate), or a shorter t_end")
    elif method == "dopri5":
        how = f"use a larger rtol (now {rtol:g}) or a shorter t_end"
    else:
        how = "use a shorter t_end or a larger output_dt"
    raise ValueError(
        f"simulate: {what} over t_end = {t_end:.6g} s (top rotor speed {max_speed:.3g} rad/s) "
        f"takes {f'{steps:.3g}' if math.isfinite(steps) else 'over 1e308'} steps, "
        f"more than the limit max_steps = {max_steps:,} (about "
        f"{max_steps * step_cost(method, scene.ball_count):.2g} s of computing); {how}; or "
        f"pass a larger max_steps if the run is meant to be that long")


def drive_max_speed(drive: SpeedProfile | MotorDrive, t_end: float,
                    scene: Scene | None = None) -> float:
    """Largest rotor speed [rad/s] the drive asks for on [0, t_end] (a motor: its target).

    With ``scene``, a motor with a torque command is also bounded by what that torque can
    reach by ``t_end``: w0 + min(|T|, T_max) t_end / J (J the rotor's own polar inertia, which
    overestimates the speed): a free spin-up is then not stepped at the pace of its start."""
    if isinstance(drive, SpeedProfile):
        return drive.max_speed(t_end)
    target = drive.target.max_speed(t_end) if isinstance(drive.target, SpeedProfile) \
        else abs(float(drive.target))
    top = max(abs(drive.initial_speed), target)
    if scene is not None and drive.torque != 0:
        reach = min(abs(drive.torque), drive.limit(scene)) * t_end / scene.rotor_polar_inertia
        top = max(top, abs(drive.initial_speed) + reach)
    return top
