"""The arrays of an environment's rows and the blocks its compiled step works in.

:class:`Buffers` holds one row per environment (state, parameters, drive rows, bookkeeping,
observation, outputs, the recorded history, the current episode's parameters) and the
blocks of lanes of the compiled step (:mod:`abb_gym.envs.kernel`,
:class:`abb_gym.physics.batch.Blocks`), packed once as the step's arguments.  The single and
the vector environment build theirs the same way: an :class:`~abb_gym.envs.setup.EnvSetup`,
then :class:`Buffers`.  Their size is checked against the machine's memory first
(:func:`check_memory`, which counts the same arrays).
"""
from __future__ import annotations

import os
from typing import Any

import numpy as np

from ..physics import batch
from ..physics import drive_law as dl
from ..physics import model as mdl
from ..physics.specialise import resolve_kernel
from . import kernel
from .episodes import EpisodeTable
from .kernel import G_HELD, N_G_ENV, entry_point, observe_rows
from .layout import (N_OUT, N_ST, S_DONE, S_DTMAX, S_K, S_USCALE, T_BALLS, T_T, T_VIB,
                     T_VIBMAX, T_W, T_X, T_Y)

__all__ = ["Buffers", "MEMORY_LIMIT", "row_bytes", "trace_bytes", "check_memory"]


def _physical_memory() -> float:
    """The machine's memory [bytes] (16 GiB where the system does not say)."""
    try:
        return float(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, OSError, ValueError):
        return 16.0 * 2 ** 30


#: Largest buffers [bytes] an environment allocates: the machine's memory.  A request beyond
#: it (``num_envs=2**40``, or a recorded history of 1e10 control intervals) is refused with a
#: ValueError naming the argument, not left to numpy's MemoryError or the system's OOM killer.
MEMORY_LIMIT = _physical_memory()


def row_bytes(setup: Any) -> int:
    """Bytes per environment of :class:`Buffers` (row arrays and compiled-step lanes, without
    the history) and of a vector environment's batched spaces."""
    nb = setup.scene.ball_count
    ns = 2 * (3 + nb)
    rows = (setup.n_actions + ns + mdl.N_PARAMS + nb * mdl.N_BALL_PARAMS
            + setup.n_rows * dl.N_DRIVE + N_ST + N_OUT + 2)
    lanes = (16 * ns + mdl.N_PARAMS + nb * (mdl.N_BALL_PARAMS + mdl.WORK_COLUMNS) + dl.N_DRIVE
             + batch.N_F + max(batch.N_G, N_G_ENV))
    spaces_bounds = 2 * 4 * (setup.obs_dim + setup.n_actions)  # float32 low and high
    return 8 * (rows + lanes) + 4 * setup.obs_dim + 2 + spaces_bounds


def trace_bytes(setup: Any) -> int:
    """Bytes of one environment's recorded history (one row per control interval)."""
    return 8 * (setup.max_steps + 1) * (T_BALLS + setup.scene.ball_count)


def _gb(n: float) -> str:
    return f"{n / 1e9:.3g} GB"


def check_memory(setup: Any, n: int, n_trace: int) -> None:
    """Raise ValueError, naming the argument and what to change, if the buffers of ``n``
    environments with ``n_trace`` histories need more than :data:`MEMORY_LIMIT`."""
    rows = float(n) * row_bytes(setup)
    trace = float(min(n_trace, n)) * trace_bytes(setup)
    if rows > MEMORY_LIMIT:
        raise ValueError(f"num_envs = {n} needs {_gb(rows)} of buffers ({row_bytes(setup)} "
                         f"bytes per sub-environment), more than this machine's "
                         f"{_gb(MEMORY_LIMIT)}: use fewer sub-environments")
    if rows + trace > MEMORY_LIMIT:
        raise ValueError(f"the history kept by record_history=True or render_mode ("
                         f"{setup.max_steps + 1} control intervals x {min(n_trace, n)} "
                         f"environment(s)) needs {_gb(trace)}, more than this machine's "
                         f"{_gb(MEMORY_LIMIT)}: record no history, or shorten the episode "
                         f"(episode_length = {setup.episode_length:.6g} s, control_interval = "
                         f"{setup.control_interval:g} s) or use fewer sub-environments")


class Buffers:
    """The preallocated arrays of ``n`` environments (rows), in blocks of lanes for the
    compiled step (:mod:`abb_gym.envs.kernel`)."""

    def __init__(self, setup: Any, n: int, n_trace: int = 0, kernel: str | None = None,
                 lanes: int | None = None):
        check_memory(setup, n, n_trace)
        nb = setup.scene.ball_count
        ns = 2 * (3 + nb)
        self.act = np.zeros((n, setup.n_actions))
        self.s = np.zeros((n, ns))
        self.p = np.zeros((n, mdl.N_PARAMS))
        self.b = np.zeros((n, nb, mdl.N_BALL_PARAMS))
        self.d = np.zeros((n, setup.n_rows, dl.N_DRIVE))
        self.st = np.zeros((n, N_ST))
        self.st[:, S_DONE] = 1.0
        self.st[:, S_USCALE] = 1.0
        self.obs = np.zeros((n, setup.frame_dim), dtype=np.float32)
        # the last frame_stack observations, oldest first (None: no stacking)
        self.frame_stack = setup.frame_stack
        self.frames = (np.zeros((n, setup.obs_dim), dtype=np.float32)
                       if setup.frame_stack > 1 else None)
        self.out = np.zeros((n, N_OUT))
        k = setup.max_steps + 1 if n_trace > 0 else 0
        self.trace = np.zeros((min(n_trace, n), k, T_BALLS + nb))
        self.active = np.ones(n, dtype=np.uint8)
        self.cfg = setup.cfg
        self.blocks = batch.Blocks(n, nb, lanes, int_rows=N_G_ENV,
                                   precision=setup.config.precision)
        self.blocks.g[:, G_HELD] = -1  # no lane holds a row yet (kernel.G_HELD)
        self.order = np.arange(n, dtype=np.int64)
        self.n_balls = nb
        # blocks of one lane (a single environment, a few sub-environments): the kernel also
        # takes the lane count as a constant
        self.spec = setup.spec | (mdl.SPEC_ONE_LANE if self.blocks.lanes == 1 else 0)
        #: the compiled step's arguments (:meth:`kernel_args`), packed once
        self.args = self.kernel_args()
        self.first_row = self.first_row_views()
        #: the current episode of every row (:mod:`abb_gym.envs.episodes`)
        self.table = EpisodeTable(setup.scene, n, setup.redistribution_events)
        self.kernel = resolve_kernel(kernel, self.blocks.lanes, cached_ok=True)
        self._step = None
        if self.kernel == "cached":
            # "auto" on a few lanes: the specialised kernel if it needs no compiling
            self._step = entry_point(self.blocks.s.shape[0]).cached_entry(*self.args)
            self.kernel = "generic" if self._step is None else "specialised"

    def step_arrays(self) -> tuple:
        """The arrays of the compiled step, in the order of
        :data:`abb_gym.envs.kernel.STEP_ARRAYS`."""
        return (self.order, self.act, self.s, self.p, self.b, self.d, self.st, self.cfg, self.obs,
                self.out, self.trace, self.active, *self.blocks.arrays())

    def first_row_views(self) -> tuple:
        """Views of the first row of the action, observation, output, status and state arrays:
        the single environment's only row, which it reads and writes at every step (made
        again after unpickling: a view would unpickle as a copy)."""
        return self.act[0], self.observations[0], self.out[0], self.st[0], self.s[0]

    def kernel_args(self) -> tuple:
        """Arguments of :data:`abb_gym.envs.kernel.step_serial` / ``step_parallel``: the packed
        :meth:`step_arrays`, the ball count and the effect bits (packed anew into
        :attr:`args` whenever one of those arrays is replaced)."""
        return kernel.pack_step_arrays(*self.step_arrays()), self.n_balls, self.spec

    def step_function(self):
        """The compiled step's entry point, called with :attr:`args` (compiled or loaded from
        the cache on the first call)."""
        if self._step is None:
            self._step = entry_point(self.blocks.s.shape[0]).entry(
                *self.args, generic=self.kernel == "generic")
        blocks = self.blocks.s.shape[0]
        # the blocks in parallel on the threads that the free CPUs allow (batch.ParallelCall)
        return batch.ParallelCall(self._step, blocks) if blocks > 1 else self._step

    def sort_lanes(self) -> None:
        """Group rows of equal step size into the same blocks (after resets), sorted per
        thread's run of blocks (:func:`abb_gym.physics.batch.lane_order`)."""
        # (one block: one run, stepped serially)
        self.order[:] = batch.lane_order(self.st[:, S_DTMAX], self.blocks.lanes,
                                         batch.thread_parts())

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_step"] = None  # compiled entry points do not pickle
        del state["args"]  # nor does the pack, which must hold the unpickled arrays
        del state["first_row"]  # nor do views, which would unpickle as copies
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self.args = self.kernel_args()
        self.first_row = self.first_row_views()

    def record_history(self, steps: int) -> None:
        """Record the first row's history from now on, ``steps`` control interval boundaries
        (a single environment asked to render after it was made without a history)."""
        self.trace = np.zeros((1, steps, T_BALLS + self.n_balls))
        self.args = self.kernel_args()

    def history(self, i: int) -> dict[str, np.ndarray]:
        """Row ``i``'s recorded history so far, one entry per control interval boundary
        (``t`` [s], ``x``, ``y`` [m], ``rotor_speed`` [rad/s], ``vibration`` (the interval's
        mean) and ``vibration_max`` [m], ``ball_angles`` [rad] (T, n)); needs a buffer built
        with a trace for that row (``record_history=True``)."""
        if i >= self.trace.shape[0]:
            raise ValueError("no history is recorded: create the environment with "
                             "record_history=True")
        rows = self.trace[i, :int(self.st[i, S_K]) + 1]
        return {"t": rows[:, T_T].copy(), "x": rows[:, T_X].copy(), "y": rows[:, T_Y].copy(),
                "rotor_speed": rows[:, T_W].copy(), "vibration": rows[:, T_VIB].copy(),
                "vibration_max": rows[:, T_VIBMAX].copy(), "ball_angles": rows[:, T_BALLS:].copy()}

    def observe(self, rows: np.ndarray) -> None:
        """Observe ``rows`` after a reset (their frame stacks filled with the first one)."""
        rows = np.asarray(rows, dtype=np.int64)
        observe_rows(rows, self.s, self.p, self.b, self.st, self.cfg, self.obs, self.out,
                     self.trace)
        self.fill_frames(rows)

    @property
    def observations(self) -> np.ndarray:
        """What the environments return: the observations, or their frame stacks."""
        return self.obs if self.frames is None else self.frames

    def fill_frames(self, rows: np.ndarray) -> None:
        """Every frame of ``rows`` := their current observation (the start of an episode)."""
        if self.frames is not None and len(rows):
            self.frames[rows] = np.tile(self.obs[rows], (1, self.frame_stack))

    def push_frames(self) -> None:
        """Shift every row's frames by one and append the current observation (after a
        step)."""
        if self.frames is not None:
            d = self.obs.shape[1]
            self.frames[:, :-d] = self.frames[:, d:].copy()
            self.frames[:, -d:] = self.obs
