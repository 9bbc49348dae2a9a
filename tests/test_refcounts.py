"""The kernels compiled without reference counts (``njit(refcounts=False)``,
:mod:`abb_gym._numba`)
keep every count balanced: stepping leaves each array's count as it was, and closing an
environment frees its buffers.

A function called from an uncounted kernel that returned a counted view would leak one
reference per call (numba refuses the other direction at compile time); these tests would
then see the count grow or the buffers survive their environment: a leak planted in
``advance_block`` failed every test below but the first.

The vector environment's parallel step is not among the cases: numba hands the arrays to
the body of a parallel loop without their reference counts (the planted leak left it
unchanged), so there is nothing to check there that the serial step does not check.
"""
from __future__ import annotations

import gc
import sys
import weakref

import gymnasium as gym
import numpy as np
import pytest

import abb_gym  # noqa: F401  (registers the environments)
from abb_gym.envs import kernel
from abb_gym.physics import batch
from abb_gym.physics import integrators as integ
from abb_gym.physics import SpeedProfile, load_scene

UNCOUNTED = (integ._rk4_step, integ._etdrk4_step, batch.advance_block, kernel._block_step)


def test_the_per_step_kernels_are_compiled_without_reference_counts():
    # the RK4 step, the block advance and the environment's block step: each is called per
    # substep or per block and calls others, which is where counting cost 30 % of the step
    for fn in UNCOUNTED:
        assert fn.targetoptions.get("_nrt") is False, fn.py_func.__qualname__


def _buffer_arrays(env) -> list[np.ndarray]:
    bufs = env.unwrapped._bufs
    arrays = list(bufs.step_arrays())
    assert all(isinstance(a, np.ndarray) for a in arrays)
    return arrays


def _step_through_episodes(env, n_steps: int, n_envs: int | None = None) -> None:
    action = (np.full((n_envs, 1), 0.8, np.float32) if n_envs else
              np.array([0.8], np.float32))
    for _ in range(n_steps):
        _, _, term, trunc, _ = env.step(action)
        if n_envs is None and (term or trunc):
            env.reset()


CASES = {
    "single rk4": dict(vector=None, integrator="rk4"),
    "single etdrk4": dict(vector=None, integrator="etdrk4"),
    "vector serial": dict(vector=1, integrator="rk4"),  # one block: the serial step
}


@pytest.mark.parametrize("case", list(CASES))
def test_stepping_keeps_counts_and_close_frees_the_buffers(case):
    n_envs, integrator = CASES[case]["vector"], CASES[case]["integrator"]
    # 5 s episodes of 0.1 s steps: 60 steps cross at least one episode end and reset
    kw = dict(scene="yoshida_odd", integrator=integrator, control_interval=0.1,
              episode_length=5.0)
    if n_envs is None:
        env = gym.make("abb_gym/RunUpSpeed-v0", **kw)
    else:
        env = gym.make_vec("abb_gym/RunUpSpeed-v0", num_envs=n_envs,
                           vectorization_mode="vector_entry_point", **kw)
    env.reset(seed=3)
    _step_through_episodes(env, 3, n_envs)  # loads the kernel
    arrays = _buffer_arrays(env)
    counts = [sys.getrefcount(a) for a in arrays]
    _step_through_episodes(env, 60, n_envs)
    assert [sys.getrefcount(a) for a in arrays] == counts
    refs = [weakref.ref(a) for a in arrays]
    del arrays
    env.close()
    del env
    gc.collect()
    alive = [k for k, r in enumerate(refs) if r() is not None]
    assert alive == [], f"step arrays still referenced after close: {alive}"


def test_run_batch_keeps_counts_and_frees_its_blocks():
    from numba.core.runtime import _nrt_python, rtsys
    scene = load_scene("yoshida_odd")
    w = scene.drive_operating_speed
    drive = SpeedProfile.ramp(scene.drive_max_acceleration / 2, w)
    scenes = [scene.replace(ball_drag=[s * v for v in scene.ball_drag])
              for s in np.linspace(0.8, 1.2, 10)]
    s0, seg_d, nseg, p, b, h = batch.run_inputs(scenes, drive, 0.3, w)
    # float64 and contiguous already: run_batch passes these very arrays to the kernel
    s0, seg_d, p, b = (np.ascontiguousarray(a, float) for a in (s0, seg_d, p, b))
    t_out = np.linspace(0.0, 0.3, 31)
    out = np.empty((len(scenes), len(t_out), s0.shape[1]))
    status = np.zeros((len(scenes), 4))
    inputs = [s0, seg_d, p, b, out, status]

    def run():
        batch.run_batch(s0, t_out, seg_d, nseg, p, b, h, out, status, lanes=4)

    run()  # loads the kernel
    _nrt_python.memsys_enable_stats()
    before = rtsys.get_allocation_stats()
    counts = [sys.getrefcount(a) for a in inputs]
    for _ in range(3):
        run()
    after = rtsys.get_allocation_stats()
    assert [sys.getrefcount(a) for a in inputs] == counts
    assert after.alloc - before.alloc > 0, "the blocks are allocated in compiled code"
    assert after.alloc - before.alloc == after.free - before.free
    assert after.mi_alloc - before.mi_alloc == after.mi_free - before.mi_free
