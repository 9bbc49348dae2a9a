"""Integrators over one right-hand side (:func:`abb_gym.physics.model.state_derivative`).

* :func:`rk4_run` - compiled classical fixed-step RK4, the production path.  It steps from
  output time to output time, never across a drive breakpoint (the step is shortened so that
  segment starts fall on step boundaries), and stops at the first non-finite state.
* :func:`scipy_run` - ``scipy.integrate.solve_ivp`` (DOP853, Radau, RK45, ...) through the same
  compiled right-hand side, restarted at every drive breakpoint; the validation reference.

Both return ``(states at the output times, status, failure time, failing state index)`` with
status 0 = ok, 1 = non-finite state.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.integrate import solve_ivp

from . import model as mdl

STATUS_OK = 0
STATUS_NONFINITE = 1


@njit(cache=True)
def _rk4_step(t, h, s, p, b, d, k1, k2, k3, k4, tmp, qdd, work):
    n = s.shape[0]
    mdl.state_derivative(t, s, p, b, d, k1, qdd, work)
    for j in range(n):
        tmp[j] = s[j] + 0.5 * h * k1[j]
    mdl.state_derivative(t + 0.5 * h, tmp, p, b, d, k2, qdd, work)
    for j in range(n):
        tmp[j] = s[j] + 0.5 * h * k2[j]
    mdl.state_derivative(t + 0.5 * h, tmp, p, b, d, k3, qdd, work)
    for j in range(n):
        tmp[j] = s[j] + h * k3[j]
    mdl.state_derivative(t + h, tmp, p, b, d, k4, qdd, work)
    for j in range(n):
        s[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])


@njit(cache=True)
def _pin_prescribed(t, s, d, nq):
    """Set th, th' to the exact drive law (no drift in the prescribed rotor angle)."""
    if d[mdl.D_MODE] == mdl.MODE_PRESCRIBED:
        tau = t - d[mdl.D_T0]
        s[2] = d[mdl.D_TH0] + d[mdl.D_W0] * tau + 0.5 * d[mdl.D_ALPHA] * tau * tau
        s[nq + 2] = d[mdl.D_W0] + d[mdl.D_ALPHA] * tau


@njit(cache=True)
def _first_nonfinite(s):
    for j in range(s.shape[0]):
        if not math.isfinite(s[j]):
            return j
    return -1


@njit(cache=True)
def rk4_run(s0, t_out, seg_t, seg_d, p, b, dt_max, out):
    """Integrate from ``t_out[0]`` and write the state at each ``t_out[k]`` into ``out[k]``.

    ``seg_t`` are segment start times (ascending, ``seg_t[0] <= t_out[0]``), ``seg_d`` the
    drive rows.  Returns (status, failure time, index of the first non-finite entry, steps).
    """
    n = s0.shape[0]
    nq = n // 2
    nb = b.shape[0]
    s = s0.copy()
    k1 = np.empty(n)
    k2 = np.empty(n)
    k3 = np.empty(n)
    k4 = np.empty(n)
    tmp = np.empty(n)
    qdd = np.empty(nq)
    work = np.empty((nb, mdl.WORK_COLUMNS))
    nseg = seg_t.shape[0]
    j = 0
    while j + 1 < nseg and seg_t[j + 1] <= t_out[0]:
        j += 1
    _pin_prescribed(t_out[0], s, seg_d[j], nq)
    out[0, :] = s
    steps = 0
    for k in range(t_out.shape[0] - 1):
        t = t_out[k]
        t_end = t_out[k + 1]
        while t < t_end:
            # advance the segment pointer when t sits on (or past) the next segment start
            while j + 1 < nseg and seg_t[j + 1] <= t + 1e-12 * (1.0 + abs(t)):
                j += 1
                _pin_prescribed(t, s, seg_d[j], nq)
            piece_end = t_end
            if j + 1 < nseg and seg_t[j + 1] < piece_end:
                piece_end = seg_t[j + 1]
            m = int(math.ceil((piece_end - t) / dt_max - 1e-9))
            if m < 1:
                m = 1
            h = (piece_end - t) / m
            for i in range(m):
                ti = t + i * h
                _rk4_step(ti, h, s, p, b, seg_d[j], k1, k2, k3, k4, tmp, qdd, work)
                steps += 1
                bad = _first_nonfinite(s)
                if bad >= 0:
                    return STATUS_NONFINITE, ti + h, bad, steps
            t = piece_end
            _pin_prescribed(t, s, seg_d[j], nq)
        out[k + 1, :] = s
    return STATUS_OK, t_out[-1], -1, steps


def scipy_run(s0, t_out, seg_t, seg_d, p, b, method="DOP853", rtol=1e-10, atol=1e-12, out=None):
    """Reference integration with ``solve_ivp`` restarted at every segment start.

    Returns (status, failure time, failing index, right-hand-side evaluations).
    """
    n = s0.shape[0]
    nq = n // 2
    out = np.empty((len(t_out), n)) if out is None else out
    qdd = np.empty(nq)
    work = np.empty((b.shape[0], mdl.WORK_COLUMNS))
    s = np.array(s0, dtype=float)
    bounds = [t_out[0]] + [t for t in seg_t if t_out[0] < t < t_out[-1]] + [t_out[-1]]
    nfev = 0
    for a, z in zip(bounds[:-1], bounds[1:]):
        j = int(np.searchsorted(seg_t, a + 1e-12 * (1 + abs(a)), side="right") - 1)
        d = seg_d[max(j, 0)]
        _pin_prescribed(a, s, d, nq)
        if a == t_out[0]:
            out[0] = s

        def rhs(t, y, d=d):
            ds = np.empty(n)
            mdl.state_derivative(t, y, p, b, d, ds, qdd, work)
            return ds

        mask = (t_out > a) & (t_out <= z)
        t_eval = t_out[mask]
        if not (len(t_eval) and t_eval[-1] == z):
            t_eval = np.append(t_eval, z)
        sol = solve_ivp(rhs, (a, z), s, method=method, rtol=rtol, atol=atol, t_eval=t_eval)
        nfev += sol.nfev
        if sol.status != 0 or not np.all(np.isfinite(sol.y)):
            finite = np.all(np.isfinite(sol.y), axis=0)
            k = int(np.argmin(finite)) if not np.all(finite) else sol.y.shape[1] - 1
            t_fail = float(sol.t[k]) if sol.t.size else a
            y_fail = sol.y[:, k] if sol.t.size else np.full(n, np.nan)
            bad = int(np.argmax(~np.isfinite(y_fail))) if not np.all(np.isfinite(y_fail)) else 0
            return STATUS_NONFINITE, t_fail, bad, nfev
        out[mask] = sol.y.T[: int(mask.sum())]
        s = sol.y[:, -1].copy()
    return STATUS_OK, float(t_out[-1]), -1, nfev
