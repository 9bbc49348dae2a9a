"""Nothing compiles without a word: a notice on stderr for every compilation that runs long.

numba compiles a kernel on its first call when its on-disk cache does not hold it (a fresh
install on another CPU, a changed compiled module): 20-70 s for the large kernels, and a
first ``gym.make``, ``reset`` and ``step`` each compile some (111 s together on a busy
2-core machine).  Two hooks announce every such compilation that is still running after
:data:`NOTICE_AFTER` seconds, and its duration when it ends:

* :func:`compile_notice`, around the compilations abb-gym starts itself (the kernels of
  :class:`abb_gym.physics.specialise.Specialised`, which it names in words);
* a listener on numba's ``numba:compile`` event (:func:`install_listener`, installed by
  :mod:`abb_gym._numba` before any kernel is compiled), for every other function of the
  package that numba compiles on first call (the stiffness check at ``gym.make``, the episode
  draws at ``reset``), outside the first hook.  Only the outermost compilation of a chain is
  announced.

The first notice of a process names ``abb-gym build-kernels``, which compiles every kernel
ahead of time.  ``ABB_GYM_QUIET=1`` silences both (``abb-gym build-kernels`` sets it: its bar
says what compiles).  Loading a cached kernel takes well under a second and stays silent.
"""
from __future__ import annotations

import os
import sys
import threading
import time
from contextlib import contextmanager

__all__ = ["NOTICE_AFTER", "compile_notice", "install_listener", "HINT"]

NOTICE_AFTER = 1.0  # [s] a compilation that takes longer than this is announced
HINT = "abb-gym build-kernels compiles every kernel ahead of time"
_hinted = threading.Event()  # the hint is given once per process
_local = threading.local()  # per thread: compilations under way that are announced


def _depth() -> int:
    return getattr(_local, "depth", 0)


class _Notice:
    """One announced compilation: a timer that writes the notice after ``after`` seconds."""

    def __init__(self, what: str, after: float | None):
        self.what = what
        self.start = time.perf_counter()
        self.announced = threading.Event()
        self.timer = threading.Timer(NOTICE_AFTER if after is None else after, self._announce)
        self.timer.daemon = True
        self.timer.start()

    def _announce(self) -> None:
        self.announced.set()
        hint = "" if _hinted.is_set() else f"; {HINT}"
        _hinted.set()
        sys.stderr.write(f"abb-gym: compiling {self.what} (once; cached on disk "
                         f"afterwards{hint}) ...\n")
        sys.stderr.flush()

    def stop(self) -> None:
        self.timer.cancel()
        if self.announced.is_set():
            sys.stderr.write(f"abb-gym: compiled {self.what} in "
                             f"{time.perf_counter() - self.start:.0f} s\n")
            sys.stderr.flush()


@contextmanager
def compile_notice(what: str, after: float | None = None):
    """Announce on stderr a compilation of ``what`` that is still running after ``after``
    seconds (default :data:`NOTICE_AFTER`), and its duration when it ends (module
    docstring); numba's compilations inside it are not announced again."""
    if os.environ.get("ABB_GYM_QUIET"):
        yield
        return
    notice = _Notice(what, after)
    _local.depth = _depth() + 1
    try:
        yield
    finally:
        _local.depth -= 1
        notice.stop()


def install_listener() -> None:
    """Announce numba's compilations of the package's functions (module docstring); once."""
    if getattr(install_listener, "done", False):
        return
    from numba.core import event

    class Listener(event.Listener):
        def on_start(self, ev) -> None:
            depth = _depth()
            _local.depth = depth + 1
            if depth or os.environ.get("ABB_GYM_QUIET"):
                return  # inside an announced compilation, or silenced
            func = getattr(ev.data.get("dispatcher"), "py_func", None)
            if not getattr(func, "__module__", "").startswith("abb_gym"):
                return
            _local.notice = _Notice(f"{func.__module__}.{func.__qualname__}", None)

        def on_end(self, ev) -> None:
            _local.depth = max(0, _depth() - 1)
            notice = getattr(_local, "notice", None)
            if _depth() == 0 and notice is not None:
                _local.notice = None
                notice.stop()

    event.register("numba:compile", Listener())
    install_listener.done = True
