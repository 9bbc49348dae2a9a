"""Time-domain checks of the eigenvalue analysis with the physics simulator.

Everything here runs :func:`abb_gym.simulate` (the compiled fixed-frame model of
:mod:`abb_gym.physics.model`) at constant speed; nothing uses the rotating-frame equations of
:mod:`.rotating_frame`, so agreement between the two is a real cross-check.

* :func:`run_from_equilibrium` starts next to an equilibrium (rotating-frame position and ball
  angles, plus a perturbation) and reports how far the run ends from it.
* :func:`settle` classifies where a run ends: ``balanced`` (whirl below ``balanced_tol``),
  ``whirl`` (non-synchronous: the balls keep moving relative to the rotor), or
  ``synchronous`` (balls at rest relative to the rotor, rotor deflected: an unbalanced
  equilibrium).
* :func:`clumped_whirl` looks for the clumped-ball whirl that coexists with the balanced state
  above the critical speed: one run from clumped balls, one from equally spaced balls.

Amplitudes are reported in units of Lu & Hung's e (:class:`~abb_gym.analysis.groups.Groups`)
as well as metres; ball speeds relative to the rotor in units of w_n.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..physics.drives import SpeedProfile
from ..physics.scene import Scene
from ..physics.simulate import simulate
from ..physics.trajectory import Trajectory
from .groups import Groups
from .rotating_frame import balanced_target, coefficients

__all__ = ["Settled", "settle", "run_from_equilibrium", "clumped_whirl", "ClumpedWhirl",
           "physical_system"]

# Lu & Hung Fig. 6 IC1 (clumped near the imbalance) and equal spacing
CLUMPED_ANGLES = (0.01 * math.pi, 0.02 * math.pi, 0.03 * math.pi)


def physical_system(system: Groups | Scene, length_scale: float | None = None
                    ) -> tuple[Scene, Groups, float, float]:
    """(scene, groups, w_n [rad/s], e [m]) for a Groups or a Scene.

    Groups are turned into a scene with :meth:`Groups.to_scene` defaults (w_n = 100 rad/s,
    M = 0.1 kg, e = 0.5 mm).
    """
    if isinstance(system, Scene):
        g = Groups.from_scene(system, length_scale)
        e = system.rotor_eccentricity if length_scale is None else float(length_scale)
        return system, g, math.sqrt(system.support_stiffness_x / system.total_mass), e
    if isinstance(system, Groups):
        e, wn = 5e-4, 100.0
        return system.to_scene(natural_frequency=wn, length_scale=e), system, wn, e
    raise ValueError(f"system must be Groups or Scene (got {type(system).__name__})")


@dataclass
class Settled:
    """Summary of the tail of a constant-speed run.

    ``state`` "balanced" / "whirl" / "synchronous"; ``radius_min``, ``radius_max`` over the
    tail [e]; ``ball_speed`` mean relative ball speed over the tail [w_n] (per ball);
    ``whirl_frequency`` inertial angular speed of the balls (Omega + ball_speed) [w_n];
    ``final_angles`` [rad] wrapped to [0, 2 pi); ``trajectory`` the run.
    """

    state: str
    radius_min: float
    radius_max: float
    ball_speed: np.ndarray
    whirl_frequency: np.ndarray
    final_angles: np.ndarray
    omega: float
    trajectory: Trajectory

    @property
    def radius_final(self) -> float:
        return self.radius_max


def _classify(tr: Trajectory, wn: float, e: float, omega: float, tail: float,
              balanced_tol: float, speed_tol: float) -> Settled:
    t = tr.t
    k = t >= t[-1] - tail
    r = tr.whirl_radius[k] / e
    ang = tr.ball_angles[k]
    dt = t[k][-1] - t[k][0]
    speed = (ang[-1] - ang[0]) / dt / wn if dt > 0 else np.zeros(ang.shape[1])
    if r.max() < balanced_tol and np.all(np.abs(speed) < speed_tol):
        state = "balanced"
    elif np.any(np.abs(speed) >= speed_tol):
        state = "whirl"
    else:
        state = "synchronous"
    return Settled(state=state, radius_min=float(r.min()), radius_max=float(r.max()),
                   ball_speed=speed, whirl_frequency=omega + speed,
                   final_angles=np.mod(tr.ball_angles[-1], 2 * np.pi), omega=omega,
                   trajectory=tr)


def settle(system: Groups | Scene, omega: float, ball_angles0, t_end: float = 500.0, *,
           x0=(0.0, 0.0), v0=(0.0, 0.0), tail: float = 100.0, balanced_tol: float = 1e-4,
           speed_tol: float = 1e-3, method: str = "rk4", dt: float | None = None,
           length_scale: float | None = None) -> Settled:
    """Run at constant speed ratio ``omega`` from ``ball_angles0`` [rad] and classify the end.

    ``t_end`` and ``tail`` are dimensionless times (units of 1/w_n); ``x0`` [m], ``v0`` [m/s]
    the initial rotor-centre state in the fixed frame; ``balanced_tol`` in units of e;
    ``speed_tol`` in units of w_n (a ball that drifts slower relative to the rotor counts as
    at rest).
    """
    scene, g, wn, e = physical_system(system, length_scale)
    om = float(omega)
    if not (math.isfinite(om) and om > 0):
        raise ValueError(f"omega must be > 0 (got {omega!r})")
    if not (t_end > tail > 0):
        raise ValueError(f"need t_end > tail > 0 (got {t_end}, {tail})")
    tr = simulate(scene, SpeedProfile.constant(om * wn), t_end / wn,
                  ball_angles0=np.asarray(ball_angles0, float), x0=x0, v0=v0, method=method,
                  dt=dt, output_dt=min(0.05, 1.0 / om) / wn)
    return _classify(tr, wn, e, om, tail / wn, balanced_tol, speed_tol)


def run_from_equilibrium(system: Groups | Scene, omega: float, q, *, perturbation: float = 1e-3,
                         t_end: float = 300.0, seed: int = 0, method: str = "rk4",
                         length_scale: float | None = None) -> dict:
    """Start next to the rotating-frame equilibrium ``q = [u, v, b_1..b_n]`` (u, v in units of
    e) with every coordinate perturbed by up to ``perturbation`` (e or rad), at rest in the
    rotating frame, and run for ``t_end`` (units of 1/w_n).

    Returns ``initial_distance``, ``final_distance`` (max-norm distance of [u, v, b] from q
    over the last 10 % of the run, angles wrapped), ``ratio`` = final/initial, and the
    trajectory.  For a member of a balanced family (n >= 3) the distance is to the family
    (``to_family`` True): max(rotor offset [e], |sum a_i e^{i b_i} - T| / sum a_i), since a
    perturbed run may settle on a neighbouring member (the structural zero eigenvalue).
    A stable equilibrium gives ratio << 1, an unstable one ratio >> 1.
    """
    scene, g, wn, e = physical_system(system, length_scale)
    q = np.asarray(q, float)
    n = scene.ball_count
    if q.shape != (2 + n,):
        raise ValueError(f"q must have 2 + n_balls = {2 + n} entries (got {q.shape})")
    rng = np.random.default_rng(seed)
    dq = perturbation * rng.uniform(-1, 1, size=q.shape)
    q0 = q + dq
    om = float(omega)
    # rotating frame coincides with the fixed frame at t = 0 (rotor angle 0); a state at rest
    # in the rotating frame moves with i Omega w in the fixed frame
    x0 = q0[:2] * e
    v0 = om * wn * np.array([-x0[1], x0[0]])
    tr = simulate(scene, SpeedProfile.constant(om * wn), t_end / wn, ball_angles0=q0[2:],
                  x0=x0, v0=v0, method=method, output_dt=min(0.05, 1.0 / om) / wn)
    th = tr.rotor_angle
    u = (np.cos(th) * tr.x + np.sin(th) * tr.y) / e
    v = (-np.sin(th) * tr.x + np.cos(th) * tr.y) / e
    c = coefficients(g)
    balanced = abs(complex(q[0], q[1]) + c.ecc) < 1e-9
    if balanced and n >= 3:
        # a member of the balanced family: measure the distance to the family (the state may
        # settle on a neighbouring member), i.e. the rotor offset and the ball-sum defect
        target = balanced_target(g, om)
        defect = np.abs(np.exp(1j * tr.ball_angles) @ c.a - target) / c.a.sum()
        dist = np.maximum(np.hypot(u - q[0], v - q[1]), defect)
        defect0 = abs(np.exp(1j * q0[2:]) @ c.a - target) / c.a.sum()
        initial = float(max(math.hypot(*(q0[:2] - q[:2])), defect0))
    else:
        db = np.angle(np.exp(1j * (tr.ball_angles - q[2:])))
        dist = np.max(np.abs(np.column_stack([u - q[0], v - q[1], db])), axis=1)
        initial = float(np.max(np.abs(dq)))
    k = tr.t >= 0.9 * tr.t[-1]
    final = float(np.max(dist[k]))
    return {"initial_distance": initial, "final_distance": final, "ratio": final / initial,
            "to_family": bool(balanced and n >= 3), "trajectory": tr}


@dataclass
class ClumpedWhirl:
    """Outcome of :func:`clumped_whirl`: the run from clumped balls and from spread balls.

    ``coexists``: the clumped start ends in the whirl while the spread start balances.
    """

    omega: float
    clumped: Settled
    spread: Settled

    @property
    def coexists(self) -> bool:
        return self.clumped.state == "whirl" and self.spread.state == "balanced"

    def report(self) -> str:
        c, s = self.clumped, self.spread
        lines = [f"Omega = {self.omega:g}:",
                 f"  clumped start -> {c.state}: r in [{c.radius_min:.4g}, {c.radius_max:.4g}] e,"
                 f" ball speed rel. rotor {np.round(c.ball_speed, 3)} w_n, inertial ball "
                 f"frequency {np.round(c.whirl_frequency, 3)} w_n",
                 f"  spread start  -> {s.state}: r in [{s.radius_min:.3g}, {s.radius_max:.3g}] e,"
                 f" balls at {np.round(np.degrees(s.final_angles), 2)} deg"]
        return "\n".join(lines)


def clumped_whirl(system: Groups | Scene, omega: float, t_end: float = 3000.0,
                  clumped_angles=None, spread_angles=None, **kwargs) -> ClumpedWhirl:
    """Search for the clumped-ball whirl coexisting with the balanced state at ``omega``.

    Two runs of ``t_end`` (units of 1/w_n): balls clumped near the imbalance (default Lu &
    Hung's Fig. 6 IC1, (0.01, 0.02, 0.03) pi, repeated for more balls) and equally spaced
    balls (0, 2 pi/n, ...).  Extra keyword arguments go to :func:`settle`.
    """
    scene, g, _, _ = physical_system(system, kwargs.get("length_scale"))
    n = g.n_balls
    if clumped_angles is None:
        clumped_angles = [CLUMPED_ANGLES[i % 3] + 0.03 * math.pi * (i // 3) for i in range(n)]
    if spread_angles is None:
        spread_angles = 2 * np.pi * np.arange(n) / n
    c = settle(system, omega, clumped_angles, t_end, **kwargs)
    s = settle(system, omega, spread_angles, t_end, **kwargs)
    return ClumpedWhirl(omega=float(omega), clumped=c, spread=s)
