"""The plain simulation API: ``simulate(scene, drive, t_end) -> Trajectory``."""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from . import integrators as integ
from . import model as mdl
from .drives import MotorDrive, SpeedProfile
from .scene import Scene, load_scene

__all__ = ["simulate", "Trajectory", "SimulationError", "default_step", "initial_state",
           "METHODS"]

METHODS = ("rk4", "DOP853", "Radau", "RK45", "LSODA", "BDF")


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


def default_step(scene: Scene, max_speed: float) -> float:
    """Default RK4 step [s]: a fixed fraction of the shortest time scale of the run.

    Time scales: the higher critical speed, the highest rotor speed ``max_speed`` [rad/s], and
    the relaxation rate of the race drag, rate = c_b / (m (1 + I/(m r^2))).  The step turns the
    fastest rotation by at most 0.4 rad and keeps h * rate <= 1.5, inside RK4's real-axis
    stability limit of 2.79.  On the Yoshida run-up this is 1.7 ms and stays within 0.1 % of the
    DOP853 peak whirl and 0.1 deg of the ball angles (``tests/test_validation.py`` checks the
    stated 1 % and 1 deg).  The output interval also caps the step.
    """
    a = scene.arrays()
    rate = float(np.max(a["ball_drag"] / (a["ball_mass"] * (1.0 + a["ball_inertia_factor"]))))
    omega = max(scene.critical_speeds[1], abs(max_speed), 1e-9)
    h = 0.4 / omega
    if rate > 0:
        h = min(h, 1.5 / rate)
    return h


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


@dataclass
class Trajectory:
    """Result of :func:`simulate`; arrays are sampled at ``t`` [s].

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
    def x(self) -> np.ndarray:
        """Rotor-centre deflection x [m]."""
        return self.states[:, 0]

    @property
    def y(self) -> np.ndarray:
        """Rotor-centre deflection y [m]."""
        return self.states[:, 1]

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
    def whirl_radius(self) -> np.ndarray:
        """W_r = sqrt(x^2 + y^2) [m]."""
        return np.hypot(self.x, self.y)

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


def simulate(scene: Scene | str, drive: SpeedProfile | MotorDrive, t_end: float, *,
             ball_angles0=None, ball_speeds0=None, x0=(0.0, 0.0), v0=(0.0, 0.0),
             method: str = "rk4", dt: float | None = None, output_dt: float | None = None,
             rtol: float = 1e-10, atol: float | None = None) -> Trajectory:
    """Simulate a run of ``scene`` under ``drive`` from t = 0 to ``t_end`` [s].

    Parameters
    ----------
    scene : Scene or scene name
    drive : SpeedProfile (prescribed rotor angle) or MotorDrive (rotor spin as a DOF)
    t_end : end time [s], > 0
    ball_angles0, ball_speeds0 : initial ball angles [rad] (default: the scene's) and relative
        speeds [rad/s] (default 0)
    x0, v0 : initial deflection [m] and velocity [m/s] of the rotor centre
    method : "rk4" (compiled fixed step) or a ``solve_ivp`` method ("DOP853", "Radau", ...)
    dt : RK4 step [s]; default :func:`default_step`
    output_dt : sampling interval of the result [s]; default 1 ms
    rtol, atol : tolerances of the ``solve_ivp`` methods (atol default 1e-10 x the state scale)

    Raises
    ------
    ValueError for bad input; :class:`SimulationError` if the state becomes non-finite.
    """
    scene = load_scene(scene) if not isinstance(scene, Scene) else scene
    if not isinstance(drive, (SpeedProfile, MotorDrive)):
        raise ValueError(f"drive must be a SpeedProfile or MotorDrive (got {type(drive).__name__})")
    t_end = float(t_end)
    if not (math.isfinite(t_end) and t_end > 0):
        raise ValueError(f"t_end must be > 0 [s] (got {t_end})")
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS} (got {method!r})")
    s0 = initial_state(scene, drive, ball_angles0, ball_speeds0, x0, v0)
    t_out = _output_times(t_end, output_dt)
    seg_t, seg_d = drive.segment_table(t_end, scene)
    p, b = mdl.pack_parameters(scene)
    out = np.empty((len(t_out), len(s0)))
    start = time.perf_counter()
    if method == "rk4":
        if dt is None:
            max_speed = drive.max_speed(t_end) if isinstance(drive, SpeedProfile) else \
                max(abs(drive.initial_speed), *(
                    [drive.target.max_speed(t_end)] if isinstance(drive.target, SpeedProfile)
                    else [abs(float(drive.target))]), 1.0)
            dt = default_step(scene, max_speed)
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be > 0 [s] (got {dt})")
        status, t_fail, bad, work = integ.rk4_run(s0, t_out, seg_t, seg_d, p, b, float(dt), out)
        # the step actually taken: an output interval is split into equal steps <= dt
        interval = t_out[1] - t_out[0]
        dt = interval / math.ceil(interval / dt - 1e-9)
    else:
        if atol is None:
            nq = 3 + scene.ball_count
            scale = np.ones(2 * nq)
            scale[[0, 1, nq, nq + 1]] = scene.reference_length
            atol = 1e-10 * scale
        status, t_fail, bad, work = integ.scipy_run(s0, t_out, seg_t, seg_d, p, b, method,
                                                    rtol, atol, out)
        dt = None
    wall = time.perf_counter() - start
    if status != integ.STATUS_OK:
        name = state_names(scene.ball_count)[bad]
        raise SimulationError(
            f"simulation of scene {scene.name!r} with {method}"
            f"{f' (dt = {dt:.3g} s)' if dt else ''} became non-finite at t = {t_fail:.6g} s "
            f"in {name!r}; reduce the step or use a stiff method", t_fail, name)
    torque = None
    if isinstance(drive, MotorDrive):
        torque = drive.torque_at(t_out, out[:, 3 + scene.ball_count + 2], scene)
    return Trajectory(scene=scene, t=t_out, states=out, method=method, step=dt, wall_time=wall,
                      work=int(work), motor_torque=torque)
