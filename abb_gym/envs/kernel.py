"""The compiled environment step, shared by the single and the vector environments.

Every environment (single or vector, any action type) keeps its state in preallocated arrays
with one row per environment (layouts: :mod:`abb_gym.envs.layout`) and advances them with
**one** compiled call per step:

* :func:`step_serial` (single environments) and :func:`step_parallel` (the native vector
  environment, ``numba.prange`` over environments) both call :func:`_env_step` for each row,
  so a sub-environment of the vector environment and a single environment do the same
  arithmetic and agree bit for bit.
* :func:`_env_step` turns the action into a drive row (:mod:`abb_gym.envs.actions`) or uses
  the rows the Python side wrote (a whole-episode action), advances one control interval (or
  every interval until the episode ends) with :func:`abb_gym.physics.batch.advance` - the
  integrators of :func:`abb_gym.physics.integrators.run` over
  :func:`abb_gym.physics.model.state_derivative` - and computes the reward terms, the
  termination flags and the observation.

The reward and observation definitions are documented in :mod:`abb_gym.envs.base`.
"""
from __future__ import annotations

import math

from numba import njit, prange

from ..physics import batch, rotor, runup
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


@njit(cache=True)
def _observe(i, s, p, b, st, cfg, obs, out, trace):
    """Write the observation row ``obs[i]``, the whirl radius and balance outputs, the trace."""
    nq = s.shape[1] // 2
    nb = nq - 3
    x = s[i, 0]
    y = s[i, 1]
    dx = x - st[i, S_XS]
    dy = y - st[i, S_YS]
    w = s[i, nq + 2]
    vs = cfg[C_VSCALE]
    vh = cfg[C_VIB_HI]
    obs[i, 0] = _clip(w / cfg[C_WOP], cfg[C_SPEED_LO], cfg[C_SPEED_HI])
    obs[i, 1] = _clip(dx / vs, -vh, vh)
    obs[i, 2] = _clip(dy / vs, -vh, vh)
    obs[i, 3] = _clip(st[i, S_FILT] / vs, 0.0, vh)
    obs[i, 4] = _clip(st[i, S_K] / cfg[C_NMAX], 0.0, 1.0)
    na = int(cfg[C_NACT])
    for a in range(na):
        obs[i, 5 + a] = st[i, S_ACT + a]
    if cfg[C_OBS_BALLS] != 0.0:
        for k in range(nb):
            ph = s[i, 3 + k]
            obs[i, 5 + na + 2 * k] = math.cos(ph)
            obs[i, 6 + na + 2 * k] = math.sin(ph)
    out[i, O_R] = math.sqrt(x * x + y * y)
    out[i, O_RDYN] = math.sqrt(dx * dx + dy * dy)
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


@njit(cache=True)
def _interval(i, s, p, b, d, st, cfg, out, ws, work):
    """Advance environment ``i`` by one control interval and add its reward terms to ``out``.

    The run-up metrics (:mod:`abb_gym.physics.runup`: the operating band, the settled entry,
    the residual over the settling window) are updated here with the interval's vibration;
    the reward's time and residual terms and the success condition read them.  Returns True
    when the episode ended (terminated or truncated) in this interval.
    """
    nq = s.shape[1] // 2
    dt = cfg[C_DT]
    kk = st[i, S_K]
    t0 = kk * dt
    t1 = (kk + 1.0) * dt
    si = s[i]
    wsi = ws[i]
    backup = wsi[batch.WS_BACKUP]
    for c in range(si.shape[0]):
        backup[c] = si[c]
    whirl = out[i, O_WINT:O_WDMAX + 1]
    whirl[0] = 0.0
    whirl[1] = 0.0
    whirl[2] = st[i, S_XS]
    whirl[3] = st[i, S_YS]
    whirl[4] = 0.0
    nseg = int(st[i, S_NSEG])
    status, j, t_fail, bad, steps = batch.advance(si, t0, t1, d[i], nseg, int(st[i, S_J]),
                                                  p[i], b[i], st[i, S_DTMAX], wsi, work[i],
                                                  whirl, int(cfg[C_METHOD]))
    st[i, S_J] = j
    out[i, O_STEPS] += steps
    st[i, S_K] = kk + 1.0
    acc = st[i, S_ACC:S_ACC + runup.N_ACC]
    wop = cfg[C_WOP]
    band = cfg[C_BAND]
    fail = FAIL_NONE
    if status != 0:
        for c in range(si.shape[0]):
            si[c] = backup[c]
        fail = FAIL_NUMERICAL
        out[i, O_FTIME] = t_fail
        out[i, O_FINDEX] = bad
        dx = si[0] - st[i, S_XS]
        dy = si[1] - st[i, S_YS]
        r_mean = math.sqrt(dx * dx + dy * dy)
        r_max = math.sqrt(si[0] * si[0] + si[1] * si[1])
        at_speed = runup.in_band(si[nq + 2], wop, band)
    else:
        r_mean = whirl[0] / dt
        r_max = whirl[1]
        at_speed = runup.update(acc, t0, t1, si[nq + 2], whirl[0], whirl[4], wop, band,
                                cfg[C_SETTLE])
    w = si[nq + 2]
    # control effort: time integral of (drive command / its limit)^2 over the interval
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
        # the time limit does not excuse the residual term: it is paid over the settling
        # window so far if the rotor is in the band, else at its bound (the whirl at the
        # clearance), so that a run-up too slow to finish, or parked off the band, never pays
        res = runup.residual(acc)
        if at_speed and math.isfinite(res):
            resid = -cfg[C_WR] * res / st[i, S_AOP]
        else:
            resid = -st[i, S_PEN_TERM]
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


@njit(cache=True)
def _env_step(i, act, s, p, b, d, st, cfg, obs, out, trace, ws, work, active):
    for c in range(out.shape[1]):
        out[i, c] = 0.0
    if active[i] == 0:
        return
    if st[i, S_DONE] != 0.0:
        # stepping a finished episode: nothing moves, no reward (the caller warns)
        out[i, O_TERM] = st[i, S_TERM]
        out[i, O_TRUNC] = st[i, S_TRUNC]
        _observe(i, s, p, b, st, cfg, obs, out, trace)
        return
    na = int(cfg[C_NACT])
    for a in range(na):
        if not math.isfinite(act[i, a]):
            out[i, O_ACTFLAG] = ACT_NONFINITE
            out[i, O_FINDEX] = a
            return
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
    if actions.whole_episode(kind):
        # the rows were written from the action: run the whole episode
        done = False
        while not done:
            done = _interval(i, s, p, b, d, st, cfg, out, ws, work)
            if not done:
                _observe(i, s, p, b, st, cfg, obs, out, trace)  # fills the render trace
    else:
        nq = s.shape[1] // 2
        actions.write_interval_row(kind, d[i, 0], st[i, S_ACT], st[i, S_K] * cfg[C_DT],
                                   s[i, 2], s[i, nq + 2], cfg[C_DT], cfg[C_WOP], cfg[C_AMAX],
                                   cfg[C_TLIM])
        st[i, S_NSEG] = 1.0
        st[i, S_J] = 0.0
        done = _interval(i, s, p, b, d, st, cfg, out, ws, work)
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
    _observe(i, s, p, b, st, cfg, obs, out, trace)


@njit(cache=True)
def step_serial(act, s, p, b, d, st, cfg, obs, out, trace, ws, work, active):
    """One environment step for every row (serial; single environments)."""
    for i in range(s.shape[0]):
        _env_step(i, act, s, p, b, d, st, cfg, obs, out, trace, ws, work, active)


@njit(cache=True, parallel=True)
def step_parallel(act, s, p, b, d, st, cfg, obs, out, trace, ws, work, active):
    """One environment step for every row, in parallel over rows (vector environment)."""
    for i in prange(s.shape[0]):
        _env_step(i, act, s, p, b, d, st, cfg, obs, out, trace, ws, work, active)


@njit(cache=True)
def observe_rows(rows, s, p, b, st, cfg, obs, out, trace):
    """Observation (and whirl/balance outputs) of the given rows, e.g. after a reset."""
    for r in range(rows.shape[0]):
        i = rows[r]
        for c in range(out.shape[1]):
            out[i, c] = 0.0
        _observe(i, s, p, b, st, cfg, obs, out, trace)
