"""Ball-ball contact in one race: a dissipative penalty on the angular gap.

Balls i and j (centres on the track of radius R) are a distance ``chord = 2 R sin(|d|/2)``
apart, with ``d = ph_j - ph_i`` wrapped to (-pi, pi].  They touch when the chord is shorter
than ``r_i + r_j``; the penetration ``delta = r_i + r_j - chord`` gives a normal force

    F_n = max(0, k delta + c delta'),   c = 2 zeta sqrt(k m_ij),

a linear spring-damper (the form of Spannan's race contact, eq. 5.3, applied between balls; the
thesis itself has no ball-ball contact).  m_ij = m_i m_j / (m_i + m_j) is the reduced mass of
the pair in the track direction, with each ball's effective mass ``m_i = I_i / R^2`` (its
relative inertia including spin and virtual mass), so ``zeta`` is the damping ratio of the
contact oscillation and the coefficient of restitution is exp(-zeta pi / sqrt(1 - zeta^2))
(0.16 for zeta = 0.5).  The max(0, .) keeps the contact from pulling.

The force is the gradient of the penalty energy ``k delta^2 / 2``, which depends on ph_j - ph_i
only, so its generalised forces are equal and opposite on the two balls,
``Q_j = -Q_i = F_n R cos(d/2) sgn(d)``, and zero on x, y and the rotor angle: the contact
conserves the total (angular) momentum, and it does negative work only through the damper.
The radial part of the force, ``F_n sin(|d|/2)`` outward on both balls, is taken by the race;
it adds to the race normal force used by friction and rolling resistance.

**Stiffness.**  The thesis notes (L1189) that an under-estimated contact stiffness gives
smoother force build-up and larger steps at a negligible geometric error.  The penetration of a
collision at relative speed v is about v / omega_c with ``omega_c = sqrt(k / m_ij)``, so pick k
for an acceptable overlap at the fastest relative speeds of the scene; omega_c then bounds the
step of every explicit method (RK4, ETDRK4: h omega_c < ~2.8), and
:func:`abb_gym.physics.model.drag_rates_block` reports it so that the RK4 step rule keeps to it.

**When it matters.**  With three or more balls (or two that start close together) the balls
meet whenever they clump: during the run-up, when they lag the rotor together, and in the final
balanced configuration, where the capacity formula (Spannan 2.3) assumes touching balls.
Without contact balls pass through each other and can settle in impossible, overlapping
positions.
"""
from __future__ import annotations

import math

from .._numba import njit

TWO_PI = 2.0 * math.pi


@njit(cache=True, inline="always")
def wrap_angle(d):
    """Angle wrapped to (-pi, pi]."""
    return d - TWO_PI * math.floor((d + math.pi) / TWO_PI)


@njit(cache=True, inline="always")
def pair_geometry(phi_i, phi_j, big_r, reach):
    """(penetration [m], d chord / d(ph_j - ph_i) [m], sin(|d|/2)) of a ball pair."""
    d = wrap_angle(phi_j - phi_i)
    half = 0.5 * abs(d)
    pen = reach - 2.0 * big_r * math.sin(half)
    dchord = big_r * math.cos(half)
    if d < 0.0:
        dchord = -dchord
    return pen, dchord, math.sin(half)


@njit(cache=True)
def ball_contacts_lane(s, l, nq, b, col_r, col_m, big_r, k, zeta, out, col_q, col_n):
    """Generalised contact forces on the ball angles of lane ``l`` into ``out[:, col_q, l]``
    [N m] and the outward radial contact force on each ball into ``out[:, col_n, l]`` [N].

    ``s`` (state, lanes), ``b[i, col_r, l]`` ball radii [m], ``b[i, col_m, l]`` effective
    masses along the track [kg] (the lane layout of :func:`abb_gym.physics.model.
    accelerations_block`)."""
    n = b.shape[0]
    for i in range(n):
        out[i, col_q, l] = 0.0
        out[i, col_n, l] = 0.0
    for i in range(n - 1):
        for j in range(i + 1, n):
            pen, dchord, sh = pair_geometry(s[3 + i, l], s[3 + j, l], big_r,
                                            b[i, col_r, l] + b[j, col_r, l])
            if pen > 0.0:
                rate = -dchord * (s[nq + 3 + j, l] - s[nq + 3 + i, l])
                mi = b[i, col_m, l]
                mj = b[j, col_m, l]
                force = k * pen + 2.0 * zeta * math.sqrt(k * mi * mj / (mi + mj)) * rate
                if force > 0.0:
                    q = force * dchord
                    out[j, col_q, l] += q
                    out[i, col_q, l] -= q
                    out[i, col_n, l] += force * sh
                    out[j, col_n, l] += force * sh


@njit(cache=True)
def contact_energy(q, b, col_r, big_r, k):
    """Penalty energy k delta^2 / 2 summed over touching pairs [J]."""
    n = b.shape[0]
    e = 0.0
    for i in range(n - 1):
        for j in range(i + 1, n):
            pen, dchord, sh = pair_geometry(q[3 + i], q[3 + j], big_r, b[i, col_r] + b[j, col_r])
            if pen > 0.0:
                e += 0.5 * k * pen * pen
    return e


@njit(cache=True)
def contact_rate_lane(s, l, i, b, col_r, col_m, big_r, k, zeta):
    """Bound on the contact eigenvalue magnitude of ball i of lane ``l`` [1/s] (0 if it
    touches nothing).

    Gershgorin over the touching neighbours, omega^2 = sum_j k (1/m_i + 1/m_j), counting the
    two largest terms only: in a ring a ball has one neighbour on each side, and the state at
    which the step rule asks (all balls at ph = 0, :func:`abb_gym.physics.steps.stiff_rate`)
    would otherwise count every ball.  Overdamped contacts (zeta > 1/2) have a fast real root
    up to 2 zeta omega."""
    first = 0.0
    second = 0.0
    for j in range(b.shape[0]):
        if j != i:
            pen, dchord, sh = pair_geometry(s[3 + i, l], s[3 + j, l], big_r,
                                            b[i, col_r, l] + b[j, col_r, l])
            if pen > 0.0:
                w2 = k * (1.0 / b[i, col_m, l] + 1.0 / b[j, col_m, l])
                if w2 > first:
                    second = first
                    first = w2
                elif w2 > second:
                    second = w2
    if first == 0.0:
        return 0.0
    return math.sqrt(first + second) * max(1.0, 2.0 * zeta)
