"""The plain simulation API: ``simulate(scene, drive, t_end) -> Trajectory``."""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
from .._numba import njit

from . import integrators as integ
from . import drive_law as dl
from . import model as mdl
from .methods import COMPILED_METHODS, FIXED_STEP, METHOD_IDS, METHODS
from .drives import MotorDrive, SpeedProfile, _finite, is_sequence
from .scene import ANGLE_LIMIT, Scene, load_scene
from .specialise import resolve_kernel

__all__ = ["simulate", "Trajectory", "SimulationError", "default_step", "stiff_rate",
           "stiff_rates", "explicit_rate", "default_max_steps", "step_cost", "max_output_samples",
           "initial_state", "state_scale", "METHODS"]



class SimulationError(FloatingPointError):
    """The state became non-finite; the message says when and in which variable."""

    def __init__(self, message: str, time: float, variable: str):
        super().__init__(message)
        self.time = time
        self.variable = variable


def state_names(n_balls: int) -> list[str]:
    """Names of the entries of the first-order state vector."""
    q = ["x", "y", "rotor_angle"] + [f"ball_angle[{i}]" for i in range(n_balls)]
    v = ["x_velocity", "y_velocity", "rotor_speed"] + [f"ball_speed[{i}]" for i in range(n_balls)]
    return q + v


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


class PlanarStates:
    """Accessors of a state history whose first two columns are the rotor centre (x, y)."""

    states: np.ndarray

    @property
    def x(self) -> np.ndarray:
        """Rotor-centre deflection x (the trajectory's length unit)."""
        return self.states[:, 0]

    @property
    def y(self) -> np.ndarray:
        """Rotor-centre deflection y (the trajectory's length unit)."""
        return self.states[:, 1]

    @property
    def whirl_radius(self) -> np.ndarray:
        """W_r = sqrt(x^2 + y^2) (the trajectory's length unit)."""
        return np.hypot(self.states[:, 0], self.states[:, 1])


@dataclass
class Trajectory(PlanarStates):
    """Result of :func:`simulate`; arrays are sampled at ``t`` [s]; lengths in m.

    ``ball_angles`` are relative to the rotor, measured from the imbalance, unwrapped [rad].
    """

    scene: Scene
    t: np.ndarray
    states: np.ndarray
    method: str
    step: float | None  # largest RK4 step taken [s] (None for solve_ivp methods)
    wall_time: float
    work: int
    motor_torque: np.ndarray | None = None
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def n_balls(self) -> int:
        return self.scene.ball_count

    @property
    def _nq(self) -> int:
        return 3 + self.n_balls

    @property
    def rotor_angle(self) -> np.ndarray:
        """Rotor angle psi [rad]."""
        return self.states[:, 2]

    @property
    def rotor_speed(self) -> np.ndarray:
        """Rotor speed psi' [rad/s]."""
        return self.states[:, self._nq + 2]

    @property
    def ball_angles(self) -> np.ndarray:
        """Ball angles relative to the rotor from the imbalance, unwrapped, shape (T, n) [rad]."""
        return self.states[:, 3:self._nq]

    @property
    def ball_speeds(self) -> np.ndarray:
        """Ball angular speeds relative to the rotor, shape (T, n) [rad/s]."""
        return self.states[:, self._nq + 3:]

    @property
    def whirl_ratio(self) -> np.ndarray:
        """W_r / e with e = ``scene.reference_length`` (Yoshida's plots) [-]."""
        return self.whirl_radius / self.scene.reference_length

    def summary(self, settle_window: float = 0.5) -> dict[str, Any]:
        """Headline numbers: peak whirl and its time, final and residual whirl, ball angles."""
        wr = self.whirl_ratio
        k = int(np.argmax(wr))
        tail = self.t >= self.t[-1] - settle_window
        return {
            "scene": self.scene.name,
            "method": self.method,
            "peak_whirl_ratio": float(wr[k]),
            "peak_time_s": float(self.t[k]),
            "residual_whirl_ratio": float(np.mean(wr[tail])),
            "final_speed_rad_s": float(self.rotor_speed[-1]),
            "final_ball_angles_deg": [float(v) for v in np.degrees(self.ball_angles[-1])],
            "wall_time_s": self.wall_time,
        }

    def to_dict(self) -> dict[str, Any]:
        d = {"scene": self.scene.to_dict(), "method": self.method, "step": self.step,
             "t": self.t.tolist(), "x": self.x.tolist(), "y": self.y.tolist(),
             "rotor_angle": self.rotor_angle.tolist(), "rotor_speed": self.rotor_speed.tolist(),
             "ball_angles": self.ball_angles.tolist(), "whirl_radius": self.whirl_radius.tolist(),
             "summary": self.summary()}
        if self.motor_torque is not None:
            d["motor_torque"] = self.motor_torque.tolist()
        return d

    def to_json(self, path=None) -> str:
        text = json.dumps(self.to_dict())
        if path is not None:
            with open(path, "w") as fh:
                fh.write(text)
        return text


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


MIN_T_END = 1e-9  # [s] shorter runs show nothing, and a subnormal span breaks solve_ivp
RTOL_RANGE = (1e-13, 1.0)  # below ~100 machine epsilons no step meets the tolerance
# largest step [x 1/rate] of the explicit adaptive methods, the reach of their stability
# regions along the negative real axis (DOPRI5 and RK45 3.3, DOP853 about 6): taken as the
# largest step they can take, so that the estimated step count stays a lower bound
EXPLICIT_STABILITY = {"dopri5": 3.3, "RK45": 3.3, "DOP853": 6.0}


def _output_times(t_end: float, output_dt: float | None, n_balls: int) -> np.ndarray:
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


def _check_work(scene: Scene, drive, method: str, t_end: float, t_out: np.ndarray,
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


def simulate(scene: Scene | str, drive: SpeedProfile | MotorDrive, t_end: float, *,
             ball_angles0=None, ball_speeds0=None, x0=(0.0, 0.0), v0=(0.0, 0.0),
             method: str = "rk4", dt: float | None = None, output_dt: float | None = None,
             rtol: float | None = None, atol: float | None = None,
             energy_tolerance: float = 1e-3, kernel: str | None = None,
             max_steps: int | None = None) -> Trajectory:
    """Simulate a run of ``scene`` under ``drive`` from t = 0 to ``t_end`` [s].

    Every argument is checked before any work: numbers must be real numbers (not text, None or
    booleans) in range (t_end >= 1e-9 s; dt, output_dt, energy_tolerance > 0; rtol in
    [1e-13, 1]; atol >= 0, one number or one per state entry; ball angles within +-1000 rad).

    Parameters
    ----------
    scene : Scene or scene name
    drive : SpeedProfile (prescribed rotor angle) or MotorDrive (rotor spin as a DOF)
    t_end : end time [s], > 0
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
    if not isinstance(drive, (SpeedProfile, MotorDrive)):
        raise ValueError(f"drive must be a SpeedProfile or MotorDrive (got {type(drive).__name__})")
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
    t_out = _output_times(t_end, output_dt, scene.ball_count)
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
    _check_work(scene, drive, method, t_end, t_out, len(seg_t), dt, default_dt, max_speed,
                max_steps, rtol)
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
        torque = drive.torque_at(t_out, out[:, 3 + scene.ball_count + 2], scene)
    return Trajectory(scene=scene, t=t_out, states=out, method=method, step=dt, wall_time=wall,
                      work=int(work), motor_torque=torque)
