"""Batched fixed-step integration: many independent balancers over the same output interval.

The environments and parameter sweeps advance many copies of the model at once.  This module
gives them the fixed-step methods of :func:`abb_gym.physics.integrators.run` (RK4 and ETDRK4)
in a form that works one output interval at a time and over a batch:

* :func:`advance` - one environment over one output interval ``[t0, t1]``, with the same
  segment and step splitting (``integrators.enter_segment`` / ``next_piece``), the same step
  functions (``integrators._rk4_step`` / ``_etdrk4_step`` over
  :func:`abb_gym.physics.model.state_derivative`), the same pinning of a prescribed rotor
  angle at piece ends, and the same non-finite check after every step as ``integrators.run``.
  For the same output times the states are therefore bit-identical to ``run``
  (``tests/test_envs_batch.py`` checks this).  It also accumulates the time integral and the
  maximum of the whirl radius over the substeps.
* :func:`run_batch` - ``integrators.run`` for ``N`` environments (own parameters, own drive
  tables, shared output times), parallel over environments with ``numba.prange``.

Array layout (``N`` environments, ``n`` balls, state length ``ns = 2 (3 + n)``):

==========  =====================  ===========================================================
name        shape                  meaning
==========  =====================  ===========================================================
s           (N, ns)                states, updated in place
p           (N, N_PARAMS)          scalar parameters (:func:`model.pack_parameters`)
b           (N, n, N_BALL_PARAMS)  per-ball parameters
seg_d       (N, R, N_DRIVE)        drive rows; row ``j`` starts at ``seg_d[., j, D_T0]``
nseg        (N,)                   number of valid rows per environment (<= R)
ws          (N, 7, ns)             scratch: RK4 stages k1..k4, stage state, accelerations,
                                   and a free row (``WS_BACKUP``) for the caller
work        (N, n, WORK_COLUMNS)   scratch of :func:`model.accelerations`
==========  =====================  ===========================================================

Workspaces are passed in (never allocated per step) so that the batch loop does no allocation.

Compiled-cache hygiene (numba does not notice edits of called functions in other files) is
handled once for the whole package by :mod:`abb_gym._jit_cache` on import.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from . import integrators as integ
from . import drive_law as dl
from . import model as mdl

__all__ = ["advance", "run_batch", "make_workspace", "WS_ROWS",
           "WS_BACKUP"]

# rows of the per-environment scratch ``ws``: stages k1..k5 (ETDRK4 uses five), the stage
# state, the accelerations, the frozen drag rates, the six ETDRK4 weights, and a free row
WS_STAGES = 0
WS_TMP = 5
WS_QDD = 6
WS_LAM = 7
WS_COEF = 8
WS_BACKUP = 14  # row of ``ws`` that callers may use to keep the state at the interval start
WS_ROWS = 15


def make_workspace(n_envs: int, n_balls: int) -> tuple[np.ndarray, np.ndarray]:
    """Scratch arrays ``(ws, work)`` for ``n_envs`` environments of ``n_balls`` balls."""
    ns = 2 * (3 + n_balls)
    return np.zeros((n_envs, WS_ROWS, ns)), np.zeros((n_envs, n_balls, mdl.WORK_COLUMNS))


@njit(cache=True)
def advance(s, t0, t1, seg_d, nseg, j, p, b, dt_max, ws, work, whirl, method):
    """Advance one state ``s`` (in place) from ``t0`` to ``t1`` with a fixed-step method,
    ``integrators.METHOD_RK4`` or ``integrators.METHOD_ETDRK4`` (the same step functions as
    :func:`integrators.run`, so the results agree bit for bit).

    ``seg_d`` holds ``nseg`` drive rows, ``j`` is the index of the current row (as returned by
    the previous call), ``ws`` a (WS_ROWS, ns) and ``work`` an (n, WORK_COLUMNS) scratch array.
    ``whirl`` (length 5) accumulates over the substeps (right-endpoint rule): ``whirl[0]`` +=
    the integral of the deflection from the rest position ``(whirl[2], whirl[3])`` (the static
    sag under gravity, else 0), ``whirl[4]`` = max(whirl[4], that deflection), ``whirl[1]`` =
    max(whirl[1], largest whirl radius
    sqrt(x^2 + y^2) measured from the bearing axis).

    Returns ``(status, j, failure time, index of the first non-finite entry, steps)``; status 0
    is ok, 1 (``integrators.STATUS_NONFINITE``) means the state became non-finite; ``s`` then
    holds the non-finite state (restore it from a copy if needed).
    """
    n = s.shape[0]
    nq = n // 2
    stages = ws[WS_STAGES:WS_STAGES + 5]
    tmp = ws[WS_TMP]
    qdd = ws[WS_QDD, :nq]
    lam = ws[WS_LAM]
    coef = ws[WS_COEF:WS_COEF + 6]
    steps = 0
    t = t0
    while t < t1:
        j = integ.enter_segment(t, s, seg_d, nseg, j, nq)
        piece_end, m, h = integ.next_piece(t, t1, seg_d, nseg, j, dt_max)
        for i in range(m):
            ti = t + i * h
            if method == integ.METHOD_ETDRK4:
                integ._etdrk4_step(ti, h, s, p, b, seg_d[j], stages, tmp, qdd, work, lam, coef)
            else:
                integ._rk4_step(ti, h, s, p, b, seg_d[j], stages, tmp, qdd, work)
            steps += 1
            bad = integ._first_nonfinite(s)
            if bad >= 0:
                return integ.STATUS_NONFINITE, j, ti + h, bad, steps
            dx = s[0] - whirl[2]
            dy = s[1] - whirl[3]
            rd = math.sqrt(dx * dx + dy * dy)
            whirl[0] += rd * h
            if rd > whirl[4]:
                whirl[4] = rd
            r = math.sqrt(s[0] * s[0] + s[1] * s[1])
            if r > whirl[1]:
                whirl[1] = r
        t = piece_end
        dl.pin_prescribed(t, s, seg_d[j], nq)
    return integ.STATUS_OK, j, t1, -1, steps


@njit(cache=True, parallel=True)
def run_batch(s0, t_out, seg_d, nseg, p, b, dt_max, out, status, ws, work,
              method=integ.METHOD_RK4):
    """:func:`integrators.run` (RK4 or ETDRK4) for ``N`` environments in parallel.

    ``s0`` (N, ns) initial states, ``t_out`` (T,) shared output times, ``seg_d``/``nseg`` the
    drive tables, ``p``/``b`` the parameters, ``out`` (N, T, ns) receives the states.
    ``status`` (N, 4) float receives (status, failure time, failing index, steps) per
    environment, as ``rk4_run`` returns them.  Workspaces from :func:`make_workspace`.
    """
    n_env = s0.shape[0]
    nq = s0.shape[1] // 2
    for e in prange(n_env):
        s = ws[e, WS_BACKUP]
        s[:] = s0[e]
        whirl = np.zeros(5)
        j = 0
        ns_e = nseg[e]
        while j + 1 < ns_e and seg_d[e, j + 1, dl.D_T0] <= t_out[0]:
            j += 1
        dl.pin_prescribed(t_out[0], s, seg_d[e, j], nq)
        out[e, 0, :] = s
        total = 0
        st = integ.STATUS_OK
        t_fail = t_out[-1]
        bad = -1
        for k in range(t_out.shape[0] - 1):
            st, j, t_fail, bad, steps = advance(s, t_out[k], t_out[k + 1], seg_d[e], ns_e, j,
                                                p[e], b[e], dt_max, ws[e], work[e], whirl,
                                                method)
            total += steps
            if st != integ.STATUS_OK:
                break
            out[e, k + 1, :] = s
        status[e, 0] = st
        status[e, 1] = t_fail
        status[e, 2] = bad
        status[e, 3] = total



