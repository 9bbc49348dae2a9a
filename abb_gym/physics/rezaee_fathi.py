"""Rezaee & Fathi (2015) spring-and-rod three-ball balancer (and its conventional limit).

Each ball slides on a rod that turns about the rotor centre; a radial spring (stiffness k_b,
free length a = lambda) holds it on the rod, and circumferential springs (k_d at lever d)
couple the rods of neighbouring balls so that at rest the balls sit 2 pi/n apart.  Each ball
has two degrees of freedom: angle phi_i relative to the rotor (from the imbalance) and radius
delta_i.  The rotor speed W(tau) is prescribed and may vary: the W' (Euler) terms are kept, so
a :class:`~abb_gym.physics.drives.SpeedProfile` run-up can drive the model.

Dimensionless model (paper eq. 10; lengths / lambda, time tau = w_n t, w_n = sqrt(k/M) with M
the total mass including the balls):

{table}

``mbar`` must also be < 1/n (the balls are part of the total mass).

Equations (derived from the paper's energies T (2), V (3), F (4); the printed (5)-(9) and
(11)-(14) carry sign errors, physics note B4/B5 - the tests check these equations against a
numerical Lagrangian of (2)-(4))::

  x:   x'' + 2 zeta x' + (1 - W^2) x - 2 W y' - (2 zeta W + W') y - mu_d eps W^2
       + mbar sum[(d_i'' - d_i (p_i' + W)^2) cos p_i
                  - (d_i p_i'' + 2 d_i' (p_i' + W) + d_i W') sin p_i] = 0
  y:   y'' + 2 zeta y' + (1 - W^2) y + 2 W x' + (2 zeta W + W') x + mu_d eps W'
       + mbar sum[(d_i'' - d_i (p_i' + W)^2) sin p_i
                  + (d_i p_i'' + 2 d_i' (p_i' + W) + d_i W') cos p_i] = 0
  p_i: mbar { d_i^2 p_i'' + 2 beta d_i^2 p_i' + 2 d_i d_i' (p_i' + W) + d_i^2 W'
              + d_i [-x'' sin p_i + y'' cos p_i + 2 W (x' cos p_i + y' sin p_i)
                     + W^2 (x sin p_i - y cos p_i) + W' (x cos p_i + y sin p_i)] + eta q_i } = 0
  d_i: mbar { d_i'' + 2 beta d_i' + f^2 (d_i - 1) - d_i (p_i' + W)^2 + x'' cos p_i + y'' sin p_i
              - W^2 (x cos p_i + y sin p_i) + 2 W (x' sin p_i - y' cos p_i)
              + W' (x sin p_i - y cos p_i) } = 0
  q_1 = p_1 - p_2 + 2 pi/n,  q_i = 2 p_i - p_{i-1} - p_{i+1},  q_n = p_n - p_{n-1} - 2 pi/n

Decisions recorded here:

* q_1 has ``+ 2 pi/n`` (the paper prints minus; d/dp_1 of (p_2 - p_1 - 2 pi/n)^2/2 is
  -(p_2 - p_1 - 2 pi/n)).  The sum of the q_i is zero: the springs exert no net torque.
* The radial equation uses ``f^2 (d - 1) - W^2 d`` (spring plus full centrifugal term), not the
  printed ``(d - 1)(f^2 - W^2)``: at r = 0 the radius is ``d* = f^2/(f^2 - W^2)``, which grows
  with speed as the paper's prose says (L121) and diverges at W = f (radial instability).
* The tangential equation's sin-group is ``-(x'' - 2 W y' - W' y - W^2 x) sin p`` (both signs
  misprinted in (13)); the printed ``d_i p_i'`` in (11)-(12) is ``d_i p_i''``.
* eta is not defined in the paper; ``k_d d^2 / (m_b lambda^2 w_n^2)`` is the definition that
  makes (13) consistent with the energies.
* mu_d defaults to the paper's ``1 - mbar``; physically it is ``1 - n mbar`` (thresholds move
  by about 0.01, note B9).
* Conventional limit (``radial=False``): d_i == race_radius fixed, the d-equations dropped;
  with eta = 0 and W' = 0 this is Lu & Hung's eq. (8) under the map of note part C (tested).

Units of the physical conversions: ``natural_frequency`` w_n [rad/s] and ``length_scale``
lambda [m] only convert a physical SpeedProfile and times; the model itself is dimensionless.
"""
from __future__ import annotations

import bisect
import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
from .._numba import njit
from scipy.integrate import solve_ivp
from scipy.optimize import root

from ..configuration import (ConfigError, build, check, declare, fields_table, locate,
                             read_yaml, specs)
from .drives import SpeedProfile
from .trajectory import PlanarStates

__all__ = ["SpringRodBalancer", "SpringRodTrajectory", "load_spring_rod", "simulate_spring_rod",
           "spring_rod_rhs", "spring_rod_equilibrium", "spring_rod_jacobian",
           "spring_rod_eigenvalues", "balanced_radius", "spring_rod_configs_dir"]


def spring_rod_configs_dir() -> Path:
    """Folder of the shipped spring-and-rod parameter files (``configs/spring_rod``)."""
    from .. import resources
    return resources.shipped_folder("spring_rod")


@dataclass(frozen=True)
class SpringRodBalancer:
    """Dimensionless parameters of the spring-and-rod balancer (module docstring table).

    Defaults: the paper's Fig. 2 set (eta = 0.01, f = 4, mbar = epsbar = 0.01,
    zeta = beta = 0.1, three balls).
    """

    n_balls: int = declare(3, kind="integer", ge=1, le=64, doc="number of balls n")
    mbar: float = declare(0.01, gt=0.0, lt=1.0,
                          doc="m_b / M, one ball's mass over the total mass, < 1/n")
    epsbar: float = declare(0.01, ge=0.0, le=1e3, doc="e / lambda, rotor eccentricity")
    zeta: float = declare(0.1, ge=0.0, le=1e3,
                          doc="c / (2 sqrt(M k)), support damping ratio (stationary damper)")
    beta: float = declare(0.1, ge=0.0, le=1e3,
                          doc="c_r / (2 m_b w_n), ball damping ratio (radial and tangential)")
    eta: float = declare(0.01, ge=0.0, le=1e6,
                         doc="k_d d^2 / (m_b lambda^2 w_n^2), circumferential stiffness")
    f: float = declare(4.0, gt=0.0, le=1e3,
                       doc="w_b / w_n = sqrt(k_b / m_b) / w_n, radial spring frequency")
    mu_d: float | None = declare(None, gt=0.0, le=1.0, nullable=True,
                                 doc="m_d / M, imbalanced rotor mass (null: the paper's "
                                     "1 - mbar)")
    race_radius: float = declare(1.0, gt=0.0, le=1e3,
                                 doc="R / lambda of the conventional comparator (1 in the "
                                     "paper)")
    closed_ring: bool = declare(False, kind="flag",
                                doc="also couple ball n to ball 1 (the paper's eq. 3 is an "
                                    "open chain of n - 1 springs)")
    natural_frequency: float = declare(100.0, unit="rad/s", gt=0.0, le=1e6,
                                       doc="w_n, converts physical speed profiles and times")
    length_scale: float = declare(0.01, unit="m", gt=0.0, le=10.0,
                                  doc="lambda, converts physical lengths")
    name: str = declare("rezaee_fathi", kind="text", doc="parameter set name")
    description: str = declare("", kind="text", doc="what it is")
    source: str = declare("", kind="text", doc="where the values come from")

    def __post_init__(self) -> None:
        for name, spec in specs(SpringRodBalancer).items():
            object.__setattr__(self, name, check("spring-and-rod balancer", name,
                                                 getattr(self, name), spec))
        if self.mu_d is None:
            object.__setattr__(self, "mu_d", 1.0 - float(self.mbar))
        if self.n_balls * self.mbar >= 1.0:
            raise ConfigError(f"spring-and-rod balancer: field 'mbar' must be < 1/n_balls = "
                              f"{1 / self.n_balls:g} (the balls are part of the total mass; "
                              f"got {self.mbar})")

    def replace(self, **changes: Any) -> "SpringRodBalancer":
        return dataclasses.replace(self, **changes)

    def pack(self) -> np.ndarray:
        """Parameter vector for the compiled right-hand side."""
        return np.array([self.mbar, self.epsbar, self.zeta, self.beta, self.eta, self.f,
                         self.mu_d, self.race_radius, 1.0 if self.closed_ring else 0.0])

    def bare_amplitude(self, speed: float) -> float:
        """Steady whirl of the same rotor without balls' imbalance (balls locked at r = 0):
        ``mu_d eps W^2 / sqrt((1 - W^2)^2 + (2 zeta W)^2)`` [lambda]."""
        w = float(speed)
        return self.mu_d * self.epsbar * w * w / math.hypot(1 - w * w, 2 * self.zeta * w)


__doc__ = __doc__.replace("{table}", fields_table(
    SpringRodBalancer, [n for n in specs(SpringRodBalancer)
                        if n not in ("name", "description", "source")], title="parameter"))


def load_spring_rod(name_or_path: str = "rezaee_fathi", **overrides: Any) -> SpringRodBalancer:
    """Load ``spring_rod/<name>.yaml`` (on the search path of :mod:`abb_gym.resources`) or a
    path, and apply overrides."""
    path = locate("spring_rod", name_or_path, "spring-and-rod parameter set")
    raw = dict(read_yaml(path, "spring-and-rod"))
    raw.setdefault("name", path.stem)
    raw.update(overrides)
    return build(SpringRodBalancer, raw, f"spring-and-rod file {str(path)!r}")


# ---------------------------------------------------------------------------- equations
@njit(cache=True)
def _rhs_kernel(s, w, wd, par, n, radial, out):
    """ds/dtau for state s (layout in :func:`spring_rod_rhs`); out is filled."""
    mbar, eps, zeta, beta, eta, f, mu_d, big_r, closed = (par[0], par[1], par[2], par[3],
                                                          par[4], par[5], par[6], par[7],
                                                          par[8])
    nq = 2 + (2 * n if radial else n)
    x, y = s[0], s[1]
    vx, vy = s[nq], s[nq + 1]
    # translational right-hand sides (everything but the mass-matrix terms)
    fx = (-2 * zeta * vx - (1 - w * w) * x + 2 * w * vy + (2 * zeta * w + wd) * y
          + mu_d * eps * w * w)
    fy = -2 * zeta * vy - (1 - w * w) * y - 2 * w * vx - (2 * zeta * w + wd) * x - mu_d * eps * wd
    # Schur complement of the (diagonal) ball block
    a00 = 1.0
    a01 = 0.0
    a11 = 1.0
    two_pi_n = 2 * math.pi / n
    fp = np.empty(n)
    fd = np.empty(n)
    bpx = np.empty(n)
    bpy = np.empty(n)
    bdx = np.empty(n)
    bdy = np.empty(n)
    for i in range(n):
        p = s[2 + i]
        dp = s[nq + 2 + i]
        if radial:
            d = s[2 + n + i]
            dd = s[nq + 2 + n + i]
        else:
            d = big_r
            dd = 0.0
        sp = math.sin(p)
        cp = math.cos(p)
        ww = dp + w
        # spring coordinate q_i
        if n == 1:
            q = 0.0
        elif i == 0:
            q = p - s[3] + two_pi_n
            if closed != 0.0:
                q = 2 * p - s[3] - (s[2 + n - 1] - 2 * math.pi)
        elif i == n - 1:
            q = p - s[2 + n - 2] - two_pi_n
            if closed != 0.0:
                q = 2 * p - s[2 + n - 2] - (s[2] + 2 * math.pi)
        else:
            q = 2 * p - s[2 + i - 1] - s[2 + i + 1]
        # ball-row mass entries (already including mbar): p-row [-mbar d s, mbar d c], d-row
        bpx[i] = -mbar * d * sp
        bpy[i] = mbar * d * cp
        bdx[i] = mbar * cp
        bdy[i] = mbar * sp
        # p-row force (mass terms excluded)
        fp[i] = -mbar * (2 * beta * d * d * dp + 2 * d * dd * ww + d * d * wd
                         + d * (2 * w * (vx * cp + vy * sp) + w * w * (x * sp - y * cp)
                                + wd * (x * cp + y * sp)) + eta * q)
        # translational forces from the ball's velocity terms
        fx += mbar * (d * ww * ww * cp + (2 * dd * ww + d * wd) * sp)
        fy += mbar * (d * ww * ww * sp - (2 * dd * ww + d * wd) * cp)
        ip = 1.0 / (mbar * d * d)
        a00 -= bpx[i] * bpx[i] * ip
        a01 -= bpx[i] * bpy[i] * ip
        a11 -= bpy[i] * bpy[i] * ip
        fx -= bpx[i] * fp[i] * ip
        fy -= bpy[i] * fp[i] * ip
        if radial:
            fd[i] = -mbar * (2 * beta * dd + f * f * (d - 1.0) - d * ww * ww
                             - w * w * (x * cp + y * sp) + 2 * w * (vx * sp - vy * cp)
                             + wd * (x * sp - y * cp))
            idm = 1.0 / mbar
            a00 -= bdx[i] * bdx[i] * idm
            a01 -= bdx[i] * bdy[i] * idm
            a11 -= bdy[i] * bdy[i] * idm
            fx -= bdx[i] * fd[i] * idm
            fy -= bdy[i] * fd[i] * idm
    det = a00 * a11 - a01 * a01
    ax = (fx * a11 - a01 * fy) / det
    ay = (a00 * fy - a01 * fx) / det
    for k in range(nq):
        out[k] = s[nq + k]
    out[nq] = ax
    out[nq + 1] = ay
    for i in range(n):
        d = s[2 + n + i] if radial else big_r
        out[nq + 2 + i] = (fp[i] - bpx[i] * ax - bpy[i] * ay) / (mbar * d * d)
        if radial:
            out[nq + 2 + n + i] = (fd[i] - bdx[i] * ax - bdy[i] * ay) / mbar


def _speed_function(params: SpringRodBalancer, speed) -> Callable[[float], tuple[float, float]]:
    """tau -> (W, W') for a constant, a physical SpeedProfile or a callable."""
    if isinstance(speed, SpeedProfile):
        wn = params.natural_frequency
        # piecewise-constant acceleration: tabulate the segment starts once
        t0 = [float(v) for v in speed.breakpoints]
        w0 = [float(v) for v in speed.speed(np.asarray(t0))]
        acc = [float(v) for v in speed.acceleration(np.asarray(t0))]

        def fn(tau):
            t = tau / wn
            k = max(0, bisect.bisect_right(t0, t) - 1)
            return (w0[k] + acc[k] * (t - t0[k])) / wn, acc[k] / (wn * wn)
        return fn
    if callable(speed):
        return lambda tau: tuple(float(v) for v in speed(tau))
    w = float(speed)
    if not (math.isfinite(w) and w >= 0):
        raise ValueError(f"speed must be a finite dimensionless W >= 0, a SpeedProfile or a "
                         f"callable tau -> (W, W') (got {speed!r})")
    return lambda tau: (w, 0.0)


def spring_rod_rhs(params: SpringRodBalancer, speed, radial: bool = True):
    """The first-order ODE ``s' = f(tau, s)``.

    State layout (radial): ``[x, y, p_1..p_n, d_1..d_n, x', y', p_1'..p_n', d_1'..d_n']``
    (lengths in lambda, angles in rad, ' = d/dtau); conventional (``radial=False``):
    ``[x, y, p_1..p_n, x', y', p_1'..p_n']`` with d_i = race_radius.
    ``speed``: constant W, a SpeedProfile (physical units, converted with natural_frequency)
    or a callable tau -> (W, W').
    """
    par = params.pack()
    n = params.n_balls
    wfun = _speed_function(params, speed)

    def f(tau, s):
        out = np.empty_like(s)
        w, wd = wfun(tau)
        _rhs_kernel(s, w, wd, par, n, radial, out)
        return out
    return f


def balanced_radius(params: SpringRodBalancer, speed: float) -> float:
    """Radial equilibrium at r = 0: ``d* = f^2/(f^2 - W^2)`` [lambda]; inf for W >= f."""
    w = float(speed)
    return math.inf if w >= params.f else params.f ** 2 / (params.f ** 2 - w * w)


def _state_size(params: SpringRodBalancer, radial: bool) -> int:
    return 2 + (2 * params.n_balls if radial else params.n_balls)


def spring_rod_equilibrium(params: SpringRodBalancer, speed: float, guess=None,
                           radial: bool = True, tol: float = 1e-13) -> np.ndarray:
    """Equilibrium q* (positions only) at constant speed W, from ``guess``.

    Default guess: rotor centred, balls spread symmetrically about pi at 0.8 x 2 pi/n spacing,
    radius d* - near the balanced state the springs select above the critical speed (found by
    long simulations, note B9); other equilibria need their own guess.  Raises ValueError
    when the solver does not converge (residual > 1e-10).
    """
    w = float(speed)
    n = params.n_balls
    nq = _state_size(params, radial)
    if guess is None:
        guess = np.zeros(nq)
        guess[2:2 + n] = math.pi + (np.arange(n) - (n - 1) / 2) * 0.8 * 2 * math.pi / n
        if radial:
            guess[2 + n:] = min(balanced_radius(params, w), 10.0)
    guess = np.asarray(guess, float)
    if guess.shape != (nq,):
        raise ValueError(f"guess must have {nq} entries (got {guess.shape})")
    f = spring_rod_rhs(params, w, radial)

    def res(q):
        return f(0.0, np.concatenate([q, np.zeros(nq)]))[nq:]
    sol = root(res, guess, method="hybr", tol=tol)
    r = np.max(np.abs(res(sol.x)))
    if r > 1e-10:
        raise ValueError(f"equilibrium not found at W = {w:g} (residual {r:.3g}); give a better "
                         f"guess (e.g. from a simulation)")
    return sol.x


def spring_rod_jacobian(params: SpringRodBalancer, speed: float, q, radial: bool = True,
                        h: float = 1e-7) -> np.ndarray:
    """Central-difference Jacobian of the first-order system at the equilibrium q."""
    nq = _state_size(params, radial)
    s0 = np.concatenate([np.asarray(q, float), np.zeros(nq)])
    f = spring_rod_rhs(params, float(speed), radial)
    jac = np.empty((2 * nq, 2 * nq))
    for k in range(2 * nq):
        e = np.zeros(2 * nq)
        e[k] = h
        jac[:, k] = (f(0.0, s0 + e) - f(0.0, s0 - e)) / (2 * h)
    return jac


def spring_rod_eigenvalues(params: SpringRodBalancer, speed: float, q, radial: bool = True
                           ) -> np.ndarray:
    """Eigenvalues of the linearisation at q [units of w_n].  With eta > 0 there is no
    structural zero eigenvalue (the springs select one state); with eta = 0 the conventional
    family's zeros remain (see abb_gym.analysis.rotating_frame for that case)."""
    return np.linalg.eigvals(spring_rod_jacobian(params, speed, q, radial))


# ---------------------------------------------------------------------------- simulation
@dataclass
class SpringRodTrajectory(PlanarStates):
    """Result of :func:`simulate_spring_rod`: ``tau`` (dimensionless time), ``states``; lengths
    in lambda, x and y in the rotating frame (``whirl_radius`` is the paper's r)."""

    params: SpringRodBalancer
    tau: np.ndarray
    states: np.ndarray
    radial: bool
    speed: np.ndarray

    @property
    def t(self) -> np.ndarray:
        """Physical time tau / w_n [s]."""
        return self.tau / self.params.natural_frequency

    @property
    def _nq(self) -> int:
        return _state_size(self.params, self.radial)

    @property
    def r(self) -> np.ndarray:
        """Whirl radius [lambda] (the paper's r)."""
        return self.whirl_radius

    @property
    def ball_angles(self) -> np.ndarray:
        """phi_i relative to the rotor, from the imbalance [rad], shape (T, n)."""
        n = self.params.n_balls
        return self.states[:, 2:2 + n]

    @property
    def ball_radii(self) -> np.ndarray:
        """delta_i [lambda], shape (T, n) (race_radius for the conventional model)."""
        n = self.params.n_balls
        if self.radial:
            return self.states[:, 2 + n:2 + 2 * n]
        return np.full((len(self.tau), n), self.params.race_radius)


def simulate_spring_rod(params: SpringRodBalancer, speed, tau_end: float, *,
                        ball_angles0=None, ball_radii0=None, state0=None, radial: bool = True,
                        method: str = "DOP853", rtol: float = 1e-9, atol: float = 1e-12,
                        output_dtau: float = 0.5, max_step: float = 1.0
                        ) -> SpringRodTrajectory:
    """Integrate the model with scipy ``solve_ivp`` from tau = 0 to ``tau_end``.

    ``speed`` as in :func:`spring_rod_rhs`.  Initial state: ``state0`` (full first-order
    state), or rotor at rest and centred, balls at ``ball_angles0`` (default equally spaced
    from 0) and radii ``ball_radii0`` (default 1, the springs' free length), at rest relative
    to the rotor.  ``max_step`` bounds the step (tau units) so speed-profile breakpoints are
    not stepped over.
    """
    tau_end = float(tau_end)
    if not (math.isfinite(tau_end) and tau_end > 0):
        raise ValueError(f"tau_end must be > 0 (got {tau_end!r})")
    n = params.n_balls
    nq = _state_size(params, radial)
    if state0 is None:
        s0 = np.zeros(2 * nq)
        ang = 2 * np.pi * np.arange(n) / n if ball_angles0 is None else \
            np.asarray(ball_angles0, float)
        if ang.shape != (n,):
            raise ValueError(f"ball_angles0 must have n_balls = {n} entries (got {ang.shape})")
        s0[2:2 + n] = ang
        if radial:
            rad = np.ones(n) if ball_radii0 is None else np.asarray(ball_radii0, float)
            if rad.shape != (n,) or np.any(rad <= 0):
                raise ValueError(f"ball_radii0 must be {n} positive numbers (got {rad})")
            s0[2 + n:2 + 2 * n] = rad
    else:
        s0 = np.asarray(state0, float)
        if s0.shape != (2 * nq,):
            raise ValueError(f"state0 must have {2 * nq} entries (got {s0.shape})")
    f = spring_rod_rhs(params, speed, radial)
    k = max(1, int(round(tau_end / output_dtau)))
    t_eval = np.linspace(0.0, tau_end, k + 1)
    sol = solve_ivp(f, (0.0, tau_end), s0, method=method, t_eval=t_eval, rtol=rtol, atol=atol,
                    max_step=max_step)
    if not sol.success:
        raise FloatingPointError(f"spring-and-rod integration failed at tau = {sol.t[-1]:.6g}: "
                                 f"{sol.message}")
    wfun = _speed_function(params, speed)
    speeds = np.array([wfun(t)[0] for t in sol.t])
    return SpringRodTrajectory(params=params, tau=sol.t, states=sol.y.T, radial=radial,
                               speed=speeds)
