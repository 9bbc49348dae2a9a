"""The environments' checks of their arguments.

Each check raises a ValueError that names the argument and what to change: a seed, a flag,
and a reset that must leave no trace when it fails (:func:`draw_safely`).  The buffers'
check against the machine's memory is :func:`abb_gym.envs.buffers.check_memory`, beside
the arrays it counts.
"""
from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["check_seed", "check_flag", "draw_safely"]


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
