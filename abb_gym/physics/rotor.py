"""Facts about a balancer machine that every layer needs, computed once.

The environments (reward scales, ``info["balanced"]``), the run-up metrics, the baselines and
the plots all call these functions; none of them re-derives a fact.

=============================  ==========  ===================================================
function                       unit        fact
=============================  ==========  ===================================================
:func:`imbalance_scale`        kg m        the imbalance that normalises residual imbalances
:func:`residual_imbalance`     kg m        ``|U0 + sum m_i (E e^{i gam} + R e^{i ph_i})|``
:func:`best_residual`          kg m        the smallest residual the balls can reach
:func:`is_balanced`            bool        residual within a tolerance of the best
:func:`reference_amplitudes`   m           whirl of the same machine with its balancer off
:func:`jeffcott_response`      m, rad      steady synchronous whirl: amplitude and phase lag
:func:`spinning_inertia`       kg m^2      rotor plus balls rolling along with it
:func:`static_deflection`      m           rest position of the rotor centre (gravity sag)
=============================  ==========  ===================================================

**Reference amplitude: one mass convention.**  The vibration scales of the environments and
the metrics compare a run with *the same machine with its balancer switched off*: the balls
locked in a self-cancelling arrangement, so the supported mass is the total mass ``M``
(rotor plus balls) and the imbalance is the primary one.  This machine resonates at the
scene's critical speed ``sqrt(k / M)``, where the run-up's own resonance is, so "a residual
ratio of 1 is no better than without a balancer" compares like with like.  (The first wave
used the rotor mass without balls in the environments and the total mass in the metrics:
2.5 % apart on ``yoshida_odd``, and a resonance at a speed the machine never has.)

**Residual imbalance** counts the race eccentricity: a race whose centre is offset by ``E``
carries the balls' mass off-centre, the fixed imbalance ``sum m_i E e^{i gam}``; the balls'
own part ``sum m_i R e^{i ph_i}`` can take any magnitude between
``max(0, 2 max m_i R - sum m_i R)`` (unequal balls cannot cancel each other completely) and
``sum m_i R``.  Hence the best residual is the distance of the fixed imbalance from that ring.

Ball angles are measured from the imbalance, relative to the rotor (radians).
"""
from __future__ import annotations

import math

import numpy as np
from .._numba import njit

from . import model as mdl
from .scene import Scene

__all__ = ["IMBALANCE_FLOOR", "imbalance_scale", "residual_imbalance", "residual_imbalance_packed",
           "best_residual", "is_balanced", "reference_amplitudes", "jeffcott_amplitude",
           "jeffcott_response",
           "spinning_inertia", "static_deflection"]


# Below this fraction of the balancing capacity sum m_i R the primary imbalance no longer sets
# the vibration a run-up sees: the balls, which start anywhere, carry an imbalance of the order
# of the capacity until they settle.  Normalising by U0 itself would make the reward scale as
# 1/U0 (a return of -3.4e6 at U0 = 1e-6 capacities, -inf at a subnormal U0) while U0 = 0 fell
# back to the capacity (-4.5): a jump of six orders of magnitude.  max(U0, floor) is
# continuous, finite for every U0 >= 0, and leaves every shipped preset's episodes (0.2 to 1.3
# capacities) and every shipped scene (0.46 to 0.91) exactly as they were.
IMBALANCE_FLOOR = 0.1


def imbalance_scale(scene: Scene, imbalance=None):
    """Imbalance [kg m] that normalises residual imbalances and the reference amplitudes:
    ``max(U0, IMBALANCE_FLOOR * sum m_i R)``, the primary imbalance U0 [kg m] floored at a
    tenth of the balancing capacity (the comment on :data:`IMBALANCE_FLOOR` says why), so
    the scale and the reward are continuous and finite down to U0 = 0.  ``imbalance``: U0
    [kg m] instead of the scene's (may be an array: the episodes of many environments)."""
    u0 = scene.imbalance if imbalance is None else imbalance
    out = np.maximum(np.asarray(u0, float), IMBALANCE_FLOOR * scene.balancing_capacity)
    return float(out) if out.ndim == 0 else out


@njit(cache=True)
def residual_imbalance_packed(p, b, ball_angles):
    """``|U0 + sum m_i (E e^{i gam} + R e^{i ph_i})|`` [kg m] from packed parameters
    (:func:`abb_gym.physics.model.pack_parameters`) and ball angles [rad]."""
    big_r = p[mdl.P_R]
    e = p[mdl.P_E]
    gam = p[mdl.P_GAM]
    ux = p[mdl.P_U0]
    uy = 0.0
    for k in range(b.shape[0]):
        m = b[k, mdl.B_MASS]
        ph = ball_angles[k]
        ux += m * (e * math.cos(gam) + big_r * math.cos(ph))
        uy += m * (e * math.sin(gam) + big_r * math.sin(ph))
    return math.sqrt(ux * ux + uy * uy)


def residual_imbalance(scene: Scene, ball_angles) -> np.ndarray | float:
    """Residual imbalance [kg m] for ball angles [rad] of shape (n,) or (T, n)."""
    p, b = mdl.pack_parameters(scene)
    angles = np.asarray(ball_angles, dtype=float)
    if angles.ndim == 1:
        return residual_imbalance_packed(p, b, angles)
    return np.array([residual_imbalance_packed(p, b, a) for a in angles])


def best_residual(scene: Scene, imbalance=None):
    """Smallest residual imbalance [kg m] the balls can reach (module docstring);
    ``imbalance``: U0 instead of the scene's (may be an array)."""
    u0 = scene.imbalance if imbalance is None else np.asarray(imbalance, float)
    mr = np.asarray(scene.ball_mass) * scene.race_radius
    cap = float(mr.sum())
    lo = max(0.0, 2.0 * float(mr.max()) - cap)
    me = float(sum(scene.ball_mass)) * scene.race_eccentricity
    fixed = np.hypot(u0 + me * math.cos(scene.race_eccentricity_angle),
                     me * math.sin(scene.race_eccentricity_angle))
    out = np.where(fixed < lo, lo - fixed, np.where(fixed > cap, fixed - cap, 0.0))
    return float(out) if out.ndim == 0 else out


@njit(cache=True)
def best_residual_packed(p, b):
    """:func:`best_residual` [kg m] and :func:`imbalance_scale` [kg m] of one machine from its
    packed parameters (:func:`abb_gym.physics.model.pack_parameters`): what a compiled step
    needs after the imbalance changed (:mod:`abb_gym.physics.laundry`)."""
    big_r = p[mdl.P_R]
    cap = 0.0
    largest = 0.0
    balls = 0.0
    for k in range(b.shape[0]):
        mr = b[k, mdl.B_MASS] * big_r
        cap += mr
        largest = max(largest, mr)
        balls += b[k, mdl.B_MASS]
    lo = max(0.0, 2.0 * largest - cap)
    me = balls * p[mdl.P_E]
    u0 = p[mdl.P_U0]
    fixed = math.hypot(u0 + me * math.cos(p[mdl.P_GAM]), me * math.sin(p[mdl.P_GAM]))
    best = lo - fixed if fixed < lo else (fixed - cap if fixed > cap else 0.0)
    return best, max(u0, IMBALANCE_FLOOR * cap)


@njit(cache=True, inline="always")
def is_balanced(residual, best, tolerance, scale):
    """True if ``residual`` [kg m] is within ``tolerance * scale`` of ``best`` [kg m]."""
    return residual <= best + tolerance * scale


def jeffcott_amplitude(imbalance: float, mass: float, stiffness: float, damping: float,
                       speed: float) -> float:
    """Steady whirl amplitude ``U w^2 / sqrt((k - m w^2)^2 + (c w)^2)`` of a Jeffcott rotor [m]."""
    w2 = speed * speed
    den = math.hypot(stiffness - mass * w2, damping * speed)
    return imbalance * w2 / den if den > 0 else math.inf


def jeffcott_response(imbalance: float, mass: float, stiffness: float, damping: float,
                      speed: float) -> tuple[float, float]:
    """Steady synchronous whirl of a Jeffcott rotor at constant ``speed`` [rad/s]: (amplitude
    [m], phase lag [rad]).  From ``M z'' + c z' + k z = U W^2 e^{i W t}``:
    ``z = U W^2 / (k - M W^2 + i c W) e^{i W t}``, so the whirl trails the imbalance by
    ``atan2(c W, k - M W^2)`` in [0, pi] (0 below the critical speed sqrt(k/M), pi/2 at it,
    towards pi above) with the amplitude of :func:`jeffcott_amplitude`."""
    w2 = speed * speed
    return (jeffcott_amplitude(imbalance, mass, stiffness, damping, speed),
            math.atan2(damping * speed, stiffness - mass * w2))


def reference_amplitudes(scene: Scene, operating_speed: float, imbalance: float | None = None,
                         mass=None, damping_scale=None) -> tuple[float, float]:
    """(peak over [0, w_op], value at w_op) [m] of the steady whirl of the same machine with
    its balancer off (module docstring): mass ``total_mass``, the scene's support, imbalance
    ``imbalance`` [kg m] (default: :func:`imbalance_scale`; an array gives arrays).
    ``mass`` [kg] and ``damping_scale`` (a factor on the support damping) describe a machine
    that differs from the scene (an episode of a preset that randomises them); arrays of them
    give arrays, computed row by row as for a scene with those values.

    With an orthotropic support each axis is a Jeffcott oscillator of its own; the orbit's
    major semi-axis is the larger of the two amplitudes.  The peak of ``U w^2 / |...|`` lies at
    ``w*^2 = k / (m - c^2 / (2 k))`` (if that is positive and ``w* <= w_op``), else at w_op.
    """
    u = imbalance_scale(scene) if imbalance is None else imbalance
    if mass is not None or damping_scale is not None:
        n = np.broadcast(u, 1.0 if mass is None else mass,
                         1.0 if damping_scale is None else damping_scale).shape
        us = np.broadcast_to(np.asarray(u, float), n)
        ms = np.broadcast_to(np.asarray(scene.total_mass if mass is None else mass, float), n)
        ds = np.broadcast_to(np.asarray(1.0 if damping_scale is None else damping_scale, float),
                             n)
        peak = np.empty(n)
        at_op = np.empty(n)
        for r in np.ndindex(*n):
            peak[r], at_op[r] = _reference_amplitudes(
                float(us[r]), float(ms[r]), scene.support_stiffness_x,
                scene.support_stiffness_y, _scaled(scene.support_damping_x, float(ds[r])),
                _scaled(scene.support_damping_y, float(ds[r])), operating_speed)
        if peak.ndim == 0:
            return float(peak), float(at_op)
        return peak, at_op
    m = scene.total_mass
    peak = 0.0
    at_op = 0.0
    for k, c in ((scene.support_stiffness_x, scene.support_damping_x),
                 (scene.support_stiffness_y, scene.support_damping_y)):
        a_op = jeffcott_amplitude(u, m, k, c, operating_speed)
        at_op = np.maximum(at_op, a_op)
        peak = np.maximum(peak, a_op)
        den = m - c * c / (2.0 * k)
        if den > 0:
            w_star = math.sqrt(k / den)
            if w_star <= operating_speed:
                peak = np.maximum(peak, jeffcott_amplitude(u, m, k, c, w_star))
    if np.ndim(peak) == 0:
        return float(peak), float(at_op)
    return peak, at_op


def _scaled(value: float, factor: float) -> float:
    """``value * factor``, exactly ``value`` for the factor 1 (how episodes scale a field)."""
    return value if factor == 1.0 else value * factor


def _reference_amplitudes(u: float, m: float, kx: float, ky: float, cx: float, cy: float,
                          operating_speed: float) -> tuple[float, float]:
    """:func:`reference_amplitudes` of one machine given by its numbers."""
    peak = at_op = 0.0
    for k, c in ((kx, cx), (ky, cy)):
        a_op = jeffcott_amplitude(u, m, k, c, operating_speed)
        at_op = max(at_op, a_op)
        peak = max(peak, a_op)
        den = m - c * c / (2.0 * k)
        if den > 0:
            w_star = math.sqrt(k / den)
            if w_star <= operating_speed:
                peak = max(peak, jeffcott_amplitude(u, m, k, c, w_star))
    return peak, at_op


def spinning_inertia(scene: Scene) -> float:
    """Polar inertia [kg m^2] of the rotor with the balls rolling along with it: the rotor's
    ``J`` plus, per ball, its spin inertia (it turns with the rotor) and ``m_i (R^2 + E^2)``,
    the rotor-row entry of the mass matrix with the ball-angle dependent part averaged out."""
    a = scene.arrays()
    ball_spin = a["ball_inertia_factor"] * a["ball_mass"] * a["ball_radius"] ** 2
    orbit = a["ball_mass"] * (scene.race_radius ** 2 + scene.race_eccentricity ** 2)
    return scene.rotor_polar_inertia + float(np.sum(ball_spin + orbit))


def static_deflection(scene: Scene, mass=None) -> tuple[float, float]:
    """Rest position (x, y) [m] of the rotor centre: the sag ``M g / k`` under gravity, else 0.

    Gravity acts in the balancing plane only for a horizontal-axis rotor (scenes with
    ``gravity_acceleration > 0``); then the supported mass M hangs at ``M g_x / k_x``,
    ``M g_y / k_y``.  ``mass``: the supported mass [kg] instead of the scene's (an array gives
    arrays: the episodes of a preset that varies the load)."""
    g = scene.gravity_acceleration
    if g <= 0.0:
        return 0.0, 0.0
    a = scene.gravity_angle
    m = scene.total_mass if mass is None else mass
    return (m * g * math.cos(a) / scene.support_stiffness_x,
            m * g * math.sin(a) / scene.support_stiffness_y)
