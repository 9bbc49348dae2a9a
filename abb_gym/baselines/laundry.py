"""The laundry oracle: the best a drive that knew the load could do on SpinRedistribute.

``baseline:laundry_oracle`` knows each sub-environment's laundry imbalance U (privileged: it
reads the machine, not the observation) and the balancer's effective capacity ``C_eff``
(:func:`abb_gym.physics.laundry.effective_capacity`: the clumped balls span an arc).  While
``U > C_eff`` and redistributions are left, it keeps the drum at rest, below the tumble
speed, so the laundry tumbles and lands anew after the tumble time; as soon as the load fits
(or none is left) it runs the tuned ``knots`` profile (``baseline:knots``, the best single
open-loop profile) from that moment.  A load above the capacity leaves a residual
``(U - C_eff)`` that no profile removes, so this is the ceiling of the redistribution decision:
it pays the least time a redistribution can cost and only when it must.

It is an upper bound on the decision, not on everything: it does not see the balls, and it
spends a tumble even when the next draw is worse.  Used on other tasks it is the tuned
``knots`` profile (no redistribution happens there).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..physics import drive_law as dl
from ..physics import laundry
from .baseline_policy import SpeedReferencePolicy, make_baseline

__all__ = ["LaundryOracle", "ORACLE_NAME", "open_loop_floor"]

ORACLE_NAME = "laundry_oracle"


class LaundryOracle(SpeedReferencePolicy):
    """See the module docstring."""

    def __init__(self):
        self.name = f"baseline:{ORACLE_NAME}"
        self.params: dict[str, Any] = {}

    def acts_on(self, setup: Any) -> bool:
        return not setup.task.one_step

    def reset(self, env, mask: np.ndarray) -> None:
        self._bind(env)
        setup = self.setup
        knots = make_baseline("knots", setup.scene, setup.operating_speed)
        self.params = {"knots": dict(knots.params)}
        profile = knots._profile(0)
        rows = profile.segment_table(math.inf)[1]
        self._tables = np.zeros((1, len(rows), dl.N_DRIVE))
        self._tables[0] = rows
        self._n_rows = np.array([len(rows)], dtype=np.int64)
        self.capacity = laundry.effective_capacity(setup.scene)
        r = setup.config.redistribution
        self.max_count = int(r.max_count) if r.enabled else 0
        n = env.num_envs
        if not hasattr(self, "_start") or self._start.shape[0] != n:
            self._start = np.full(n, np.nan)
        self._start[np.asarray(mask, bool)] = np.nan

    def act(self, obs: np.ndarray, info: dict) -> np.ndarray:
        env = self._env
        t = env.times
        w = env.rotor_speeds
        waiting = np.isnan(self._start)
        fits = (env.imbalances <= self.capacity) | (env.redistributions >= self.max_count)
        go = waiting & fits
        self._start[go] = t[go]
        ref = np.zeros_like(t)
        live = ~np.isnan(self._start)
        if live.any():
            elapsed = t[live] - self._start[live] + self.dt
            tables = np.broadcast_to(self._tables, (int(live.sum()),) + self._tables.shape[1:])
            counts = np.broadcast_to(self._n_rows, (int(live.sum()),))
            ref[live] = dl.prescribed_speeds(np.ascontiguousarray(elapsed),
                                             np.ascontiguousarray(tables),
                                             np.ascontiguousarray(counts))
        return self._actions(ref, w)


def open_loop_floor(env_id: str, scene: Any, preset: str, seeds, env_kwargs=None) -> np.ndarray:
    """The open-loop floor of each episode ``seeds[k]`` of ``env_id`` on ``scene`` and
    ``preset``, in the task's unit of length (mm on SpinRedistribute): the steady whirl at
    the operating speed of the machine with its balancer off and the imbalance
    ``max(0, U - C_eff)``, U the episode's first laundry load, ``C_eff`` the effective
    capacity (:func:`abb_gym.physics.laundry.effective_capacity`).  A drive that never
    redistributes keeps U, and balls that cancel at most ``C_eff`` leave that excess whatever
    the speed profile (tests/test_spin.py holds the ramp and ``knots`` above it).  Computed on
    the nominal machine (the episode's critical-speed scale moves the whirl at spin by under
    1 %, the speed ratio being about 8).  ``env_kwargs``: further environment keywords."""
    import gymnasium as gym

    from ..physics import rotor

    seeds = [int(s) for s in seeds]
    if not seeds:
        return np.zeros(0)
    kwargs = dict(env_kwargs or {})
    kwargs.update(scene=scene, preset=preset)
    env = gym.make_vec(env_id, num_envs=len(seeds), vectorization_mode="vector_entry_point",
                       **kwargs)
    try:
        env.reset(seed=seeds)
        setup = env.unwrapped.setup
        loads = env.unwrapped.imbalances
    finally:
        env.close()
    excess = np.maximum(loads - laundry.effective_capacity(setup.scene), 0.0)
    unit = setup.reward_length_scale or 1.0
    whirl = np.array([rotor.reference_amplitudes(setup.scene, setup.operating_speed, u)[1]
                      if u > 0.0 else 0.0 for u in excess])
    return whirl / unit


open_loop_floor.definition = ("the steady whirl at spin of the laundry load in excess of the "
                              "balancer's effective capacity, max(0, U - C_eff)")
