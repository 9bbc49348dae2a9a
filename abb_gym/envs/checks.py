"""The environments' checks of their arguments and of the memory they would take.

Each check raises a ValueError that names the argument and what to change: a seed, a flag,
a reset that must leave no trace when it fails (:func:`draw_safely`), and buffers larger
than the machine's memory (:func:`check_memory`).
"""
from __future__ import annotations

import os
from typing import Any

import numpy as np

from ..physics import batch
from ..physics import drive_law as dl
from ..physics import model as mdl
from .kernel import N_G_ENV
from .layout import N_OUT, N_ST, T_BALLS

__all__ = ["MEMORY_LIMIT", "row_bytes", "trace_bytes", "check_memory", "check_seed",
           "check_flag", "draw_safely"]


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


def check_seed(seed: Any, what: str = "seed") -> int | None:
    """``seed`` as a Python int >= 0, or None; anything else (negative, bool, float, text)
    raises ValueError naming ``what`` (gymnasium's seeding raises its own error type)."""
    if seed is None:
        return None
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) \
            or seed < 0:
        raise ValueError(f"{what} must be None or an integer >= 0 (got {seed!r})")
    return int(seed)


def check_flag(value: Any, what: str) -> bool:
    """``value`` if it is True or False (numpy's too), else a ValueError naming ``what``:
    ``"no"`` or ``[]`` are not read as flags."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{what} must be True or False (got {value!r:.80})")
    return bool(value)


def draw_safely(prepare, rngs: list):
    """``prepare()`` (which draws from the generators ``rngs``), with the generators put back
    as they were if it raises: a rejected reset leaves no trace, not even in the random
    streams, so the next reset draws what it would have drawn."""
    saved = [(rng, rng.bit_generator.state) for rng in rngs]
    try:
        return prepare()
    except BaseException:
        for rng, state in saved:
            rng.bit_generator.state = state
        raise
