"""Work-precision benchmark: error against a DOP853 reference versus wall time, for every
integrator over a range of steps or tolerances, on two scenes.  ``abb-gym bench accuracy``.

The batched RK4 of :func:`abb_gym.physics.batch.run_batch` appears twice more, as its users
(the vector environment, the tuner, parameter studies) run it: 64 copies of the run at once,
wall time per run, in float64 (its errors equal ``rk4``'s: the same arithmetic) and in
float32 (``precision="float32"``).  :func:`precision_table` compares float32 with float64 on
a run-up of every shipped scene against the 1 % peak-whirl / 1 deg criterion under which
float32 could become the default."""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._files import savefig
from ..physics import MotorDrive, SimulationError, SpeedProfile, list_scenes, load_scene
from ..physics import model as mdl
from ..physics import simulate
from ..physics.simulate import initial_state
from ..physics.steps import default_step, drive_max_speed
from ..physics.trajectory import Trajectory
from ..progress import ProgressBar

OUTPUT_DT = 0.01  # s, the environments' control interval


@dataclass(frozen=True)
class Case:
    scene: str
    drive: SpeedProfile
    t_end: float
    label: str


def default_cases() -> list[Case]:
    yoshida = load_scene("yoshida_odd")
    cfrp = load_scene("spannan_cfrp")
    accel = cfrp.drive_max_acceleration
    return [
        Case("yoshida_odd", SpeedProfile.dwell(40.0, yoshida.critical_speed, 0.5), 6.0,
             "Yoshida run-up with a 0.5 s dwell, 6 s"),
        Case("spannan_cfrp", SpeedProfile.ramp(accel, cfrp.drive_operating_speed),
             cfrp.drive_operating_speed / accel + 10.0,
             f"CFRP run-up at {accel:g} rad/s^2 to {cfrp.drive_operating_speed:g} rad/s"),
    ]


def settings(scene, case: Case) -> list[tuple[str, dict]]:
    """(method, keyword arguments) pairs spanning coarse to fine."""
    h0 = default_step(scene, drive_max_speed(case.drive, case.t_end), "rk4")
    steps = [h0 * f for f in (4.0, 2.0, 1.0, 0.5, 0.25, 0.125)]
    out = [("rk4", {"dt": h}) for h in steps]
    out += [("etdrk4", {"dt": h}) for h in steps]
    out += [("ros2", {"dt": h}) for h in steps[1:]]
    out += [("dopri5", {"rtol": r}) for r in (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9)]
    out += [("DOP853", {"rtol": r}) for r in (1e-4, 1e-6, 1e-8)]
    out += [("RK45", {"rtol": r}) for r in (1e-3, 1e-5, 1e-7)]
    out += [("Radau", {"rtol": r}) for r in (1e-3, 1e-5, 1e-7)]
    out += [(f"rk4 x{BATCH_RUNS} {precision}", {"dt": h}) for precision in ("float64", "float32")
            for h in steps]
    return out


#: copies of a run that the batched rows integrate at once (a block of 32 lanes per core)
BATCH_RUNS = 64


def batch_run(scene, drive, t_out: np.ndarray, dt: float, precision: str,
              runs: int = BATCH_RUNS, kernel: str | None = None,
              state0: np.ndarray | None = None) -> Trajectory:
    """``runs`` copies of ``simulate(scene, drive, method="rk4", dt=dt)`` at once through
    :func:`abb_gym.physics.batch.run_batch` in ``precision`` (``kernel``: its argument), from
    ``state0`` (default: the scene's initial state): the first copy's trajectory, with the
    wall time per copy.  Raises SimulationError if the run failed."""
    from ..physics import batch
    s0, seg_d, nseg, p, b, _ = batch.run_inputs([scene], drive, float(t_out[-1]),
                                                scene.drive_operating_speed)
    if state0 is not None:
        s0 = np.asarray(state0, float)[None]
    s0, seg_d, nseg, p, b = (np.repeat(a, runs, axis=0) for a in (s0, seg_d, nseg, p, b))
    out = np.empty((runs, len(t_out), s0.shape[1]))
    status = np.zeros((runs, 4))
    args = (s0, t_out, seg_d, nseg, p, b, dt, out, status)
    start = time.perf_counter()
    batch.run_batch(*args, precision=precision, kernel=kernel)
    wall = time.perf_counter() - start
    if status[0, 0] != 0:
        raise SimulationError(f"batched rk4 ({precision}) failed at t = {status[0, 1]:.6g} s",
                              float(status[0, 1]), f"state entry {int(status[0, 2])}")
    return Trajectory(scene, np.asarray(t_out), out[0], f"rk4 {precision}", dt, wall / runs,
                      int(status[0, 3]))


def errors(tr, ref) -> dict[str, float]:
    """Peak-whirl, final-ball-angle and whole-trajectory errors of ``tr`` against ``ref``."""
    w, wr = tr.whirl_ratio, ref.whirl_ratio
    return {
        "peak_whirl_rel": float(abs(w.max() / wr.max() - 1)),
        "final_angle_deg": float(np.degrees(np.abs(tr.ball_angles[-1] - ref.ball_angles[-1]).max())),
        "trajectory_rel": float(max(np.abs(w - wr).max() / wr.max(),
                                    np.abs(tr.ball_angles - ref.ball_angles).max() / np.pi)),
    }


def _timed(scene, case, method, kw, repeats, t_out):
    best = np.inf
    tr = None
    for _ in range(repeats):
        if method.startswith("rk4 x"):
            tr = batch_run(scene, case.drive, t_out, kw["dt"], method.split()[-1])
        else:
            tr = simulate(scene, case.drive, case.t_end, method=method, output_dt=OUTPUT_DT,
                          **kw)
        best = min(best, tr.wall_time)
    return tr, best


def run_accuracy(cases: list[Case] | None = None, repeats: int = 3,
                 progress: bool = True) -> list[dict]:
    """Rows: scene, method, setting, wall time per simulated second, work, the three errors
    (NaN and ``stable = False`` where the method failed)."""
    cases = cases or default_cases()
    rows = []
    simulate(load_scene("yoshida_odd"), SpeedProfile.ramp(40.0), 0.02)  # compile / load cache
    for case in cases:
        scene = load_scene(case.scene)
        ref = simulate(scene, case.drive, case.t_end, method="DOP853", rtol=1e-12,
                       output_dt=OUTPUT_DT)
        for precision in ("float64", "float32"):  # compile / load the batched kernels
            batch_run(scene, case.drive, ref.t[:2], 1e-3, precision)
        todo = settings(scene, case)
        for method, kw in ProgressBar(todo, desc=f"accuracy {case.scene}", disable=not progress):
            setting = ", ".join(f"{k}={v:.3g}" for k, v in kw.items())
            row = {"scene": case.scene, "method": method, "setting": setting}
            try:
                timed = method in ("rk4", "etdrk4", "dopri5", "ros2") or method.startswith("rk4 x")
                tr, wall = _timed(scene, case, method, kw, repeats if timed else 1, ref.t)
                row.update(stable=True, wall_ms_per_sim_s=1e3 * wall / case.t_end,
                           work=tr.work, **errors(tr, ref))
            except SimulationError:
                row.update(stable=False, wall_ms_per_sim_s=np.nan, work=0,
                           peak_whirl_rel=np.nan, final_angle_deg=np.nan, trajectory_rel=np.nan)
            rows.append(row)
    return rows


#: the criterion under which float32 could become the default (issue "Vector simulation")
FLOAT32_BOUNDS = {"peak_whirl_rel": 0.01, "ball_angle_deg": 1.0}


def precision_table(scenes: list[str] | None = None, kernel: str = "generic",
                    progress: bool = True) -> list[dict]:
    """float32 against float64 on every shipped scene (or ``scenes``): a run-up at half the drive's largest
    acceleration to the operating speed with a 0.3 s dwell at the critical speed, then 2 s at
    speed, RK4 at the default step, one run in each precision (``kernel``, default the general
    kernel: one compilation for every scene, the same numbers as the specialised ones).  Rows: the peak
    whirl's relative difference, the largest ball-angle difference over the run [deg], the
    rotor angle's [rad], whether the first two are within :data:`FLOAT32_BOUNDS`, the final
    whirl radius in both precisions [m], and two controls that say how much of a difference
    is the scene's own sensitivity: the largest ball-angle difference of a float64 run whose
    first ball starts 1e-7 rad (float32's resolution of an angle near 1) away, and of a
    float64 run with one step more per output interval.  Balls that lag the rotor for many turns amplify any such
    difference; balls that travel as a clump and then part (an unstable equilibrium) go the
    way the rounding at that moment tips them, and float32's rounding is 1e9 times float64's."""
    rows = []
    for name in ProgressBar(scenes or list_scenes(), desc="float32 against float64",
                            disable=not progress):
        scene = load_scene(name)
        a = scene.drive_max_acceleration / 2
        w = scene.drive_operating_speed
        drive = SpeedProfile.dwell(a, scene.critical_speed, 0.3, 0.0, w)
        t_end = w / a + 2.3
        t_out = np.arange(0.0, t_end + 1e-9, OUTPUT_DT)
        dt = default_step(scene, w)
        run = {p: batch_run(scene, drive, t_out, dt, p, runs=1, kernel=kernel)
               for p in ("float64", "float32")}
        r64, r32 = run["float64"], run["float32"]
        nudged = initial_state(scene, drive)
        nudged[3] += 1e-7
        # one step more per output interval than the default step takes
        finer = OUTPUT_DT / (np.ceil(OUTPUT_DT / dt - 1e-9) + 1)
        controls = (batch_run(scene, drive, t_out, dt, "float64", runs=1, kernel=kernel,
                              state0=nudged),
                    batch_run(scene, drive, t_out, finer, "float64", runs=1, kernel=kernel))
        peak = float(abs(r32.whirl_radius.max() / r64.whirl_radius.max() - 1.0))
        balls = float(np.degrees(np.abs(r32.ball_angles - r64.ball_angles).max()))
        rows.append({"scene": name, "balls": scene.ball_count, "dt_ms": dt * 1e3,
                     "t_end_s": t_end, "peak_whirl_rel": peak, "ball_angle_deg": balls,
                     "rotor_angle_rad": float(np.abs(r32.rotor_angle - r64.rotor_angle).max()),
                     "final_whirl_float64_m": float(r64.whirl_radius[-1]),
                     "final_whirl_float32_m": float(r32.whirl_radius[-1]),
                     "nudged_float64_ball_angle_deg": float(np.degrees(np.abs(
                         controls[0].ball_angles - r64.ball_angles).max())),
                     "finer_step_float64_ball_angle_deg": float(np.degrees(np.abs(
                         controls[1].ball_angles - r64.ball_angles).max())),
                     "within": bool(peak <= FLOAT32_BOUNDS["peak_whirl_rel"]
                                    and balls <= FLOAT32_BOUNDS["ball_angle_deg"])})
    return rows


def energy_drift(t_end: float = 60.0, progress: bool = True) -> list[dict]:
    """Relative energy drift of each integrator over a long undamped, free-rotor run."""
    scene = load_scene("yoshida_odd", support_damping=0.0, ball_drag=0.0,
                       ball_rolling_resistance=0.0, bearing_drag=0.0)
    p, b = mdl.pack_parameters(scene)
    drive = MotorDrive(torque=0.0, initial_speed=150.0)
    kw = dict(ball_speeds0=[3.0, -2.0], x0=(1e-3, 0.0), output_dt=0.1)
    runs = [("rk4", {"dt": 2e-3}), ("rk4", {"dt": 5e-4}), ("etdrk4", {"dt": 2e-3}),
            ("ros2", {"dt": 5e-4}), ("dopri5", {"rtol": 1e-6}), ("dopri5", {"rtol": 1e-9}),
            ("DOP853", {"rtol": 1e-10}), ("Radau", {"rtol": 1e-8, "max_steps": 200_000})]
    rows = []
    for method, opts in ProgressBar(runs, desc="energy drift", disable=not progress):
        tr = simulate(scene, drive, t_end, method=method, energy_tolerance=np.inf, **kw, **opts)
        e = np.array([mdl.total_energy(s, p, b) for s in tr.states])
        # Radau at rtol 1e-8 over 60 s needs about 1.8e6 right-hand sides (some 100 s), beyond
        # simulate's default work bound: the benchmark raises the bound for that run
        setting = ", ".join(f"{k}={v:.3g}" for k, v in opts.items() if k != "max_steps")
        rows.append({"method": method, "setting": setting,
                     "t_end_s": t_end, "energy_drift_rel": float((e[-1] - e[0]) / e[0]),
                     "max_abs_drift_rel": float(np.abs(e - e[0]).max() / e[0]),
                     "wall_s": tr.wall_time})
    return rows


def plot_work_precision(rows: list[dict], path: str | Path) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    metrics = [("peak_whirl_rel", "peak whirl, relative error"),
               ("final_angle_deg", "final ball angle error [deg]"),
               ("trajectory_rel", "whole trajectory, relative error")]
    methods = list(dict.fromkeys(r["method"] for r in rows))
    markers = dict(zip(methods, "osD^v<>ph*"))
    fig, axes = plt.subplots(len(scenes), len(metrics), figsize=(14, 4.2 * len(scenes)),
                             squeeze=False, constrained_layout=True)
    for i, scene in enumerate(scenes):
        for j, (key, label) in enumerate(metrics):
            ax = axes[i, j]
            for method in methods:
                pts = [r for r in rows if r["scene"] == scene and r["method"] == method]
                ok = [r for r in pts if r["stable"]]
                x = [r["wall_ms_per_sim_s"] for r in ok]
                y = [max(r[key], 1e-16) for r in ok]
                line, = ax.loglog(x, y, marker=markers[method], label=method, lw=1)
                bad = [r for r in pts if not r["stable"]]
                if bad:
                    ax.plot([], [], "x", color=line.get_color(),
                            label=f"{method}: {len(bad)} unstable")
            ax.set_xlabel("wall time per simulated second [ms]")
            ax.set_ylabel(label)
            ax.set_title(f"{scene}: {label}", fontsize=10)
            ax.grid(True, which="both", alpha=0.3)
            if j == 0:
                ax.legend(fontsize=7)
    fig.suptitle("Work-precision: error against DOP853 (rtol 1e-12) at a 10 ms output interval")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path = savefig(fig, path, dpi=100)
    plt.close(fig)
    return path
