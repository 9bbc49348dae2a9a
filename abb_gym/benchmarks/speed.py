"""Throughput benchmark (``abb-gym bench speed``), every measurement side by side in one run.

Measurements (the targets are the project's, from the Integrators issue):

* the whole Yoshida run-up (6 s simulated) through ``simulate`` at the default accuracy;
* 10 ms control steps through the compiled kernel (one call per step, as an environment does);
* the same 10 ms steps through ``scipy.integrate.solve_ivp`` (RK45) with a numpy right-hand
  side (:mod:`abb_gym.benchmarks.numpy_reference`), at the loosest tolerance whose error over
  the run-up is no worse than the kernel's: what a user would otherwise write;
* single-environment steps per second through ``gym.make`` and the native vector environment
  at 1024 sub-environments (when :mod:`abb_gym.envs` is installed), and its memory at 4096;
* CPU time per env-step side by side (:mod:`abb_gym.benchmarks.env_cost`): the CartPole ratio
  per core, ball counts, the washer, batch sizes with the default threads and one.

Wall times are the best of several repeats; the machine is shared and noisy, so these are
benchmarks, not tests.  :func:`iter_speed` yields each row as soon as it is measured (the
command prints it then); :func:`run_speed` collects them.
"""
from __future__ import annotations

import time
from typing import Iterator

import numpy as np
from scipy.integrate import solve_ivp

from ..physics import SpeedProfile, load_scene, simulate
from ..physics import integrators as integ
from ..physics import model as mdl
from ..physics.simulate import initial_state
from ..physics.steps import default_step
from .numpy_reference import yoshida_rhs

CONTROL_DT = 0.01  # s
RUNUP_S = 6.0


def _best(fn, repeats):
    best = np.inf
    out = None
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - start)
    return best, out


def runup_wall_time(repeats: int = 20) -> Iterator[dict]:
    """The row of each kernel, as it is measured."""
    scene = load_scene("yoshida_odd")
    drive = SpeedProfile.dwell(40.0, scene.critical_speed, 0.5)
    for kernel in ("generic", "specialised"):
        simulate(scene, drive, 0.1, kernel=kernel)
        wall, tr = _best(lambda: simulate(scene, drive, RUNUP_S, output_dt=CONTROL_DT,
                                          kernel=kernel), repeats)
        yield {"measurement": f"Yoshida run-up, 6 s simulated, default accuracy "
                              f"(simulate, RK4, kernel={kernel!r})",
               "value": f"{wall * 1e3:.2f} ms", "target": "<= 5 ms",
               "note": f"step {tr.step * 1e3:.2f} ms, {tr.work} steps"}


def _kernel_steps(scene, profile, n_steps, dt):
    """Run-up as n_steps calls of the compiled integrator, one per control interval."""
    p, b = mdl.pack_parameters(scene)
    s = initial_state(scene, profile)
    seg_t, seg_d = profile.segment_table(n_steps * CONTROL_DT + 1.0)
    out = np.empty((2, s.size))
    traj = np.empty((n_steps + 1, s.size))
    traj[0] = s
    t_pair = np.empty(2)
    # one lane, as simulate runs it (model.SPEC_ONE_LANE: the lane and row counts constant)
    nb, spec = b.shape[0], mdl.spec_of(p, seg_d) | mdl.SPEC_ONE_LANE
    step = integ.run.entry(integ.METHOD_RK4, s, t_pair, seg_t, seg_d, p, b, dt, 0.0,
                           integ._NO_ATOL, out, nb, spec)  # fetched once, as the envs do
    for k in range(n_steps):
        t_pair[0] = k * CONTROL_DT
        t_pair[1] = (k + 1) * CONTROL_DT
        step(integ.METHOD_RK4, s, t_pair, seg_t, seg_d, p, b, dt, 0.0, integ._NO_ATOL, out,
             nb, spec)
        s = out[1].copy()
        traj[k + 1] = s
    return traj


def _scipy_steps(scene, profile, n_steps, rtol):
    rhs = yoshida_rhs(scene, profile)
    s = initial_state(scene, profile)
    traj = np.empty((n_steps + 1, s.size))
    traj[0] = s
    for k in range(n_steps):
        sol = solve_ivp(rhs, (k * CONTROL_DT, (k + 1) * CONTROL_DT), s, method="RK45",
                        rtol=rtol, atol=rtol * 1e-4)
        s = sol.y[:, -1]
        traj[k + 1] = s
    return traj


def _trajectory_error(traj, ref, scene):
    nq = 3 + scene.ball_count
    w, wr = np.hypot(traj[:, 0], traj[:, 1]), np.hypot(ref[:, 0], ref[:, 1])
    return max(np.abs(w - wr).max() / wr.max(),
               np.abs(traj[:, 3:nq] - ref[:, 3:nq]).max() / np.pi)


def stepping_rates(quick: bool = False) -> tuple[list[dict], float]:
    """Compiled 10 ms steps versus solve_ivp RK45 with a numpy right-hand side, at equal or
    better accuracy.  Returns (rows, compiled steps per second)."""
    scene = load_scene("yoshida_odd")
    profile = SpeedProfile.dwell(40.0, scene.critical_speed, 0.5)
    n = int(round((1.5 if quick else RUNUP_S) / CONTROL_DT))
    dt = default_step(scene, profile.max_speed(n * CONTROL_DT))
    ref = simulate(scene, profile, n * CONTROL_DT, method="DOP853", rtol=1e-12,
                   output_dt=CONTROL_DT).states
    _kernel_steps(scene, profile, 2, dt)
    wall_k, traj_k = _best(lambda: _kernel_steps(scene, profile, n, dt), 3 if quick else 10)
    err_k = _trajectory_error(traj_k, ref, scene)
    chosen = None
    for rtol in (1e-3, 1e-4, 1e-5, 1e-6, 1e-7):
        wall_s, traj_s = _best(lambda: _scipy_steps(scene, profile, n, rtol), 1)
        err_s = _trajectory_error(traj_s, ref, scene)
        chosen = (rtol, wall_s, err_s)
        if err_s <= err_k:
            break
    rtol, wall_s, err_s = chosen
    rate_k, rate_s = n / wall_k, n / wall_s
    rows = [
        {"measurement": "compiled kernel, 10 ms steps, one call per step (Yoshida run-up)",
         "value": f"{rate_k:,.0f} steps/s", "target": "-",
         "note": f"RK4 {dt * 1e3:.2f} ms substeps, trajectory error {err_k:.1e}"},
        {"measurement": "solve_ivp RK45 + numpy right-hand side, same 10 ms steps",
         "value": f"{rate_s:,.0f} steps/s", "target": "-",
         "note": f"rtol {rtol:g}, trajectory error {err_s:.1e}"
                 f"{'' if err_s <= err_k else ' (could not match the kernel)'}"},
    ]
    return rows, rate_s


#: the columns of every row
COLUMNS = ("measurement", "value", "target", "note")


def iter_speed(quick: bool = False, costs_only: bool = False) -> Iterator[dict]:
    """Every row of the benchmark, each as soon as it is measured (``costs_only``: the rows
    of :mod:`abb_gym.benchmarks.env_cost` alone)."""
    if costs_only:
        from . import env_cost
        yield from env_cost.speed_rows(quick=quick)
        return
    yield from runup_wall_time(5 if quick else 20)
    step_rows, scipy_rate = stepping_rates(quick)
    yield from step_rows
    try:
        from . import env_speed
    except ImportError:  # the environments are not installed
        return
    yield from env_speed.measure(scipy_rate, quick=quick)
    from . import env_cost
    yield from env_cost.speed_rows(quick=quick)


def run_speed(quick: bool = False) -> list[dict]:
    """Every row of the benchmark (:func:`iter_speed`), at the end."""
    return list(iter_speed(quick))
