"""Spannan (2021): averaged stationary states, stability matrices, border speeds, capacity.

Physical units (SI) throughout: masses kg, stiffness N/m, damping N s/m, race drag torque
coefficient beta N m s, lengths m, speeds rad/s.  Ball angles are relative to the rotor and
measured from the primary imbalance, as in the thesis (ph_0i) and in :mod:`abb_gym.physics`.

Contents (equation numbers of the thesis):

* (4.41) damped orthotropic critical speeds, (4.71) circular-orbit speed;
* (4.30)-(4.36) ideal balancing with race eccentricity (a residual),
* (4.52)-(4.60) averaged stationary amplitudes with race eccentricity E at angle gamma and
  orthotropic support, (4.61)-(4.67) two-ball stationary positions and their existence;
* (4.68)-(4.70) averaged stability matrices A, B and their eigenvalues, for any number of
  balls (the two-ball matrices extended column by column);
* (4.73) Ryzhik border, (4.74) explicit border speed, (4.75) minimum drag, (A.7) one ball,
  (A.1)-(A.2) the quartic factor and its Hurwitz test;
* (2.1)-(2.3) balancing capacity of n touching balls.

Decisions recorded here (physics note sections 1.9-1.12):

* **Row 4 of B** is printed with cos(ph_01), cos(ph_02) in columns 5-6 (a copy of row 3).
  It must be sin, as in row 2: by the x/y symmetry of the averaged equations (4.25)-(4.28)
  the y-rows repeat the x-rows with (k_y, b_y).  Verified: with sin, the numerical EVP border
  at ph_01 = 3 pi/4 equals (4.74) (the tests check 80.43 / 69.43 / 64.68 rad/s of the
  discoidal rig, note A6); with the printed cos it does not.  ``row4="printed"`` keeps the
  misprint for comparison.
* (4.65)/(4.66) use ``atan2(chi_s, chi_c)``: the plain arctan returns the wrong quadrant for
  chi_c < 0 (the usual case).
* (4.24) lost ``+ m_i eps_i^2`` in the ball inertia; irrelevant here (second derivatives are
  dropped in (4.68)).
* (4.41) is evaluated as printed; for equal stiffness and damping it is 0/0 and the isotropic
  ``sqrt(k/M)`` is returned.  Its undamped limit is ``sqrt(k_x/M), sqrt(k_y/M)`` (tested).
* (A.7) is read as a single ball at ph_01 = pi balancing U0 = m_b eps; it equals (4.74) with
  beta_min halved.  The tests compare it with the eigenvalues of the one-ball averaged matrices.
* w_c = sqrt(k/M) with M the total mass (balls included), as in the thesis (L1976).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import brentq

from ..physics.scene import Scene

__all__ = ["SpannanParameters", "as_parameters", "critical_speeds", "circular_orbit_speed",
           "stationary_amplitudes", "two_ball_positions", "ideal_balancing_residual",
           "averaged_matrices",
           "averaged_eigenvalues", "averaged_max_real", "eigenvalue_border", "border_speed",
           "minimum_drag", "one_ball_border_speed", "ryzhik_border_speed",
           "quartic_coefficients", "hurwitz_margin", "single_ball_capacity",
           "ball_half_angle", "max_ball_count", "capacity", "capacity_ratio"]


@dataclass(frozen=True)
class SpannanParameters:
    """Planar oscillator with identical balls (thesis symbols in brackets).

    total_mass M [kg] (rotor + balls), stiffness_x/_y k [N/m], damping_x/_y b [N s/m],
    ball_mass m_b [kg], orbit_radius eps [m], drag beta [N m s] (race drag torque per
    relative ball speed), imbalance m_0 eps_0 [kg m], race_eccentricity E [m],
    race_angle gamma [rad], n_balls.
    """

    total_mass: float
    stiffness_x: float
    damping_x: float
    ball_mass: float
    orbit_radius: float
    drag: float
    imbalance: float = 0.0
    stiffness_y: float | None = None
    damping_y: float | None = None
    race_eccentricity: float = 0.0
    race_angle: float = 0.0
    n_balls: int = 2

    def __post_init__(self) -> None:
        if self.stiffness_y is None:
            object.__setattr__(self, "stiffness_y", self.stiffness_x)
        if self.damping_y is None:
            object.__setattr__(self, "damping_y", self.damping_x)
        for name, lo, incl in (("total_mass", 0, False), ("stiffness_x", 0, False),
                               ("stiffness_y", 0, False), ("damping_x", 0, True),
                               ("damping_y", 0, True), ("ball_mass", 0, False),
                               ("orbit_radius", 0, False), ("drag", 0, True),
                               ("imbalance", 0, True), ("race_eccentricity", 0, True),
                               ("race_angle", None, True)):
            v = float(getattr(self, name))
            if not math.isfinite(v) or (lo is not None and (v < lo or (v == lo and not incl))):
                raise ValueError(f"field {name!r} must be {'>=' if incl else '>'} 0 "
                                 f"(got {getattr(self, name)!r})")
            object.__setattr__(self, name, v)
        if isinstance(self.n_balls, bool) or int(self.n_balls) != self.n_balls or \
                self.n_balls < 1:
            raise ValueError(f"field 'n_balls' must be an integer >= 1 (got {self.n_balls!r})")

    @property
    def isotropic(self) -> bool:
        return self.stiffness_x == self.stiffness_y and self.damping_x == self.damping_y

    @property
    def critical_speed(self) -> float:
        """w_c = sqrt(k_x/M) [rad/s] (the isotropic critical speed, thesis L1976)."""
        return math.sqrt(self.stiffness_x / self.total_mass)

    @property
    def ball_imbalance(self) -> float:
        """m_b eps [kg m]."""
        return self.ball_mass * self.orbit_radius

    def replace(self, **changes) -> "SpannanParameters":
        return replace(self, **changes)

    @classmethod
    def from_scene(cls, scene: Scene) -> "SpannanParameters":
        """Parameters of a scene; the balls must be identical (mass and drag)."""
        a = scene.arrays()
        if np.ptp(a["ball_mass"]) > 0 or np.ptp(a["ball_drag"]) > 0:
            raise ValueError(f"scene {scene.name!r}: fields 'ball_mass' and 'ball_drag' must be "
                             f"the same for every ball for Spannan's averaged analysis")
        r = scene.race_radius
        return cls(total_mass=scene.total_mass, stiffness_x=scene.support_stiffness_x,
                   stiffness_y=scene.support_stiffness_y, damping_x=scene.support_damping_x,
                   damping_y=scene.support_damping_y, ball_mass=float(a["ball_mass"][0]),
                   orbit_radius=r, drag=float(a["ball_drag"][0]) * r * r,
                   imbalance=scene.imbalance, race_eccentricity=scene.race_eccentricity,
                   race_angle=scene.race_eccentricity_angle, n_balls=scene.ball_count)


def as_parameters(system: SpannanParameters | Scene) -> SpannanParameters:
    """SpannanParameters of a SpannanParameters or Scene."""
    if isinstance(system, SpannanParameters):
        return system
    if isinstance(system, Scene):
        return SpannanParameters.from_scene(system)
    raise ValueError(f"system must be SpannanParameters or Scene (got {type(system).__name__})")


def _speed(om: float, name: str = "Omega") -> float:
    om = float(om)
    if not (math.isfinite(om) and om > 0):
        raise ValueError(f"{name} must be > 0 [rad/s] (got {om!r})")
    return om


# ---------------------------------------------------------------------------- speeds
def critical_speeds(system: SpannanParameters | Scene) -> tuple[float, float]:
    """Damped orthotropic critical speeds (4.41) [rad/s], lower first.

    Isotropic support (0/0 in (4.41)): (sqrt(k/M), sqrt(k/M)).
    """
    p = as_parameters(system)
    m, kx, ky, bx, by = p.total_mass, p.stiffness_x, p.stiffness_y, p.damping_x, p.damping_y
    den1 = 2 * m * kx - 2 * m * ky - bx * bx + by * by
    if abs(kx - ky) <= 1e-12 * max(kx, ky) and abs(den1) <= 1e-12 * max(1.0, m * kx):
        w = math.sqrt(kx / m)
        return w, w
    first = (kx - ky) * (kx + ky) / den1
    root = math.sqrt((m * (kx - ky) ** 2 + bx * bx * ky + by * by * kx) ** 2
                     - (bx * by * (kx + ky)) ** 2)
    second = root / (m * (2 * m * (ky - kx) + bx * bx - by * by))
    w2 = sorted([first - second, first + second])
    return tuple(math.sqrt(max(v, 0.0)) for v in w2)


def circular_orbit_speed(system: SpannanParameters | Scene) -> float:
    """w_r = sqrt((k_x + k_y)/(2M)) [rad/s] (4.71): equal x and y amplitudes."""
    p = as_parameters(system)
    return math.sqrt((p.stiffness_x + p.stiffness_y) / (2 * p.total_mass))


# ---------------------------------------------------------------------------- stationary state
def stationary_amplitudes(system: SpannanParameters | Scene, omega: float) -> dict[str, float]:
    """Averaged stationary amplitudes A_0x, B_0x, A_0y, B_0y [m] with race eccentricity
    ((4.52)-(4.60)); x~ = A_x cos th - B_x sin th, y~ = A_y sin th + B_y cos th.

    For E = 0 all four vanish (ideal balancing).  Isotropic support: the deflection radius is
    exactly E (L899).  Returns also ``radius_x``, ``radius_y`` [m].
    """
    p = as_parameters(system)
    om = _speed(omega)
    m, kx, ky, bx, by = p.total_mass, p.stiffness_x, p.stiffness_y, p.damping_x, p.damping_y
    e, gam = p.race_eccentricity, p.race_angle
    pxy = om ** 3 * m * (by - bx) + om * (bx * ky - by * kx)
    pyx = om ** 3 * m * (bx - by) + om * (by * kx - bx * ky)
    qxy = (2 * m * m * om ** 4 - m * om * om * (kx + 3 * ky) + kx * ky + ky * ky
           + om * om * (bx * by + by * by))
    qyx = (2 * m * m * om ** 4 - m * om * om * (ky + 3 * kx) + kx * ky + kx * kx
           + om * om * (bx * by + bx * bx))
    s = om * om * (bx + by) ** 2 + (2 * m * om * om - kx - ky) ** 2
    sg, cg = math.sin(gam), math.cos(gam)
    a0x = -2 * e * (pxy * sg + qxy * cg) / s
    a0y = -2 * e * (pyx * sg + qyx * cg) / s
    b0x = -2 * e * (qxy * sg + pyx * cg) / s
    b0y = -2 * e * (qyx * sg + pxy * cg) / s
    return {"A0x": a0x, "B0x": b0x, "A0y": a0y, "B0y": b0y,
            "radius_x": math.hypot(a0x, b0x), "radius_y": math.hypot(a0y, b0y)}


def ideal_balancing_residual(system: SpannanParameters | Scene, ball_angles) -> float:
    """Residual of the ideal-balancing conditions (4.30)-(4.32) [kg m] for given ball angles.

    Ideal balancing (A_0 = B_0 = 0) needs ``sum eps m_i cos ph_i = -m_0 eps_0 - E cos(gam)
    sum m_i`` (4.30), ``sum eps m_i sin ph_i = -E sin(gam) sum m_i`` (4.31) and
    ``sin(gam - ph_i) = 0`` for every ball (4.32, weighted here by m_i eps).  Hence with
    E > 0 only gam, ph_i in {0, pi} and the exact cancellation (4.36) balance ideally - "a
    condition that is not found in reality" (L835).  Returns the largest absolute residual.
    """
    p = as_parameters(system)
    ph = np.atleast_1d(np.asarray(ball_angles, float))
    me, e, gam = p.ball_imbalance, p.race_eccentricity, p.race_angle
    msum = p.ball_mass * len(ph)
    r1 = me * np.sum(np.cos(ph)) + p.imbalance + e * math.cos(gam) * msum
    r2 = me * np.sum(np.sin(ph)) + e * math.sin(gam) * msum
    r3 = me * np.max(np.abs(np.sin(gam - ph))) if e > 0 else 0.0
    return float(max(abs(r1), abs(r2), r3))


def two_ball_positions(system: SpannanParameters | Scene, omega: float
                       ) -> tuple[float, float]:
    """Stationary angles (ph_01, ph_02) [rad] of two identical balls ((4.61)-(4.66)).

    ``chi_s = sin ph_01 + sin ph_02`` (4.61), ``chi_c = cos ph_01 + cos ph_02`` (4.62),
    ``ph_0{1,2} = atan2(chi_s, chi_c) +- acos((chi_s^2 + chi_c^2)/2 - 1)/2`` (4.65)/(4.66).
    Raises ValueError when (4.67) ``chi_s^2 + chi_c^2 <= 4`` fails (balls too light).
    """
    p = as_parameters(system)
    om = _speed(omega)
    st = stationary_amplitudes(p, om)
    mb, eps, m = p.ball_mass, p.orbit_radius, p.total_mass
    e, gam = p.race_eccentricity, p.race_angle
    chi_s = (p.damping_x / (eps * mb * om) * st["A0x"]
             + (p.stiffness_x / om ** 2 - m) * st["B0x"] / (eps * mb) - 2 * e / eps * math.sin(gam))
    chi_c = (-p.damping_x / (eps * mb * om) * st["B0x"]
             + (p.stiffness_x / om ** 2 - m) * st["A0x"] / (eps * mb)
             - 2 * e / eps * math.cos(gam) - p.imbalance / (mb * eps))
    r2 = chi_s ** 2 + chi_c ** 2
    if r2 > 4.0 * (1 + 1e-12):
        raise ValueError(f"two balls cannot balance: chi_s^2 + chi_c^2 = {r2:.6g} > 4 (4.67); "
                         f"increase ball_mass * orbit_radius or reduce the imbalance")
    psi = math.atan2(chi_s, chi_c)
    half = 0.5 * math.acos(max(-1.0, min(1.0, r2 / 2 - 1)))
    return psi + half, psi - half


# ---------------------------------------------------------------------------- stability
def averaged_matrices(system: SpannanParameters | Scene, omega: float, ball_angles,
                      row4: str = "corrected") -> tuple[np.ndarray, np.ndarray]:
    """Matrices A, B of (4.68) ``A z' + B z = 0``, z = [dA_x, dB_x, dA_y, dB_y, dph_1..n].

    Two balls give the thesis's 6x6 matrices; n balls repeat the ball columns and rows.
    ``row4="corrected"`` uses sin in row 4 (module docstring), ``"printed"`` the misprint.
    """
    p = as_parameters(system)
    om = _speed(omega)
    if row4 not in ("corrected", "printed"):
        raise ValueError(f"row4 must be 'corrected' or 'printed' (got {row4!r})")
    ph = np.atleast_1d(np.asarray(ball_angles, float))
    n = len(ph)
    s, c = np.sin(ph), np.cos(ph)
    m, me = p.total_mass, p.ball_imbalance
    a = np.zeros((4 + n, 4 + n))
    b = np.zeros((4 + n, 4 + n))
    a[:4, :4] = -np.eye(4)
    a[0, 4:] = me * s / m
    a[1, 4:] = -me * c / m
    a[2, 4:] = me * s / m
    a[3, 4:] = -me * c / m
    for i in range(n):
        a[4 + i, :4] = [om * c[i] / 2, om * s[i] / 2, om * c[i] / 2, om * s[i] / 2]
        a[4 + i, 4 + i] = p.drag / me
        b[4 + i, :4] = [om * om * s[i] / 2, -om * om * c[i] / 2,
                        om * om * s[i] / 2, -om * om * c[i] / 2]
    for r0, k, bb in ((0, p.stiffness_x, p.damping_x), (2, p.stiffness_y, p.damping_y)):
        b[r0, r0] = b[r0 + 1, r0 + 1] = -bb / (2 * m)
        b[r0, r0 + 1] = om / 2 - k / (2 * m * om)
        b[r0 + 1, r0] = -om / 2 + k / (2 * m * om)
    b[0, 4:] = me * om * c / (2 * m)
    b[1, 4:] = me * om * s / (2 * m)
    b[2, 4:] = me * om * c / (2 * m)
    b[3, 4:] = me * om * (s if row4 == "corrected" else c) / (2 * m)
    return a, b


def _default_angles(p: SpannanParameters, om: float):
    if p.n_balls == 2:
        return np.array(two_ball_positions(p, om))
    if p.n_balls == 1 and p.race_eccentricity == 0:
        if p.imbalance > p.ball_imbalance * (1 + 1e-12):
            raise ValueError("one ball cannot balance: imbalance > ball_mass * orbit_radius")
        return np.array([math.pi])
    raise ValueError(f"give ball_angles for n_balls = {p.n_balls} (closed-form stationary "
                     f"positions exist for two balls, or one ball without eccentricity)")


def averaged_eigenvalues(system: SpannanParameters | Scene, omega: float, ball_angles=None,
                         row4: str = "corrected") -> np.ndarray:
    """Eigenvalues lambda of (4.69) ``(B + lambda A) v = 0`` [1/s]; stable iff all Re < 0
    (4.70).  ``ball_angles`` default: the stationary positions (two balls: (4.65)/(4.66))."""
    p = as_parameters(system)
    om = _speed(omega)
    ph = _default_angles(p, om) if ball_angles is None else ball_angles
    a, b = averaged_matrices(p, om, ph, row4)
    return np.linalg.eigvals(-np.linalg.solve(a, b))


def averaged_max_real(system: SpannanParameters | Scene, omega: float, ball_angles=None,
                      row4: str = "corrected") -> float:
    """Largest real part of :func:`averaged_eigenvalues` [1/s]."""
    return float(np.max(averaged_eigenvalues(system, omega, ball_angles, row4).real))


def eigenvalue_border(system: SpannanParameters | Scene, ball_angles=None,
                      omega_max: float | None = None, row4: str = "corrected",
                      points: int = 400) -> float:
    """Lowest speed above w_c beyond which the averaged EVP is stable for good [rad/s].

    Scans (w_c, omega_max] (default 20 w_c) on ``points`` log-spaced speeds, takes the last
    unstable-to-stable change and refines it with brentq.  Returns w_c when stable on the
    whole scan, inf when unstable at omega_max.  ``ball_angles`` fixed angles, or None for
    the stationary positions at each speed.
    """
    p = as_parameters(system)
    wc = p.critical_speed
    top = 20 * wc if omega_max is None else _speed(omega_max, "omega_max")
    oms = wc * np.exp(np.linspace(np.log(1.0 + 1e-6), np.log(top / wc), points))
    f = [averaged_max_real(p, o, ball_angles, row4) for o in oms]
    if f[-1] >= 0:
        return math.inf
    unstable = [k for k, v in enumerate(f) if v >= 0]
    if not unstable:
        return wc
    k = unstable[-1]
    return brentq(lambda o: averaged_max_real(p, o, ball_angles, row4), oms[k], oms[k + 1],
                  xtol=1e-10 * wc, rtol=1e-12)


def minimum_drag(system: SpannanParameters | Scene) -> float:
    """beta_min = (m_b eps)^2 w_c^2 / b [N m s] (4.75): below it the two-ball balancer never
    leaves the Sommerfeld region (isotropic, E = 0)."""
    p = as_parameters(system)
    if p.damping_x <= 0:
        raise ValueError("field 'damping_x' must be > 0 for beta_min (4.75)")
    return p.ball_imbalance ** 2 * p.critical_speed ** 2 / p.damping_x


def border_speed(system: SpannanParameters | Scene) -> float:
    """Omega_bo [rad/s] of (4.74): ``w_c sqrt((beta + beta_min)/(beta - beta_min))``.

    Worst case over the ball angle (ph_01 = 3 pi/4), isotropic, E = 0, two balls; inf when
    beta <= beta_min.
    """
    p = as_parameters(system)
    bmin = minimum_drag(p)
    if p.drag <= bmin:
        return math.inf
    return p.critical_speed * math.sqrt((p.drag + bmin) / (p.drag - bmin))


def one_ball_border_speed(system: SpannanParameters | Scene) -> float:
    """Border speed of one ball at ph_01 = pi (A.7) [rad/s]: (4.74) with beta_min / 2."""
    p = as_parameters(system)
    bmin = 0.5 * minimum_drag(p)
    if p.drag <= bmin:
        return math.inf
    return p.critical_speed * math.sqrt((p.drag + bmin) / (p.drag - bmin))


def ryzhik_border_speed(system: SpannanParameters | Scene) -> float:
    """Ryzhik's approximation (4.73): ``w_c (1 + 2 (m_b eps w_c)^2/(b beta))`` [rad/s]."""
    p = as_parameters(system)
    if p.drag <= 0 or p.damping_x <= 0:
        raise ValueError("fields 'drag' and 'damping_x' must be > 0 for (4.73)")
    wc = p.critical_speed
    return wc * (1 + 2 * (p.ball_imbalance * wc) ** 2 / (p.damping_x * p.drag))


def quartic_coefficients(system: SpannanParameters | Scene, omega: float, ph01: float
                         ) -> np.ndarray:
    """[a4, a3, a2, a1, a0] of the quartic factor of the isotropic two-ball characteristic
    equation (A.1), balls at (ph01, -ph01)."""
    p = as_parameters(system)
    om = _speed(omega)
    m, b, beta, wc = p.total_mass, p.damping_x, p.drag, p.critical_speed
    me2 = p.ball_imbalance ** 2
    sc2 = (math.sin(ph01) * math.cos(ph01)) ** 2
    a4 = 4 * om ** 2 * (4 * me2 ** 2 * om ** 2 * sc2 + m * m * beta * beta)
    a3 = 4 * m * beta * om ** 2 * (2 * me2 * om ** 2 + me2 * wc ** 2 + beta * b)
    a2 = (m * m * beta * beta * (om * om - wc * wc) ** 2
          + om ** 2 * (20 * me2 ** 2 * om ** 4 * sc2 + 6 * me2 * beta * om ** 2 * b
                       + beta * beta * b * b))
    a1 = 2 * me2 * m * beta * om ** 4 * (om - wc) * (om + wc)
    a0 = 4 * me2 ** 2 * om ** 8 * sc2
    return np.array([a4, a3, a2, a1, a0])


def hurwitz_margin(system: SpannanParameters | Scene, omega: float, ph01: float) -> float:
    """a1 (a3 a2 - a4 a1) - a0 a3^2 of (A.2); with all a_k > 0, positive means stable."""
    a4, a3, a2, a1, a0 = quartic_coefficients(system, omega, ph01)
    return float(a1 * (a3 * a2 - a4 * a1) - a0 * a3 * a3)


# ---------------------------------------------------------------------------- capacity
def single_ball_capacity(ball_diameter: float, orbit_radius: float, ball_density: float = 7860.0,
                         fluid_density: float = 0.0) -> float:
    """U_b = (pi/6) d_b^3 (rho_b - rho_fl) eps [kg m] (2.1); densities in kg/m^3."""
    for name, v in (("ball_diameter", ball_diameter), ("orbit_radius", orbit_radius),
                    ("ball_density", ball_density)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be > 0 (got {v!r})")
    if not (math.isfinite(fluid_density) and 0 <= fluid_density < ball_density):
        raise ValueError(f"fluid_density must be in [0, ball_density) kg/m^3 "
                         f"(got {fluid_density!r})")
    return math.pi / 6 * ball_diameter ** 3 * (ball_density - fluid_density) * orbit_radius


def ball_half_angle(ball_diameter: float, orbit_radius: float) -> float:
    """alpha = asin(d_b / (2 eps)) [rad] (2.2): half the sector one ball occupies."""
    if not (0 < ball_diameter < 2 * orbit_radius):
        raise ValueError(f"ball_diameter must be in (0, 2 orbit_radius) (got {ball_diameter!r})")
    return math.asin(ball_diameter / (2 * orbit_radius))


def max_ball_count(ball_diameter: float, orbit_radius: float) -> int:
    """n_max = floor(pi / (2 alpha)): balls that fill half the annulus (L379)."""
    return int(math.floor(math.pi / (2 * ball_half_angle(ball_diameter, orbit_radius))))


def capacity_ratio(n: int, alpha: float) -> float:
    """U_max(n)/U_b of (2.3) for n touching balls of half-angle alpha [rad].

    Odd n: ``1 + sum_{j=2..n, j odd} 2 cos((j-1) alpha)``; even n:
    ``sum_{j=2..n, j even} 2 cos((j-1) alpha)`` (the balls packed symmetrically about the
    direction opposite the imbalance).
    """
    if isinstance(n, bool) or int(n) != n or n < 1:
        raise ValueError(f"n must be an integer >= 1 (got {n!r})")
    n = int(n)
    odd = n % 2
    total = float(odd)
    for j in range(2, n + 1):
        if (odd and j % 2 == 1) or (not odd and j % 2 == 0):
            total += 2 * math.cos((j - 1) * alpha)
    return total


def capacity(ball_diameter: float, orbit_radius: float, n: int | None = None,
             ball_density: float = 7860.0, fluid_density: float = 0.0) -> float:
    """Largest imbalance n touching balls can cancel, U_max(n) [kg m] ((2.1)-(2.3)).

    ``n`` defaults to n_max (the thesis's App. C "max. compensation", steel, no fluid); n must
    not exceed n_max.
    """
    nmax = max_ball_count(ball_diameter, orbit_radius)
    n = nmax if n is None else n
    if isinstance(n, bool) or int(n) != n or not 1 <= n <= nmax:
        raise ValueError(f"n must be an integer in [1, n_max = {nmax}] (got {n!r})")
    alpha = ball_half_angle(ball_diameter, orbit_radius)
    return capacity_ratio(int(n), alpha) * single_ball_capacity(ball_diameter, orbit_radius,
                                                                ball_density, fluid_density)
