"""Integrators behind one interface, all over one right-hand side
(:func:`abb_gym.physics.model.accelerations_block`).

Compiled (numba), chosen by :data:`~abb_gym.physics.methods.METHOD_IDS` and run by
:func:`run`:

* ``"rk4"`` - classical fixed-step Runge-Kutta, order 4.  Explicit: its real-axis stability
  limit h * rate < 2.79 is set by the ball drag (rate ~ c_b / (1.4 m)) and, through the
  smoothed rolling resistance, by the rotor speed (rate grows with Omega^2).
* ``"dopri5"`` - adaptive Dormand-Prince 5(4) embedded pair with FSAL and a standard
  step-size controller (``rtol``, ``atol``); the step never crosses an output time or a drive
  breakpoint.  Explicit too, so stiffness makes it take many small steps.
* ``"etdrk4"`` - the exponential time-differencing RK4 of Cox & Matthews (2002) with the stiff
  part of the ball equations, the race drag and the slope of the smoothed rolling resistance
  (:func:`abb_gym.physics.model.drag_rates`, frozen over a step), integrated exactly.  Fourth
  order like RK4 at a little more cost per step, and free of the drag step limit; what stays
  explicit is the rotor-ball coupling of relative size m/M.  (A Lawson integrating factor was
  tried first: stable, but 10-100x less accurate, because it is not exact for the
  quasi-steady balance of drag and driving force.)
* ``"ros2"`` - the two-stage linearly implicit Rosenbrock W-method of Verwer et al. (1999),
  gamma = 1 + 1/sqrt(2): order 2 for any Jacobian approximation and L-stable, so stiff ball
  drag does not limit the step.  Fixed step; the Jacobian is formed by forward differences at
  the start of each step (2 (3 + n) extra right-hand sides) and factorised once per step.

``scipy_run`` integrates with ``scipy.integrate.solve_ivp`` (DOP853, Radau, ...) through the
same compiled right-hand side and is the validation reference.

Every path steps from output time to output time and never across a drive breakpoint, and
stops at the first non-finite state.  They return ``(status, failure time, index of the
failing state entry, work)`` with work = steps (fixed-step) or right-hand-side evaluations.
"""
from __future__ import annotations

import math

import numpy as np
from .._numba import njit
from . import drive_law as dl
from . import elementary as el
from . import model as mdl
from .methods import METHOD_DOPRI5, METHOD_ETDRK4, METHOD_RK4
from .specialise import Specialised

STATUS_OK = 0
STATUS_NONFINITE = 1
STATUS_STEP_UNDERFLOW = 2
STATUS_WORK_LIMIT = 3  # solve_ivp used more right-hand sides than it was allowed



# --------------------------------------------------------------------------- helpers
@njit(cache=True)
def enter_segment(t, s, lane, seg_d, nseg, j, nq, angle_offset=0.0):
    """Index of the drive segment that holds ``t``, moving on from segment ``j``; at every
    segment start passed, the prescribed rotor state of lane ``lane`` of state block ``s`` is
    pinned to the exact drive law (``angle_offset``: :func:`drive_law.pin_prescribed`)."""
    while j + 1 < nseg and seg_d[j + 1, dl.D_T0] <= t + 1e-12 * (1.0 + abs(t)):
        j += 1
        dl.pin_prescribed(t, s, lane, seg_d[j], nq, angle_offset)
    return j


@njit(cache=True)
def next_piece(t, t_end, seg_d, nseg, j, h_max):
    """The piece from ``t`` to the next output time or segment start, whichever is first,
    split into ``m`` equal steps ``h <= h_max``: returns (piece end, m, h)."""
    piece_end = t_end
    if j + 1 < nseg and seg_d[j + 1, dl.D_T0] < piece_end:
        piece_end = seg_d[j + 1, dl.D_T0]
    m = int(math.ceil((piece_end - t) / h_max - 1e-9))
    if m < 1:
        m = 1
    return piece_end, m, (piece_end - t) / m


@njit(cache=True)
def _first_nonfinite(s):
    for j in range(s.shape[0]):
        if not math.isfinite(s[j]):
            return j
    return -1


@njit(cache=True, error_model="numpy", noalias=True, refcounts=False)
def _rk4_step(t, h, s, p, b, d, k, tmp, tt, work, active, nb, spec):
    """One classical RK4 step of every lane of a block (arrays lane-last, see
    :func:`abb_gym.physics.model.accelerations_block`): lane ``l`` from ``t[l]`` by ``h[l]``;
    lanes with ``active[l] == 0`` are computed but keep their state (a masked update, so that
    the lane loops stay branch-free).  No two array arguments may overlap (compiled
    ``noalias``: :mod:`abb_gym._numba`); compiled without reference counts (same module)."""
    n = mdl.rows_of(s, nb, spec)
    L = mdl.lanes_of(s, spec)
    k1, k2, k3, k4 = k[0], k[1], k[2], k[3]
    # constants in the arrays' precision (float64 or float32: elementary.like)
    half = el.like(h, 0.5)
    two = el.like(h, 2.0)
    six = el.like(h, 6.0)
    mdl.accelerations_block(t, s, p, b, d, k1, work, nb, spec)
    for j in range(n):
        for l in range(L):
            tmp[j, l] = s[j, l] + half * h[l] * k1[j, l]
    for l in range(L):
        tt[l] = t[l] + half * h[l]
    mdl.accelerations_block(tt, tmp, p, b, d, k2, work, nb, spec)
    for j in range(n):
        for l in range(L):
            tmp[j, l] = s[j, l] + half * h[l] * k2[j, l]
    mdl.accelerations_block(tt, tmp, p, b, d, k3, work, nb, spec)
    for j in range(n):
        for l in range(L):
            tmp[j, l] = s[j, l] + h[l] * k3[j, l]
    for l in range(L):
        tt[l] = t[l] + h[l]
    mdl.accelerations_block(tt, tmp, p, b, d, k4, work, nb, spec)
    for j in range(n):
        for l in range(L):
            new = s[j, l] + h[l] / six * (k1[j, l] + two * k2[j, l] + two * k3[j, l] + k4[j, l])
            s[j, l] = new if active[l] != 0 else s[j, l]


@njit(cache=True)
def _lu_factor(a, piv):
    """In-place LU with partial pivoting (small dense matrices)."""
    n = a.shape[0]
    for c in range(n):
        r = c
        big = abs(a[c, c])
        for i in range(c + 1, n):
            if abs(a[i, c]) > big:
                big = abs(a[i, c])
                r = i
        piv[c] = r
        if r != c:
            for j in range(n):
                tmp = a[c, j]
                a[c, j] = a[r, j]
                a[r, j] = tmp
        inv = 1.0 / a[c, c]
        for i in range(c + 1, n):
            a[i, c] *= inv
            f = a[i, c]
            if f != 0.0:
                for j in range(c + 1, n):
                    a[i, j] -= f * a[c, j]


@njit(cache=True)
def _lu_solve(lu, piv, x):
    """Solve in place: x <- A^-1 x for the factors of :func:`_lu_factor`."""
    n = lu.shape[0]
    for c in range(n):
        r = piv[c]
        if r != c:
            tmp = x[c]
            x[c] = x[r]
            x[r] = tmp
    for i in range(n):
        acc = x[i]
        for j in range(i):
            acc -= lu[i, j] * x[j]
        x[i] = acc
    for i in range(n - 1, -1, -1):
        acc = x[i]
        for j in range(i + 1, n):
            acc -= lu[i, j] * x[j]
        x[i] = acc / lu[i, i]


_Q_SERIES = np.array([1 / 2, 1 / 8, 1 / 48, 1 / 384, 1 / 3840, 1 / 46080, 1 / 645120,
                      1 / 10321920])
_F1_SERIES = np.array([1 / 6, 1 / 6, 3 / 40, 1 / 45, 5 / 1008, 1 / 1120, 7 / 51840, 1 / 56700])
_F2_SERIES = np.array([1 / 6, 1 / 12, 1 / 40, 1 / 180, 1 / 1008, 1 / 6720, 1 / 51840,
                       1 / 453600])
_F3_SERIES = np.array([1 / 6, 0.0, -1 / 120, -1 / 360, -1 / 1680, -1 / 10080, -1 / 72576,
                       -1 / 604800])


@njit(cache=True, inline="always")
def _series(c, z):
    acc = 0.0
    for k in range(c.shape[0] - 1, -1, -1):
        acc = acc * z + c[k]
    return acc


@njit(cache=True, inline="always")
def etd_coefficients(z):
    """ETDRK4 weights for z = h L <= 0: (e^(z/2), e^z, Q, f1, f2, f3) (Cox & Matthews 2002).

    Q = (e^(z/2) - 1)/z, f1 = (-4 - z + e^z (4 - 3z + z^2))/z^3, f2 = (2 + z + e^z (z - 2))/z^3,
    f3 = (-4 - 3z - z^2 + e^z (4 - z))/z^3; Taylor series for |z| < 0.2, where the closed forms
    lose digits to cancellation (series truncation there < 1e-11).  At z = 0 they are RK4's.
    The exponential is :func:`abb_gym.physics.elementary.exp_bounded` (vectorises), with z
    held above -700, where e^z is 0 to double precision anyway.
    """
    zc = max(z, -700.0)
    e2 = el.exp_bounded(0.5 * zc)
    e = e2 * e2
    if abs(z) < 0.2:
        return (e2, e, _series(_Q_SERIES, z), _series(_F1_SERIES, z), _series(_F2_SERIES, z),
                _series(_F3_SERIES, z))
    z3 = z * z * z
    return (e2, e, (e2 - 1.0) / z, (-4.0 - z + e * (4.0 - 3.0 * z + z * z)) / z3,
            (2.0 + z + e * (z - 2.0)) / z3, (-4.0 - 3.0 * z - z * z + e * (4.0 - z)) / z3)


@njit(cache=True, error_model="numpy", noalias=True, refcounts=False)
def _etdrk4_step(t, h, s, p, b, d, k, tmp, tt, work, lam, coef, active, nb, spec):
    """Cox-Matthews ETDRK4 for y' = -lam y + N(t, y), N = f + lam y, lam frozen per step, for
    every lane of a block (masked like :func:`_rk4_step`).

    Exact for the drag relaxation under constant forcing (the quasi-steady balance of drag and
    driving force that a Lawson integrating factor gets badly wrong), fourth order like RK4.
    No two array arguments may overlap (compiled ``noalias``: :mod:`abb_gym._numba`);
    compiled without reference counts (same module).
    """
    n = mdl.rows_of(s, nb, spec)
    L = mdl.lanes_of(s, spec)
    nu, na, nbb, nc = k[0], k[1], k[2], k[3]
    a = k[4]
    mdl.drag_rates_block(t, s, p, b, d, lam, nb, spec)
    # only the balls' relative speeds relax (drag_rates_block leaves every other row 0): the
    # other rows take the weights at z = -0.0, computed once (the same bits as per lane)
    first = n // 2 + 3
    rk = etd_coefficients(-0.0)
    for j in range(n):
        if first <= j < first + nb:
            for l in range(L):
                e2, e, q, f1, f2, f3 = etd_coefficients(-h[l] * lam[j, l])
                coef[0, j, l] = e2
                coef[1, j, l] = e
                coef[2, j, l] = q
                coef[3, j, l] = f1
                coef[4, j, l] = f2
                coef[5, j, l] = f3
        else:
            for c in range(6):
                for l in range(L):
                    coef[c, j, l] = rk[c]
    mdl.accelerations_block(t, s, p, b, d, nu, work, nb, spec)
    for j in range(n):
        for l in range(L):
            nu[j, l] += lam[j, l] * s[j, l]
            a[j, l] = coef[0, j, l] * s[j, l] + h[l] * coef[2, j, l] * nu[j, l]
    for l in range(L):
        tt[l] = t[l] + 0.5 * h[l]
    mdl.accelerations_block(tt, a, p, b, d, na, work, nb, spec)
    for j in range(n):
        for l in range(L):
            na[j, l] += lam[j, l] * a[j, l]
            tmp[j, l] = coef[0, j, l] * s[j, l] + h[l] * coef[2, j, l] * na[j, l]
    mdl.accelerations_block(tt, tmp, p, b, d, nbb, work, nb, spec)
    for j in range(n):
        for l in range(L):
            nbb[j, l] += lam[j, l] * tmp[j, l]
            tmp[j, l] = coef[0, j, l] * a[j, l] + h[l] * coef[2, j, l] * (2.0 * nbb[j, l]
                                                                          - nu[j, l])
    for l in range(L):
        tt[l] = t[l] + h[l]
    mdl.accelerations_block(tt, tmp, p, b, d, nc, work, nb, spec)
    for j in range(n):
        for l in range(L):
            nc[j, l] += lam[j, l] * tmp[j, l]
            new = coef[1, j, l] * s[j, l] + h[l] * (
                coef[3, j, l] * nu[j, l] + 2.0 * coef[4, j, l] * (na[j, l] + nbb[j, l])
                + coef[5, j, l] * nc[j, l])
            s[j, l] = new if active[l] != 0 else s[j, l]


@njit(cache=True, inline="always")
def _rhs1(t, s, p2, b3, d, ds, work, tt, nb, spec):
    """d(state)/dt of a one-lane run with 1-D state ``s`` and drive row ``d`` (``p2``, ``b3``:
    the parameters with a lane axis of length 1)."""
    tt[0] = t
    mdl.accelerations_block(tt, s.reshape((s.shape[0], 1)), p2, b3, d.reshape((d.shape[0], 1)),
                            ds.reshape((ds.shape[0], 1)), work, nb, spec)


ROS2_GAMMA = 1.0 + 1.0 / math.sqrt(2.0)


@njit(cache=True, error_model="numpy")
def _ros2_step(t, h, s, p2, b3, d, k, tmp, work, tt, wmat, piv, nb, spec):
    n = s.shape[0]
    f0, k1, k2, fp = k[0], k[1], k[2], k[3]
    _rhs1(t, s, p2, b3, d, f0, work, tt, nb, spec)
    # W = I - gamma h J with J by forward differences
    for j in range(n):
        delta = 1.5e-8 * max(abs(s[j]), 1e-5)
        for i in range(n):
            tmp[i] = s[i]
        tmp[j] += delta
        _rhs1(t, tmp, p2, b3, d, fp, work, tt, nb, spec)
        for i in range(n):
            wmat[i, j] = -ROS2_GAMMA * h * (fp[i] - f0[i]) / delta
        wmat[j, j] += 1.0
    _lu_factor(wmat, piv)
    for i in range(n):
        k1[i] = f0[i]
    _lu_solve(wmat, piv, k1)
    for i in range(n):
        tmp[i] = s[i] + h * k1[i]
    _rhs1(t + h, tmp, p2, b3, d, k2, work, tt, nb, spec)
    for i in range(n):
        k2[i] -= 2.0 * k1[i]
    _lu_solve(wmat, piv, k2)
    for i in range(n):
        s[i] += h * (1.5 * k1[i] + 0.5 * k2[i])


# Dormand-Prince 5(4) tableau
_C = np.array([0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0])
_A = np.array([
    [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [1 / 5, 0.0, 0.0, 0.0, 0.0, 0.0],
    [3 / 40, 9 / 40, 0.0, 0.0, 0.0, 0.0],
    [44 / 45, -56 / 15, 32 / 9, 0.0, 0.0, 0.0],
    [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0.0, 0.0],
    [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656, 0.0],
    [35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84],
])
_E = np.array([71 / 57600, 0.0, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40])


@njit(cache=True, error_model="numpy")
def _dopri5_attempt(t, h, s, p2, b3, d, k, tmp, work, tt, s_new, rtol, atol, nb, spec):
    """One trial step; k[0] must hold f(t, s).  Returns the scaled error norm."""
    n = s.shape[0]
    for stage in range(1, 7):
        for i in range(n):
            acc = 0.0
            for j in range(stage):
                acc += _A[stage, j] * k[j, i]
            tmp[i] = s[i] + h * acc
        _rhs1(t + _C[stage] * h, tmp, p2, b3, d, k[stage], work, tt, nb, spec)
    err = 0.0
    for i in range(n):
        s_new[i] = tmp[i]  # stage 7 evaluates at the 5th-order solution (FSAL)
        e = 0.0
        for j in range(7):
            e += _E[j] * k[j, i]
        sc = atol[i] + rtol * max(abs(s[i]), abs(s_new[i]))
        err += (h * e / sc) ** 2
    return math.sqrt(err / n)


# --------------------------------------------------------------------------- driver
@njit(cache=True, error_model="numpy")
def _run(method, s0, t_out, seg_t, seg_d, p, b, h, rtol, atol, out, nb, spec):
    """Integrate from ``t_out[0]``; write the state at each ``t_out[k]`` into ``out[k]``.

    ``method`` is a value of :data:`~abb_gym.physics.methods.METHOD_IDS`; ``h`` the fixed step
    (or the first trial step of the adaptive method) [s]; ``rtol`` and ``atol`` (array) are used
    by the adaptive method only.  ``seg_t`` are segment start times (ascending, ``seg_t[0] <=
    t_out[0]``) and ``seg_d`` the drive rows; ``spec`` the kernel's ``SPEC_*`` bits
    (:func:`abb_gym.physics.model.spec_of`).  Returns (status, failure time, failing index,
    work).  RK4 and ETDRK4 run the step functions of the vector environments on one lane.
    """
    n = s0.shape[0]
    nq = n // 2
    s = s0.copy()
    s2 = s.reshape((n, 1))
    p2 = p.reshape((p.shape[0], 1))
    b3 = b.reshape((nb, b.shape[1], 1))
    k = np.empty((7, n))
    k3 = k.reshape((7, n, 1))
    tmp = np.empty((n, 1))
    tmp1 = np.empty(n)
    tt = np.empty(1)
    t1 = np.empty(1)
    h1 = np.empty(1)
    one = np.ones(1, dtype=np.uint8)
    s_new = np.empty(n)
    work = np.zeros((nb, mdl.WORK_COLUMNS, 1))
    wmat = np.empty((n, n))
    piv = np.empty(n, dtype=np.int64)
    lam = np.empty((n, 1))
    coef = np.empty((6, n, 1))
    nseg = seg_t.shape[0]
    j = 0
    while j + 1 < nseg and seg_t[j + 1] <= t_out[0]:
        j += 1
    dl.pin_prescribed(t_out[0], s2, 0, seg_d[j], nq)
    out[0, :] = s
    count = 0
    h_adapt = h
    fsal_valid = False
    for kk in range(t_out.shape[0] - 1):
        t = t_out[kk]
        t_end = t_out[kk + 1]
        while t < t_end:
            j_before = j
            j = enter_segment(t, s2, 0, seg_d, nseg, j, nq)
            if j != j_before:
                fsal_valid = False
            piece_end, m, hh = next_piece(t, t_end, seg_d, nseg, j, h)
            d = seg_d[j]
            d2 = d.reshape((d.shape[0], 1))
            if method == METHOD_DOPRI5:
                tp = t
                while tp < piece_end:
                    if not fsal_valid:
                        _rhs1(tp, s, p2, b3, d, k[0], work, tt, nb, spec)
                        count += 1
                    remaining = piece_end - tp
                    last = h_adapt >= remaining * (1.0 - 1e-12)
                    hh = remaining if last else h_adapt
                    err = _dopri5_attempt(tp, hh, s, p2, b3, d, k, tmp1, work, tt, s_new,
                                          rtol, atol, nb, spec)
                    count += 6
                    if not math.isfinite(err):
                        err = 1e10
                    fac = 0.9 * err ** -0.2 if err > 0 else 10.0
                    fac = min(10.0, max(0.2, fac))
                    if err <= 1.0:
                        tp = piece_end if last else tp + hh
                        for i in range(n):
                            s[i] = s_new[i]
                            k[0, i] = k[6, i]
                        fsal_valid = True
                        bad = _first_nonfinite(s)
                        if bad >= 0:
                            return STATUS_NONFINITE, tp, bad, count
                        if not last or fac < 1.0:
                            h_adapt = hh * fac
                    else:
                        h_adapt = hh * fac
                        fsal_valid = True  # k[0] still holds f(tp, s)
                        if h_adapt < 1e-14 * (1.0 + abs(tp)):
                            return STATUS_STEP_UNDERFLOW, tp, 0, count
            else:
                h1[0] = hh
                for i in range(m):
                    ti = t + i * hh
                    if method == METHOD_RK4:
                        t1[0] = ti
                        _rk4_step(t1, h1, s2, p2, b3, d2, k3, tmp, tt, work, one, nb, spec)
                    elif method == METHOD_ETDRK4:
                        t1[0] = ti
                        _etdrk4_step(t1, h1, s2, p2, b3, d2, k3, tmp, tt, work, lam, coef,
                                     one, nb, spec)
                    else:
                        _ros2_step(ti, hh, s, p2, b3, d, k, tmp1, work, tt, wmat, piv,
                                   nb, spec)
                    count += 1
                    bad = _first_nonfinite(s)
                    if bad >= 0:
                        return STATUS_NONFINITE, ti + hh, bad, count
            t = piece_end
            dl.pin_prescribed(t, s2, 0, d, nq)
            if d[dl.D_MODE] == dl.MODE_PRESCRIBED:
                fsal_valid = False  # the pinned state may differ from the FSAL state by rounding
        out[kk + 1, :] = s
    return STATUS_OK, t_out[-1], -1, count


run = Specialised(_run, literal=(0, 11, 12), names=("method", "balls", mdl.EFFECTS))
"""``run(method, s0, t_out, seg_t, seg_d, p, b, h, rtol, atol, out, nb, spec)``:
:func:`_run` compiled for this method, ball count ``nb`` and kernel specialisation ``spec``
(each combination once, then cached), so that the equations carry exactly the scene's terms."""

_NO_ATOL = np.zeros(1)


def rk4_run(s0, t_out, seg_t, seg_d, p, b, dt_max, out):
    """Fixed-step RK4 with step <= ``dt_max``; see :func:`run`."""
    return run.generic(METHOD_RK4, s0, t_out, seg_t, seg_d, p, b, dt_max, 0.0, _NO_ATOL, out,
                       b.shape[0], mdl.spec_of(p, seg_d))


class _WorkLimit(Exception):
    """Raised inside solve_ivp's right-hand side when the evaluation budget is spent."""


def scipy_run(s0, t_out, seg_t, seg_d, p, b, method="DOP853", rtol=1e-10, atol=1e-12, out=None,
              max_nfev=None):
    """Reference integration with ``solve_ivp`` restarted at every segment start.

    Returns (status, failure time, failing index, right-hand-side evaluations).  With
    ``max_nfev`` the run stops with :data:`STATUS_WORK_LIMIT` once it has evaluated the
    right-hand side that often (solve_ivp itself has no bound on its work).
    """
    n = s0.shape[0]
    nq = n // 2
    from scipy.integrate import solve_ivp

    out = np.empty((len(t_out), n)) if out is None else out
    spec = mdl.spec_of(p, seg_d)
    s = np.array(s0, dtype=float)
    bounds = [t_out[0]] + [t for t in seg_t if t_out[0] < t < t_out[-1]] + [t_out[-1]]
    nfev = 0
    calls = [0, t_out[0]]  # right-hand sides evaluated in all pieces, the last time seen
    for a, z in zip(bounds[:-1], bounds[1:]):
        j = int(np.searchsorted(seg_t, a + 1e-12 * (1 + abs(a)), side="right") - 1)
        d = seg_d[max(j, 0)]
        dl.pin_prescribed(a, s.reshape((n, 1)), 0, d, nq)
        if a == t_out[0]:
            out[0] = s

        def rhs(t, y, d=d):
            # every call counts, the Jacobian's finite differences too (sol.nfev omits them)
            calls[0] += 1
            calls[1] = t
            if max_nfev is not None and calls[0] > max_nfev:
                raise _WorkLimit
            ds = np.empty(n)
            mdl.state_derivative(t, np.ascontiguousarray(y), p, b, d, ds, spec)
            return ds

        mask = (t_out > a) & (t_out <= z)
        t_eval = t_out[mask]
        if not (len(t_eval) and t_eval[-1] == z):
            t_eval = np.append(t_eval, z)
        try:
            with np.errstate(over="ignore"):  # scipy's finite-difference Jacobian probes far
                sol = solve_ivp(rhs, (a, z), s, method=method, rtol=rtol, atol=atol,
                                t_eval=t_eval)
        except _WorkLimit:
            return STATUS_WORK_LIMIT, float(calls[1]), 0, calls[0]
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
