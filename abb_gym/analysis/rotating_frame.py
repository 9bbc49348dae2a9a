"""Constant-speed balancer in the rotating frame: equilibria, linearisation, eigenvalues.

Model (isotropic support, n balls, race eccentricity E at angle gamma), in Lu & Hung's
dimensionless variables (lengths / e, time * w_n, masses / M; see :mod:`.groups`).  With the
rotor-centre position in the co-rotating frame written as the complex number ``w = u + i v``
and the ball angles ``b_i`` measured from the imbalance, Spannan's (4.14), (4.15), (4.17) with
``th = Omega t`` become (multiply the fixed-frame equations by ``exp(-i Omega t)``)::

    w'' + 2 i Omega w' - Omega^2 w + i sum a_i e^{i b_i} b_i''
        = -2 zeta (w' + i Omega w) - w + mu Omega^2
          + sum [ E m_i Omega^2 e^{i gamma} + a_i (Omega + b_i')^2 e^{i b_i} ]
    I_i b_i'' + a_i Im( e^{-i b_i} (w'' + 2 i Omega w' - Omega^2 w) )
        = -beta_i b_i' + a_i E Omega^2 sin(gamma - b_i)

with ``a_i = mu eta_i`` (ball imbalance), ``m_i = mu eta_i / delta`` (ball mass),
``I_i = a_i delta (1 + spin_i)`` (ball inertia about the rotor axis, rolling spin included),
``beta_i = 2 zeta_b,i a_i delta`` (race drag torque).  For E = 0 and spin = 0 this is exactly
Lu & Hung's Eq. (8) (checked in the tests against the printed matrices M, C, G, f).

Equilibria (q' = 0).  The ball equations require ``Im(e^{-i b_i} p) = 0`` with
``p = w + E e^{i gamma}`` (the race centre): either

* ``p = 0`` - the *balanced* family, rotor centre at ``w = -E e^{i gamma}`` (|w| = E, Spannan
  L899) and ``sum a_i e^{i b_i} = T(Omega)``; an (n - 2)-parameter family for n >= 3, or
* every ball on the line of p (at its angle or opposite): the *unbalanced* equilibria.  For a
  sign pattern s_i = +-1, with ``S = sum s_i a_i`` and ``Z = Omega^2 - 1 - 2 i zeta Omega``,
  ``|Z rho + Omega^2 S| = |G|`` is a quadratic in rho = |p| (Lu & Hung eqs. 14-24 for E = 0).

Linearisation.  At an equilibrium (q' = q'' = 0) ``M(q0) dq'' = K dq + C dq'`` with K, C the
exact partial derivatives of the right-hand side (written out in :func:`jacobian`); the
first-order matrix is ``A = [[0, I], [M^-1 K, M^-1 C]]`` of size 2 (2 + n).

Structural zero eigenvalues (recorded decision).  Along the balanced family, A has the n - 2
tangent directions of the family in its kernel.  Instead of dropping "the eigenvalue nearest
zero" (the note's recipe, A5) the analysis takes the exact quotient: with V an orthonormal
basis of the tangent space (null space of ``[Re, Im] of (i a_i e^{i b_i})``) and W an
orthonormal basis of its complement, the remaining eigenvalues are those of ``W^T A W``
(A V = 0, so the induced map on R^N / span V is W^T A W).  A member is stable when the largest
real part of these is below ``-tol`` (normal hyperbolicity, note A5).  The family is reported
both as the *union* (some member stable: balancing is possible, Lu & Hung's criterion) and per
member (``all_stable``: every member stable).

All eigenvalues are in units of w_n.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from ..physics.scene import Scene
from .groups import Groups

__all__ = ["Equilibrium", "FamilyStability", "coefficients", "residual", "jacobian",
           "eigenvalues", "unbalanced_equilibria", "balanced_target", "balanced_family",
           "family_stability", "equilibria", "rhs", "as_groups", "DEFAULT_TOL", "OMEGA_RANGE",
           "MAX_FAMILY_CANDIDATES", "family_candidates", "check_family_size"]

DEFAULT_TOL = 1e-9


def as_groups(system: Groups | Scene, length_scale: float | None = None) -> Groups:
    """Groups of a Groups or a Scene (see :meth:`Groups.from_scene`)."""
    if isinstance(system, Groups):
        return system
    if isinstance(system, Scene):
        return Groups.from_scene(system, length_scale)
    raise ValueError(f"system must be Groups or Scene (got {type(system).__name__})")


#: Range of the speed ratio Omega = w / w_n: beyond it (5e-324, 1e308) the eigenvalue problems
#: divide by zero or overflow (the groups have ranges for the same reason, :mod:`.groups`).
OMEGA_RANGE = (1e-3, 1e3)


def _check_omega(omega: float) -> float:
    try:
        om = math.nan if isinstance(omega, (bool, str, bytes)) else float(omega)
    except (TypeError, ValueError, OverflowError):
        om = math.nan
    lo, hi = OMEGA_RANGE
    if not (math.isfinite(om) and lo <= om <= hi):
        raise ValueError(f"Omega (speed ratio w/w_n) must be in [{lo:g}, {hi:g}] (got "
                         f"{omega!r:.80})")
    return om


@dataclass(frozen=True)
class _Coef:
    a: np.ndarray       # ball imbalances mu eta_i
    m: np.ndarray       # ball masses mu eta_i / delta
    inertia: np.ndarray  # a_i delta (1 + spin_i)
    beta: np.ndarray    # 2 zeta_b a_i delta
    mu: float
    zeta: float
    ecc: complex        # E e^{i gamma}


def coefficients(g: Groups) -> _Coef:
    """Per-ball coefficients of the dimensionless equations (see the module docstring)."""
    a = g.mu * g.per_ball("eta")
    return _Coef(a=a, m=a / g.delta, inertia=a * g.delta * (1.0 + g.per_ball("spin")),
                 beta=2.0 * g.per_ball("zeta_b") * a * g.delta, mu=g.mu, zeta=g.zeta,
                 ecc=g.race_eccentricity * complex(math.cos(g.race_angle),
                                                   math.sin(g.race_angle)))


def _mass_matrix(c: _Coef, b: np.ndarray) -> np.ndarray:
    """Mass matrix M(b) at ball angles ``b`` (n,), or a stack of them for ``b`` (k, n)."""
    b = np.asarray(b, float)
    n = b.shape[-1]
    mm = np.zeros(b.shape[:-1] + (2 + n, 2 + n))
    mm[..., 0, 0] = mm[..., 1, 1] = 1.0
    s, co = np.sin(b), np.cos(b)
    mm[..., 0, 2:] = mm[..., 2:, 0] = -c.a * s
    mm[..., 1, 2:] = mm[..., 2:, 1] = c.a * co
    idx = np.arange(n)
    mm[..., 2 + idx, 2 + idx] = c.inertia
    return mm


def _forces(c: _Coef, om: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Right-hand side F(q, q') (everything except the mass-matrix terms)."""
    n = len(q) - 2
    w = complex(q[0], q[1])
    wd = complex(qd[0], qd[1])
    b, bd = q[2:], qd[2:]
    eb = np.exp(1j * b)
    fw = (-2 * c.zeta * (wd + 1j * om * w) - w - (2j * om * wd - om * om * w) + c.mu * om * om
          + c.ecc * om * om * c.m.sum() + np.sum(c.a * (om + bd) ** 2 * eb))
    inner = 2j * om * wd - om * om * w
    fb = (-c.beta * bd + c.a * om * om * np.imag(c.ecc * np.conj(eb))
          - c.a * np.imag(np.conj(eb) * inner))
    out = np.empty(2 + n)
    out[0], out[1] = fw.real, fw.imag
    out[2:] = fb
    return out


def residual(system: Groups | Scene, omega: float, q) -> np.ndarray:
    """Static residual F(q, 0) of the equilibrium equations (zero at an equilibrium).

    q = [u, v, b_1..b_n]: rotor-centre position in the rotating frame [units of e] and ball
    angles [rad].
    """
    g = as_groups(system)
    q = np.asarray(q, float)
    if q.shape != (2 + g.n_balls,):
        raise ValueError(f"q must have 2 + n_balls = {2 + g.n_balls} entries (got {q.shape})")
    return _forces(coefficients(g), _check_omega(omega), q, np.zeros_like(q))


def rhs(system: Groups | Scene, omega: float):
    """The nonlinear first-order ODE ``s' = f(t, s)`` in the rotating frame, s = [q, q']
    (dimensionless time t* = w_n t).  For quick checks; the physics simulator is
    :func:`abb_gym.simulate`."""
    g = as_groups(system)
    c = coefficients(g)
    om = _check_omega(omega)
    nq = 2 + g.n_balls

    def f(t, s):
        q, qd = s[:nq], s[nq:]
        return np.concatenate([qd, np.linalg.solve(_mass_matrix(c, q[2:]),
                                                   _forces(c, om, q, qd))])
    return f


def jacobian(system: Groups | Scene, omega: float, q) -> np.ndarray:
    """First-order system matrix A (2(2+n) square) of the linearisation at an equilibrium q.

    Exact derivatives (the formulas are derived in the module docstring's complex notation):
    ``dF_w/dw = Omega^2 - 1 - 2 i zeta Omega``, ``dF_w/db_i = i a_i Omega^2 e^{i b_i}``,
    ``dF_w/dw' = -2 zeta - 2 i Omega``, ``dF_w/db_i' = 2 a_i Omega e^{i b_i}``,
    ``dF_bi/db_i = -a_i Omega^2 Re(e^{-i b_i} (w + E e^{i gamma}))``,
    ``dF_bi/dw = a_i Omega^2 Im(e^{-i b_i} dw)``, ``dF_bi/dw' = -2 a_i Omega Re(e^{-i b_i} dw')``,
    ``dF_bi/db_i' = -beta_i``.  Only valid at an equilibrium (q' = 0, q'' = 0).
    """
    g = as_groups(system)
    c = coefficients(g)
    om = _check_omega(omega)
    q = np.asarray(q, float)
    nq = 2 + g.n_balls
    if q.shape != (nq,):
        raise ValueError(f"q must have 2 + n_balls = {nq} entries (got {q.shape})")
    return _jacobians(c, om, complex(q[0], q[1]), q[None, 2:])[0]


def _jacobians(c: _Coef, om: float, w: complex, b: np.ndarray) -> np.ndarray:
    """:func:`jacobian` of the equilibria with rotor centre ``w`` and ball angles ``b`` (k, n):
    a stack (k, 2 (2 + n), 2 (2 + n)), so that a family is linearised in one pass."""
    k_members, n = b.shape
    nq = 2 + n
    s, co = np.sin(b), np.cos(b)
    p = w + c.ecc
    aoo = c.a * om * om
    k = np.zeros((k_members, nq, nq))
    cm = np.zeros((k_members, nq, nq))
    idx = 2 + np.arange(n)
    z = complex(om * om - 1.0, -2 * c.zeta * om)
    k[:, 0, 0], k[:, 1, 0] = z.real, z.imag
    k[:, 0, 1], k[:, 1, 1] = -z.imag, z.real
    k[:, 0, 2:] = k[:, 2:, 0] = -aoo * s
    k[:, 1, 2:] = k[:, 2:, 1] = aoo * co
    # Re(e^{-i b} p) = cos b Re p + sin b Im p
    k[:, idx, idx] = -aoo * (co * p.real + s * p.imag)
    zd = complex(-2 * c.zeta, -2 * om)
    cm[:, 0, 0], cm[:, 1, 0] = zd.real, zd.imag
    cm[:, 0, 1], cm[:, 1, 1] = -zd.imag, zd.real
    cm[:, 0, 2:] = 2 * c.a * om * co
    cm[:, 1, 2:] = 2 * c.a * om * s
    cm[:, 2:, 0] = -2 * c.a * om * co
    cm[:, 2:, 1] = -2 * c.a * om * s
    cm[:, idx, idx] = -c.beta
    minv = np.linalg.inv(_mass_matrix(c, b))
    a = np.zeros((k_members, 2 * nq, 2 * nq))
    a[:, :nq, nq:] = np.eye(nq)
    a[:, nq:, :nq] = minv @ k
    a[:, nq:, nq:] = minv @ cm
    return a


def eigenvalues(system: Groups | Scene, omega: float, q, *, balanced: bool | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """(eigenvalues, structural eigenvalues) of the linearisation at equilibrium q.

    For a member of the balanced family (``balanced`` True, or None and |w + E e^{i gamma}|
    below 1e-9) the n - 2 structural zero eigenvalues of the family's tangent directions are
    removed exactly (quotient, module docstring); the second array holds the n - 2
    eigenvalues of smallest modulus of the full matrix (zero to round-off: a check that the
    family is a manifold of equilibria there).  Otherwise the second array is empty.
    Eigenvalues are in units of w_n.
    """
    g = as_groups(system)
    c = coefficients(g)
    q = np.asarray(q, float)
    a = jacobian(g, omega, q)
    if balanced is None:
        balanced = abs(complex(q[0], q[1]) + c.ecc) < 1e-9
    if not balanced:
        return np.linalg.eigvals(a), np.zeros(0, complex)
    return _member_spectra(c, a[None], q[None, 2:])[0]


def _member_spectra(c: _Coef, a: np.ndarray, b: np.ndarray
                    ) -> list[tuple[np.ndarray, np.ndarray]]:
    """(eigenvalues, structural eigenvalues) of :func:`eigenvalues` for members of the
    balanced family with ball angles ``b`` (k, n) and Jacobians ``a`` (k, N, N), computed as
    stacks (one LAPACK call per kind for the whole family).

    The family's tangent space at a member is the null space V of ``[Re, Im]`` of
    ``d/db sum a_i e^{i b_i}`` (from its SVD; its dimension n - rank is n - 2, or n - 1 where
    every ball is on one line); W, the orthonormal complement of span(V), comes from the QR
    factorisation of [V, I].  Members are grouped by that dimension."""
    k_members, n = b.shape
    size = a.shape[-1]
    out: list = [None] * k_members
    if k_members == 0:
        return out
    cons = np.stack([-c.a * np.sin(b), c.a * np.cos(b)], axis=1)   # (k, 2, n)
    _, sv, vt = np.linalg.svd(cons)
    scale = np.maximum(1.0, sv.max(axis=1, initial=0.0))
    rank = np.sum(sv > 1e-12 * scale[:, None], axis=1)
    full = np.linalg.eigvals(a)
    for r in np.unique(rank):
        sel = np.flatnonzero(rank == r)
        dim = n - int(r)
        if dim == 0:
            for i in sel:
                out[i] = (full[i], np.zeros(0, complex))
            continue
        basis = np.zeros((len(sel), size, dim))
        basis[:, 2:2 + n, :] = np.swapaxes(vt[sel, r:, :], 1, 2)
        eye = np.broadcast_to(np.eye(size), (len(sel), size, size))
        qfull, _ = np.linalg.qr(np.concatenate([basis, eye], axis=2))
        w = qfull[:, :, dim:size]
        reduced = np.linalg.eigvals(np.swapaxes(w, 1, 2) @ a[sel] @ w)
        nearest = np.argsort(np.abs(full[sel]), axis=1)[:, :dim]
        structural = np.take_along_axis(full[sel], nearest, axis=1)
        for j, i in enumerate(sel):
            out[i] = (reduced[j], structural[j])
    return out


def _family_spectra(c: _Coef, om: float, members: np.ndarray
                    ) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`eigenvalues` of every member (rows of ball angles) of the balanced family."""
    if len(members) == 0:
        return []
    return _member_spectra(c, _jacobians(c, om, -c.ecc, members), members)


# ---------------------------------------------------------------------------- equilibria
@dataclass
class Equilibrium:
    """One equilibrium of the rotating-frame system.

    ``kind`` is "balanced" (rotor centre at -E e^{i gamma}) or "unbalanced"; ``signs`` the
    ball pattern of an unbalanced one (+1: ball at the angle ``theta`` of the race centre p,
    -1: opposite); ``signed_count`` = sum of signs (Lu & Hung: +3 case i, -3 ii, +1 iii,
    -1 iv); ``branch`` 1 or 2 (the +- root of the quadratic).  ``q`` = [u, v, b_1..b_n]
    (u, v in units of e, angles in rad), ``radius`` = |w| [e], ``rho`` = |p| [e],
    ``eigenvalues`` in units of w_n (structural zeros removed), ``stable`` max Re < -tol.
    """

    kind: str
    q: np.ndarray
    radius: float
    theta: float
    eigenvalues: np.ndarray
    stable: bool
    signs: tuple[int, ...] = ()
    branch: int = 0
    rho: float = 0.0
    structural: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))

    @property
    def signed_count(self) -> int:
        return int(sum(self.signs))

    @property
    def max_real(self) -> float:
        """Largest real part of the (non-structural) eigenvalues [w_n]."""
        return float(np.max(self.eigenvalues.real))

    @property
    def ball_angles(self) -> np.ndarray:
        """Ball angles wrapped to [0, 2 pi) [rad]."""
        return np.mod(self.q[2:], 2 * np.pi)


def _translation_constant(c: _Coef, om: float) -> complex:
    """G in (Z rho + Omega^2 S) e^{i theta} = -G (module docstring)."""
    z = complex(om * om - 1.0, -2 * c.zeta * om)
    return -z * c.ecc + c.mu * om * om + c.ecc * om * om * c.m.sum()


def unbalanced_equilibria(system: Groups | Scene, omega: float, *, tol: float = DEFAULT_TOL,
                          with_eigenvalues: bool = True) -> list[Equilibrium]:
    """All unbalanced equilibria (every ball on the line of the race centre), rho > 0.

    Identical balls: one representative per signed count (sign patterns that only permute
    identical balls are the same state).  Otherwise all 2^n patterns.  For E = 0 these are
    Lu & Hung's cases (i)-(iv) with the +- branches (eqs. 14-24), generalised to n balls.
    """
    g = as_groups(system)
    c = coefficients(g)
    om = _check_omega(omega)
    n = g.n_balls
    z = complex(om * om - 1.0, -2 * c.zeta * om)
    gconst = _translation_constant(c, om)
    if g.identical_balls:
        patterns = [tuple([1] * (n - k) + [-1] * k) for k in range(n + 1)]
    else:
        patterns = list(itertools.product((1, -1), repeat=n))
    out = []
    for signs in patterns:
        sgn = np.asarray(signs, float)
        big_s = float(np.sum(sgn * c.a))
        # |Z|^2 rho^2 + 2 Re(Z) Om^2 S rho + Om^4 S^2 - |G|^2 = 0
        qa = abs(z) ** 2
        qb = 2 * z.real * om * om * big_s
        qc = om ** 4 * big_s ** 2 - abs(gconst) ** 2
        disc = qb * qb - 4 * qa * qc
        if disc < 0:
            continue
        roots = [(-qb + math.sqrt(disc)) / (2 * qa), (-qb - math.sqrt(disc)) / (2 * qa)]
        for branch, rho in enumerate(roots, start=1):
            if rho <= 1e-12:
                continue
            theta = math.atan2((-gconst).imag, (-gconst).real) - \
                math.atan2((z * rho + om * om * big_s).imag, (z * rho + om * om * big_s).real)
            p = rho * complex(math.cos(theta), math.sin(theta))
            w = p - c.ecc
            b = theta + np.where(sgn > 0, 0.0, np.pi)
            q = np.concatenate([[w.real, w.imag], b])
            if with_eigenvalues:
                ev, _ = eigenvalues(g, om, q, balanced=False)
                stable = bool(np.max(ev.real) < -tol)
            else:
                ev, stable = np.zeros(0, complex), False
            out.append(Equilibrium(kind="unbalanced", q=q, radius=abs(w),
                                   theta=math.atan2(w.imag, w.real), eigenvalues=ev,
                                   stable=stable, signs=tuple(int(s) for s in signs),
                                   branch=branch, rho=rho))
    return out


def balanced_target(system: Groups | Scene, omega: float) -> complex:
    """T with ``sum a_i e^{i b_i} = T`` on the balanced family (rotor centre at -E e^{i gamma}).

    ``T = -mu - E e^{i gamma} sum m_i + (1 - 1/Omega^2 - 2 i zeta/Omega) E e^{i gamma}``
    (for E = 0: sum eta_i e^{i b_i} = -1, Lu & Hung eqs. 25-26).
    """
    g = as_groups(system)
    c = coefficients(g)
    om = _check_omega(omega)
    return (-c.mu - c.ecc * c.m.sum()
            + complex(1.0 - 1.0 / (om * om), -2 * c.zeta / om) * c.ecc)


def _two_ball(a1: float, a2: float, target: complex, sign: int):
    """b1, b2 with a1 e^{i b1} + a2 e^{i b2} = target, or None if impossible."""
    rho = abs(target)
    if rho < 1e-300:
        if abs(a1 - a2) > 1e-12 * max(a1, a2):
            return None
        return 0.0, math.pi
    c1 = (rho * rho + a1 * a1 - a2 * a2) / (2 * a1 * rho)
    c2 = (rho * rho + a2 * a2 - a1 * a1) / (2 * a2 * rho)
    if abs(c1) > 1 + 1e-12 or abs(c2) > 1 + 1e-12:
        return None
    psi = math.atan2(target.imag, target.real)
    g1 = math.acos(max(-1.0, min(1.0, c1)))
    g2 = math.acos(max(-1.0, min(1.0, c2)))
    return psi + sign * g1, psi - sign * g2


#: Most candidate members :func:`balanced_family` samples per call: ``n_members ** (n - 2)``
#: for n >= 4 balls grows without bound (13 members and 8 balls: 4.8e6 candidates, a minute;
#: 2 members and 32 balls: 1e9, hours), so larger requests are refused up front.
MAX_FAMILY_CANDIDATES = 10 ** 6


def family_candidates(n_balls: int, n_members: int) -> float:
    """Candidate members :func:`balanced_family` samples for ``n_balls`` balls and
    ``n_members`` (a float: it may be astronomically large)."""
    if n_balls <= 2:
        return 1.0
    return float(n_members) ** max(1, n_balls - 2)


def check_family_size(n_balls: int, n_members: int) -> None:
    """Raise ValueError naming ``n_members`` and ``n_balls`` if the family sampling would take
    more than :data:`MAX_FAMILY_CANDIDATES` candidates."""
    if isinstance(n_members, (bool, np.bool_)) or not isinstance(n_members, (int, np.integer)) \
            or n_members < 1:
        raise ValueError(f"n_members must be an integer >= 1 (got {n_members!r:.80})")
    count = family_candidates(n_balls, n_members)
    if count > MAX_FAMILY_CANDIDATES:
        largest = int(MAX_FAMILY_CANDIDATES ** (1.0 / max(1, n_balls - 2)))
        raise ValueError(f"n_members = {n_members} with n_balls = {n_balls} samples "
                         f"{count:.3g} candidate members ({n_members}^{max(1, n_balls - 2)}); "
                         f"at most {MAX_FAMILY_CANDIDATES:.0e}: use n_members <= {largest} or "
                         f"fewer balls")


def balanced_family(system: Groups | Scene, omega: float, n_members: int = 13
                    ) -> np.ndarray:
    """Members of the balanced family, shape (k, n) ball angles [rad] (k may be 0).

    * n = 1: the single ball at T's angle if |T| = a_1 (generically none).
    * n = 2: the isolated solutions (one for identical balls; two mirror states otherwise).
    * n = 3: Lu & Hung's discretisation (L228): the allowed arc of b_3 (eq. 35 for E = 0) is
      split into ``n_members`` intervals and the midpoints are taken; b_1, b_2 from the
      two-ball closed form (eq. 34, atan2 form).  Both branches when the balls differ.
    * n >= 4: b_3..b_n on a grid of ``n_members`` points per angle over the circle, feasible
      points kept, thinned evenly to at most ``n_members**2`` members.
    """
    g = as_groups(system)
    c = coefficients(g)
    n = g.n_balls
    check_family_size(n, n_members)
    t = balanced_target(g, omega)
    a = c.a
    signs = (1,) if g.identical_balls else (1, -1)
    if n == 1:
        if abs(abs(t) - a[0]) < 1e-12 * a[0]:
            return np.array([[math.atan2(t.imag, t.real)]])
        return np.zeros((0, 1))
    if n == 2:
        out = [sol for s in signs if (sol := _two_ball(a[0], a[1], t, s)) is not None]
        return np.array(out).reshape(-1, 2)
    members = []
    if n == 3:
        arcs = _third_ball_arcs(a, t)
        per_arc = max(1, n_members // max(1, len(arcs)))
        for lo, hi in arcs:
            edges = np.linspace(lo, hi, per_arc + 1)
            for b3 in 0.5 * (edges[:-1] + edges[1:]):
                rest = t - a[2] * complex(math.cos(b3), math.sin(b3))
                for s in signs:
                    sol = _two_ball(a[0], a[1], rest, s)
                    if sol is not None:
                        members.append([sol[0], sol[1], b3])
        return np.array(members).reshape(-1, 3)
    grid = (np.arange(n_members) + 0.5) * 2 * np.pi / n_members
    for free in itertools.product(grid, repeat=n - 2):
        rest = t - np.sum(a[2:] * np.exp(1j * np.asarray(free)))
        for s in signs:
            sol = _two_ball(a[0], a[1], rest, s)
            if sol is not None:
                members.append([sol[0], sol[1], *free])
    arr = np.array(members).reshape(-1, n)
    cap = n_members ** 2
    if len(arr) > cap:
        arr = arr[np.linspace(0, len(arr) - 1, cap).round().astype(int)]
    return arr


def _third_ball_arcs(a: np.ndarray, t: complex) -> list[tuple[float, float]]:
    """Allowed intervals of b_3 for three balls (module docstring); empty if none.

    |t - a_3 e^{i b_3}| must lie in [|a_1 - a_2|, a_1 + a_2].  For E = 0 and identical balls
    this is Lu & Hung's [beta*, 2 pi - beta*] (eqs. 32-36)."""
    rt = abs(t)
    lo_r, hi_r = abs(a[0] - a[1]), a[0] + a[1]
    if rt < 1e-300:
        return [(0.0, 2 * np.pi)] if lo_r <= a[2] <= hi_r else []
    psi = math.atan2(t.imag, t.real)
    c_min = (rt * rt + a[2] ** 2 - hi_r ** 2) / (2 * a[2] * rt)   # cos(b - psi) >= c_min
    c_max = (rt * rt + a[2] ** 2 - lo_r ** 2) / (2 * a[2] * rt)   # cos(b - psi) <= c_max
    if c_min > 1 + 1e-12 or c_max < -1 - 1e-12:
        return []
    half = math.acos(max(-1.0, min(1.0, c_min)))
    if c_max < 1.0:          # unequal balls: two arcs, symmetric about psi
        inner = math.acos(max(-1.0, min(1.0, c_max)))
        return [(psi - half, psi - inner), (psi + inner, psi + half)]
    return [(psi - half, psi + half)]


@dataclass
class FamilyStability:
    """Stability of the sampled balanced family at one speed.

    ``members`` (k, n) ball angles [rad]; ``max_real`` (k,) largest non-structural real part
    of each member [w_n]; ``structural`` (k,) largest |structural eigenvalue| (a round-off
    check, ~1e-15); ``union_stable``: some member stable (Lu & Hung's union); ``all_stable``:
    every member stable; ``exists``: the family is not empty.
    """

    omega: float
    members: np.ndarray
    max_real: np.ndarray
    structural: np.ndarray
    tol: float = DEFAULT_TOL

    @property
    def exists(self) -> bool:
        return len(self.members) > 0

    @property
    def stable_mask(self) -> np.ndarray:
        return self.max_real < -self.tol

    @property
    def union_stable(self) -> bool:
        return bool(np.any(self.stable_mask))

    @property
    def all_stable(self) -> bool:
        return bool(self.exists and np.all(self.stable_mask))

    @property
    def fraction_stable(self) -> float:
        return float(np.mean(self.stable_mask)) if self.exists else 0.0

    @property
    def best(self) -> float:
        """Smallest max-real over the members (the most stable member) [w_n]."""
        return float(np.min(self.max_real)) if self.exists else math.nan

    @property
    def worst(self) -> float:
        return float(np.max(self.max_real)) if self.exists else math.nan


def family_stability(system: Groups | Scene, omega: float, n_members: int = 13,
                     tol: float = DEFAULT_TOL) -> FamilyStability:
    """Eigenvalue stability of every sampled member of the balanced family (see
    :func:`balanced_family`), structural zeros removed exactly."""
    g = as_groups(system)
    c = coefficients(g)
    om = _check_omega(omega)
    mem = balanced_family(g, om, n_members)
    spectra = _family_spectra(c, om, mem)
    mr = np.array([np.max(ev.real) for ev, _ in spectra], dtype=float)
    st = np.array([np.max(np.abs(s)) if len(s) else 0.0 for _, s in spectra], dtype=float)
    return FamilyStability(omega=om, members=mem, max_real=mr, structural=st, tol=tol)


def equilibria(system: Groups | Scene, omega: float, n_members: int = 13,
               tol: float = DEFAULT_TOL) -> list[Equilibrium]:
    """Every equilibrium at speed ratio ``omega``: the unbalanced ones and the sampled
    members of the balanced family (each with eigenvalues and a stability flag)."""
    g = as_groups(system)
    c = coefficients(g)
    om = _check_omega(omega)
    out = unbalanced_equilibria(g, om, tol=tol)
    members = balanced_family(g, om, n_members)
    w = -c.ecc
    for b, (ev, structural) in zip(members, _family_spectra(c, om, members)):
        q = np.concatenate([[w.real, w.imag], b])
        out.append(Equilibrium(kind="balanced", q=q, radius=abs(w),
                               theta=math.atan2(w.imag, w.real) if abs(w) else 0.0,
                               eigenvalues=ev, stable=bool(np.max(ev.real) < -tol),
                               structural=structural))
    return out
