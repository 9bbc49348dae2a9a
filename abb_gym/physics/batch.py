"""Batched fixed-step integration: many independent balancers in blocks of lanes.

The environments, parameter sweeps and batch simulations advance many copies of the model at
once.  They do it in *blocks*: up to 128 environments side by side as the lanes of
structure-of-arrays blocks (every array carries the lane last), so that the compiled
right-hand side (:func:`abb_gym.physics.model.accelerations_block`) works on all lanes of a
block with vector instructions.  A single environment or a single simulation is a block of one
lane: the same code.

* :func:`advance_block` advances every lane of one block over its own interval
  ``[t0, t1]`` with the fixed-step methods of :func:`abb_gym.physics.integrators.run` (RK4,
  ETDRK4).  Each lane follows its own schedule - the same segment and step splitting as
  ``integrators.run`` (``enter_segment`` / ``next_piece``), the same pinning of a prescribed
  rotor angle at piece ends, the same non-finite check after every step, with its own step
  size - and the lanes step together, a lane that has finished (or failed) being masked out
  of the update.  For the same output times each lane's states are therefore bit-identical to
  ``integrators.run`` (``tests/test_envs_batch.py`` checks this).  It also accumulates the
  time integral and the maximum of the whirl radius over the substeps.
* :func:`run_batch` - ``integrators.run`` for ``N`` environments (own parameters, own drive
  tables, shared output times), parallel over blocks with ``numba.prange``.

**Threads.**  A batch of at most :data:`MAX_LANES` environments is one block and runs on one
thread (:func:`lanes_per_block`); larger batches run their blocks in parallel on as many
threads as other processes leave CPUs free (:func:`parallel_threads`, :class:`ParallelCall`,
:class:`abb_gym._threads.FreeCpus`), so that a busy machine never makes the default slower
than one thread.  Neither the block shape nor the thread count changes a result.

Lanes of a block run until the block's slowest lane is done, so a block works as long as its
largest step count: callers that mix step sizes group lanes of similar step size into the
same block (``order``, below; :func:`lane_order`).

Arrays of one block (``n`` balls, ``ns = 2 (3 + n)`` state rows, ``L`` lanes):

==========  =========================  ======================================================
name        shape                      meaning
==========  =========================  ======================================================
s           (ns, L)                    states
p           (N_PARAMS, L)              scalar parameters (:func:`model.pack_parameters`)
b           (n, N_BALL_PARAMS, L)      per-ball parameters
d           (N_DRIVE, L)               each lane's current drive row
k, tmp      (7, ns, L), (ns, L)        stages and stage state of the step functions
lam, coef   (ns, L), (6, ns, L)        ETDRK4 drag rates and weights
work        (n [+1], WORK_COLUMNS, L)  scratch of the right-hand side (+1 row in float32)
f           (N_F, L) float             per-lane schedule (``F_*``) and whirl (``W_*``)
g           (N_G, L) int64             per-lane schedule, status and row (``G_*``)
act         (L,) uint8                 lanes that take the current step
==========  =========================  ======================================================

:class:`Blocks` holds these for many blocks (a leading block axis); the drive tables stay per
environment, ``seg_d`` (N, R, N_DRIVE), and a lane reads the table of its row ``g[G_ROW]``.

**Precision.**  The block arrays above (all but ``f``, ``g``, ``act``) are float64, or
float32 (``Blocks(..., precision="float32")``, ``run_batch(..., precision="float32")``, the
environments' ``precision`` field).  The equations, the RK4 step and the elementary
functions are written once for both (constants through :func:`~abb_gym.physics.elementary.
like`; float64 is unchanged bit for bit), and a float32 block computes 8 lanes per AVX2
instruction instead of 4: the right-hand side of ``yoshida_odd`` costs 21 instead of 33 ns
per lane at 64 lanes (the extended effects' helpers - contact, fluid drag, friction - still
compute in float64 and return float32).  What float32 cannot hold is kept out of it:

* the schedule (times, step sizes, whirl accumulators in ``f``) stays float64, and the step
  functions get float32 times *into the current piece* (``_rk_clock``: the last work row);
  each piece's drive row is restated to start there (``_start_piece``: the prescribed angle
  and speed and the motor's target speed evaluated in float64 at the piece start);
* the rotor angle, which grows without bound, is held less whole turns: the block holds
  ``th - f[F_THOFF]`` in [0, 2 pi) when a lane is loaded (:func:`load_lane`) and within one
  turn after every step (``_keep_angles_small``, exact), and :func:`lane_value` adds the
  float64 offset back.  The rest of the state returns to float64 at every output or control
  interval.

float32 runs RK4 only (ETDRK4's coefficients and drag rates are written for float64), and
pays only where many lanes run together: on one lane it is slower than float64 (a scalar
float32 right-hand side costs what a float64 one does, plus the conversions), so the single
environment refuses it.

Compiled-cache hygiene (numba does not notice edits of called functions in other files) is
handled once for the whole package by :mod:`abb_gym._jit_cache` on import.
"""
from __future__ import annotations

import math

import numpy as np
from numba import get_num_threads, set_num_threads
from numba.extending import overload

from .._numba import njit, prange
from .._threads import free_cpus
from . import drive_law as dl
from . import elementary as el
from . import integrators as integ
from . import model as mdl
from . import sensors
from .methods import PRECISIONS
from .simulate import initial_state
from .steps import default_step
from .specialise import Specialised, resolve_kernel

__all__ = ["advance_block", "run_batch", "run_inputs", "Blocks", "lanes_per_block",
           "lane_order", "thread_parts", "parallel_threads", "ParallelCall"]

# f rows: interval, step size limit, piece, step, failure time; then the whirl accumulators.
# The accumulators (W_INT .. W_DMAX) and the synchronous demodulator (W_SYNC .. W_GAIN) are the
# environments' measurement hook inside the integrator: what the reward's vibration and
# residual terms and the 1x sensor integrate at every integrator step (a sample per control
# interval would alias the whirl), set and read by the envs' compiled step (abb_gym.envs.kernel)
# into the observation and the reward; the equations of motion never read them.
(F_T0, F_T1, F_HMAX, F_TP, F_PE, F_H, F_TC, F_TT, F_TFAIL, W_INT, W_MAX, W_XS, W_YS,
 W_DMAX) = range(14)
# the synchronous demodulator (:mod:`abb_gym.physics.sensors`), run when W_SYNC != 0: its
# low-pass time constant [s], the reference mark's offset th_mark [rad], the filter state
# (in and out) [m], the filter gain of the current piece's step
(W_SYNC, W_LAG, W_MARK, W_ZX, W_ZY, W_GAIN) = range(14, 20)
# a float32 block's rotor angle offset [rad] (below: "Precision"); the finiteness check of a
# step (0 when every state entry of the lane is finite, NaN otherwise)
F_THOFF = 20
F_CHK = 21
N_F = 22
# g rows: taking part, still running, segment, segment count, steps left in the piece, step
# index in the piece, status, first non-finite state entry, steps taken, environment row
(G_ON, G_RUN, G_J, G_NSEG, G_LEFT, G_IX, G_STATUS, G_BAD, G_STEPS, G_ROW) = range(10)
N_G = 10
#: lanes per block at most.  A right-hand side call has a fixed cost (the vector loop's set-up
#: and its constants), which a block of 128 lanes spreads over twice the lanes of one of 64:
#: per lane 21 against 27 ns in float64, 10 against 15 ns in float32 on ``yoshida_odd``
#: (``python -m abb_gym.benchmarks.rhs_cost``).  In the vector environment at 1024
#: sub-environments 256 lanes per block gained nothing over 128, and lost with the varied
#: preset, whose lanes take steps of different sizes (``python -m
#: abb_gym.benchmarks.block_size`` measures block sizes side by side).
#: A row's arithmetic does not depend on its block's size (``tests/test_envs_batch.py``).
MAX_LANES = 128
TWO_PI = 2.0 * math.pi


def precision_dtype(precision: str) -> np.dtype:
    """The numpy dtype of a block precision ("float64" or "float32"; module docstring)."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    return np.dtype(precision)


def work_rows(n_balls: int, dtype) -> int:
    """Leading size of a block's work array: the balls' rows, plus in float32 one row whose
    first three columns hold the step functions' float32 times (``_rk_clock``)."""
    return n_balls + (1 if np.dtype(dtype) == np.float32 else 0)


def lanes_per_block(n_envs: int, cores: int = 1) -> int:
    """Lanes per block for ``n_envs`` environments: a power of two up to :data:`MAX_LANES`,
    small enough that there are at least ``cores`` blocks (1 for a single environment).

    The default is one block of as many lanes as fit, so that only batches of more than
    :data:`MAX_LANES` environments run blocks in parallel.  Split in two blocks of half the
    lanes for a second thread, a small batch gained 1.0-1.2x on a quiet machine and lost
    3-4x beside one busy process (the parallel region waits for its second thread), while a
    wide block is cheaper per lane (the right-hand side's fixed cost, :data:`MAX_LANES`);
    ``abb-gym bench speed`` measures the batch sizes with the default threads and one."""
    lanes = 1
    while lanes * 2 <= MAX_LANES and lanes * 2 * cores <= n_envs:
        lanes *= 2
    return lanes


#: free CPUs beyond the first (:func:`abb_gym._threads.free_cpus`) that a parallel loop needs
#: for each further thread: a second thread only when another process leaves at least 0.8 of
#: a second CPU idle.
THREAD_FREE = 0.8


def parallel_threads(n_blocks: int) -> int:
    """Threads for a parallel loop over ``n_blocks`` blocks: one per block, at most the
    caller's numba thread count (numba's default, or :func:`abb_gym._threads.share_cores`),
    and one more than the CPUs beyond the first that other processes leave free
    (:data:`THREAD_FREE`).  The thread count never changes a result: every lane's arithmetic
    is its own (``tests/test_threads.py``)."""
    limit = get_num_threads()
    if n_blocks < 2 or limit < 2:
        return 1
    free = free_cpus()
    return max(1, min(n_blocks, limit, 1 + int((free - 1.0) / THREAD_FREE + 1e-9)))


class ParallelCall:
    """``fn(*args)`` (a compiled function with a parallel loop over ``n_blocks`` blocks) on
    :func:`parallel_threads` threads, the caller's thread count restored afterwards; the
    environments' step and :func:`run_batch` call their kernels so.  About 2 us a call."""

    def __init__(self, fn, n_blocks: int):
        self.fn = fn
        self.n_blocks = int(n_blocks)

    def __call__(self, *args):
        threads = parallel_threads(self.n_blocks)
        before = get_num_threads()
        if threads == before:
            return self.fn(*args)
        set_num_threads(threads)
        try:
            return self.fn(*args)
        finally:
            set_num_threads(before)


def lane_order(step_sizes: np.ndarray, lanes: int = 1, parts: int = 1) -> np.ndarray:
    """Rows in the order of their step size (stable), so that environments that take as many
    steps per interval share blocks and no block waits for one slow lane.

    ``parts`` > 1 (the threads of the parallel loop over blocks, :func:`thread_parts`; at most
    one run per block): the blocks of ``lanes`` rows are cut into that many contiguous runs, as
    numba's parallel loop hands them to its threads, and each run sorts its own contiguous range
    of rows.  Sorted as a whole, the first thread got the blocks of the smallest steps, i.e. the
    most substeps: at 1024 sub-environments of ``yoshida_odd`` 37 block-substeps per control
    step against the second thread's 30; sorted per run, 34 and 34 (the vector environment's
    compiled step 3 % faster, median of 14 alternating rounds in one process).  The order
    changes which lanes share a block, never a lane's arithmetic: the results are the same
    bits."""
    step_sizes = np.asarray(step_sizes)
    n = step_sizes.shape[0]
    n_blocks = -(-n // max(int(lanes), 1))
    parts = max(1, min(int(parts), n_blocks))
    edges = [min(k * n_blocks // parts * lanes, n) for k in range(parts)] + [n]
    order = [lo + np.argsort(step_sizes[lo:hi], kind="stable")
             for lo, hi in zip(edges[:-1], edges[1:])]
    return np.concatenate(order).astype(np.int64)


def thread_parts() -> int:
    """The threads of a parallel loop over blocks (numba's current thread count): the
    ``parts`` of :func:`lane_order`, which caps them at one per block."""
    return get_num_threads()


# Bytes between the block arrays' start addresses, modulo 4096 (:func:`staggered_zeros`).
STAGGER = 576


def staggered_zeros(shape: tuple, dtype, slot: int) -> np.ndarray:
    """``np.zeros(shape, dtype)`` (C-contiguous) starting ``slot * STAGGER`` bytes, modulo
    4096, past a 4096-byte boundary: a view into a slightly larger buffer.

    Why: a block's rows are whole kilobytes (128 float64 lanes), and large numpy arrays
    start at the same address modulo 4096, so the same lane of every array shared its low
    twelve address bits.  The processor takes a load whose address matches an earlier
    store's in those bits for a dependence until it has compared the whole addresses (4K
    aliasing), and the right-hand side stores its derivatives while it loads state and
    parameters.  Its cost per lane on a block of the vector environment: 25.0 ns in the
    environment's own arrays, 24.1 ns with every array at one address modulo 4096, 20.9 ns
    with the arrays 576 bytes apart (a scratch measurement with ``rhs_cost``'s compiled
    loop on a block's state after 60 steps).  A copy (pickling) is an ordinary array: the
    same results, without the stagger."""
    dtype = np.dtype(dtype)
    n = int(np.prod(shape))
    page = 4096 // dtype.itemsize
    buf = np.zeros(n + 2 * page, dtype)
    offset = (-buf.ctypes.data) % 4096 + (slot * STAGGER) % 4096
    start = offset // dtype.itemsize
    return buf[start:start + n].reshape(shape)


class Blocks:
    """Preallocated block arrays (module docstring) for ``n_envs`` environments of
    ``n_balls`` balls, ``lanes`` per block (default :func:`lanes_per_block`); ``int_rows``
    (>= ``N_G``) rows of ``g``, the ones past ``N_G`` free for the caller."""

    def __init__(self, n_envs: int, n_balls: int, lanes: int | None = None, int_rows: int = 0,
                 precision: str = "float64"):
        lanes = lanes_per_block(n_envs) if lanes is None else int(lanes)
        nblk = -(-n_envs // lanes)
        ns = 2 * (3 + n_balls)
        dtype = precision_dtype(precision)
        self.lanes = lanes
        slots = iter(range(12))  # each array in its own place modulo 4096 (staggered_zeros)

        def zeros(shape, dt=dtype):
            return staggered_zeros(shape, dt, next(slots))

        self.s = zeros((nblk, ns, lanes))
        self.p = zeros((nblk, mdl.N_PARAMS, lanes))
        self.b = zeros((nblk, n_balls, mdl.N_BALL_PARAMS, lanes))
        self.d = zeros((nblk, dl.N_DRIVE, lanes))
        self.k = zeros((nblk, 7, ns, lanes))
        self.tmp = zeros((nblk, ns, lanes))
        self.lam = zeros((nblk, ns, lanes))
        self.coef = zeros((nblk, 6, ns, lanes))
        self.work = zeros((nblk, work_rows(n_balls, dtype), mdl.WORK_COLUMNS, lanes))
        self.f = zeros((nblk, N_F, lanes), np.float64)
        self.g = zeros((nblk, max(N_G, int_rows), lanes), np.int64)
        self.act = zeros((nblk, lanes), np.uint8)

    def arrays(self) -> tuple:
        """``(s, p, b, d, k, tmp, lam, coef, work, f, g, act)``, each with the block axis first."""
        return (self.s, self.p, self.b, self.d, self.k, self.tmp, self.lam, self.coef,
                self.work, self.f, self.g, self.act)


@njit(cache=True, inline="always")
def _hold_angle(th, s, f, lane):
    """Hold the float64 rotor angle ``th`` [rad] in a float32 block's lane as whole turns in
    ``f[F_THOFF]`` plus the rest, in [0, 2 pi), in ``s`` (module docstring, "Precision")."""
    off = TWO_PI * np.floor(th * (1.0 / TWO_PI))
    f[F_THOFF, lane] = off
    s[2, lane] = th - off


@njit(cache=True, inline="always")
def rebase_angle(s, f, lane):
    """Move whole turns of a float32 block's rotor angle into its offset ``f[F_THOFF]``, so
    that the float32 angle stays in [0, 2 pi) at the start of an interval (module docstring,
    "Precision"); nothing in a float64 block."""
    if el.is_single(s):
        _hold_angle(s[2, lane] + f[F_THOFF, lane], s, f, lane)


@njit(cache=True, inline="always")
def load_lane(s_rows, p_rows, b_rows, row, s, p, b, f, lane):
    """Copy environment ``row``'s state and parameters (row-major float64 arrays) into
    ``lane`` of a block (lane-last arrays, float64 or float32; a float32 block takes whole
    turns of the rotor angle into ``f[F_THOFF]``).  The environments' step copies a row in
    only when its lane does not hold it already (:func:`abb_gym.envs.kernel._block_step`):
    67 entries of a two-ball lane, each written to its own cache line."""
    for c in range(s.shape[0]):
        s[c, lane] = s_rows[row, c]
    for c in range(p.shape[0]):
        p[c, lane] = p_rows[row, c]
    for i in range(b.shape[0]):
        for c in range(b.shape[1]):
            b[i, c, lane] = b_rows[row, i, c]
    if el.is_single(s):
        _hold_angle(s_rows[row, 2], s, f, lane)


@njit(cache=True, inline="always")
def lane_value(s, f, lane, c):
    """State entry ``c`` of ``lane`` of a block as a float64 (the rotor angle with its offset
    back on, in a float32 block).  The callers copy a lane out entry by entry: with a row
    view of the destination made per lane and interval (``out[e, k]``) ``run_batch`` measured
    5-8 % slower (alternating processes against the commit before)."""
    if el.is_single(s) and c == 2:
        return s[2, lane] + f[F_THOFF, lane]
    return s[c, lane]


@njit(cache=True, inline="always")
def _keep_angles_small(s, f, act, L):
    """Keep the integrated float32 rotor angle of each lane with ``act`` set within one turn
    of [0, 2 pi) after each step (its rounding grows with its size): a whole turn ``c`` (2 pi
    in float32) moves into the offset.  ``th - c`` is exact for th in [c, 2c] (Sterbenz),
    which a step that turns the rotor less than a turn keeps it in, so the angle's float64
    value ``th + offset`` does not change."""
    c = el.like(s, TWO_PI)
    for l in range(L):
        th = s[2, l]
        off = f[F_THOFF, l]
        up = act[l] != 0 and th >= c
        down = act[l] != 0 and th <= -c
        s[2, l] = th - c if up else (th + c if down else th)
        f[F_THOFF, l] = off + c if up else (off - c if down else off)


def _rk_clock(f, work, nb):
    raise TypeError("compiled code only")


@overload(_rk_clock, inline="always")
def _pick_clock(f, work, nb):
    if work.dtype.bitwidth == 32:
        def impl(f, work, nb):
            return work[nb, 0], work[nb, 1], work[nb, 2]
    else:
        def impl(f, work, nb):
            return f[F_TC], f[F_H], f[F_TT]
    return impl


@njit(cache=True, inline="always")
def _start_piece(d, lane, table, j, t, off):
    """Lane ``lane``'s drive row ``d[:, lane]`` for a piece that starts at ``t`` [s] from
    row ``j`` of the drive table: the row itself in float64; in float32 the row restated to
    start at ``t`` (prescribed angle (less the block's offset ``off``), speed and target speed
    at ``t`` in float64, time 0), so that the float32 drive law only sees the time into the
    piece."""
    for c in range(dl.N_DRIVE):
        d[c, lane] = table[j, c]
    if el.is_single(d):
        tau = t - table[j, dl.D_T0]
        th, w, _ = dl.prescribed_law(tau, table[j, dl.D_TH0], table[j, dl.D_W0],
                                     table[j, dl.D_ALPHA])
        d[dl.D_T0, lane] = 0.0
        d[dl.D_TH0, lane] = th - off
        d[dl.D_W0, lane] = w
        d[dl.D_TW0, lane] = table[j, dl.D_TW0] + table[j, dl.D_TALPHA] * tau


@njit(cache=True)
def _first_nonfinite_lane(s, lane):
    for j in range(s.shape[0]):
        if not math.isfinite(s[j, lane]):
            return j
    return -1


@njit(cache=True, inline="always")
def _book_step(s, f, g, act, h, tc, L):
    """After a step of the lanes with ``act`` set: count it, stop the lanes whose state is no
    longer finite (status, first bad entry, failure time; ``act`` cleared), keep a float32
    rotor angle small, and add the step to the whirl accumulators.  Lane loops without early
    exits, so that they vectorise; only a lane that failed takes the scalar search.  ``L``:
    the lane count (:func:`abb_gym.physics.model.lanes_of`)."""
    for l in range(L):
        a = act[l]
        g[G_STEPS, l] += a
        g[G_IX, l] += a
        g[G_LEFT, l] -= a
        f[F_CHK, l] = 0.0
    for j in range(s.shape[0]):
        for l in range(L):
            f[F_CHK, l] += s[j, l] - s[j, l]  # NaN from an infinite or NaN entry
    for l in range(L):
        if act[l] != 0 and not f[F_CHK, l] == 0.0:
            g[G_STATUS, l] = integ.STATUS_NONFINITE
            g[G_BAD, l] = _first_nonfinite_lane(s, l)
            g[G_RUN, l] = 0
            f[F_TFAIL, l] = tc[l] + h[l]
            act[l] = 0
    if el.is_single(s):
        _keep_angles_small(s, f, act, L)
    for l in range(L):
        on = act[l] != 0
        x = s[0, l]
        y = s[1, l]
        dx = x - f[W_XS, l]
        dy = y - f[W_YS, l]
        rd = math.sqrt(dx * dx + dy * dy)
        r = math.sqrt(x * x + y * y)
        w_int = f[W_INT, l]
        w_dmax = f[W_DMAX, l]
        w_max = f[W_MAX, l]
        f[W_INT, l] = w_int + rd * h[l] if on else w_int
        f[W_DMAX, l] = rd if on and rd > w_dmax else w_dmax
        f[W_MAX, l] = r if on and r > w_max else w_max


@njit(cache=True, error_model="numpy", refcounts=False)
def advance_block(s, p, b, d, k, tmp, lam, coef, work, f, g, act, seg_d, method, nb, spec):
    """Advance every lane ``l`` of one block with ``g[G_ON, l]`` set from ``f[F_T0, l]`` to
    ``f[F_T1, l]`` with steps of at most ``f[F_HMAX, l]``, by ``method``
    (``integrators.METHOD_RK4`` or ``METHOD_ETDRK4``), in place.

    Inputs per lane besides the block arrays: ``g[G_ROW]`` (its drive table
    ``seg_d[g[G_ROW]]``), ``g[G_NSEG]`` (valid rows of that table), ``g[G_J]`` (current row,
    updated), ``f[W_XS]``, ``f[W_YS]`` (the rest position of the whirl).  Outputs:
    ``g[G_STATUS]`` (0, or ``integrators.STATUS_NONFINITE``: the lane then holds the non-finite
    state, at time ``f[F_TFAIL]``, first bad entry ``g[G_BAD]``), ``g[G_STEPS]``, and over the
    substeps (right-endpoint rule) ``f[W_INT]`` the time integral of the deflection from the
    rest position, ``f[W_DMAX]`` its maximum, ``f[W_MAX]`` the largest whirl radius
    ``sqrt(x^2 + y^2)`` from the bearing axis.  Compiled without reference counts
    (:mod:`abb_gym._numba`).
    """
    L = mdl.lanes_of(s, spec)
    nq = 3 + nb
    single = el.is_single(s)
    wb = work[:nb]
    # the step functions' times: f's rows, or float32 times into the piece (_rk_clock)
    rt, rh, rtt = _rk_clock(f, work, nb)
    for l in range(L):
        g[G_RUN, l] = g[G_ON, l]
        g[G_LEFT, l] = 0
        g[G_IX, l] = -1
        g[G_STEPS, l] = 0
        g[G_STATUS, l] = integ.STATUS_OK
        g[G_BAD, l] = -1
        f[F_TP, l] = f[F_T0, l]
        f[F_TFAIL, l] = f[F_T1, l]
        f[W_INT, l] = 0.0
        f[W_MAX, l] = 0.0
        f[W_DMAX, l] = 0.0
    h = f[F_H]
    tc = f[F_TC]
    tt = f[F_TT]
    sync = False
    for l in range(L):
        if g[G_ON, l] != 0 and f[W_SYNC, l] != 0.0:
            sync = True
    while True:
        # lanes at a piece's end or start (a few substeps in a control interval): scalar
        for l in range(L):
            if g[G_RUN, l] == 0 or g[G_LEFT, l] != 0:
                continue
            # (the table view only here, at a piece's start: a view per lane and substep
            # cost two atomic reference counts, on a count both threads share)
            table = seg_d[g[G_ROW, l]]
            if g[G_IX, l] >= 0:
                # a piece is done: its end is the next piece's start
                f[F_TP, l] = f[F_PE, l]
                dl.pin_prescribed(f[F_TP, l], s, l, table[g[G_J, l]], nq, f[F_THOFF, l])
            t = f[F_TP, l]
            if t >= f[F_T1, l]:
                g[G_RUN, l] = 0
                continue
            nseg = g[G_NSEG, l]
            j = integ.enter_segment(t, s, l, table, nseg, g[G_J, l], nq, f[F_THOFF, l])
            piece_end, m, hh = integ.next_piece(t, f[F_T1, l], table, nseg, j, f[F_HMAX, l])
            g[G_J, l] = j
            g[G_LEFT, l] = m
            g[G_IX, l] = 0
            f[F_PE, l] = piece_end
            h[l] = hh
            if f[W_SYNC, l] != 0.0:
                f[W_GAIN, l] = sensors.filter_gain(hh, f[W_LAG, l])
            _start_piece(d, l, table, j, t, f[F_THOFF, l])
        # every lane's step: a loop without branches, which vectorises
        running = 0
        for l in range(L):
            on = g[G_RUN, l] != 0
            tc[l] = f[F_TP, l] + g[G_IX, l] * h[l]
            if single:
                rt[l] = g[G_IX, l] * h[l]
                rh[l] = h[l]
            act[l] = 1 if on else 0
            running += act[l]
        if running == 0:
            break
        if method == integ.METHOD_ETDRK4:
            integ._etdrk4_step(rt, rh, s, p, b, d, k, tmp, rtt, wb, lam, coef, act, nb, spec)
        else:
            integ._rk4_step(rt, rh, s, p, b, d, k, tmp, rtt, wb, act, nb, spec)
        _book_step(s, f, g, act, h, tc, L)
        if sync:
            # a loop of its own, free of early exits, so that it vectorises across the lanes
            for l in range(L):
                if act[l] != 0 and g[G_STATUS, l] == integ.STATUS_OK and f[W_SYNC, l] != 0.0:
                    ux, uy = sensors.demodulate(s[0, l] - f[W_XS, l], s[1, l] - f[W_YS, l],
                                                lane_value(s, f, l, 2) - f[W_MARK, l])
                    a = f[W_GAIN, l]
                    f[W_ZX, l] += a * (ux - f[W_ZX, l])
                    f[W_ZY, l] += a * (uy - f[W_ZY, l])


@njit(cache=True, parallel=True, error_model="numpy")
def _run_batch(s0, t_out, seg_d, nseg, p, b, dt_max, out, status, order, lanes, method, nb,
               spec, precision):
    n_env = order.shape[0]
    ns = s0.shape[1]
    nq = ns // 2
    nblk = (n_env + lanes - 1) // lanes
    dtype = precision.dtype  # the blocks' precision (an empty array of it)
    rows = nb + 1 if el.is_single(precision) else nb  # work_rows
    for q in prange(nblk):
        s = np.zeros((ns, lanes), dtype)
        pb = np.zeros((p.shape[1], lanes), dtype)
        bb = np.zeros((nb, b.shape[2], lanes), dtype)
        d = np.zeros((dl.N_DRIVE, lanes), dtype)
        k = np.zeros((7, ns, lanes), dtype)
        tmp = np.zeros((ns, lanes), dtype)
        lam = np.zeros((ns, lanes), dtype)
        coef = np.zeros((6, ns, lanes), dtype)
        work = np.zeros((rows, mdl.WORK_COLUMNS, lanes), dtype)
        f = np.zeros((N_F, lanes))
        g = np.zeros((N_G, lanes), dtype=np.int64)
        act = np.zeros(lanes, dtype=np.uint8)
        for l in range(lanes):
            r = q * lanes + l
            if r >= n_env:
                continue
            e = order[r]
            g[G_ON, l] = 1
            g[G_ROW, l] = e
            g[G_NSEG, l] = nseg[e]
            f[F_HMAX, l] = dt_max[e]
            load_lane(s0, p, b, e, s, pb, bb, f, l)
            j = 0
            while j + 1 < nseg[e] and seg_d[e, j + 1, dl.D_T0] <= t_out[0]:
                j += 1
            g[G_J, l] = j
            dl.pin_prescribed(t_out[0], s, l, seg_d[e, j], nq, f[F_THOFF, l])
            rebase_angle(s, f, l)
            for c in range(ns):
                out[e, 0, c] = lane_value(s, f, l, c)
            status[e, 0] = integ.STATUS_OK
            status[e, 1] = t_out[-1]
            status[e, 2] = -1
            status[e, 3] = 0
        for kk in range(t_out.shape[0] - 1):
            for l in range(lanes):
                f[F_T0, l] = t_out[kk]
                f[F_T1, l] = t_out[kk + 1]
            advance_block(s, pb, bb, d, k, tmp, lam, coef, work, f, g, act, seg_d, method, nb,
                          spec)
            for l in range(lanes):
                if g[G_ON, l] == 0:
                    continue
                e = g[G_ROW, l]
                status[e, 3] += g[G_STEPS, l]
                if g[G_STATUS, l] != integ.STATUS_OK:
                    status[e, 0] = g[G_STATUS, l]
                    status[e, 1] = f[F_TFAIL, l]
                    status[e, 2] = g[G_BAD, l]
                    g[G_ON, l] = 0
                    continue
                for c in range(ns):
                    out[e, kk + 1, c] = lane_value(s, f, l, c)
                rebase_angle(s, f, l)


_run_batch_specialised = Specialised(_run_batch, literal=(11, 12, 13),
                                     names=("method", "balls", mdl.EFFECTS))


def run_inputs(scenes, drive, t_end: float, max_speed: float) -> tuple:
    """The per-run inputs of :func:`run_batch` for one run per scene in ``scenes`` under the
    one ``drive`` up to ``t_end`` [s]: ``(s0, seg_d, nseg, p, b, dt_max)``, each run from its
    scene's initial state with the default RK4 step for ``max_speed`` [rad/s]."""
    scenes = list(scenes)
    _, rows = drive.segment_table(t_end, scenes[0])
    n = len(scenes)
    s0 = np.stack([initial_state(sc, drive) for sc in scenes])
    packed = [mdl.pack_parameters(sc) for sc in scenes]
    p = np.stack([pk[0] for pk in packed])
    b = np.stack([pk[1] for pk in packed])
    dt_max = np.array([default_step(sc, max_speed) for sc in scenes])
    return s0, np.repeat(rows[None], n, axis=0), np.full(n, len(rows)), p, b, dt_max


def run_batch(s0, t_out, seg_d, nseg, p, b, dt_max, out, status, method=integ.METHOD_RK4,
              order=None, lanes=None, kernel=None, precision="float64"):
    """:func:`integrators.run` (RK4 or ETDRK4) for ``N`` environments, in parallel blocks.

    ``s0`` (N, ns) initial states, ``t_out`` (T,) shared output times, ``seg_d`` (N, R,
    N_DRIVE) / ``nseg`` (N,) the drive tables (every table of the same mode), ``p``/``b`` the
    parameters, ``dt_max`` (N,) the step limits [s]; ``out`` (N, T, ns) receives the states
    and ``status`` (N, 4) float (status, failure time, failing index, steps) per environment,
    as ``integrators.run`` returns them.  ``order`` (default :func:`lane_order` of ``dt_max``)
    assigns environments to lanes; ``lanes`` per block defaults to :func:`lanes_per_block`.
    Environments are run in two groups, prescribed rotor and motor drive; ``kernel``
    (:func:`~abb_gym.physics.specialise.resolve_kernel`: "auto", "generic" or "specialised")
    says whether a group runs the general kernel or one specialised on the union of its
    environments' effects (an effect a lane does not have contributes exactly zero there).
    Both give the same result bit for bit.  ``precision`` "float32" runs the blocks in
    float32 (RK4 only; module docstring, "Precision"): faster on many lanes, less accurate.
    """
    dtype = precision_dtype(precision)
    if dtype == np.float32 and int(method) != integ.METHOD_RK4:
        raise ValueError("precision='float32' runs RK4 only (method=METHOD_RK4), "
                         f"got method={int(method)}")
    n_env = s0.shape[0]
    nb = b.shape[1]
    dt_max = np.broadcast_to(np.asarray(dt_max, float), (n_env,)).copy()
    lanes = lanes_per_block(n_env) if lanes is None else int(lanes)
    if order is None:
        order = lane_order(dt_max, lanes, thread_parts())
    order = np.asarray(order, np.int64)
    nseg = np.asarray(nseg, np.int64)
    seg_d = np.ascontiguousarray(seg_d, float)
    args = (np.ascontiguousarray(s0, float), np.asarray(t_out, float), seg_d, nseg,
            np.ascontiguousarray(p, float), np.ascontiguousarray(b, float), dt_max, out, status)
    # the rotor spin is prescribed or a degree of freedom: one compiled kernel per mode
    motor = seg_d[:, 0, dl.D_MODE] == dl.MODE_MOTOR
    for group in (order[~motor[order]], order[motor[order]]):
        if group.size == 0:
            continue
        group_lanes = min(lanes, lanes_per_block(group.size))
        # the union of the group's effects over the valid rows of each drive table, in one
        # call (spec_of per environment cost 47 us each: 4 times the kernel at 1024 runs)
        valid = np.arange(seg_d.shape[1]) < np.maximum(nseg[group], 1)[:, None]
        spec = mdl.spec_of(p[group], seg_d[group][valid])
        call = (_run_batch_specialised if resolve_kernel(kernel, group_lanes) == "specialised"
                else _run_batch_specialised.generic)
        ParallelCall(call, -(-group.size // group_lanes))(
            *args, group, group_lanes, int(method), nb, spec, np.empty(0, dtype))
