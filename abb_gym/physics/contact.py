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
from . import elementary as el

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
    sh, ch = el.sincos(half)
    pen = reach - 2.0 * big_r * sh
    dchord = big_r * ch
    if d < 0.0:
        dchord = -dchord
    return pen, dchord, sh


@njit(cache=True, inline="always")
def pair_force(phi_i, phi_j, dphi_i, dphi_j, big_r, reach, mi, mj, k, zeta):
    """(touching, q [N m], radial force [N]) of the pair of balls at angles ``phi_i``,
    ``phi_j`` [rad] with angular speeds ``dphi_i``, ``dphi_j`` [rad/s], effective masses ``mi``,
    ``mj`` [kg] and ``reach`` = r_i + r_j [m]: the generalised force is +q on ball j and -q on
    ball i, the radial force acts outward on both; q and the radial force are 0 when the pair
    does not touch (penetration or force not positive).  Written without branches, so that a
    lane loop over it vectorises; where the pair touches, every operation is the one the
    module docstring's force law needs, in the same order whoever calls it."""
    pen, dchord, sh = pair_geometry(phi_i, phi_j, big_r, reach)
    rate = -dchord * (dphi_j - dphi_i)
    force = k * pen + 2.0 * zeta * math.sqrt(k * mi * mj / (mi + mj)) * rate
    on = pen > 0.0 and force > 0.0
    return on, (force * dchord if on else 0.0), (force * sh if on else 0.0)


@njit(cache=True)
def ball_contacts_lane(s, l, nq, b, col_r, col_m, big_r, k, zeta, out, row_q, row_n):
    """Generalised contact forces on the ball angles of lane ``l`` over **all pairs** into
    ``out[row_q + i, l]`` [N m] and the outward radial contact force on each ball into
    ``out[row_n + i, l]`` [N] (rows of a lane-last array).

    ``s`` (state, lanes), ``b[i, col_r, l]`` ball radii [m], ``b[i, col_m, l]`` effective
    masses along the track [kg] (the lane layout of :func:`abb_gym.physics.model.
    accelerations_block`).  The kernels use it where the neighbour list does not apply
    (:func:`ring_holds`) and in float32 blocks."""
    n = b.shape[0]
    for i in range(n):
        out[row_q + i, l] = 0.0
        out[row_n + i, l] = 0.0
    for i in range(n - 1):
        for j in range(i + 1, n):
            on, q, radial = pair_force(s[3 + i, l], s[3 + j, l], s[nq + 3 + i, l],
                                       s[nq + 3 + j, l], big_r,
                                       b[i, col_r, l] + b[j, col_r, l], b[i, col_m, l],
                                       b[j, col_m, l], k, zeta)
            if on:
                out[row_q + j, l] += q
                out[row_q + i, l] -= q
                out[row_n + i, l] += radial
                out[row_n + j, l] += radial


def neighbour_reach_angle(radii, big_r: float) -> float:
    """The angular distance [rad] at or beyond which no two balls of radii ``radii`` [m] on a
    track of radius ``big_r`` [m] can touch: 2 asin(2 r_max / (2 R)), widened by a relative
    1e-6 against rounding (pi when the balls are as large as the track).  The kernels' guard
    of the neighbour list (:func:`ring_holds`) compares the arc across one ball with it."""
    half = min(1.0, max(radii) / big_r)
    return min(math.pi, 2.0 * math.asin(half) * (1.0 + 1e-6))


#: largest reach angle [rad] (:func:`neighbour_reach_angle`) for which :func:`may_touch` rules
#: pairs out: balls smaller than sin(1) = 0.84 of the track radius.  Below it the angle's
#: relative widening of 1e-6 keeps the chord of a pair beyond the angle longer than its reach
#: by at least 1e-6 cos(1) / 2 relative, far above the rounding of the pair's geometry.
GUARD_LIMIT = 2.0


@njit(cache=True, inline="always")
def may_touch(d, reach_angle):
    """Whether a pair of balls ``d`` [rad] apart (wrapped, as :func:`pair_geometry` wraps
    it) may touch, for the ``reach_angle`` of :func:`neighbour_reach_angle`: False only where
    :func:`pair_force` is certain to find no penetration, so that it need not be asked there
    (a few operations against the pair force's sine, cosine, square root and division).
    Without branches."""
    return abs(d) <= reach_angle or reach_angle >= GUARD_LIMIT


@njit(cache=True, inline="always")
def mod_turn(a):
    """``a`` [rad] reduced to [0, 2 pi) (floor, which vectorises)."""
    return a - TWO_PI * math.floor(a * (1.0 / TWO_PI))


@njit(cache=True, inline="always")
def ring_holds(s, l, n, reach_angle):
    """Whether the neighbour list of lane ``l`` is exact: the balls, taken in index order,
    go round the race once (index order is their order along the race), and the arc across
    every ball, from its previous to its next neighbour, is at least ``reach_angle``
    (:func:`neighbour_reach_angle`), so that no two balls but neighbours can touch.  For
    ``n`` >= 4; with 2 or 3 balls every pair is a neighbour pair.  Without branches (it
    vectorises); the forward gaps are reduced to [0, 2 pi), so their sum is 2 pi times the
    number of turns."""
    total = 0.0
    first = mod_turn(s[3, l] - s[3 + n - 1, l])
    prev = first
    narrow = 0.0
    for i in range(n):
        gap = mod_turn(s[3 + i + 1, l] - s[3 + i, l]) if i + 1 < n else first
        total += gap
        narrow = max(narrow, reach_angle - (prev + gap))
        prev = gap
    return total < 3.0 * math.pi and narrow <= 0.0


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


@njit(cache=True, inline="always")
def _pair_rate2(s, l, i, j, b, col_r, col_m, big_r, k):
    """k (1/m_i + 1/m_j) [1/s^2] of the pair (i, j) of lane ``l`` if it touches, else 0."""
    pen, dchord, sh = pair_geometry(s[3 + i, l], s[3 + j, l], big_r,
                                    b[i, col_r, l] + b[j, col_r, l])
    if pen > 0.0:
        return k * (1.0 / b[i, col_m, l] + 1.0 / b[j, col_m, l])
    return 0.0


@njit(cache=True, inline="always")
def add_contact_rates_lane(s, l, b, col_r, col_m, big_r, k, zeta, reach_angle, out, row):
    """:func:`contact_rate_lane` of every ball of lane ``l``, added to ``out[row + i, l]``
    [1/s].  Where the neighbour list holds (four or more balls, :func:`ring_holds`), each
    neighbour pair's term is computed once and shared by its two balls, and the ring test is
    made once for the lane instead of once per ball: the same two terms per ball, summed to
    the same bits (a sum of two non-negative terms is the same in either order, and
    :func:`pair_geometry` gives a pair the same numbers in either order)."""
    n = b.shape[0]
    if n >= 4 and ring_holds(s, l, n, reach_angle):
        scale = max(1.0, 2.0 * zeta)
        first = _pair_rate2(s, l, n - 1, 0, b, col_r, col_m, big_r, k)
        left = first
        for i in range(n):
            right = _pair_rate2(s, l, i, i + 1, b, col_r, col_m, big_r, k) if i + 1 < n \
                else first
            both = left + right
            out[row + i, l] += math.sqrt(both) * scale if both > 0.0 else 0.0
            left = right
    else:
        for i in range(n):
            out[row + i, l] += contact_rate_lane(s, l, i, b, col_r, col_m, big_r, k, zeta)


@njit(cache=True)
def contact_rate_lane(s, l, i, b, col_r, col_m, big_r, k, zeta):
    """Bound on the contact eigenvalue magnitude of ball i of lane ``l`` [1/s] (0 if it
    touches nothing), asking every other ball.

    Gershgorin over the touching neighbours, omega^2 = sum_j k (1/m_i + 1/m_j), counting the
    two largest terms only: in a ring a ball has one neighbour on each side, and the state at
    which the step rule asks (all balls at ph = 0, :func:`abb_gym.physics.steps.stiff_rate`)
    would otherwise count every ball.  Overdamped contacts (zeta > 1/2) have a fast real root
    up to 2 zeta omega.  Where the neighbour list holds, :func:`add_contact_rates_lane` asks
    the neighbours only, for the same bits."""
    n = b.shape[0]
    first = 0.0
    second = 0.0
    for j in range(n):
        if j != i:
            w2 = _pair_rate2(s, l, i, j, b, col_r, col_m, big_r, k)
            if w2 > first:
                second = first
                first = w2
            elif w2 > second:
                second = w2
    if first == 0.0:
        return 0.0
    return math.sqrt(first + second) * max(1.0, 2.0 * zeta)
