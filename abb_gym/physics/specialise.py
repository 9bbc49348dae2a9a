"""Compiled functions specialised on some arguments' values, called without dispatch cost.

The kernels are written once and compiled for each combination of a few small integers (the
integration method, the ball count, the kernel's ``SPEC_*`` effect bits), so that the compiler
sees them as constants: dead terms vanish and the lane loops vectorise.  numba offers
``numba.literally`` for this, but a call from Python then re-runs type inference every time
(about 5 ms per call, measured), which the environments' step cannot afford.

:class:`Specialised` instead compiles (or loads from numba's cache) the signature with those
arguments typed as literals once per combination, keeps the compiled entry point, and calls it
directly afterwards: a dictionary lookup plus the usual unboxing of the arguments.
"""
from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
from .._compile_notice import NOTICE_AFTER, compile_notice  # noqa: F401  (re-exported)
from .._numba import typeof, types

__all__ = ["Specialised", "compile_notice", "resolve_kernel", "start_parallel_runtime",
           "KERNELS"]

KERNELS = ("auto", "generic", "specialised")
VECTORISE_FROM = 8  # lanes per block from which "auto" picks the vectorised kernel


def resolve_kernel(kernel: str | None, lanes: int, cached_ok: bool = False) -> str:
    """The kernel a batch of ``lanes`` lanes per block runs: ``kernel`` (default:
    ``$ABB_GYM_KERNEL``, else "auto").  "specialised" is compiled for the scene's ball count
    and effects (once per pair, 20-60 s; it vectorises across lanes and runs fastest),
    "generic" is compiled once for every scene; "auto" picks the specialised kernel from
    ``VECTORISE_FROM`` lanes per block on, where its compilation pays off.

    With ``cached_ok``, "auto" below ``VECTORISE_FROM`` lanes gives "cached": the specialised
    kernel if it is already compiled (this process or numba's on-disk cache, e.g. the wheel's
    kernels of the default scene), else the general one (:meth:`Specialised.cached_entry`).
    On one lane the specialised kernel takes half the general kernel's time per right-hand
    side (the single environment: 1.2x the steps per second), which does not pay for a
    compilation of 20-60 s in a short run."""
    if kernel is not None and not isinstance(kernel, str):
        raise ValueError(f"kernel must be None or one of {KERNELS} (got {kernel!r:.80})")
    # only None means the default: an empty name is refused like any unknown one (an empty
    # ABB_GYM_KERNEL is unset)
    passed = kernel is not None
    if not passed:
        kernel = os.environ.get("ABB_GYM_KERNEL") or "auto"
    if kernel not in KERNELS:
        where = "" if passed else "; from $ABB_GYM_KERNEL"
        raise ValueError(f"kernel must be one of {KERNELS} (got {kernel!r:.80}{where})")
    if kernel == "auto":
        kernel = ("specialised" if lanes >= VECTORISE_FROM else
                  "cached" if cached_ok else "generic")
    return kernel

def _layout(flags) -> str:
    """numba's layout letter of an array (numba.np.numpy_support.map_layout)."""
    return "C" if flags.c_contiguous else "F" if flags.f_contiguous else "A"


def start_parallel_runtime() -> None:
    """Start numba's threading layer (its public ``get_num_threads`` does so).

    A compiled function that calls a ``parallel=True`` one links against the parallel
    runtime's symbols (``allocate_sched``, ``do_scheduling_*``), which exist only once the
    threading layer runs.  numba restarts it when it loads a cached function that carries its
    reload hook, but numba 0.68 gives the caller that hook only when the parallel callee was
    compiled, not loaded from the cache, in the process that compiled the caller.  A wrapper
    compiled over a cached callee therefore loads, in the next fresh process, into "LLVM
    ERROR: Symbol not found: allocate_sched" and the process aborts (it did: ``abb-gym
    evaluate --scene spannan_cfrp`` after ``make setup``).  Starting the layer first costs
    one thread pool, which the parallel kernel is about to start anyway."""
    import numba
    numba.get_num_threads()


class Specialised:
    """Call ``dispatcher`` (an ``njit`` function) with the arguments at ``literal`` positions
    compiled in as constants.

    The compiled entry point is kept per combination of those values and of the other
    arguments' types (dtype, dimensions, layout and writeability of arrays), so a call with
    new types compiles a new entry as numba's own dispatch would.  Hot loops that call with
    the same arrays every time can fetch the entry point once with :meth:`entry`.

    ``parallel``: ``dispatcher`` is a serial function that calls a ``parallel=True`` one;
    numba's threading layer is then started (:func:`start_parallel_runtime`) before any entry
    point compiles or loads.  ``names`` name the literal arguments in the compile notice; a
    name may come with a function that puts the value in words, ``("effects", describe)``.
    """

    def __init__(self, dispatcher, literal: Sequence[int], names: Sequence = (),
                 parallel: bool = False):
        self.dispatcher = dispatcher
        self.parallel = parallel
        self.literal = tuple(literal)
        self.names = {i: name if isinstance(name, tuple) else (name, str)
                      for i, name in zip(self.literal, names)}
        self._entries: dict[tuple, object] = {}
        self.__doc__ = dispatcher.__doc__
        self.__name__ = getattr(dispatcher, "__name__", "specialised")

    def _key(self, args) -> tuple:
        # the literal values plus what numba's type of each argument depends on: an entry point
        # trusts its argument types (a non-contiguous array passed to a contiguous signature
        # would be read as contiguous), so every type gets its own entry
        # (the layout as numba reads it: C when C-contiguous, so a one-row array, which is
        # both, shares the entry of a many-row one)
        # (a StructRef proxy carries its numba type, which holds its arrays' types)
        return tuple(int(args[i]) for i in self.literal) + tuple(
            (a.dtype.char, a.ndim, _layout(a.flags), a.flags.writeable)
            if isinstance(a, np.ndarray) else getattr(a, "_type", None) or type(a)
            for a in args)

    def entry(self, *args, generic: bool = False):
        """The compiled entry point for these arguments (compiled or loaded on first use);
        ``generic``: the general kernel's entry point (the literal arguments typed as plain
        integers).  Long compilations say so on stderr while they run."""
        key = self._key(args) + (generic,)
        fn = self._entries.get(key)
        if fn is None:
            sig = self._signature(args, generic)
            what = ("the general kernel" if generic else
                    "a kernel for " + ", ".join(self._describe(i, args[i])
                                                for i in self.literal))
            if self.parallel:
                start_parallel_runtime()
            with compile_notice(f"{self.__name__}: {what}"):
                fn = self.dispatcher.compile(sig)
            self._entries[key] = fn
        return fn

    def _describe(self, i: int, value) -> str:
        name, words = self.names.get(i, (f"argument {i}", str))
        return f"{name} = {words(int(value))}"

    def _signature(self, args, generic: bool) -> tuple:
        return tuple(typeof(a) if generic or i not in self.literal else types.literal(int(a))
                     for i, a in enumerate(args))

    def cached_entry(self, *args):
        """The specialised entry point for these arguments if it needs no compiling (loaded
        already, or in numba's on-disk cache), else None.  The cache's index is asked for the
        key numba's ``compile`` loads by (``_cache._index_key``), without loading the kernel:
        :meth:`entry` then loads it once (asking ``load_overload`` instead loaded it twice,
        17 ms more per kernel at the first ``gym.make``).  If that interface is missing,
        nothing counts as cached."""
        fn = self._entries.get(self._key(args) + (False,))
        if fn is not None:
            return fn
        try:
            cache = self.dispatcher._cache
            key = cache._index_key(self._signature(args, False),
                                   self.dispatcher.targetctx.codegen())
            hit = key in cache._cache_file._load_index()
        except Exception:  # noqa: BLE001 - a numba without this interface: compile nothing
            hit = False
        return self.entry(*args) if hit else None

    def __call__(self, *args):
        fn = self._entries.get(self._key(args) + (False,))
        if fn is None:
            fn = self.entry(*args)
        return fn(*args)

    def generic(self, *args):
        """Call the general kernel: the same code compiled once for run-time values of the
        literal arguments (no vector instructions across lanes, but no compilation per
        combination either)."""
        fn = self._entries.get(self._key(args) + (True,))
        if fn is None:
            fn = self.entry(*args, generic=True)
        return fn(*args)
