"""numba as abb-gym's compiled modules use it: ``from .._numba import njit`` instead of
``from numba import njit``.

Importing this module first points numba's cache at ``abb_gym/_kernels`` and drops stale
caches (:mod:`abb_gym._jit_cache`), so every compiled module gets both before its first
decorator runs, whichever of them is imported first.  ``import abb_gym`` imports none of
them: numba (0.2-0.3 s) loads with the first simulator or environment that needs it.

**No-alias kernels.**  ``njit(noalias=True)`` tells LLVM that no two array arguments of the
function share memory (numba's compiler flag ``noalias``, which its decorator does not expose;
this module maps the option onto it).  The lane loops of the equations of motion read about
fifty array rows and write fifteen; without the promise LLVM guards its vector loop with run-time
overlap checks between them, about 1.5 us per call, and skips the vector loop altogether
below 48 lanes (``python -m abb_gym.benchmarks.rhs_cost``).  A function marked so must
never be called with overlapping arrays (distinct views of one buffer that do not overlap are
fine); each says so in its docstring.  On a numba without the flag the option is dropped and
LLVM gets the large check budget the kernels used before (:func:`allow_overlap_checks`):
same results, the old speed.

**Kernels without reference counts.**  ``njit(refcounts=False)`` compiles a function without
numba's reference counting (its target option ``_nrt``).  Counted, a function that calls
others takes a reference on each array argument at its entry and drops it at its exits, and
on each view it makes (``k[0]``): an atomic operation in a call the compiler cannot see into,
so the code around it reloads what the call might have changed.  ``_rk4_step`` made 14 such
pairs per RK4 step, which uncounted compilation removes (``python -m
abb_gym.benchmarks.kernel_profile`` shows where the step's time goes).  Such a function may not allocate (numba refuses to compile it), and
the functions it calls inherit the setting where they set none.  The rule that keeps this
safe: **no function called, not inlined, from an uncounted function may return an array**
(or anything else numba counts).  Compiled counted, it would hand the uncounted caller a
reference that is never dropped (a leak); compiled uncounted, numba refuses to return a new
view.  Array arguments are safe either way, since a callee takes and drops its own
references.  ``tests/test_refcounts.py`` checks that stepping leaves every buffer's count
as it was and that closing an environment frees its buffers.
"""
from ._jit_cache import flush_if_sources_changed, install_locator

install_locator()
flush_if_sources_changed()

import numba  # noqa: E402
from numba import prange, typeof, types  # noqa: E402

from ._compile_notice import install_listener  # noqa: E402

install_listener()  # every long compilation of the package is announced

__all__ = ["njit", "prange", "typeof", "types", "NOALIAS", "allow_overlap_checks"]


def _allow_noalias() -> bool:
    try:
        from numba.core.compiler import Flags
        from numba.core.cpu import CPUTargetOptions
        from numba.core.options import TargetOptions
    except ImportError:  # pragma: no cover - a numba with other internals
        return False
    if not hasattr(Flags, "noalias"):  # pragma: no cover
        return False
    if not isinstance(getattr(CPUTargetOptions, "noalias", None), TargetOptions.Mapping):
        CPUTargetOptions.noalias = TargetOptions.Mapping("noalias")
    return True


def allow_overlap_checks() -> None:
    """Let LLVM guard a vector loop with as many run-time overlap checks as the lane loops need
    without the no-alias promise (its default budget is too small for the equations of
    motion).  Process wide: it applies to everything compiled afterwards."""
    import llvmlite.binding as llvm
    llvm.set_option("abb_gym", "-vectorize-memory-check-threshold=100000")


#: whether ``njit(noalias=True)`` reaches the compiler on this numba
NOALIAS = _allow_noalias()
if not NOALIAS:  # pragma: no cover - the lane loops then vectorise behind run-time checks
    allow_overlap_checks()


def njit(*args, noalias: bool = False, refcounts: bool = True, **options):
    """``numba.njit``, plus ``noalias`` and ``refcounts`` (module docstring)."""
    if noalias and NOALIAS:
        options["noalias"] = True
    if not refcounts:
        options["_nrt"] = False
    return numba.njit(*args, **options)
