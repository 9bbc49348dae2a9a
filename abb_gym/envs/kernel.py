"""The compiled environment step, shared by the single and the vector environments.

Every environment (single or vector, any action type) keeps its state in preallocated arrays
with one row per environment (layouts: :mod:`abb_gym.envs.layout`) and advances them with
**one** compiled call per step, :func:`step`.  The environments are taken in blocks of lanes
(:class:`abb_gym.physics.batch.Blocks`; one lane for a single environment, up to 128 for a
vector environment, blocks in parallel with ``numba.prange``).  For each block:

1. each lane's row turns its action into a drive row (:mod:`abb_gym.envs.actions`) or keeps
   the rows the Python side wrote (a whole-episode action) (:func:`_begin`);
2. the lanes advance one control interval together (or, for a whole-episode action, every
   interval until the episode ends) with :func:`abb_gym.physics.batch.advance_block` - the
   integrators of :func:`abb_gym.physics.integrators.run` over
   :func:`abb_gym.physics.model.accelerations_block` - and each interval's reward terms and
   run-up metrics are booked per row (:func:`_interval_begin`, :func:`_interval_end`);
3. each row sums its reward and writes its flags (:func:`_finish`) and its observation
   (:func:`_observe`; also for a row whose episode had ended, which only observes).

The per-row functions are inlined into the block step (``inline="always"``): called, each
would take ten arrays, nine or more machine words apiece, per lane and step.

A row gets the same arithmetic whichever block and lane it lands in, so a sub-environment of
the vector environment and a single environment agree bit for bit.

The reward and observation definitions are documented in :mod:`abb_gym.envs.base`.
"""
from __future__ import annotations

import math

from .._numba import njit, prange, types
from numba.experimental import structref  # noqa: E402  (after .._numba: the cache set-up)

from ..physics.specialise import Specialised

from ..physics import batch, laundry, model, rotor, runup, sensors
from ..physics import drive_law as dl
from . import actions
from .layout import *  # noqa: F401,F403  (the column names are the kernel's vocabulary)


@njit(cache=True)
def _balance(i, s, p, b, st, cfg, out):
    """Residual imbalance / scale and the balanced flag of row ``i`` (:mod:`..physics.rotor`)."""
    nb = b.shape[1]
    res = rotor.residual_imbalance_packed(p[i], b[i], s[i, 3:3 + nb])
    out[i, O_IMB] = res / st[i, S_USCALE]
    out[i, O_BAL] = 1.0 if rotor.is_balanced(res, st[i, S_UBEST], cfg[C_BAL_TOL],
                                              st[i, S_USCALE]) else 0.0


@njit(cache=True)
def _clip(v, lo, hi):
    if v < lo:
        return lo
    if v > hi:
        return hi
    return v


@njit(cache=True, inline="always")
def _observe(i, s, p, b, st, cfg, obs, out, trace, balance):
    """Write the observation row ``obs[i]``, the whirl radius outputs, the trace, and with
    ``balance`` the balance outputs (for an info that shows them: EnvSetup.set_info_level)."""
    nq = s.shape[1] // 2
    nb = nq - 3
    x = s[i, 0]
    y = s[i, 1]
    dx = x - st[i, S_XS]
    dy = y - st[i, S_YS]
    w = s[i, nq + 2]
    vs = cfg[C_VSCALE]
    vh = cfg[C_VIB_HI]
    # each entry at its offset in the row (abb_gym.envs.observation), -1: left out
    obs[i, int(cfg[C_OBS + OBS_SPEED])] = _clip(w / cfg[C_WOP], cfg[C_SPEED_LO],
                                                cfg[C_SPEED_HI])
    obs[i, int(cfg[C_OBS + OBS_VIB_X])] = _clip(dx / vs, -vh, vh)
    obs[i, int(cfg[C_OBS + OBS_VIB_Y])] = _clip(dy / vs, -vh, vh)
    obs[i, int(cfg[C_OBS + OBS_VIB_AMP])] = _clip(st[i, S_FILT] / vs, 0.0, vh)
    c = int(cfg[C_OBS + OBS_TIME])
    if c >= 0:
        obs[i, c] = _clip(st[i, S_K] / cfg[C_NMAX], 0.0, 1.0)
    c = int(cfg[C_OBS + OBS_ACTION])
    for a in range(int(cfg[C_NACT])):
        obs[i, c + a] = st[i, S_ACT + a]
    c = int(cfg[C_OBS + OBS_SYNC])
    if c >= 0:
        # the synchronous vibration (abb_gym.physics.sensors): the tracking filter's output
        # plus the read-out noise of this control step
        zx = st[i, S_ZX]
        zy = st[i, S_ZY]
        if cfg[C_SYNC_NOISE] > 0.0:
            n1, n2 = sensors.gaussian_pair(st[i, S_NKEY], st[i, S_K])
            zx += cfg[C_SYNC_NOISE] * n1
            zy += cfg[C_SYNC_NOISE] * n2
        amp = math.sqrt(zx * zx + zy * zy)
        obs[i, c] = _clip(amp / vs, 0.0, vh)
        obs[i, c + 1] = zx / amp if amp > 0.0 else 0.0
        obs[i, c + 2] = zy / amp if amp > 0.0 else 0.0
    c = int(cfg[C_OBS + OBS_REDIST])
    if c >= 0:
        top = cfg[C_REDIST_MAX]
        obs[i, c] = st[i, S_NREDIST] / top if top > 0.0 else 0.0
    c = int(cfg[C_OBS + OBS_BALLS])
    if c >= 0:
        for k in range(nb):
            ph = s[i, 3 + k]
            obs[i, c + 2 * k] = math.cos(ph)
            obs[i, c + 1 + 2 * k] = math.sin(ph)
    out[i, O_R] = math.sqrt(x * x + y * y)
    out[i, O_RDYN] = math.sqrt(dx * dx + dy * dy)
    if balance:
        _balance(i, s, p, b, st, cfg, out)
    if i < trace.shape[0]:
        k = int(st[i, S_K])
        if k < trace.shape[1]:
            row = trace[i, k]
            row[T_T] = k * cfg[C_DT]
            row[T_X] = x
            row[T_Y] = y
            row[T_W] = w
            # the interval's mean and largest vibration (at k = 0: the rest state's)
            row[T_VIB] = out[i, O_WINT] / cfg[C_DT] if k > 0 else out[i, O_RDYN]
            row[T_VIBMAX] = out[i, O_WDMAX] if k > 0 else out[i, O_RDYN]
            for kb in range(nb):
                row[T_BALLS + kb] = s[i, 3 + kb]


@njit(cache=True, inline="always")
def _interval_begin(i, st, cfg, f, g, lane):
    """Set lane ``lane``'s interval, step limit, drive table position and whirl rest position
    for row ``i``'s next control interval."""
    dt = cfg[C_DT]
    kk = st[i, S_K]
    f[batch.F_T0, lane] = kk * dt
    f[batch.F_T1, lane] = (kk + 1.0) * dt
    f[batch.F_HMAX, lane] = st[i, S_DTMAX]
    f[batch.W_XS, lane] = st[i, S_XS]
    f[batch.W_YS, lane] = st[i, S_YS]
    g[batch.G_NSEG, lane] = int(st[i, S_NSEG])
    g[batch.G_J, lane] = int(st[i, S_J])
    f[batch.W_SYNC, lane] = cfg[C_SYNC]
    if cfg[C_SYNC] != 0.0:
        f[batch.W_LAG, lane] = cfg[C_SYNC_LAG]
        f[batch.W_MARK, lane] = st[i, S_MARK]
        f[batch.W_ZX, lane] = st[i, S_ZX]
        f[batch.W_ZY, lane] = st[i, S_ZY]


@njit(cache=True)
def _tumble(i, s, p, b, st, cfg, g, lane, w):
    """Redistribution of the laundry (:mod:`abb_gym.envs.redistribution`): after an unbroken
    stay of the tumble time below the tumble speed the laundry lands anew
    (:func:`abb_gym.physics.laundry.redistribute`), with the next of the episode's drawn
    imbalances, while any are left.  The row's state and parameters change, so the lane that
    holds the row loads it again (``G_HELD``)."""
    dt = cfg[C_DT]
    if abs(w) < cfg[C_TUMBLE_SPEED]:
        st[i, S_TUMBLE] += dt
    else:
        st[i, S_TUMBLE] = 0.0
    done = st[i, S_NREDIST]
    if st[i, S_TUMBLE] >= cfg[C_TUMBLE_TIME] - 1e-9 * dt and done < cfg[C_REDIST_MAX]:
        k = S_REDIST + 2 * int(done)
        laundry.redistribute(s[i], p[i], b[i], st[i, k], st[i, k + 1], st[i, S_MARK])
        st[i, S_MARK] = st[i, k + 1]
        st[i, S_UBEST], st[i, S_USCALE] = rotor.best_residual_packed(p[i], b[i])
        st[i, S_NREDIST] = done + 1.0
        st[i, S_TUMBLE] = 0.0
        g[G_HELD, lane] = -1


@njit(cache=True, inline="always")
def _interval_end(i, s, p, b, d, st, cfg, out, f, g, lane):
    """Book row ``i``'s control interval just advanced in lane ``lane`` (its state already
    copied back to ``s[i]`` unless it failed, in which case ``s[i]`` still holds the state at
    the interval start): the run-up metrics (:mod:`abb_gym.physics.runup`: the operating band,
    the settled entry, the residual over the settling window), the reward terms, failure and
    success.  Returns True when the episode ended (terminated or truncated) in this interval.
    """
    nq = s.shape[1] // 2
    dt = cfg[C_DT]
    kk = st[i, S_K]
    t0 = kk * dt
    t1 = (kk + 1.0) * dt
    si = s[i]
    status = g[batch.G_STATUS, lane]
    st[i, S_J] = g[batch.G_J, lane]
    out[i, O_STEPS] += g[batch.G_STEPS, lane]
    out[i, O_WINT] = f[batch.W_INT, lane]
    out[i, O_WMAX] = f[batch.W_MAX, lane]
    out[i, O_WXS] = f[batch.W_XS, lane]
    out[i, O_WYS] = f[batch.W_YS, lane]
    out[i, O_WDMAX] = f[batch.W_DMAX, lane]
    if cfg[C_SYNC] != 0.0 and status == 0:
        # (a failed interval keeps the filter where the state is: at the interval start)
        st[i, S_ZX] = f[batch.W_ZX, lane]
        st[i, S_ZY] = f[batch.W_ZY, lane]
    st[i, S_K] = kk + 1.0
    acc = st[i, S_ACC:S_ACC + runup.N_ACC]
    wop = cfg[C_WOP]
    band = cfg[C_BAND]
    fail = FAIL_NONE
    if status != 0:
        fail = FAIL_NUMERICAL
        out[i, O_FTIME] = f[batch.F_TFAIL, lane]
        out[i, O_FINDEX] = g[batch.G_BAD, lane]
        dx = si[0] - st[i, S_XS]
        dy = si[1] - st[i, S_YS]
        r_mean = math.sqrt(dx * dx + dy * dy)
        r_max = math.sqrt(si[0] * si[0] + si[1] * si[1])
        at_speed = runup.in_band(si[nq + 2], wop, band)
    else:
        r_mean = out[i, O_WINT] / dt
        r_max = out[i, O_WMAX]
        at_speed = runup.update(acc, t0, t1, si[nq + 2], out[i, O_WINT], out[i, O_WDMAX], wop,
                                band, cfg[C_SETTLE])
    w = si[nq + 2]
    # control effort: time integral of (drive command / its limit)^2 over the interval
    nseg = int(st[i, S_NSEG])
    effort = 0.0
    for r in range(nseg):
        ts = d[i, r, dl.D_T0]
        te = d[i, r + 1, dl.D_T0] if r + 1 < nseg else math.inf
        ov = min(t1, te) - max(t0, ts)
        if ov > 0.0:
            if d[i, r, dl.D_MODE] == dl.MODE_PRESCRIBED:
                u = d[i, r, dl.D_ALPHA] / cfg[C_AMAX]
            else:
                u = d[i, r, dl.D_TORQUE] / cfg[C_TLIM]
            effort += u * u * ov
    tref = cfg[C_TREF]
    vib = -cfg[C_WV] * (r_mean / st[i, S_AREF]) * dt / tref
    tim = 0.0 if at_speed else -cfg[C_WT] * dt / tref
    eff = -cfg[C_WE] * effort / tref
    st[i, S_FILT] += cfg[C_FILT] * (r_mean - st[i, S_FILT])
    if r_max > st[i, S_PEAK]:
        st[i, S_PEAK] = r_max
    if fail == FAIL_NONE:
        if r_max > cfg[C_CLEAR]:
            fail = FAIL_CLEARANCE
        elif abs(w) > cfg[C_OVERSPEED] * wop:
            fail = FAIL_OVERSPEED
    resid = 0.0
    pen = 0.0
    term = False
    if fail != FAIL_NONE:
        term = True
        remaining = cfg[C_TEP] - t1
        if remaining < 0.0:
            remaining = 0.0
        pen = -(cfg[C_WF] + st[i, S_PEN_RATE] * remaining / tref + st[i, S_PEN_TERM])
        out[i, O_FCODE] = fail
        if fail != FAIL_NUMERICAL:
            out[i, O_FTIME] = t1
    elif acc[runup.R_SETTLED] != 0.0:
        term = True
        resid = -cfg[C_WR] * runup.residual(acc) / st[i, S_AOP]
    trunc = (not term) and st[i, S_K] >= cfg[C_NMAX]
    if trunc:
        # an episode that has not completed its settling window by the limit failed (the
        # metrics count it so): it pays the residual term at its bound (the whirl at the
        # clearance), whatever part of the window it spent in the band.  A partial window
        # would let a run-up that enters the band just before the limit measure its residual
        # over a moment and beat every finished run-up (CMA-ES found exactly that)
        resid = -st[i, S_PEN_TERM]
    if cfg[C_REDIST] != 0.0 and not (term or trunc):
        _tumble(i, s, p, b, st, cfg, g, lane, w)
    out[i, O_VIB] += vib
    out[i, O_TIME] += tim
    out[i, O_EFFORT] += eff
    out[i, O_RESID] += resid
    out[i, O_FAIL] += pen
    if term:
        out[i, O_TERM] = 1.0
    if trunc:
        out[i, O_TRUNC] = 1.0
    return term or trunc


# what _begin found for a row
ROW_IDLE = 0      # inactive, or a non-finite action: the row's outputs are complete
ROW_STEPS = 1     # the row integrates this step
ROW_FINISHED = 2  # its episode had ended: nothing moves, the row is only observed


@njit(cache=True, inline="always")
def _begin(i, act, s, d, st, cfg, out, active):
    """The start of row ``i``'s step: check and clip the action, write the interval's drive
    row.  Returns ``ROW_STEPS``, ``ROW_FINISHED`` or ``ROW_IDLE``."""
    for c in range(out.shape[1]):
        out[i, c] = 0.0
    if active[i] == 0:
        return ROW_IDLE
    if st[i, S_DONE] != 0.0:
        # stepping a finished episode: nothing moves, no reward (the caller warns)
        out[i, O_TERM] = st[i, S_TERM]
        out[i, O_TRUNC] = st[i, S_TRUNC]
        return ROW_FINISHED
    na = int(cfg[C_NACT])
    for a in range(na):
        if not math.isfinite(act[i, a]):
            out[i, O_ACTFLAG] = ACT_NONFINITE
            out[i, O_FINDEX] = a
            return ROW_IDLE
    flag = ACT_OK
    for a in range(na):
        v = act[i, a]
        if v > 1.0:
            v = 1.0
            flag = ACT_CLIPPED
        elif v < -1.0:
            v = -1.0
            flag = ACT_CLIPPED
        st[i, S_ACT + a] = v
    out[i, O_ACTFLAG] = flag
    kind = int(cfg[C_KIND])
    if not actions.rows_from_python(kind):
        nq = s.shape[1] // 2
        actions.write_interval_row(kind, d[i, 0], st[i, S_ACT], st[i, S_K] * cfg[C_DT],
                                   s[i, 2], s[i, nq + 2], cfg[C_DT], cfg[C_WOP], cfg[C_AMAX],
                                   cfg[C_TLIM])
        st[i, S_NSEG] = 1.0
        st[i, S_J] = 0.0
    # (otherwise the Python side wrote the rows from the action: a whole-episode action or an
    # action model of its own)
    return ROW_STEPS


@njit(cache=True, inline="always")
def _finish(i, done, st, cfg, out):
    """The end of row ``i``'s step: time limit, reward sum, episode flags.  Returns whether
    its observation measures the balance (the episode ended, or the info shows it always)."""
    kind = int(cfg[C_KIND])
    if cfg[C_BACKSTOP] > 0.0:
        # the rule of gymnasium's TimeLimit: truncated once elapsed steps >= the limit
        elapsed = 1.0 if actions.whole_episode(kind) else st[i, S_K]
        if elapsed >= cfg[C_BACKSTOP]:
            out[i, O_TRUNC] = 1.0
            done = True
    out[i, O_REWARD] = (out[i, O_VIB] + out[i, O_TIME] + out[i, O_EFFORT] + out[i, O_RESID]
                        + out[i, O_FAIL])
    if done:
        st[i, S_DONE] = 1.0
        st[i, S_TERM] = out[i, O_TERM]
        st[i, S_TRUNC] = out[i, O_TRUNC]
    return done or cfg[C_INFO_FULL] != 0.0


@njit(cache=True)
def _record_trace(i, s, p, b, st, cfg, obs, out, trace):
    """Row ``i``'s observation and trace between the intervals of a whole-episode action (the
    render trace).  A function of its own, so that the block step inlines the observation
    once."""
    _observe(i, s, p, b, st, cfg, obs, out, trace, False)


# rows of the block's integer array that the environment step uses (beyond batch.N_G)
G_STEPPING = batch.N_G      # what _begin found (ROW_*)
G_INTEGRATE = batch.N_G + 1  # the row takes part in the next interval
G_DONE = batch.N_G + 2      # the row's episode ended in this step
# the row whose state and parameters the lane holds, as its last step left them (-1: none;
# Buffers sets it).  Only a reset writes a row's parameters and state from outside the step
# (episodes.commit), so a lane that held row i loads it again only for another row, at the
# first step of an episode (st[i, S_K] == 0) or after a failed interval (G_HELD = -1)
G_HELD = batch.N_G + 3
N_G_ENV = batch.N_G + 4


@njit(cache=True, error_model="numpy", refcounts=False)
def _block_step(q, order, act, s, p, b, d, st, cfg, obs, out, trace, active, bs, bp, bb, bd,
                bk, btmp, blam, bcoef, bwork, bf, bg, bact, nb, spec):
    """One environment step of every row in block ``q`` (rows ``order[q L : (q + 1) L]``).
    A lane keeps the state and parameters of the row it stepped last (``G_HELD``): they are
    copied in again only for another row, after a failed interval, or at an episode's first
    step, after the reset that wrote them (the only writer of a row's ``s``, ``p`` and ``b``
    outside the step: :func:`abb_gym.envs.episodes.commit`).  After a good interval the row
    holds the lane's state (copied back) and the lane holds the row's: in float32 too (the
    float64 copy of a float32 value converts back to the same float32, and ``rebase_angle``
    leaves the rotor angle's offset as ``load_lane`` would set it).
    Compiled without reference counts (:mod:`abb_gym._numba`)."""
    n_env = order.shape[0]
    ns = s.shape[1]
    sb = bs[q]
    lanes = model.lanes_of(sb, spec)
    pb = bp[q]
    bbq = bb[q]
    f = bf[q]
    g = bg[q]
    whole = actions.whole_episode(int(cfg[C_KIND]))
    for l in range(lanes):
        r = q * lanes + l
        g[batch.G_ON, l] = 0
        g[G_STEPPING, l] = 0
        g[G_INTEGRATE, l] = 0
        g[G_DONE, l] = 0
        if r >= n_env:
            continue
        i = order[r]
        g[batch.G_ROW, l] = i
        found = _begin(i, act, s, d, st, cfg, out, active)
        g[G_STEPPING, l] = found
        if found == ROW_STEPS:
            g[G_INTEGRATE, l] = 1
            if g[G_HELD, l] != i or st[i, S_K] == 0.0:
                batch.load_lane(s, p, b, i, sb, pb, bbq, f, l)
                g[G_HELD, l] = i
    while True:
        any_lane = False
        for l in range(lanes):
            g[batch.G_ON, l] = g[G_INTEGRATE, l]
            if g[G_INTEGRATE, l] != 0:
                _interval_begin(g[batch.G_ROW, l], st, cfg, f, g, l)
                any_lane = True
        if not any_lane:
            break
        batch.advance_block(sb, pb, bbq, bd[q], bk[q], btmp[q], blam[q], bcoef[q], bwork[q],
                            f, g, bact[q], d, int(cfg[C_METHOD]), nb, spec)
        for l in range(lanes):
            if g[G_INTEGRATE, l] == 0:
                continue
            i = g[batch.G_ROW, l]
            if g[batch.G_STATUS, l] == 0:
                for c in range(ns):
                    s[i, c] = batch.lane_value(sb, f, l, c)
                batch.rebase_angle(sb, f, l)
            else:
                g[G_HELD, l] = -1  # the lane holds the failed state, the row the one before
            done = _interval_end(i, s, p, b, d, st, cfg, out, f, g, l)
            if done or not whole or g[batch.G_STATUS, l] != 0:
                g[G_INTEGRATE, l] = 0
                g[G_DONE, l] = 1 if done else 0
            else:
                if g[G_HELD, l] != i:  # the laundry redistributed: the row changed
                    batch.load_lane(s, p, b, i, sb, pb, bbq, f, l)
                    g[G_HELD, l] = i
                _record_trace(i, s, p, b, st, cfg, obs, out, trace)
    for l in range(lanes):
        found = g[G_STEPPING, l]
        if found == ROW_IDLE:
            continue
        i = g[batch.G_ROW, l]
        balance = True
        if found == ROW_STEPS:
            balance = _finish(i, g[G_DONE, l] != 0, st, cfg, out)
        _observe(i, s, p, b, st, cfg, obs, out, trace, balance)


@njit(cache=True, error_model="numpy")
def _step_serial(order, act, s, p, b, d, st, cfg, obs, out, trace, active, bs, bp, bb, bd, bk,
                 btmp, blam, bcoef, bwork, bf, bg, bact, nb, spec):
    for q in range(bs.shape[0]):
        _block_step(q, order, act, s, p, b, d, st, cfg, obs, out, trace, active, bs, bp, bb,
                    bd, bk, btmp, blam, bcoef, bwork, bf, bg, bact, nb, spec)


@njit(cache=True, parallel=True, error_model="numpy")
def _step_parallel(order, act, s, p, b, d, st, cfg, obs, out, trace, active, bs, bp, bb, bd,
                   bk, btmp, blam, bcoef, bwork, bf, bg, bact, nb, spec):
    for q in prange(bs.shape[0]):
        _block_step(q, order, act, s, p, b, d, st, cfg, obs, out, trace, active, bs, bp, bb,
                    bd, bk, btmp, blam, bcoef, bwork, bf, bg, bact, nb, spec)


# ------------------------------------------------------------------ the packed call
# numba's dispatch unboxes each array argument (about 70 ns apiece): the step's 24 arrays
# cost 1.75 us a call, a tenth of a single environment's step.  They travel instead in one
# StructRef, whose unboxing is one pointer (0.4 us a call, measured with a 24-array stand-in);
# the arrays inside are the buffers' own (the same memory, not copies).
# ("st" is named st_rows: numba's generated constructor calls its new struct st)
STEP_ARRAYS = ("order", "act", "s", "p", "b", "d", "st_rows", "cfg", "obs", "out", "trace",
               "active", "bs", "bp", "bb", "bd", "bk", "btmp", "blam", "bcoef", "bwork", "bf",
               "bg", "bact")


@structref.register
class StepArraysType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class StepArrays(structref.StructRefProxy):
    """The arrays of one environment step, in the order of :data:`STEP_ARRAYS` (made by
    :func:`pack_step_arrays`)."""


structref.define_proxy(StepArrays, StepArraysType, list(STEP_ARRAYS))


@njit(cache=True)
def pack_step_arrays(*arrays):
    """:class:`StepArrays` of ``arrays``, given in the order of :data:`STEP_ARRAYS` (compiled
    and cached: the proxy's own constructor would compile on every start)."""
    return StepArrays(*arrays)


# The two wrappers pass the arrays one by one, never as star arguments
# (``_step_serial(*fields_of(a), nb, spec)``): numba types a star call's arguments as
# one tuple, which turns the literal ``nb`` and ``spec`` into plain integers, so every callee
# compiles as the general kernel while the entry point still counts as specialised, and the
# environments run at the general kernel's speed (CHANGELOG.md, Fixed);
# ``tests/test_kernel_packing.py`` checks the order of the arrays and that no compiled call
# passes a literal argument beside star arguments.
@njit(cache=True, error_model="numpy")
def _step_serial_packed(a, nb, spec):
    _step_serial(a.order, a.act, a.s, a.p, a.b, a.d, a.st_rows, a.cfg, a.obs, a.out, a.trace,
                 a.active, a.bs, a.bp, a.bb, a.bd, a.bk, a.btmp, a.blam, a.bcoef, a.bwork, a.bf,
                 a.bg, a.bact, nb, spec)


@njit(cache=True, error_model="numpy")
def _step_parallel_packed(a, nb, spec):
    _step_parallel(a.order, a.act, a.s, a.p, a.b, a.d, a.st_rows, a.cfg, a.obs, a.out, a.trace,
                   a.active, a.bs, a.bp, a.bb, a.bd, a.bk, a.btmp, a.blam, a.bcoef, a.bwork,
                   a.bf, a.bg, a.bact, nb, spec)


step_serial = Specialised(_step_serial_packed, literal=(1, 2), names=("balls", model.EFFECTS))
step_parallel = Specialised(_step_parallel_packed, literal=(1, 2),
                            names=("balls", model.EFFECTS), parallel=True)
"""``step_serial`` / ``step_parallel`` (blocks in parallel) ``(arrays, nb, spec)``, ``arrays``
the :class:`StepArrays` of ``(order, act, s, p, b, d, st, cfg, obs, out, trace, active,
*block_arrays)``: one environment step of every row (``order``: the rows in lane order,
:func:`abb_gym.physics.batch.lane_order`; ``block_arrays``:
:meth:`abb_gym.physics.batch.Blocks.arrays`).  Called, they compile a kernel specialised on
the ball count ``nb`` and the effects ``spec`` (vectorised across the lanes of a block); their
``.generic`` runs the general kernel, compiled once for every scene."""


def entry_point(n_blocks: int) -> Specialised:
    """The compiled step of ``n_blocks`` blocks of lanes: ``step_parallel`` (the blocks in
    parallel) for several, ``step_serial`` for one."""
    return step_parallel if n_blocks > 1 else step_serial


@njit(cache=True)
def observe_rows(rows, s, p, b, st, cfg, obs, out, trace):
    """Observation (and whirl/balance outputs) of the given rows, e.g. after a reset."""
    for r in range(rows.shape[0]):
        i = rows[r]
        for c in range(out.shape[1]):
            out[i, c] = 0.0
        _observe(i, s, p, b, st, cfg, obs, out, trace, True)
