"""Threads and block shape never change a result: the vector environment and the batch
simulation give the same bits on one thread and on two, in one block and in many; and the
thread count follows the CPUs that other processes leave free."""
import gymnasium as gym
import numpy as np
import pytest

import abb_gym  # noqa: F401
from abb_gym import _threads
from abb_gym.physics import batch


def _run(monkeypatch, num_envs, free, max_lanes=None, steps=25):
    monkeypatch.setattr(batch, "free_cpus", lambda: free)
    if max_lanes is not None:
        monkeypatch.setattr(batch, "MAX_LANES", max_lanes)
    env = gym.make_vec("abb_gym/RunUpSpeed-v0", num_envs=num_envs,
                       vectorization_mode="vector_entry_point", scene="yoshida_odd",
                       preset="train", max_episode_steps=10)
    lanes = env.unwrapped._bufs.blocks.lanes
    obs, _ = env.reset(seed=11)
    rng = np.random.default_rng(2)
    out = [obs]
    for _ in range(steps):
        obs, rew, term, trunc, _ = env.step(rng.uniform(-1, 1, (num_envs, 1)).astype(np.float32))
        out += [obs, rew[:, None], term[:, None], trunc[:, None]]
    env.close()
    return np.concatenate(out, axis=1), lanes


def test_threads_and_blocks_give_the_bits_of_one_thread(monkeypatch):
    one, lanes = _run(monkeypatch, 40, free=0.0)
    assert lanes == 32  # one block of 32 and one of 8
    for free, max_lanes in [(2.0, None), (2.0, 4), (0.0, 4), (2.0, 1)]:
        got, lanes = _run(monkeypatch, 40, free=free, max_lanes=max_lanes)
        assert lanes == (max_lanes or 32)
        assert np.array_equal(got, one), (free, max_lanes)


def test_parallel_threads_follow_the_free_cpus(monkeypatch):
    import numba
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has one thread")
    numba.set_num_threads(2)
    for free, want in [(2.0, 2), (1.85, 2), (1.7, 1), (1.0, 1), (0.0, 1)]:
        monkeypatch.setattr(batch, "free_cpus", lambda f=free: f)
        assert batch.parallel_threads(8) == want, free
    monkeypatch.setattr(batch, "free_cpus", lambda: 2.0)
    assert batch.parallel_threads(1) == 1  # one block: nothing to share
    numba.set_num_threads(1)
    assert batch.parallel_threads(8) == 1  # the caller's count is the bound (share_cores)
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


def test_a_parallel_call_restores_the_callers_thread_count(monkeypatch):
    import numba
    monkeypatch.setattr(batch, "free_cpus", lambda: 0.0)
    seen = []
    call = batch.ParallelCall(lambda x: seen.append(numba.get_num_threads()) or x, 4)
    before = numba.get_num_threads()
    assert call(7) == 7
    assert seen == [1] and numba.get_num_threads() == before


def test_free_cpus_counts_other_processes_not_this_one(monkeypatch):
    free = _threads.FreeCpus(interval=0.0, cpus=2)
    clock = iter([0.0, 1.0, 2.0])
    busy = iter([100.0, 101.0, 101.2])  # the machine's busy CPU seconds
    own = iter([5.0, 5.0, 5.2])  # this process's
    monkeypatch.setattr(_threads.time, "monotonic", lambda: next(clock))
    monkeypatch.setattr(_threads.time, "process_time", lambda: next(own))
    monkeypatch.setattr(free, "_machine_busy", lambda: next(busy))
    monkeypatch.setattr(_threads.os, "cpu_count", lambda: 2)
    assert free() == 2.0  # no interval measured yet: every CPU counts as free
    assert free() == pytest.approx(1.0)  # another process kept one CPU busy
    assert free() == pytest.approx(2.0)  # only this process worked
