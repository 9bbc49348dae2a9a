"""numba as abb-gym's compiled modules use it: ``from .._numba import njit`` instead of
``from numba import njit``.

Importing this module first points numba's cache at ``abb_gym/_kernels`` and drops stale
caches (:mod:`abb_gym._jit_cache`), so every compiled module gets both before its first
decorator runs, whichever of them is imported first.  ``import abb_gym`` imports none of
them: numba (0.2-0.3 s) loads with the first simulator or environment that needs it.
"""
from ._jit_cache import flush_if_sources_changed, install_locator

install_locator()
flush_if_sources_changed()

from numba import njit, prange, typeof, types  # noqa: E402

__all__ = ["njit", "prange", "typeof", "types"]
