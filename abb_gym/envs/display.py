"""What the environments show: ``render_mode`` and ``info_level``, checked in one place for
the single and the vector environment, and the single environment's ``metadata``.

Light on purpose (no compiled module): ``gym.make`` reads the entry point's metadata before it
builds anything, and ``import abb_gym`` registers the ids without loading numba.
"""
from __future__ import annotations

from typing import Any

__all__ = ["INFO_LEVELS", "check_info_level", "check_display", "RenderModes",
           "SINGLE_METADATA"]

INFO_LEVELS = ("lean", "full")


def check_info_level(level: Any) -> str:
    """``level`` if it is one of :data:`INFO_LEVELS`, else a ValueError naming them."""
    # text first: ``in`` on an array is ambiguous, and a list is unhashable
    if not isinstance(level, str) or level not in INFO_LEVELS:
        raise ValueError(f"info_level must be one of {INFO_LEVELS} (got {level!r})")
    return level


class RenderModes(list):
    """The ``metadata["render_modes"]`` of the environments: a list whose ``in`` is true for
    any value that is not text.

    ``gym.make`` checks ``render_mode`` against the entry point's modes before it calls it,
    and for a mode not in the list it calls ``render_mode.endswith(...)``: ``render_mode=True``
    or ``b"x"`` would end in gymnasium's AttributeError or TypeError instead of the
    environment's ValueError.  Such values pass gymnasium's ``in`` and reach
    :func:`check_display`, which names ``render_mode``; text behaves as in a plain list
    ("human" and "rgb_array_list" get gymnasium's wrappers, other text a ValueError)."""

    def __contains__(self, value: Any) -> bool:
        if not isinstance(value, str):
            return True
        return list.__contains__(self, value)


def check_display(render_mode: Any, render_modes: list[str], info_level: Any) -> str:
    """The checks of the single and the vector environment's ``render_mode`` and
    ``info_level`` arguments; returns the info level."""
    # text first (``in`` on an array is ambiguous; :class:`RenderModes` lets any non-text
    # value through its own ``in``, so that it reaches this check)
    if render_mode is not None and (not isinstance(render_mode, str)
                                    or not any(render_mode == m for m in render_modes)):
        raise ValueError(f"render_mode must be None or one of {render_modes} "
                         f"(got {render_mode!r})")
    return check_info_level(info_level)


#: ``metadata`` of the single environments (and their ``gym.make`` entry points)
SINGLE_METADATA = {"render_modes": RenderModes(["human", "rgb_array"]), "render_fps": 25}
