"""Keep numba's and torch's OpenMP threads from spinning against each other.

The vector environments run one compiled parallel call per step (numba); a torch policy in
the same process runs its own OpenMP threads.  GNU OpenMP reads ``OMP_WAIT_POLICY`` once, when
its library loads; without it an idle worker busy-waits about 300 000 iterations after every
parallel region, and on a small machine those spinning workers slow the next environment step
or the next torch call: SB3 PPO ``learn(2048)`` with 8 sub-environments took 66 s instead of
8 s on a 2-core machine.

:func:`quiet_openmp` runs on ``import abb_gym`` (before numba loads):

* ``OMP_WAIT_POLICY`` unset: it is set to ``PASSIVE``, and ``GOMP_SPINCOUNT`` (if unset) to
  :data:`SHORT_SPIN`; every GNU OpenMP runtime loaded from now on (numba's, torch's) waits
  that short while, then sleeps.  A fully passive worker (no spin at all) sleeps at once after
  every parallel region and must be woken, through the kernel, at the next one, and a thread
  that reaches a region's end barrier first sleeps and is woken too.  With a vector step every
  few hundred microseconds that cost the vector environment a seventh of its speed at 1024
  sub-environments (six alternating whole-process pairs, 10 000 spins against none: x1.02-1.31,
  median 1.15), and SB3 PPO ``learn(4096)`` with 8 sub-environments took 0.99-1.15 s instead
  of 0.51-0.66 s.  30 000 spins were no faster than 10 000 (six pairs, median 1.0).  On this
  2-core machine 10 000 spins last about 0.17 ms (the extra CPU time per step of a worker
  stepped every 5 ms), so an idle worker gives its core back after at most that.
* an OpenMP runtime was loaded before that (typically ``import torch`` before ``import
  abb_gym``; rl_zoo3 always does so), it already busy-waits and cannot be changed.  Then

  - numba's threading layer becomes ``workqueue`` (numba's own pool, which sleeps when idle):
    numba's OpenMP layer binds to the runtime torch loaded globally (``LD_DEBUG=bindings``
    shows ``GOMP_parallel`` resolved in ``torch/lib/libgomp.so.1``), spinning included;
  - torch's intra-op threads become 1 (``torch.set_num_threads(1)``): its OpenMP workers then
    never run, so never spin.  These policies are small MLPs, for which one thread is as fast
    (``abb_gym.rl.train`` uses one thread in any case).

  Measured on 2 cores, ``RunUpSpeed-v0`` x 8: SB3 PPO ``learn(2048)`` (default settings)
  took 66 s torch first without this, 8 s with it, 8-9 s abb_gym first; the project's
  :func:`abb_gym.rl.train` (16 384 steps, already one torch thread) 28 s torch first with
  numba's OpenMP layer, 3.8 s with ``workqueue``, 3.8 s abb_gym first.  Either change alone
  is not enough: 65 s with ``workqueue`` only, 22 s with one torch thread only.

Nothing is changed when ``OMP_WAIT_POLICY`` was set before (``ACTIVE`` is a choice; so is
``PASSIVE`` with its spin count), ``GOMP_SPINCOUNT`` set before is kept, and numba's
layer is not chosen when ``NUMBA_THREADING_LAYER`` is set or a parallel function already ran.
After the adjustment ``torch.set_num_threads(n)`` still works; it brings the spinning back.
The ``workqueue`` layer must not run parallel functions from several Python threads at once
(numba aborts the process); set ``OMP_WAIT_POLICY=PASSIVE`` before importing torch to keep
numba's OpenMP layer instead.
"""
from __future__ import annotations

import importlib
import os
import re
import sys
import time

__all__ = ["quiet_openmp", "ADJUSTED", "SHORT_SPIN", "available_cpus", "share_cores",
           "free_cpus", "FreeCpus"]

#: GNU OpenMP's ``GOMP_SPINCOUNT`` that :func:`quiet_openmp` sets with the passive policy: the
#: spins an idle thread waits before it sleeps (module docstring)
SHORT_SPIN = "10000"

#: what :func:`quiet_openmp` changed in this process (empty: nothing; for diagnostics, tests)
ADJUSTED: dict[str, object] = {}

# GNU (libgomp), Intel (libiomp5) and LLVM (libomp) OpenMP runtimes, versioned copies included
_OPENMP_LIBRARY = re.compile(r"/lib(?:gomp|iomp5|omp)[-.\w]*\.so")


def openmp_loaded() -> bool:
    """True if an OpenMP runtime is mapped into this process (Linux ``/proc/self/maps``;
    elsewhere: whether torch, which brings its own, is imported)."""
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as fh:
            return _OPENMP_LIBRARY.search(fh.read()) is not None
    except OSError:
        return "torch" in sys.modules


def quiet_openmp() -> dict[str, object]:
    """Apply the rules of the module docstring once; returns :data:`ADJUSTED`."""
    if "OMP_WAIT_POLICY" in os.environ:
        return ADJUSTED  # the user's choice, or already done by an earlier call
    os.environ["OMP_WAIT_POLICY"] = "PASSIVE"
    ADJUSTED["OMP_WAIT_POLICY"] = "PASSIVE"
    if "GOMP_SPINCOUNT" not in os.environ:
        os.environ["GOMP_SPINCOUNT"] = SHORT_SPIN
        ADJUSTED["GOMP_SPINCOUNT"] = SHORT_SPIN
    if not openmp_loaded():
        return ADJUSTED
    # imported by name: a numba import statement here would put this module (which compiles
    # nothing) into the kernel-cache fingerprint of abb_gym._jit_cache
    config = importlib.import_module("numba.core.config")
    parallel = sys.modules.get("numba.np.ufunc.parallel")
    launched = parallel is not None and getattr(parallel, "_is_initialized", False)
    if "NUMBA_THREADING_LAYER" not in os.environ and not launched:
        # numba keeps values set on its config module unless a NUMBA_* variable changes later
        config.THREADING_LAYER = "workqueue"
        ADJUSTED["numba_threading_layer"] = "workqueue"
    torch = sys.modules.get("torch")
    if torch is not None and hasattr(torch, "set_num_threads"):
        ADJUSTED["torch_threads_before"] = torch.get_num_threads()
        torch.set_num_threads(1)
        ADJUSTED["torch_threads"] = 1
    return ADJUSTED


def available_cpus() -> int:
    """The CPUs this process may use (its affinity on Linux, else the machine's count)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not Linux
        return max(1, os.cpu_count() or 1)


def share_cores(threads: int) -> int:
    """Run this thread's compiled parallel loops (numba) on at most ``threads`` threads;
    returns the count set.  For a worker process of a sweep, one of several on the machine:
    left at numba's default, each worker would run a thread per core, and with the short spin
    (module docstring) the idle ones would take turns from the other workers.  Measured on 2
    cores, ``abb-gym evaluate --scene yoshida_odd --policy baseline:knots --episodes 200
    --workers 2``: 3.3-4.2 s without the spin, 4.5-5.4 s with it and two threads per worker;
    with it and this share, 3.4-3.9 s against 3.4-3.6 s for the tree before the spin (four
    alternating pairs).  Never more than numba's pool (``NUMBA_NUM_THREADS``, default all
    cores), which stays as it is: a Ray worker process runs tasks of different CPU counts in
    turn."""
    # imported by name, like numba's config above (the kernel-cache fingerprint)
    numba = importlib.import_module("numba")
    n = max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS))
    numba.set_num_threads(n)
    return n


class FreeCpus:
    """How many of this process's CPUs other processes leave free, measured over the last
    ``interval`` seconds: the CPUs less the other processes' busy CPUs, from the machine's CPU
    time (``/proc/stat``) less this process's own (:func:`time.process_time`, all its threads).

    Why: a parallel loop over blocks hands each thread an equal share and waits for the last.
    Beside one busy process on two cores, the second thread shares a core with it and finishes
    late, and each region's start and end wait for the operating system to schedule it: the
    vector environment ran 3-4x slower with two threads than with one at 8-64
    sub-environments.  The parallel loops therefore take only the CPUs that are actually free
    (:func:`abb_gym.physics.batch.parallel_threads`).

    A call costs a clock read; the counters are read again (about 20 us) at most once per
    ``interval``.  Where ``/proc/stat`` cannot be read (not Linux), every CPU counts as free.
    """

    def __init__(self, interval: float = 0.25, cpus: int | None = None):
        self.interval = float(interval)
        self.cpus = available_cpus() if cpus is None else int(cpus)
        self._last = None  # (wall, machine busy [s], own CPU [s])
        self._free = float(self.cpus)
        self._next = 0.0

    @staticmethod
    def _machine_busy() -> float | None:
        """CPU seconds the whole machine spent busy since boot (all CPUs), or None."""
        try:
            with open("/proc/stat", encoding="ascii") as fh:
                fields = fh.readline().split()
        except OSError:
            return None
        if not fields or fields[0] != "cpu":
            return None
        ticks = [int(v) for v in fields[1:]]
        idle = ticks[3] + (ticks[4] if len(ticks) > 4 else 0)  # idle + iowait
        # (guest time is counted in user time already)
        busy = sum(ticks[:8]) - idle
        return busy / os.sysconf("SC_CLK_TCK")

    def __call__(self) -> float:
        now = time.monotonic()
        if now < self._next:
            return self._free
        self._next = now + self.interval
        busy = self._machine_busy()
        if busy is None:
            return self._free
        sample = (now, busy, time.process_time())
        if self._last is not None:
            wall = now - self._last[0]
            if wall > 0:
                others = (busy - self._last[1]) - (sample[2] - self._last[2])
                total = os.cpu_count() or self.cpus
                # the others' load spread over the machine, counted against this process's CPUs
                load = max(0.0, others / wall) * self.cpus / max(total, self.cpus)
                self._free = max(0.0, self.cpus - load)
        self._last = sample
        return self._free


_FREE = FreeCpus()


def free_cpus() -> float:
    """This process's CPUs that other processes left free recently (:class:`FreeCpus`)."""
    return _FREE()
