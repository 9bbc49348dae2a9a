"""The plain simulation API: ``simulate(scene, drive, t_end) -> Trajectory``."""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
from numba import njit

from . import integrators as integ
from . import drive_law as dl
from . import model as mdl
from .drives import MotorDrive, SpeedProfile
from .scene import Scene, load_scene
from .specialise import resolve_kernel

__all__ = ["simulate", "Trajectory", "SimulationError", "default_step", "stiff_rate",
           "stiff_rates",
           "initial_state", "state_scale", "METHODS"]

COMPILED_METHODS = tuple(integ.METHOD_IDS)
SCIPY_METHODS = ("DOP853", "Radau", "RK45", "LSODA", "BDF")
METHODS = COMPILED_METHODS + SCIPY_METHODS


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
    spec = 0
    for row in p:
        spec |= mdl.spec_of(row, d)
    return _stiff_rates(np.ascontiguousarray(p, float), np.ascontiguousarray(b, float), d, spec)


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
# exactly, so only accuracy bounds its step (tests/test_validation.py checks both rules)
ROTATION_PER_STEP = {"rk4": 0.4, "etdrk4": 1.0, "ros2": 0.4}


def contact_frequency(scene: Scene) -> float:
    """Upper bound [rad/s] of the ball-ball contact frequency, sqrt(4 k_c / m_min)."""
    return math.sqrt(4.0 * scene.contact_stiffness / min(scene.ball_mass))


def default_step(scene: Scene, max_speed: float, method: str = "rk4", rate=None):
    """Default step [s] of the fixed-step methods for a run reaching ``max_speed`` [rad/s]
    (``rate``: the :func:`stiff_rate` if known, or an array of them: an array of steps).

    The step turns the fastest rotation (the higher critical speed or ``max_speed``) by at most
    :data:`ROTATION_PER_STEP` (0.4 rad for RK4 and ROS2, 1.0 rad for ETDRK4).  For the explicit
    RK4 it also keeps h * :func:`stiff_rate` <= 1.5, inside RK4's real-axis stability limit of
    2.79; "etdrk4" treats that rate exactly and the L-stable "ros2" is stable at any step, but
    both keep h * (contact frequency) <= 1 when balls can collide.  On the Yoshida run-up RK4
    takes 1.3 ms steps (0.001 % of the DOP853 peak whirl, 4e-4 deg) and ETDRK4 4.2 ms steps
    (0.1 %, 0.2 deg); ``tests/test_validation.py`` checks the stated 1 % and 1 deg.
    The output interval also caps the step.
    """
    omega = max(scene.critical_speeds[1], abs(max_speed), 1e-9)
    h = ROTATION_PER_STEP.get(method, 0.4) / omega
    if method == "rk4":
        rate = stiff_rate(scene, max_speed) if rate is None else rate
        h = np.where(np.asarray(rate) > 0, np.minimum(h, 1.5 / np.maximum(rate, 1e-300)), h)
    elif scene.contact_stiffness > 0:
        h = np.minimum(h, 1.0 / contact_frequency(scene))
    return float(h) if np.ndim(h) == 0 else h


def initial_state(scene: Scene, drive, ball_angles0=None, ball_speeds0=None,
                  x0: Sequence[float] = (0.0, 0.0), v0: Sequence[float] = (0.0, 0.0)) -> np.ndarray:
    """First-order state at t = 0 (rotor angle and speed from the drive)."""
    n = scene.ball_count
    angles = np.asarray(scene.ball_angles0 if ball_angles0 is None else ball_angles0, float)
    speeds = np.zeros(n) if ball_speeds0 is None else np.asarray(ball_speeds0, float)
    for label, arr in (("ball_angles0", angles), ("ball_speeds0", speeds)):
        if arr.shape != (n,):
            raise ValueError(f"{label} must have ball_count = {n} entries (got shape {arr.shape})")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{label} must be finite (got {arr})")
    for label, arr in (("x0", x0), ("v0", v0)):
        arr = np.asarray(arr, float)
        if arr.shape != (2,) or not np.all(np.isfinite(arr)):
            raise ValueError(f"{label} must be two finite numbers [m or m/s] (got {arr})")
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


def _output_times(t_end: float, output_dt: float | None) -> np.ndarray:
    if output_dt is None:
        output_dt = max(1e-3, t_end / 200_000)
    if not (math.isfinite(output_dt) and output_dt > 0):
        raise ValueError(f"output_dt must be > 0 [s] (got {output_dt})")
    n = max(1, int(round(t_end / output_dt)))
    return np.linspace(0.0, t_end, n + 1)


def drive_max_speed(drive: SpeedProfile | MotorDrive, t_end: float) -> float:
    """Largest rotor speed [rad/s] the drive asks for on [0, t_end] (a motor: its target)."""
    if isinstance(drive, SpeedProfile):
        return drive.max_speed(t_end)
    target = drive.target.max_speed(t_end) if isinstance(drive.target, SpeedProfile) \
        else abs(float(drive.target))
    return max(abs(drive.initial_speed), target)


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
             energy_tolerance: float = 1e-3, kernel: str | None = None) -> Trajectory:
    """Simulate a run of ``scene`` under ``drive`` from t = 0 to ``t_end`` [s].

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
        atol defaults to rtol x the state scale (reference length for x, y; 1 for angles)
    energy_tolerance : in a conservative run (no damping, free rotor) a relative growth of the
        total energy beyond this raises :class:`SimulationError`
    kernel : compiled methods only: "generic" (default through "auto": compiled once for every
        scene) or "specialised" (compiled once per method, ball count and set of effects,
        about 20 s; some 20 % faster per step, for many runs of one kind of scene); default
        ``$ABB_GYM_KERNEL``.  Both give the same trajectory bit for bit.

    Raises
    ------
    ValueError for bad input; :class:`SimulationError` if the state becomes non-finite, the
    adaptive step underflows, or an undamped run gains energy.
    """
    scene = load_scene(scene) if not isinstance(scene, Scene) else scene
    if not isinstance(drive, (SpeedProfile, MotorDrive)):
        raise ValueError(f"drive must be a SpeedProfile or MotorDrive (got {type(drive).__name__})")
    t_end = float(t_end)
    if not (math.isfinite(t_end) and t_end > 0):
        raise ValueError(f"t_end must be > 0 [s] (got {t_end})")
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS} (got {method!r})")
    specialised = resolve_kernel(kernel, 1) == "specialised"
    if rtol is None:
        rtol = 1e-6 if method in COMPILED_METHODS else 1e-10
    if not (math.isfinite(rtol) and rtol > 0):
        raise ValueError(f"rtol must be > 0 (got {rtol})")
    s0 = initial_state(scene, drive, ball_angles0, ball_speeds0, x0, v0)
    t_out = _output_times(t_end, output_dt)
    seg_t, seg_d = drive.segment_table(t_end, scene)
    p, b = mdl.pack_parameters(scene)
    out = np.empty((len(t_out), len(s0)))
    atol_arr = rtol * state_scale(scene) if atol is None else np.broadcast_to(
        np.asarray(atol, float), s0.shape).copy()
    start = time.perf_counter()
    if method in COMPILED_METHODS:
        if dt is None:
            dt = default_step(scene, drive_max_speed(drive, t_end), method)
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be > 0 [s] (got {dt})")
        # "auto" is the general kernel: compiled once for every scene (a specialisation per
        # scene pays off only over many runs)
        run = integ.run if specialised else integ.run.generic
        status, t_fail, bad, work = run(
            integ.METHOD_IDS[method], s0, t_out, seg_t, seg_d, p, b, float(dt), float(rtol),
            atol_arr, out, b.shape[0], mdl.spec_of(p, seg_d))
        if method in integ.FIXED_STEP:
            # the step actually taken: an output interval is split into equal steps <= dt
            interval = t_out[1] - t_out[0]
            dt = interval / math.ceil(interval / dt - 1e-9)
        else:
            dt = None
    else:
        status, t_fail, bad, work = integ.scipy_run(s0, t_out, seg_t, seg_d, p, b, method,
                                                    rtol, atol_arr, out)
        dt = None
    wall = time.perf_counter() - start
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
