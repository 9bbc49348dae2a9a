"""Closed-form equilibria of the n-ball balancer, Lu & Hung (2008) eqs. 14-36.

All quantities are Lu & Hung's dimensionless ones (see :mod:`.groups`): amplitudes r~ in
units of the disk eccentricity e, speed ratio Omega = w/w_n, angles in rad measured from the
direction of the disk's mass centre G (the primary imbalance).  Race eccentricity is not part
of the paper; with E != 0 use :mod:`.rotating_frame`, which reduces to these formulas at E = 0
(checked in the tests).

Decisions recorded here (physics note A4):

* theta uses ``atan2(-2 zeta Omega r~, (1 - Omega^2) r~ - m mu eta Omega^2)``: the equations
  give ``cos th = a/(mu Omega^2)``, ``sin th = -2 zeta Omega r~/(mu Omega^2)``; the printed
  plain arctan (eqs. 17, 19, 22, 24) picks the wrong quadrant.
* Eq. (34) uses atan2 for ``phi`` (eq. 29) for the same reason.
* The n-ball generalisation: the unbalanced cases are indexed by the signed equivalent ball
  count ``m`` (balls at theta minus balls at theta + pi), m = n, n-2, ..., -n; Lu & Hung's
  cases (i)-(iv) are m = +3, -3, +1, -1.  ``D_m = (1-Omega^2)^2 + 4 (1 - m^2 eta^2) zeta^2
  Omega^2`` (eqs. 16, 21).
* Allowed ball range for n >= 3 identical balls: a ball at b can be completed to a balanced
  set iff the other n - 1 balls can reach the vector ``(-1/eta - cos b, -sin b)``, i.e.
  ``cos b <= A_n(eta) = (n (n-2) eta^2 - 1)/(2 eta)``; n = 3 gives eq. (32)
  ``A = (3 eta^2 - 1)/(2 eta)``.  The n = 2 balancer has no range, only the two positions
  ``pi -+ acos(1/(2 eta))``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["balance_exists", "minimum_eta", "range_bound", "allowed_ball_range",
           "two_ball_positions", "three_ball_positions", "UnbalancedBranch",
           "unbalanced_branches", "amplification_factor", "discriminant",
           "saddle_node_speeds", "CASE_SIGNED_COUNT"]

# Lu & Hung's case numbers -> signed equivalent ball count
CASE_SIGNED_COUNT = {1: 3, 2: -3, 3: 1, 4: -1}


def _pos(name: str, v: float, allow_zero: bool = False) -> float:
    v = float(v)
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise ValueError(f"{name} must be {'>=' if allow_zero else '>'} 0 (got {v!r})")
    return v


def _count(n: int) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n_balls must be an integer >= 1 (got {n!r})")
    return int(n)


def minimum_eta(n_balls: int) -> float:
    """Smallest eta for which n identical balls can balance: 1/n (L188, L198)."""
    return 1.0 / _count(n_balls)


def balance_exists(n_balls: int, eta: float) -> bool:
    """Perfect balancing exists iff ``n eta >= 1`` (identical balls, no race eccentricity)."""
    n = _count(n_balls)
    return n * _pos("eta", eta) >= 1.0 - 1e-12


def range_bound(eta: float, n_balls: int = 3) -> float:
    """A_n(eta) = (n (n-2) eta^2 - 1)/(2 eta): a ball of a balanced set has cos b <= A_n.

    n = 3: Lu & Hung eq. (32), A(1/3) = -1, A(1/sqrt 3) = 0, A(1) = 1.
    """
    n = _count(n_balls)
    if n < 3:
        raise ValueError(f"n_balls must be >= 3 for a ball range (got {n}); two balls have "
                         f"fixed positions, see two_ball_positions")
    eta = _pos("eta", eta)
    return (n * (n - 2) * eta * eta - 1.0) / (2.0 * eta)


def allowed_ball_range(eta: float, n_balls: int = 3) -> tuple[float, float]:
    """[beta*, 2 pi - beta*] [rad]: where every ball of a balanced set must lie (eqs. 33-36).

    beta* = acos(A_n(eta)), clipped to [0, pi]: 0 (no restriction) when A_n >= 1.
    Raises ValueError when the balls cannot balance (n eta < 1).
    """
    n = _count(n_balls)
    if not balance_exists(n, eta):
        raise ValueError(f"eta = {eta:g} with n_balls = {n} cannot balance: needs n*eta >= 1 "
                         f"(eta >= {1.0 / n:g})")
    a = range_bound(eta, n)
    beta_star = math.acos(max(-1.0, min(1.0, a)))
    return beta_star, 2.0 * math.pi - beta_star


def two_ball_positions(eta: float) -> tuple[float, float]:
    """Balancing positions of two balls, ``pi -+ acos(1/(2 eta))`` [rad] (needs eta >= 1/2)."""
    eta = _pos("eta", eta)
    if 2 * eta < 1.0 - 1e-12:
        raise ValueError(f"eta must be >= 0.5 for two balls to balance (got {eta:g})")
    g = math.acos(min(1.0, 1.0 / (2.0 * eta)))
    return math.pi - g, math.pi + g


def three_ball_positions(eta: float, b3: float) -> tuple[float, float, float]:
    """Balls 1 and 2 of the balanced family for a given ball 3 at ``b3`` [rad] (eq. 34).

    ``b1,2 = pi -+ acos(sqrt(eta^2 + 2 eta cos b3 + 1)/(2 eta)) + atan2(eta sin b3,
    eta cos b3 + 1)``.  Raises ValueError if ``b3`` is outside the allowed range (eq. 35).
    """
    eta = _pos("eta", eta)
    b3 = float(b3)
    lo, hi = allowed_ball_range(eta, 3)
    c = (eta * eta + 2 * eta * math.cos(b3) + 1.0)
    arg = math.sqrt(max(c, 0.0)) / (2.0 * eta)
    if arg > 1.0 + 1e-12:
        raise ValueError(f"b3 = {b3:g} rad is outside the allowed range [{lo:.6g}, {hi:.6g}] "
                         f"rad for eta = {eta:g} (eq. 35)")
    g = math.acos(min(1.0, arg))
    phi = math.atan2(eta * math.sin(b3), eta * math.cos(b3) + 1.0)
    return math.pi - g + phi, math.pi + g + phi, b3


def amplification_factor(omega: float, zeta: float, mu: float) -> float:
    """K = mu Omega^2 / ((1 - Omega^2)^2 + 4 zeta^2 Omega^2) (eq. 15)."""
    om = _pos("Omega", omega)
    return mu * om * om / ((1 - om * om) ** 2 + 4 * zeta * zeta * om * om)


def discriminant(omega: float, zeta: float, eta: float, signed_count: int) -> float:
    """D_m = (1 - Omega^2)^2 + 4 (1 - m^2 eta^2) zeta^2 Omega^2 (eqs. 16, 21)."""
    om = _pos("Omega", omega)
    return (1 - om * om) ** 2 + 4 * (1 - signed_count ** 2 * eta * eta) * zeta * zeta * om * om


def saddle_node_speeds(zeta: float, eta: float, signed_count: int = 3
                       ) -> tuple[float, float] | None:
    """Speeds where the branch pair of signed count m appears/disappears (D_m = 0).

    For |m| eta > 1: ``Omega = -+ zeta s + sqrt(zeta^2 s^2 + 1)`` with
    ``s = sqrt(m^2 eta^2 - 1)``; the pair exists outside that interval.  None if |m| eta <= 1
    (the pair exists at every speed).
    """
    zeta = _pos("zeta", zeta, allow_zero=True)
    eta = _pos("eta", eta)
    if abs(signed_count) * eta <= 1.0:
        return None
    s = math.sqrt(signed_count ** 2 * eta * eta - 1.0)
    root = math.sqrt(zeta * zeta * s * s + 1.0)
    return root - zeta * s, root + zeta * s


@dataclass(frozen=True)
class UnbalancedBranch:
    """One unbalanced equilibrium r~_{jk} of Lu & Hung.

    ``signed_count`` m (+3 case i, -3 ii, +1 iii, -1 iv), ``branch`` 1 (+sqrt) or 2 (-sqrt),
    ``r`` the amplitude [e] (negative values are returned as computed; Lu & Hung discard them),
    ``theta`` [rad] the direction of the rotor centre, ``beta_eq`` [rad] the angle of the
    equivalent single ball (= theta for m > 0, theta + pi for m < 0), ``ball_angles`` the n
    balls [rad] (balls at theta first).
    """

    signed_count: int
    branch: int
    r: float
    theta: float
    beta_eq: float
    ball_angles: tuple[float, ...]

    @property
    def physical(self) -> bool:
        """Lu & Hung keep only r > 0 (L234)."""
        return self.r > 0


def unbalanced_branches(omega: float, eta: float, zeta: float, mu: float = 1.0,
                        n_balls: int = 3, keep_negative: bool = False
                        ) -> list[UnbalancedBranch]:
    """Closed-form unbalanced equilibria (eqs. 14-24, generalised to n balls).

    ``r~ = K [m eta (1 - Omega^2) +- sqrt(D_m)]`` with theta from the atan2 form.  Branch
    pairs with D_m < 0 do not exist (saddle-node).  Negative radii are dropped unless
    ``keep_negative`` (Lu & Hung discard them as unrealistic, L234).  The equivalent single
    ball of mass |m| m_b sits at ``beta_eq``.
    """
    om = _pos("Omega", omega)
    eta = _pos("eta", eta)
    zeta = _pos("zeta", zeta, allow_zero=True)
    mu = _pos("mu", mu)
    n = _count(n_balls)
    k = amplification_factor(om, zeta, mu)
    out = []
    for n_minus in range(n + 1):
        m = n - 2 * n_minus
        d = discriminant(om, zeta, eta, m)
        if d < 0:
            continue
        for branch, sgn in ((1, 1.0), (2, -1.0)):
            r = k * (m * eta * (1 - om * om) + sgn * math.sqrt(d))
            if r <= 0 and not keep_negative:
                continue
            a = (1 - om * om) * r - m * mu * eta * om * om
            theta = math.atan2(-2 * zeta * om * r, a)
            balls = (theta,) * (n - n_minus) + (theta + math.pi,) * n_minus
            beta_eq = theta if m >= 0 else theta + math.pi
            out.append(UnbalancedBranch(signed_count=m, branch=branch, r=r, theta=theta,
                                        beta_eq=beta_eq, ball_angles=balls))
    return out
