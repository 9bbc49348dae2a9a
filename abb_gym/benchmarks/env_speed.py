"""Environment throughput for ``abb-gym bench speed``, side by side in one process.

* the native vector environment at 64, 1024 and 4096 sub-environments with its vectorised
  kernel (and the general kernel at 1024), **resets included**: episodes are cut at
  :data:`EPISODE_STEPS` control steps, so one sub-environment in 100 resets at each step, and
  the reset of all sub-environments is timed on its own;
* batch simulation without an environment (:func:`abb_gym.physics.batch.run_batch`, the
  parameter studies' entry point) over as many run-ups, in 10 ms intervals;
* the single environment through ``gym.make`` (lean info, the default);
* Gymnasium's own ``CartPoleVectorEnv`` and ``CartPole-v1`` in the same run, as the peer
  reference of what a vector environment costs per env-step in plain numpy;
* cold start, each in a fresh process: ``import abb_gym``, ``abb-gym --help``, and the first
  ``gym.make`` + reset + step with the compiled kernels in the cache and with an empty cache
  (``NUMBA_CACHE_DIR`` pointing at a new folder: what a user sees without shipped kernels);
* the memory of the vector environment at 4096 sub-environments.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
import tracemalloc
from typing import Iterator

import gymnasium as gym
import numpy as np

from ..envs import tasks

ENV_ID = tasks.DEFAULT_ENV_ID
SCENE = "yoshida_odd"
EPISODE_STEPS = 100  # 1 s episodes at 10 ms: resets are 1 % of the sub-environment steps
VECTOR_SIZES = (64, 1024, 4096)

__all__ = ["measure", "vector_rate", "batch_rate", "single_rate", "cartpole_rates",
           "cold_start"]


def make_vector(num_envs: int, kernel: str | None, integrator: str = "rk4",
                precision: str = "float64", preset: str = "train", scene: str = SCENE):
    """The vector environment every speed benchmark steps (``bench speed``'s rows,
    :mod:`~abb_gym.benchmarks.block_size`, :mod:`~abb_gym.benchmarks.kernel_profile`)."""
    return gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        scene=scene, preset=preset, control_interval=0.01,
                        integrator=integrator, precision=precision, kernel=kernel,
                        max_episode_steps=EPISODE_STEPS)


#: below this ratio of specialised to general vector-env speed the specialised kernel is not
#: in effect (it measures several times the general kernel's speed on yoshida_odd, and 1.0x
#: when the literal ball count and effects are lost on the way to the equations: CHANGELOG.md)
SPECIALISATION_FLOOR = 1.5


def specialisation_note(specialised: float, general: float) -> str:
    """The bench row's note on the specialised kernel's gain over the general one, with a
    warning when it is below :data:`SPECIALISATION_FLOOR`."""
    ratio = specialised / general
    note = f"specialised/general = {ratio:.2f}x"
    if ratio < SPECIALISATION_FLOOR:
        note += (f" - WARNING: below {SPECIALISATION_FLOOR}x, the specialised kernel may not be "
                 f"in effect (do the literal ball count and effects reach the equations? see "
                 f"abb_gym.envs.kernel), or the machine was busy")
    return note


def vector_rate(num_envs: int, n_steps: int, kernel: str | None = None,
                integrator: str = "rk4", repeats: int = 1, precision: str = "float64") -> dict:
    """Env-steps per second of the native vector env (resets included) and the cost of one
    sub-environment's reset [us] (best of ``repeats``), in the step's ``precision``."""
    env = make_vector(num_envs, kernel, integrator, precision)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = rng.uniform(0.2, 1.0, size=(n_steps, num_envs, 1)).astype(np.float32)
    for k in range(min(n_steps, 20)):
        env.step(actions[k])
    best_step = best_reset = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        for k in range(n_steps):
            env.step(actions[k])
        best_step = min(best_step, time.perf_counter() - start)
        start = time.perf_counter()
        env.reset()
        best_reset = min(best_reset, time.perf_counter() - start)
    used = env.unwrapped.kernel
    env.close()
    return {"rate": num_envs * n_steps / best_step, "reset_us": best_reset / num_envs * 1e6,
            "kernel": used}


def batch_rate(n_runs: int, intervals: int, repeats: int = 1,
               precision: str = "float64") -> float:
    """Simulated 10 ms intervals per second of :func:`abb_gym.physics.batch.run_batch` over
    ``n_runs`` run-ups of the scene (half the drive's acceleration, ball drag spread over
    0.7-1.3 of nominal so that the runs take different step sizes), output every 10 ms (best
    of ``repeats``; the first call compiles or loads the kernel), in ``precision``."""
    from ..physics import SpeedProfile, batch, load_scene
    scene = load_scene(SCENE)
    w = scene.drive_operating_speed
    drive = SpeedProfile.ramp(scene.drive_max_acceleration / 2, w)
    t_out = np.linspace(0.0, 0.01 * intervals, intervals + 1)
    scenes = [scene.replace(ball_drag=[scale * v for v in scene.ball_drag])
              for scale in np.linspace(0.7, 1.3, n_runs)]
    s0, seg_d, nseg, p, b, h = batch.run_inputs(scenes, drive, t_out[-1], w)
    out = np.empty((n_runs, len(t_out), s0.shape[1]))
    status = np.zeros((n_runs, 4))
    args = (s0, t_out, seg_d, nseg, p, b, h, out, status)
    batch.run_batch(*args, precision=precision)
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        batch.run_batch(*args, precision=precision)
        best = min(best, time.perf_counter() - start)
    if not np.all(status[:, 0] == 0):
        raise RuntimeError("batch benchmark: a run failed")
    return n_runs * intervals / best


def single_rate(n_steps: int, repeats: int = 1) -> float:
    """Steps per second of one environment through ``gym.make`` (wrappers included)."""
    env = gym.make(ENV_ID, scene=SCENE, control_interval=0.01)
    env.reset(seed=0)
    action = np.array([0.6], dtype=np.float32)
    best = np.inf
    for r in range(repeats + 1):  # the first round loads the kernel and warms up
        start = time.perf_counter()
        for _ in range(n_steps if r else 200):
            _, _, term, trunc, _ = env.step(action)
            if term or trunc:
                env.reset()
        if r:
            best = min(best, time.perf_counter() - start)
    return n_steps / best


def cartpole_rates(num_envs: int, n_steps: int) -> tuple[float, float]:
    """(vector, single) steps per second of Gymnasium's CartPole: the peer reference."""
    vec = gym.make_vec("CartPole-v1", num_envs=num_envs, vectorization_mode="vector_entry_point")
    vec.reset(seed=0)
    acts = np.random.default_rng(0).integers(0, 2, size=(n_steps, num_envs))
    start = time.perf_counter()
    for k in range(n_steps):
        vec.step(acts[k])
    vec_rate = num_envs * n_steps / (time.perf_counter() - start)
    vec.close()
    env = gym.make("CartPole-v1")
    env.reset(seed=0)
    n_single = 20 * n_steps
    start = time.perf_counter()
    for k in range(n_single):
        _, _, term, trunc, _ = env.step(k % 2)
        if term or trunc:
            env.reset()
    return vec_rate, n_single / (time.perf_counter() - start)


def _fresh_process(code: str, env: dict | None = None) -> float:
    """Wall time [s] of ``python -c code`` in a new process (interpreter start included)."""
    start = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "ABB_GYM_QUIET": "1", **(env or {})}, timeout=1800)
    wall = time.perf_counter() - start
    if res.returncode != 0:
        raise RuntimeError(f"cold-start measurement failed:\n{res.stderr[-2000:]}")
    return wall


FIRST_STEP = (f"import gymnasium as gym, abb_gym; e = gym.make({ENV_ID!r}); "
              "e.reset(seed=0); e.step(e.action_space.sample())")


def cold_start(with_empty_cache: bool = True) -> dict:
    """Seconds, each in a fresh process: interpreter alone, ``import abb_gym``,
    ``abb-gym --help``, first gym.make + reset + step with the cache, and with an empty cache."""
    out = {"python": min(_fresh_process("pass") for _ in range(3)),
           "import": min(_fresh_process("import abb_gym") for _ in range(3)),
           "help": min(_fresh_process("import sys; sys.argv = ['abb-gym', '--help']\n"
                                      "from abb_gym.cli import main\ntry: main()\n"
                                      "except SystemExit: pass") for _ in range(3))}
    _fresh_process(FIRST_STEP)  # fills the cache if it was not
    out["first_step_cached"] = min(_fresh_process(FIRST_STEP) for _ in range(2))
    if with_empty_cache:
        with tempfile.TemporaryDirectory() as empty:
            out["first_step_empty_cache"] = _fresh_process(FIRST_STEP,
                                                           {"NUMBA_CACHE_DIR": empty})
    return out


def _vector_memory(num_envs: int) -> float:
    """Peak memory [MB] traced while building, resetting and stepping the vector env."""
    tracemalloc.start()
    env = make_vector(num_envs, None)
    env.reset(seed=0)
    actions = np.full((num_envs, 1), 0.6, dtype=np.float32)
    for _ in range(5):
        env.step(actions)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    env.close()
    return peak / 2 ** 20


def measure(scipy_rate: float, quick: bool = False) -> Iterator[dict]:
    """The rows of the environment part of ``abb-gym bench speed``, each as soon as the
    measurements it reports are done."""
    from ..progress import ProgressBar
    repeats = 1 if quick else 3
    steps = {64: 400, 1024: 100, 4096: 30} if not quick else {64: 40, 1024: 10, 4096: 5}
    bar = ProgressBar(total=len(VECTOR_SIZES) + 9, desc="bench speed (environments)", leave=False)
    note = f"{SCENE}, rk4 at the default step, random actions, {EPISODE_STEPS}-step episodes"
    try:
        vec = {}
        for n in VECTOR_SIZES:
            vec[n] = vector_rate(n, steps[n], "specialised", repeats=repeats)
            bar.update()
            yield {"measurement": f"native vector environment, {n} sub-environments "
                                  f"(specialised kernel), resets included",
                   "value": f"{vec[n]['rate']:,.0f} env-steps/s",
                   "target": ">= 2,500,000" if n == 1024 else "-",
                   "note": f"{note}; reset {vec[n]['reset_us']:.1f} us per sub-environment"}
        generic = vector_rate(1024, steps[1024], "generic", repeats=repeats)
        bar.update()
        yield {"measurement": "the same at 1024 with the general kernel (kernel='generic')",
               "value": f"{generic['rate']:,.0f} env-steps/s", "target": "-",
               "note": specialisation_note(vec[1024]["rate"], generic["rate"])}
        etd = vector_rate(1024, steps[1024], "specialised", integrator="etdrk4",
                          repeats=repeats)
        bar.update()
        yield {"measurement": "the same at 1024 with integrator='etdrk4' (not the default)",
               "value": f"{etd['rate']:,.0f} env-steps/s", "target": "-",
               "note": f"etdrk4/rk4 = {etd['rate'] / vec[1024]['rate']:.2f}x at its default "
                       f"step; less accurate than rk4's default step but within 1 % / 1 deg "
                       f"on {SCENE} (tests/test_bad_input.py; not on lu_hung_odd3)"}
        vec32 = vector_rate(1024, steps[1024], "specialised", repeats=repeats,
                               precision="float32")
        bar.update()
        yield {"measurement": "the same at 1024 in float32 (precision='float32')",
               "value": f"{vec32['rate']:,.0f} env-steps/s", "target": "-",
               "note": f"float32/float64 = {vec32['rate'] / vec[1024]['rate']:.2f}x; its "
                       f"accuracy: abb-gym bench accuracy"}
        batch_runs = batch_rate(1024, 10 if quick else 100, repeats)
        bar.update()
        yield {"measurement": "batch simulation without an environment (physics.batch."
                              "run_batch), 1024 run-ups",
               "value": f"{batch_runs:,.0f} run-intervals/s (10 ms each)", "target": "-",
               "note": "ball drag 0.7-1.3 of nominal, output every 10 ms; vector env at 1024 "
                       f"= {vec[1024]['rate'] / batch_runs:.2f}x of it"}
        batch32 = batch_rate(1024, 10 if quick else 100, repeats, precision="float32")
        bar.update()
        yield {"measurement": "the same in float32 (precision='float32')",
               "value": f"{batch32:,.0f} run-intervals/s", "target": "-",
               "note": f"float32/float64 = {batch32 / batch_runs:.2f}x"}
        single = single_rate(3000 if quick else 30000, repeats)
        bar.update()
        cp_vec, cp_single = cartpole_rates(1024, 20 if quick else 200)
        bar.update()
        yield {"measurement": "Gymnasium CartPoleVectorEnv, 1024 sub-environments (peer)",
               "value": f"{cp_vec:,.0f} env-steps/s", "target": "-",
               "note": f"abb-gym costs {cp_vec / vec[1024]['rate']:.1f}x CartPole's per "
                       f"env-step (target <= 5x); CartPole vector/single "
                       f"{cp_vec / cp_single:.0f}x, abb-gym {vec[1024]['rate'] / single:.0f}x"}
        yield {"measurement": f"single environment through gym.make ({SCENE}, 10 ms steps)",
               "value": f"{single:,.0f} steps/s", "target": ">= 100,000",
               "note": f"lean info; CartPole-v1 through gym.make: {cp_single:,.0f} steps/s"}
        yield {"measurement": "speed-up over solve_ivp RK45 + numpy, per 10 ms step",
               "value": f"{single / scipy_rate:,.0f}x single, "
                        f"{vec[1024]['rate'] / scipy_rate:,.0f}x vector (1024)",
               "target": "-", "note": "equal or better accuracy"}
        cold = cold_start(with_empty_cache=not quick)
        bar.update()
        yield {"measurement": "cold start, fresh process: import abb_gym / abb-gym --help",
               "value": f"{cold['import']:.2f} s / {cold['help']:.2f} s",
               "target": "<= 0.5 s", "note": f"the interpreter alone: {cold['python']:.2f} s"}
        empty = cold.get("first_step_empty_cache")
        yield {"measurement": "cold start, first gym.make + reset + step (fresh process)",
               "value": f"{cold['first_step_cached']:.2f} s with the cache"
                        + (f", {empty:.1f} s with an empty cache" if empty else ""),
               "target": "<= 5 s", "note": "the cache is built by abb-gym build-kernels "
                                           "and shipped in the wheel"}
        mem = _vector_memory(4096)
        bar.update()
        yield {"measurement": "vector environment memory at 4096 sub-environments",
               "value": f"{mem:.1f} MB", "target": "-", "note": "peak traced (tracemalloc)"}
    finally:
        bar.close()
    try:
        from .effects import iter_speed_rows
    except ImportError:
        return
    for r in iter_speed_rows(repeats=2 if quick else 5):
        yield {"measurement": f"simulate {r['method']}, {r['case']}",
               "value": f"{r['ms_per_simulated_s']:.2f} ms per simulated s",
               "target": "effects off: as fast as before" if "off" in r["case"] else "-",
               "note": f"{r['us_per_step']:.2f} us/step, dt {r['dt_s'] * 1e3:.2f} ms"}
