"""Equations of motion of the planar rotor with an n-ball automatic balancer (compiled).

Generalised coordinates ``q = [x, y, th, ph_1 .. ph_n]``:

* ``x, y`` [m] deflection of the rotor centre from the bearing axis (fixed frame),
* ``th`` [rad] rotor angle, measured to the primary imbalance,
* ``ph_i`` [rad] angle of ball i relative to the rotor, measured from the imbalance
  (the balanced position of two balls against a small imbalance is near +-pi).

The state is ``s = [q, q']`` (length ``2 (3 + n)``).

Equations: Spannan (2021) eqs. (4.14)-(4.17) in the symmetric mass-matrix form of the physics
note (section 1.4), which was re-derived here from the kinetic energy of point masses plus ball
spin (the test-suite checks the mass matrix and the velocity terms against finite differences of
the kinematics (4.9)), plus rolling resistance:

    row x   M x'' - Sx th'' - sum m_i R sin(th+ph_i) ph_i''
              = -c_x x' - k_x x + U0 cos th th'^2
                + sum [E m_i cos(th+gam) th'^2 + m_i R (th'+ph_i')^2 cos(th+ph_i)]
    row y   M y'' + Cy th'' + sum m_i R cos(th+ph_i) ph_i''
              = -c_y y' - k_y y + U0 sin th th'^2
                + sum [E m_i sin(th+gam) th'^2 + m_i R (th'+ph_i')^2 sin(th+ph_i)]
    row th  Jt th'' - Sx x'' + Cy y'' + sum c_i ph_i''
              = T_motor - beta_0 th' - sum E m_i R sin(gam-ph_i) ph_i' (2 th' + ph_i')
    row ph  I_i ph_i'' - m_i R sin(th+ph_i) x'' + m_i R cos(th+ph_i) y'' + c_i th''
              = -beta_i ph_i' + m_i R E sin(gam-ph_i) th'^2 + Q_roll,i

    Sx  = U0 sin th + sum [E m_i sin(th+gam) + m_i R sin(th+ph_i)]
    Cy  = U0 cos th + sum [E m_i cos(th+gam) + m_i R cos(th+ph_i)]
    Jt  = J + sum [J_i + m_i E^2 + m_i R^2 + 2 E m_i R cos(gam-ph_i)]
    c_i = m_i R^2 + E m_i R cos(gam-ph_i) - J_i R / r_i
    I_i = J_i R^2 / r_i^2 + m_i R^2

with M the total mass (rotor + balls), U0 = m0 e0 the primary imbalance, J the rotor's polar
inertia (including its imbalance), R the ball-centre track radius, r_i, J_i the ball radius and
spin inertia, beta_i = c_b,i R^2 the race-drag torque coefficient, E and gam the race eccentricity.

Decisions recorded here:

* Rolling constraint: Spannan's (4.8) ``R ph + (kappa - th) r = 0`` is exact for a ball whose
  centre runs on radius R and touches the outer race at R + r (its contact point is at rest in
  the rotor frame), so no (R + r) correction is applied.
* Yoshida's ball equation (2-11) is this ph-row divided by R with th = psi prescribed; the term
  ``((R + a)/a^2) I psi''`` of the thesis is exactly the ``c_i th''`` coupling (c_i = m R^2 -
  J R / a) once ``psi_i'' = psi'' + ph_i''`` is substituted, so the thesis and Spannan agree.
  The race drag maps as beta = c_b R^2 (Yoshida's Rayleigh term c_b/2 R^2 (psi_i' - psi')^2).
* Rolling resistance (Yoshida eq. 2-8, Spannan eq. 5.14): a torque of the normal force N_i about
  an offset beta_b on the ball spin, i.e. a generalised force
  ``Q_roll,i = -(beta_b / r_i) R N_i sgn(ph_i')`` with the race normal force
  ``N_i = m_i [R (th'+ph_i')^2 + E th'^2 cos(gam-ph_i) + E th'' sin(gam-ph_i) -
  x'' cos(th+ph_i) - y'' sin(th+ph_i)]``
  (the inward acceleration of the ball centre; with E = 0 it is Yoshida's bracket).  Its
  acceleration terms enter the left-hand side, which makes that part of the matrix
  non-symmetric; it is dissipative and not part of the mass matrix.  Spannan's factor 1/1.4 in
  (5.14) belongs to his contact-force element with a separate ball spin; in the one-DOF rolling
  model the offset torque acts on the spin directly and the factor does not appear.  The sign
  is regularised as tanh(R ph'/u*) with u* = ``rolling_regularization_speed`` so that the
  fixed-step integrators do not chatter; with u* = 1 mm/s the extra damping slope mu_r N / u*
  stays well below the race drag of every shipped scene.
* The rotor row carries no reaction of the race drag or the rolling resistance: both act
  between ball and rotor and do virtual work only on the relative coordinate ph_i.

Extended physics (each switched per scene by its parameters, :attr:`Scene.effects`).  The
equations are written once (:func:`_accelerations_body`) and compiled twice: a scene with no
extended effect runs the plain specialisation, in which their terms do not exist; in the
extended one each effect's terms run only where its flag is set:

* **Gravity** (``gravity``, horizontal-axis rotors): g along (cos a, sin a) in the fixed
  frame, a = ``gravity_angle`` (default -pi/2).  From V = -g . (sum of mass x position)
  (:func:`gravity_energy`): ``Q_x = M g cos a``, ``Q_y = M g sin a``,
  ``Q_th = g (sin a Cy - cos a Sx)`` and ``Q_ph,i = g m_i R sin(a - th - ph_i)``; the race
  normal force gains the outward weight component ``m_i g cos(a - th - ph_i)``.  Static sag:
  ``y = -M g / k_y``.  The ball stays on its track (bilateral constraint): when the weight
  beats the centrifugal force (R (th'+ph')^2 < g, a ball in the upper half at low speed) N
  turns negative, read as the ball bearing on the inner wall of the annulus, and friction and
  rolling resistance use |N| (its sign taken from the velocity-dependent part of N).  Real balls
  would fall and roll at the bottom there; the model is right for R Omega^2 > g and for balls in
  the lower half.  Gravity matters while the rotor is slow (start-up of washing machines and
  horizontal centrifuges: the balls gather at the bottom and are dragged round; R Omega^2 / g
  is 420 at 1200 rpm in the washer scene but below 1 under 59 rpm) and for the static sag of
  soft suspensions; it is "of minor relevance at the appropriate speed" (Spannan L1258).
* **Ball-ball contact** (``ball_contact``): penalty on the angular gap, equal and opposite
  generalised forces on the two balls (:mod:`abb_gym.physics.contact`); its radial part adds
  to the race normal force.  The penalty energy is part of :func:`total_energy`.
* **Nonlinear race drag** (``fluid_drag``): ``Q = -F(R ph') R`` with the c_d(Re) laws of
  :mod:`abb_gym.physics.fluids`, fluid co-rotating with the rotor; added to any ``ball_drag``.
* **Virtual mass** (``virtual_mass``): ``c_vm rho V R^2`` added to I_i (and so to the mass
  matrix diagonal and the kinetic energy); see :mod:`abb_gym.physics.fluids`.
* **Friction and stick** (``friction``/``stiction``): ``Q_fric,i = -mu(R ph') R |N_i|`` with
  the regularised Coulomb/Stribeck law of :mod:`abb_gym.physics.friction`; it shares the
  normal force (and so the left-hand-side acceleration terms) with the rolling resistance.
* The limited-power drive needs no new equations: the motor torque
  (:func:`abb_gym.physics.drive_law.motor_torque`) gets an available-torque envelope (linear
  torque-speed characteristic, power limit).

Solution: the ball block of the matrix is diagonal, so the balls are eliminated with a Schur
complement and only a 2x2 (prescribed speed) or 3x3 (rotor spin as a DOF) system is solved.
Kernels assume valid input; validation happens in :mod:`abb_gym.physics.scene`.
"""
from __future__ import annotations

import math

import numpy as np
from .._numba import njit

from . import contact as _contact
from . import elementary as el
from . import drive_law as dl
from . import fluids as _fluids
from .friction import friction_coefficient, friction_secant
from .scene import Scene

# scalar parameter vector layout (new entries are appended; users size arrays with N_PARAMS)
P_MASS, P_KX, P_KY, P_CX, P_CY, P_U0, P_J, P_BETA0, P_R, P_E, P_GAM, P_UREG, P_ROLL, P_ECC = \
    range(14)
# extended physics: gravity (flag, components g cos(angle), g sin(angle) [m/s^2]); ball-ball
# contact (stiffness [N/m], damping ratio); fluid drag law (kernel id, cubic of log10 c_d over
# log10 Re, plateau c_d); friction (flag, mu_k, mu_s, regularisation and Stribeck speeds [m/s])
(P_GRAV, P_GX, P_GY, P_KC, P_ZC, P_DLAW, P_CD0, P_CD1, P_CD2, P_CD3, P_CDINF, P_FRIC, P_MUK,
 P_MUS, P_UFR, P_USTR) = range(14, 30)
P_EXT = 30  # 1 if any of the extended effects above (or the virtual mass) is on
# ball-ball contact: the angular distance [rad] beyond which no two balls touch (the guard of
# the neighbour list, :func:`abb_gym.physics.contact.neighbour_reach_angle`)
P_REACH = 31
N_PARAMS = 32
EXTENDED_EFFECTS = frozenset({"gravity", "ball_contact", "fluid_drag", "virtual_mass",
                              "friction"})
# per-ball parameter matrix columns: mass [kg], radius [m], spin inertia [kg m^2], race drag
# torque coefficient [N m s], rolling-resistance offset / radius [-]; added relative inertia
# of the virtual mass [kg m^2], Stokes drag coefficient [N s/m], rho pi r^2 / 2 [kg/m],
# Reynolds number per relative speed 2 r / nu [s/m], effective track mass I_i / R^2 [kg];
# then the ball's constant mass-matrix entries (ball_inertias): c_i without the race
# eccentricity [kg m^2], I_i with any virtual mass [kg m^2], and 1 / I_i [1/(kg m^2)]
B_MASS, B_RADIUS, B_INERTIA, B_BETA, B_MUR = range(5)
B_VM, B_KLIN, B_KQUAD, B_REU, B_MEFF = range(5, 10)
B_CI, B_II, B_INV = range(10, 13)
N_BALL_PARAMS = 13
# scratch of the right-hand side, work[ball, column, lane]: the contact forces, then each
# ball's terms kept for the second pass (its 1 / I_i is read from B_INV again)
W_QC = 0  # generalised contact force on the ball [N m]
W_NC = 1  # outward radial contact force on the ball [N]
W_FI, W_BX, W_BY, W_BTH = range(2, 6)
# the ball's shares of the rotor's rows (col_x, col_y, c_i, Jt, Sx, Cy, x, y and th forces)
W_COLX, W_COLY, W_CI, W_JT, W_SX, W_CY, W_FX, W_FY, W_FTH = range(6, 15)
# the contact of neighbour pair k (balls k and k + 1, the last with ball 0) in row k: q (+q on
# the higher index, -q on the lower) [N m] and the radial force [N]; row 0 only: whether the
# lane's neighbour list is exact (1) or it takes every pair (0) (:func:`_contacts`)
W_PQ, W_PN, W_RING = 15, 16, 17
WORK_COLUMNS = 18
# after the contact forces are in ds, the columns W_QC, W_NC, W_PQ, W_PN and W_RING of balls
# 0-3 hold the 18 running sums of the rotor's rows (Sx, Cy, Jt, the three forces, the twelve
# Schur sums) while the split passes of accelerations_block add the balls one at a time
# (_sum_pass); sum k is in ball k // 5, column _SUM_COLUMNS[k % 5]
_SUM_COLUMNS = (W_QC, W_NC, W_PQ, W_PN, W_RING)
# kernel specialisation: which terms exist (compile-time constants of the vector kernels)
SPEC_EXT = 1       # an extended effect (gravity, contact, fluid drag, virtual mass, friction)
SPEC_ECC = 2       # race eccentricity
SPEC_ROLL = 4      # rolling resistance
SPEC_MOTOR = 8     # the rotor spin is a degree of freedom (motor drive rows)
SPEC_ENVELOPE = 16  # a motor with a torque-speed envelope
# not an effect but a layout: every block has one lane (a single environment), so that the
# lane count is a compile-time constant too (lanes_of)
SPEC_ONE_LANE = 32
# which of the extended effects (under SPEC_EXT) exist: a kernel compiled without one has none
# of its code.  Each term is also guarded by its lane's parameter (p[P_KC] != 0, ...), but LLVM
# turns such a branch into a select, which evaluates both sides in every lane: without the
# bits, every kernel with any extended effect would compute the fluid drag and the friction
# law in every lane and throw the results away.  A lane computes the same terms either way,
# so the bits change the cost, not the results.
SPEC_CONTACT = 64   # ball-ball contact (P_KC != 0)
SPEC_DRAG = 128     # a nonlinear fluid drag law (P_DLAW != 0)
SPEC_FRICTION = 256  # race friction (P_FRIC != 0)
SPEC_GRAVITY = 512  # gravity (P_GRAV != 0)


def pack_parameters(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Scene -> (scalar parameter vector, per-ball parameter matrix) for the kernels."""
    p = np.zeros(N_PARAMS)
    p[P_MASS] = scene.total_mass
    p[P_KX], p[P_KY] = scene.support_stiffness_x, scene.support_stiffness_y
    p[P_CX], p[P_CY] = scene.support_damping_x, scene.support_damping_y
    p[P_U0] = scene.imbalance
    p[P_J] = scene.rotor_polar_inertia
    p[P_BETA0] = scene.bearing_drag
    p[P_R] = scene.race_radius
    p[P_E] = scene.race_eccentricity
    p[P_GAM] = scene.race_eccentricity_angle
    p[P_UREG] = scene.rolling_regularization_speed
    p[P_ROLL] = 1.0 if "rolling_resistance" in scene.effects else 0.0
    p[P_ECC] = 1.0 if "race_eccentricity" in scene.effects else 0.0
    effects = scene.effects
    p[P_EXT] = 1.0 if effects & EXTENDED_EFFECTS else 0.0
    if "gravity" in effects:
        p[P_GRAV] = scene.gravity_acceleration
        p[P_GX] = scene.gravity_acceleration * math.cos(scene.gravity_angle)
        p[P_GY] = scene.gravity_acceleration * math.sin(scene.gravity_angle)
    if "ball_contact" in effects:
        p[P_KC] = scene.contact_stiffness
        p[P_ZC] = scene.contact_damping_ratio
        p[P_REACH] = _contact.neighbour_reach_angle(scene.ball_radius, scene.race_radius)
    rho, nu = scene.fluid_state
    law, cdre, cubic, plateau = _fluids.law_coefficients(
        scene.fluid_drag_law, scene.fluid_stokes_drag, scene.fluid_drag_plateau)
    p[P_DLAW] = law
    p[P_CD0], p[P_CD1], p[P_CD2], p[P_CD3] = cubic
    p[P_CDINF] = plateau
    if "friction" in effects:
        p[P_FRIC] = 1.0
        p[P_MUK] = scene.friction_kinetic
        p[P_MUS] = max(scene.friction_static, scene.friction_kinetic)
        p[P_UFR] = scene.friction_regularization_speed
        p[P_USTR] = scene.friction_stribeck_speed
    a = scene.arrays()
    big_r = scene.race_radius
    b = np.zeros((scene.ball_count, N_BALL_PARAMS))
    b[:, B_MASS] = a["ball_mass"]
    b[:, B_RADIUS] = a["ball_radius"]
    b[:, B_INERTIA] = a["ball_inertia_factor"] * a["ball_mass"] * a["ball_radius"] ** 2
    b[:, B_BETA] = a["ball_drag"] * big_r ** 2
    b[:, B_MUR] = a["ball_rolling_resistance"] / a["ball_radius"]
    if "virtual_mass" in effects:
        volume = 4.0 / 3.0 * math.pi * a["ball_radius"] ** 3
        b[:, B_VM] = scene.fluid_virtual_mass * rho * volume * big_r ** 2
    if law != _fluids.LAW_NONE:
        b[:, B_KLIN] = _fluids.stokes_drag_coefficient(cdre, rho, nu, a["ball_radius"])
        b[:, B_KQUAD] = 0.5 * rho * math.pi * a["ball_radius"] ** 2
        b[:, B_REU] = 2.0 * a["ball_radius"] / nu
    b[:, B_MEFF] = (b[:, B_INERTIA] / a["ball_radius"] ** 2 + b[:, B_MASS]
                    + b[:, B_VM] / big_r ** 2)
    b[:, B_CI], b[:, B_II], b[:, B_INV] = ball_inertias(
        b[:, B_MASS], b[:, B_RADIUS], b[:, B_INERTIA], big_r, b[:, B_VM])
    return p, b


def ball_inertias(m, r, ji, big_r, vm):
    """The constant mass-matrix entries of balls of mass ``m`` [kg], radius ``r`` [m] and spin
    inertia ``ji`` [kg m^2] on a track of radius ``big_r`` [m] with virtual mass ``vm``
    [kg m^2] (numbers or arrays): ``(c_i, I_i, 1 / I_i)`` with ``c_i = m R^2 - J_i R / r``
    (the rotor coupling before the race eccentricity's term) and ``I_i = J_i R^2 / r^2 + m R^2
    + vm`` [kg m^2].

    They depend on the episode only; computed at every right-hand side they cost three
    divisions per ball, half of the divisions of ``yoshida_odd``'s vectorised right-hand side
    (12 -> 6), so :func:`pack_parameters` stores them, and the equations, the mass matrix and
    the drag rates of ETDRK4 read them from there (one formula for I_i, where the drag rates
    had a copy).  ``python -m abb_gym.benchmarks.rhs_cost`` at 128 lanes: 22.3-22.5 -> 20.0-20.9
    ns per lane (two alternated runs each); the vector environment's step did not change
    beyond the noise (ten alternated whole-process pairs, median ratio 1.0).  The operations
    and their order are those the kernels did at each call, so float64 runs give the same bits
    as before; a float32 block now rounds these float64 values once instead of computing
    them in float32."""
    mr = m * big_r
    ii = ji * big_r * big_r / (r * r) + mr * big_r + vm
    return mr * big_r - ji * big_r / r, ii, 1.0 / ii


@njit(cache=True, inline="always")
def _ball_coupling(th, ph, m, ji, big_r, ci, e, gam, ecc):
    """Mass-matrix entries of one ball that change with the angles: (col_x, col_y, c_i, its
    share of Jt, sin(th+ph), cos(th+ph), sin(gam-ph), cos(gam-ph)); the last two 0 without
    eccentricity.  ``ci``: c_i without the eccentricity (column ``B_CI``, :func:`ball_inertias`,
    which holds the constant I_i too)."""
    mr = m * big_r
    s, c = el.sincos(th + ph)
    jt = ji + mr * big_r
    sgp = el.like(th, 0.0)
    cgp = el.like(th, 0.0)
    if ecc:
        sgp, cgp = el.sincos(gam - ph)
        ci += e * mr * cgp
        jt += m * e * e + el.like(e, 2.0) * e * mr * cgp
    return -mr * s, mr * c, ci, jt, s, c, sgp, cgp


@njit(cache=True)
def mass_matrix(q, p, b):
    """Symmetric mass matrix M(q) of size 3 + n (kinetic energy T = q'^T M q' / 2)."""
    n = b.shape[0]
    nq = 3 + n
    th = q[2]
    mm = np.zeros((nq, nq))
    total = p[P_MASS]
    sth, cth = el.sincos(th)
    sx = p[P_U0] * sth
    cy = p[P_U0] * cth
    jt = p[P_J]
    ecc = p[P_ECC] != 0.0
    stg, ctg = el.sincos(th + p[P_GAM])
    for i in range(n):
        if ecc:
            sx += p[P_E] * b[i, B_MASS] * stg
            cy += p[P_E] * b[i, B_MASS] * ctg
        colx, coly, ci, jti, _, _, _, _ = _ball_coupling(
            th, q[3 + i], b[i, B_MASS], b[i, B_INERTIA], p[P_R], b[i, B_CI], p[P_E],
            p[P_GAM], ecc)
        sx -= colx
        cy += coly
        jt += jti
        k = 3 + i
        mm[0, k] = mm[k, 0] = colx
        mm[1, k] = mm[k, 1] = coly
        mm[2, k] = mm[k, 2] = ci
        # (B_II holds the virtual mass of the fluid, 0 unless that effect is on: it adds to
        # the relative inertia only, the fluid moves with the rotor otherwise)
        mm[k, k] = b[i, B_II]
    mm[0, 0] = total
    mm[1, 1] = total
    mm[2, 2] = jt
    mm[0, 2] = mm[2, 0] = -sx
    mm[1, 2] = mm[2, 1] = cy
    return mm


@njit(cache=True)
def potential_energy(q, p):
    """Support-spring energy [J]."""
    return 0.5 * (p[P_KX] * q[0] * q[0] + p[P_KY] * q[1] * q[1])


@njit(cache=True)
def gravity_energy(q, p, b):
    """Gravity potential -g . (sum of mass x position) [J] (0 without gravity).

    The mass-weighted position sum is ``M (x, y) + U0 (cos th, sin th) + sum m_i [E (cos, sin)
    (th + gam) + R (cos, sin)(th + ph_i)]``; with g along (cos a, sin a) its x-derivative is
    M g cos a, its th-derivative -g cos a Sx + g sin a Cy (the kernel's generalised forces)."""
    if p[P_GRAV] == 0.0:
        return 0.0
    th = q[2]
    sth, cth = el.sincos(th)
    sx = p[P_MASS] * q[0] + p[P_U0] * cth
    sy = p[P_MASS] * q[1] + p[P_U0] * sth
    stg, ctg = el.sincos(th + p[P_GAM])
    for i in range(b.shape[0]):
        m = b[i, B_MASS]
        sp, cp = el.sincos(th + q[3 + i])
        sx += m * p[P_R] * cp
        sy += m * p[P_R] * sp
        if p[P_ECC] != 0.0:
            sx += m * p[P_E] * ctg
            sy += m * p[P_E] * stg
    return -(p[P_GX] * sx + p[P_GY] * sy)


@njit(cache=True, inline="always")
def lanes_of(s, spec):
    """Lanes of the lane-last array ``s``: 1 under ``SPEC_ONE_LANE``, else ``s.shape[1]``.
    With a literal ``spec`` the one-lane count is a compile-time constant and the lane loops
    compile to straight code, without a loop's set-up and its vector-or-scalar checks (the
    single environment's step: 770 -> 720 ns per RK4 step, 2.1 -> 1.65 us of bookkeeping)."""
    return 1 if (spec & SPEC_ONE_LANE) != 0 else s.shape[1]


@njit(cache=True, inline="always")
def rows_of(s, nb, spec):
    """State rows of the lane-last block ``s`` of ``nb`` balls, for the step functions' loops
    over them: under ``SPEC_ONE_LANE`` the compile-time constant 2 (3 + nb) (``nb`` a literal),
    else ``s.shape[0]``.  With a known count of ten rows LLVM unrolls a one-lane block's row
    loops whole; with an unknown one it vectorises them by two vectors of 8 (the interleave
    option of :mod:`abb_gym.physics.elementary`), which leaves all ten rows to the scalar
    remainder: the one-lane kernel of ``simulate`` ran about 10 % slower.  On many lanes the
    row loops stay loops (unrolled around the vectorised lane loops, the vector environment
    measured x0.76-0.80)."""
    return 2 * (3 + nb) if (spec & SPEC_ONE_LANE) != 0 else s.shape[0]


@njit(cache=True, inline="always")
def _ball_terms(th, w, w2, ph, dph, ball, geometry, extended_inputs, flags):
    """One ball's terms of the equations (module docstring), from scalars only, so that the
    lane loop that calls it vectorises: (col_x, col_y, c_i, its Jt share, its Sx and Cy
    shares, its x and y forces, its rotor torque, the generalised force Q_i and the rows b_x,
    b_y, b_th of the ball equation ``I_i ph'' + b_x x'' + b_y y'' + b_th th'' = Q_i``; I_i
    itself is constant: column ``B_II``).

    The inputs come in tuples (a call with more than 30 arguments compiles to a star-args
    call, which numba cannot inline): ``ball`` (m, J_i, c_i without the eccentricity: column
    ``B_CI``, beta_i, mu_r / r), ``geometry`` (R, u*, E, gam, sin(th + gam), cos(th + gam),
    g_x, g_y), ``extended_inputs`` (contact Q and N, the drag law's coefficients, the
    friction law's), ``flags`` (ext, ecc, roll, grav, touch, fric: compile-time constants of
    the specialised kernels)."""
    m, ji, ci0, beta, mur = ball
    big_r, ureg, e, gam, stg, ctg, gx, gy = geometry
    (qc, nc, klin, kquad, reu, dlaw, a0, a1, a2, a3, plateau, muk, mus, ufr,
     ustr) = extended_inputs
    ext, ecc, roll, grav, touch, fric = flags
    mr = m * big_r
    colx, coly, ci, jti, sp, cp, sgp, cgp = _ball_coupling(th, ph, m, ji, big_r, ci0, e, gam,
                                                           ecc)
    sx = -colx
    cy = coly
    wrel2 = (w + dph) * (w + dph)
    fx = mr * wrel2 * cp
    fy = mr * wrel2 * sp
    fth = el.like(w, 0.0)
    fi = -beta * dph
    if ext and dlaw != 0.0:
        drag, slope = _fluids.race_drag(big_r * dph, dlaw, klin, kquad, reu, a0, a1, a2, a3,
                                        plateau)
        fi -= el.like(fi, drag) * big_r
    if ext and touch:
        fi += qc
    bx = colx
    by = coly
    bth = ci
    if ecc:
        sx += e * m * stg
        cy += e * m * ctg
        fx += e * m * ctg * w2
        fy += e * m * stg * w2
        fth -= e * mr * sgp * dph * (el.like(w, 2.0) * w + dph)
        fi += mr * e * sgp * w2
    if ext and grav:
        # g m R sin(a - th - ph): the weight's component along the track
        fi += mr * (gy * cp - gx * sp)
    if roll or (ext and fric):
        # friction-type forces -coef R N with the race normal force N (module docstring)
        kr = mur * mr * el.tanh(big_r * dph / ureg) if roll else el.like(w, 0.0)
        if ext and fric:
            kr += mr * el.like(w, friction_coefficient(big_r * dph, muk, mus, ufr, ustr))
        if ext and grav:
            # |N|: a ball that the weight presses onto the inner wall of the annulus
            # (N < 0) is still resisted; the sign comes from the velocity-dependent part
            n0 = big_r * wrel2 + gx * cp + gy * sp
            if ecc:
                n0 += e * w2 * cgp
            if touch:
                n0 += nc / m
            if n0 < 0.0:
                kr = -kr
            fi -= kr * (gx * cp + gy * sp)
        fi -= kr * big_r * wrel2
        bx -= kr * cp
        by -= kr * sp
        if ecc:
            fi -= kr * e * w2 * cgp
            bth += kr * e * sgp
        if ext and touch:
            fi -= kr * nc / m
    return colx, coly, ci, jti, sx, cy, fx, fy, fth, fi, bx, by, bth


@njit(cache=True, inline="always")
def _pair_may_touch(s, p, l, lo, hi):
    """Whether balls ``lo`` and ``hi`` of lane ``l`` may touch: contact on and the balls
    within the lane's reach angle (:func:`abb_gym.physics.contact.may_touch`)."""
    d = _contact.wrap_angle(s[3 + hi, l] - s[3 + lo, l])
    return p[P_KC, l] != 0.0 and _contact.may_touch(d, p[P_REACH, l])


@njit(cache=True, inline="always")
def _contacts(s, p, b, ds, work, nb, nq, L):
    """Pass (1) of :func:`accelerations_block`: each ball's generalised contact force [N m]
    into ``ds[3 + i]`` and its outward radial contact force [N] into ``ds[nq + 3 + i]``, every
    lane (0 where a lane has no contact).

    **Neighbour list.**  Balls in one race cannot pass each other: they roll on one track, and
    a ball that meets another is pushed back by the contact before their centres come closer
    than about one radius (the penetration of a collision at relative speed v is v /
    omega_c, :mod:`abb_gym.physics.contact`; the washer's 5 % of the diameter at 0.5 m/s).  Their
    order along the race therefore never changes, and a ball can only touch the next ball
    ahead and the next behind: n pairs instead of n (n - 1) / 2 (12 instead of 66 for the
    washer).  Here the neighbours are the balls of adjacent index (ball n - 1 next to ball 0),
    each pair in two lane loops without branches (they vectorise): the first asks whether
    any lane's two balls are within the reach angle (:func:`~abb_gym.physics.contact.
    may_touch`, a few operations), and only if some are, the second computes every lane's
    pair force (:func:`~abb_gym.physics.contact.pair_force`, which is 0 for a pair beyond
    the reach angle), so that the spread balls of a ring cost a test per pair.

    **When it does not apply.**  Index order need not be race order (a scene's or an episode's
    initial angles in any order), and a penalty contact lets a ball through a neighbour when
    a collision is fast enough to overlap them by a whole radius (a stiffness far too low for
    the speeds; the balls then pass, as they do with every pair).  Each lane is therefore
    checked at every call (:func:`~abb_gym.physics.contact.ring_holds`: index order goes
    round the race once, and the arc across each ball is at least the reach of a pair, so
    that no two balls but neighbours can touch), and a lane where that fails takes every
    pair (:func:`~abb_gym.physics.contact.ball_contacts_lane`), so the result never depends on
    it.  Where it holds, the pairs left out have no force, and each ball's two neighbour
    terms are added to 0 in the order of the all-pairs loop (a sum of two terms is the same
    in either order anyway): the same bits as every pair (``tests/test_contact.py``).  A
    float32 block takes every pair (the all-pairs loop rounds each sum in float32)."""
    if el.is_single(s) or nb < 2:
        for l in range(L):
            if p[P_KC, l] != 0.0:
                _contact.ball_contacts_lane(s, l, nq, b, B_RADIUS, B_MEFF, p[P_R, l],
                                            p[P_KC, l], p[P_ZC, l], ds, 3, nq + 3)
            else:
                for i in range(nb):
                    ds[3 + i, l] = 0.0
                    ds[nq + 3 + i, l] = 0.0
        return
    pairs = 1 if nb == 2 else nb
    for k in range(pairs):
        lo = 0 if k == nb - 1 else k
        hi = nb - 1 if k == nb - 1 else k + 1
        # whether any lane's two balls may touch (a cheap test), and only then every lane's
        # pair force (both loops without branches or calls: they vectorise)
        near = 0
        for l in range(L):
            near += 1 if _pair_may_touch(s, p, l, lo, hi) else 0
        if near == 0:
            for l in range(L):
                work[k, W_PQ, l] = 0.0
                work[k, W_PN, l] = 0.0
            continue
        for l in range(L):
            _, q, radial = _contact.pair_force(
                s[3 + lo, l], s[3 + hi, l], s[nq + 3 + lo, l], s[nq + 3 + hi, l],
                p[P_R, l], b[lo, B_RADIUS, l] + b[hi, B_RADIUS, l], b[lo, B_MEFF, l],
                b[hi, B_MEFF, l], p[P_KC, l], p[P_ZC, l])
            work[k, W_PQ, l] = q
            work[k, W_PN, l] = radial
    for i in range(nb):
        # ball i is the higher index of pair i - 1 (+q) and the lower of pair i (-q); ball 0
        # the lower of pair n - 1 too, ball n - 1 its higher (the all-pairs loop's order)
        for l in range(L):
            if nb == 2:
                ds[3 + i, l] = (0.0 + work[0, W_PQ, l]) if i == 1 else (0.0 - work[0, W_PQ, l])
                ds[nq + 3 + i, l] = 0.0 + work[0, W_PN, l]
            elif i == 0:
                ds[3, l] = (0.0 - work[0, W_PQ, l]) - work[nb - 1, W_PQ, l]
                ds[nq + 3, l] = (0.0 + work[0, W_PN, l]) + work[nb - 1, W_PN, l]
            elif i == nb - 1:
                ds[3 + i, l] = (0.0 + work[nb - 1, W_PQ, l]) + work[nb - 2, W_PQ, l]
                ds[nq + 3 + i, l] = (0.0 + work[nb - 1, W_PN, l]) + work[nb - 2, W_PN, l]
            else:
                ds[3 + i, l] = (0.0 + work[i - 1, W_PQ, l]) - work[i, W_PQ, l]
                ds[nq + 3 + i, l] = (0.0 + work[i - 1, W_PN, l]) + work[i, W_PN, l]
    if nb >= 4:
        for l in range(L):
            work[0, W_RING, l] = 1.0 if _contact.ring_holds(s, l, nb, p[P_REACH, l]) else 0.0
        for l in range(L):
            if p[P_KC, l] != 0.0 and work[0, W_RING, l] == 0.0:
                _contact.ball_contacts_lane(s, l, nq, b, B_RADIUS, B_MEFF, p[P_R, l],
                                            p[P_KC, l], p[P_ZC, l], ds, 3, nq + 3)


@njit(cache=True, inline="always")
def _lane_drive(t, s, d, l, nq, motor, envelope):
    """(th, w, alpha, torque) of lane ``l``: the rotor angle [rad], speed [rad/s] and
    acceleration [rad/s^2] (0 under a motor, where it is an unknown) and the motor torque
    [N m] (0 under a prescribed spin).  The passes of :func:`accelerations_block` ask again
    rather than keep them: a few operations, the same bits each time."""
    x = s[0, l]
    tau = t[l] - d[dl.D_T0, l]
    if motor:
        th = s[2, l]
        w = s[nq + 2, l]
        torque = el.like(x, dl.motor_law(
            tau, w, d[dl.D_TORQUE, l], d[dl.D_GAIN, l], d[dl.D_TW0, l], d[dl.D_TALPHA, l],
            d[dl.D_TLIM, l], d[dl.D_WNL, l], d[dl.D_PLIM, l], envelope))
        alpha = el.like(x, 0.0)
    else:
        th, w, alpha = dl.prescribed_law(tau, d[dl.D_TH0, l], d[dl.D_W0, l], d[dl.D_ALPHA, l])
        torque = el.like(x, 0.0)
    return th, w, alpha, torque


@njit(cache=True, inline="always")
def _lane_ball_terms(t, s, p, b, d, ds, i, l, nq, spec):
    """Ball ``i``'s terms in lane ``l`` (:func:`_ball_terms`), its generalised force less any
    prescribed ``b_th th''``.  The lane's sin and cos of th + gam come from ``ds`` rows 0 and
    1, the ball's contact force and radial force from rows ``3 + i`` and ``nq + 3 + i``, where
    :func:`accelerations_block` left them."""
    ext = (spec & SPEC_EXT) != 0
    ecc = (spec & SPEC_ECC) != 0
    roll = (spec & SPEC_ROLL) != 0
    motor = (spec & SPEC_MOTOR) != 0
    envelope = (spec & SPEC_ENVELOPE) != 0
    x = s[0, l]
    th, w, alpha, _ = _lane_drive(t, s, d, l, nq, motor, envelope)
    w2 = w * w
    stg = ds[0, l] if ecc else el.like(x, 0.0)
    ctg = ds[1, l] if ecc else el.like(x, 0.0)
    big_r = p[P_R, l]
    grav = ext and (spec & SPEC_GRAVITY) != 0 and p[P_GRAV, l] != 0.0
    touch = ext and (spec & SPEC_CONTACT) != 0 and p[P_KC, l] != 0.0
    fric = ext and (spec & SPEC_FRICTION) != 0 and p[P_FRIC, l] != 0.0
    dlaw = p[P_DLAW, l] if ext and (spec & SPEC_DRAG) != 0 else el.like(x, 0.0)
    geometry = (big_r, p[P_UREG, l], p[P_E, l], p[P_GAM, l], stg, ctg, p[P_GX, l],
                p[P_GY, l])
    law = (dlaw, p[P_CD0, l], p[P_CD1, l], p[P_CD2, l], p[P_CD3, l], p[P_CDINF, l],
           p[P_MUK, l], p[P_MUS, l], p[P_UFR, l], p[P_USTR, l])
    flags = (ext, ecc, roll, grav, touch, fric)
    colx, coly, ci, jti, sxi, cyi, fxi, fyi, fthi, fi, bx, by, bth = _ball_terms(
        th, w, w2, s[3 + i, l], s[nq + 3 + i, l],
        (b[i, B_MASS, l], b[i, B_INERTIA, l], b[i, B_CI, l], b[i, B_BETA, l],
         b[i, B_MUR, l]), geometry,
        (ds[3 + i, l], ds[nq + 3 + i, l], b[i, B_KLIN, l], b[i, B_KQUAD, l],
         b[i, B_REU, l]) + law, flags)
    if not motor:
        fi -= bth * alpha
    return colx, coly, ci, jti, sxi, cyi, fxi, fyi, fthi, fi, bx, by, bth


@njit(cache=True, error_model="numpy", noalias=True)
def _ball_pass(t, s, p, b, d, ds, fi_row, bx_row, by_row, bth_row, colx_row, coly_row, ci_row,
               jt_row, sx_row, cy_row, fx_row, fy_row, fth_row, i, nq, spec):
    """Ball ``i``'s terms (:func:`_lane_ball_terms`) in every lane, into the rows of
    ``work[i]`` given one by one (the split passes of :func:`accelerations_block`).

    A function of its own, not inlined by numba, so that each output row is an argument of
    its own under the no-alias promise (views of one array that do not overlap:
    :mod:`abb_gym._numba`): written as thirteen rows of one array, LLVM could not tell that
    they do not overlap, and left the lane loop scalar."""
    for l in range(lanes_of(s, spec)):
        colx, coly, ci, jti, sxi, cyi, fxi, fyi, fthi, fi, bx, by, bth = _lane_ball_terms(
            t, s, p, b, d, ds, i, l, nq, spec)
        fi_row[l] = fi
        bx_row[l] = bx
        by_row[l] = by
        bth_row[l] = bth
        colx_row[l] = colx
        coly_row[l] = coly
        ci_row[l] = ci
        jt_row[l] = jti
        sx_row[l] = sxi
        cy_row[l] = cyi
        fx_row[l] = fxi
        fy_row[l] = fyi
        fth_row[l] = fthi


@njit(cache=True, inline="always")
def _rotor_start(t, s, p, d, l, nq, motor, envelope):
    """Lane ``l``'s rotor rows before the balls' shares: (Sx, Cy, Jt, x, y and th forces,
    th'', the 12 sums of the Schur complement at 0) and (th, w, alpha, vx, vy)."""
    x = s[0, l]
    y = s[1, l]
    vx = s[nq, l]
    vy = s[nq + 1, l]
    th, w, alpha, torque = _lane_drive(t, s, d, l, nq, motor, envelope)
    w2 = w * w
    sth, cth = el.sincos(th)
    u0 = p[P_U0, l]
    sx = u0 * sth
    cy = u0 * cth
    fx = -p[P_CX, l] * vx - p[P_KX, l] * x + u0 * cth * w2
    fy = -p[P_CY, l] * vy - p[P_KY, l] * y + u0 * sth * w2
    fth = torque - p[P_BETA0, l] * w
    jt = p[P_J, l]
    zero = el.like(x, 0.0)
    # Schur complement of the (diagonal) ball block: D = sum col b^T / I, g = sum col Q / I
    # (d00, d01, d10, d11, d02, d12, d20, d21, d22, g0, g1, g2)
    schur = (zero, zero, zero, zero, zero, zero, zero, zero, zero, zero, zero, zero)
    return (sx, cy, jt, fx, fy, fth) + schur, (th, w, alpha, vx, vy)


@njit(cache=True, inline="always")
def _add_ball(acc, terms, inv, motor):
    """``acc`` (:func:`_rotor_start`) plus one ball's ``terms`` (:func:`_lane_ball_terms`)
    with its 1 / I_i ``inv``, each sum in ball order."""
    (sx, cy, jt, fx, fy, fth, d00, d01, d10, d11, d02, d12, d20, d21, d22, g0, g1, g2) = acc
    colx, coly, ci, jti, sxi, cyi, fxi, fyi, fthi, fi, bx, by, bth = terms
    sx += sxi
    cy += cyi
    jt += jti
    fx += fxi
    fy += fyi
    fth += fthi
    d00 += colx * bx * inv
    d01 += colx * by * inv
    d10 += coly * bx * inv
    d11 += coly * by * inv
    g0 += colx * fi * inv
    g1 += coly * fi * inv
    if motor:
        d02 += colx * bth * inv
        d12 += coly * bth * inv
        d20 += ci * bx * inv
        d21 += ci * by * inv
        d22 += ci * bth * inv
        g2 += ci * fi * inv
    return (sx, cy, jt, fx, fy, fth, d00, d01, d10, d11, d02, d12, d20, d21, d22, g0, g1, g2)


@njit(cache=True, inline="always")
def _solve_rotor(acc, lane, p, l, gravity, motor):
    """(x'', y'', th'') of lane ``l`` from its sums ``acc`` and ``lane`` (:func:`_rotor_start`):
    gravity's rotor terms (where ``gravity``, the kernel's gravity bit, and the lane's
    parameter say so), the 2x2 (prescribed spin) or 3x3 (motor) system."""
    (sx, cy, jt, fx, fy, fth, d00, d01, d10, d11, d02, d12, d20, d21, d22, g0, g1, g2) = acc
    alpha = lane[2]
    total = p[P_MASS, l]
    if gravity and p[P_GRAV, l] != 0.0:
        gx = p[P_GX, l]
        gy = p[P_GY, l]
        fx += total * gx
        fy += total * gy
        fth += gy * cy - gx * sx
    # top block [[M, 0, -Sx], [0, M, Cy], [-Sx, Cy, Jt]] minus D
    a00 = total - d00
    a01 = -d01
    a10 = -d10
    a11 = total - d11
    if motor:
        a02 = -sx - d02
        a12 = cy - d12
        a20 = -sx - d20
        a21 = cy - d21
        a22 = jt - d22
        fx -= g0
        fy -= g1
        fth -= g2
        c00 = a11 * a22 - a12 * a21
        c01 = a12 * a20 - a10 * a22
        c02 = a10 * a21 - a11 * a20
        det = a00 * c00 + a01 * c01 + a02 * c02
        ax = (fx * c00 + a01 * (a12 * fth - fy * a22) + a02 * (fy * a21 - a11 * fth)) / det
        ay = (a00 * (fy * a22 - a12 * fth) + fx * c01 + a02 * (a10 * fth - fy * a20)) / det
        ath = (a00 * (a11 * fth - fy * a21) + a01 * (fy * a20 - a10 * fth) + fx * c02) / det
    else:
        # the prescribed th'' moves to the right-hand side
        fx += -sx * -alpha - g0
        fy -= cy * alpha + g1
        det = a00 * a11 - a01 * a10
        ax = (fx * a11 - a01 * fy) / det
        ay = (a00 * fy - a10 * fx) / det
        ath = alpha
    return ax, ay, ath


@njit(cache=True, inline="always")
def _write_lane(s, b, ds, work, l, nb, nq, lane, ax, ay, ath, motor):
    """The derivatives of lane ``l``: the balls' from their rows of ``work`` (``W_FI`` holds
    Q_i less the prescribed b_th th'' already), then the rotor's."""
    for i in range(nb):
        ds[3 + i, l] = s[nq + 3 + i, l]
        qi = work[i, W_FI, l] - work[i, W_BX, l] * ax - work[i, W_BY, l] * ay
        if motor:
            qi -= work[i, W_BTH, l] * ath
        ds[nq + 3 + i, l] = qi * b[i, B_INV, l]
    ds[0, l] = lane[3]
    ds[1, l] = lane[4]
    ds[2, l] = s[nq + 2, l] if motor else lane[1]
    ds[nq, l] = ax
    ds[nq + 1, l] = ay
    ds[nq + 2, l] = ath


@njit(cache=True, error_model="numpy", noalias=True)
def _sum_start(t, s, p, d, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13, a14,
               a15, a16, a17, nq, spec):
    """The 18 sums of every lane at their rotor values (:func:`_rotor_start`), into the rows
    ``a0`` .. ``a17`` (no two overlap: compiled ``noalias``, as :func:`_ball_pass`)."""
    motor = (spec & SPEC_MOTOR) != 0
    envelope = (spec & SPEC_ENVELOPE) != 0
    for l in range(lanes_of(s, spec)):
        acc, _ = _rotor_start(t, s, p, d, l, nq, motor, envelope)
        (a0[l], a1[l], a2[l], a3[l], a4[l], a5[l], a6[l], a7[l], a8[l], a9[l], a10[l], a11[l],
         a12[l], a13[l], a14[l], a15[l], a16[l], a17[l]) = acc


@njit(cache=True, error_model="numpy", noalias=True)
def _sum_pass(a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13, a14, a15, a16, a17,
              colx, coly, ci, jt, sx, cy, fx, fy, fth, fi, bx, by, bth, inv, spec):
    """One ball's terms (the rows :func:`_ball_pass` wrote) added to the 18 sums of every
    lane (:func:`_add_ball`: the same operations in the same order as the lane loop of the
    fused path, so the same bits).  A lane loop over rows that are each an argument of their
    own: with the ball loop inside the lane loop, LLVM vectorised that loop up to about five
    balls and left it scalar beyond."""
    motor = (spec & SPEC_MOTOR) != 0
    for l in range(1 if (spec & SPEC_ONE_LANE) != 0 else inv.shape[0]):  # lanes_of
        acc = (a0[l], a1[l], a2[l], a3[l], a4[l], a5[l], a6[l], a7[l], a8[l], a9[l], a10[l],
               a11[l], a12[l], a13[l], a14[l], a15[l], a16[l], a17[l])
        terms = (colx[l], coly[l], ci[l], jt[l], sx[l], cy[l], fx[l], fy[l], fth[l], fi[l],
                 bx[l], by[l], bth[l])
        (a0[l], a1[l], a2[l], a3[l], a4[l], a5[l], a6[l], a7[l], a8[l], a9[l], a10[l], a11[l],
         a12[l], a13[l], a14[l], a15[l], a16[l], a17[l]) = _add_ball(acc, terms, inv[l], motor)


#: ball counts from which the split passes add the balls to the rotor's sums one ball at a
#: time, each a lane loop (:func:`_sum_pass`), rather than in one lane loop around the ball
#: loop; the sums then live in free columns of balls 0-3 (``_SUM_COLUMNS``), so this needs at
#: least four balls
SUMMED_BALLS = 4

#: ball counts up to which the right-hand side is one lane loop around the ball loop (LLVM
#: unrolls the ball loop whole and vectorises the lane loop); more balls take the split
#: passes of :func:`accelerations_block`.  At 3 balls the split passes were faster (the
#: right-hand side at 128 lanes, CPU time: 122 ns per lane fused, against 79 ns for 5 balls
#: split)
FUSED_BALLS = 2


@njit(cache=True, error_model="numpy", noalias=True)
def accelerations_block(t, s, p, b, d, ds, work, nb, spec):
    """The equations of motion, once, for a block of lanes (one environment per lane):
    ``ds[:, l]`` = d(state)/dt of lane ``l`` at time ``t[l]``.

    Arrays carry the lane last: ``s``, ``ds`` (2 (3 + nb), L), ``p`` (N_PARAMS, L), ``b`` (nb,
    N_BALL_PARAMS, L), ``d`` (N_DRIVE, L) the current drive row of each lane, ``work`` (nb,
    WORK_COLUMNS, L) scratch (the contact forces, the balls' terms).  ``spec`` (``SPEC_*`` bits)
    says which terms exist; with ``nb`` and ``spec`` compile-time constants (literal types given
    by :class:`~abb_gym.physics.specialise.Specialised`: one compilation per literal pair) the
    lane loops compile to straight-line code over all lanes at once (vector instructions, with
    the LLVM options of :mod:`abb_gym.physics.elementary`); with run-time values it is the
    general kernel.  Either way every lane does the same arithmetic in the same order, so the
    results agree bit for bit.  No two array arguments may overlap (compiled ``noalias``, which
    spares the vector loop its run-time overlap checks: :mod:`abb_gym._numba`).

    The balls are eliminated by a Schur complement (module docstring) accumulated ball by
    ball (:func:`_add_ball`).  **Loop order.**  First the contact forces (:func:`_contacts`)
    and the race's sin and cos of th + gam go into rows of ``ds`` that the derivatives
    overwrite last.  Up to :data:`FUSED_BALLS` balls, one lane loop then does the rest, the
    ball loop inside it, which LLVM unrolls whole, so that the lane loop vectorises.  With
    more balls LLVM unrolled it no longer, and the lane loop stayed scalar (``yoshida_odd``'s
    right-hand side at 128 lanes: 42-52 ns per lane at 2-3 balls, 290 at 4, 580-960 at 5-12:
    the "vectorisation cliff"); they take split passes, each a lane loop: per ball its terms
    (:func:`_ball_pass`, kept in ``work``), then the sums in ball order, the solve and the
    derivatives.  From :data:`SUMMED_BALLS` balls the sums are a lane loop per ball too
    (:func:`_sum_pass`): one lane loop around the ball loop stayed scalar beyond about five
    balls, as the fused loop does beyond two.  Each pass reads arrays that it does not
    write, so its lane loop needs no overlap checks.  The split passes cost two balls 15 %
    more (the terms go through memory), hence the fused loop where it vectorises.  Each
    lane's operations and their order are the same either way, so the results are the same
    bits."""
    L = lanes_of(s, spec)
    nq = 3 + nb
    ext = (spec & SPEC_EXT) != 0
    gravity = ext and (spec & SPEC_GRAVITY) != 0
    ecc = (spec & SPEC_ECC) != 0
    motor = (spec & SPEC_MOTOR) != 0
    envelope = (spec & SPEC_ENVELOPE) != 0
    # pair forces first, into the balls' rows of ds: the contact's radial part loads the race
    # (friction, rolling); and the race's sin and cos of th + gam into ds rows 0 and 1
    if ext and (spec & SPEC_CONTACT) != 0:
        _contacts(s, p, b, ds, work, nb, nq, L)
    if ecc:
        for l in range(L):
            th, _, _, _ = _lane_drive(t, s, d, l, nq, motor, envelope)
            stg, ctg = el.sincos(th + p[P_GAM, l])
            ds[0, l] = stg
            ds[1, l] = ctg
    if nb <= FUSED_BALLS:
        for l in range(L):
            acc, lane = _rotor_start(t, s, p, d, l, nq, motor, envelope)
            for i in range(nb):
                terms = _lane_ball_terms(t, s, p, b, d, ds, i, l, nq, spec)
                work[i, W_FI, l] = terms[9]
                work[i, W_BX, l] = terms[10]
                work[i, W_BY, l] = terms[11]
                work[i, W_BTH, l] = terms[12]
                acc = _add_ball(acc, terms, b[i, B_INV, l], motor)
            ax, ay, ath = _solve_rotor(acc, lane, p, l, gravity, motor)
            _write_lane(s, b, ds, work, l, nb, nq, lane, ax, ay, ath, motor)
        return
    for i in range(nb):
        wi = work[i]
        _ball_pass(t, s, p, b, d, ds, wi[W_FI], wi[W_BX], wi[W_BY], wi[W_BTH], wi[W_COLX],
                   wi[W_COLY], wi[W_CI], wi[W_JT], wi[W_SX], wi[W_CY], wi[W_FX], wi[W_FY],
                   wi[W_FTH], i, nq, spec)
    if nb >= SUMMED_BALLS:
        w0, w1, w2, w3 = work[0], work[1], work[2], work[3]
        c0, c1, c2, c3, c4 = _SUM_COLUMNS
        _sum_start(t, s, p, d, w0[c0], w0[c1], w0[c2], w0[c3], w0[c4], w1[c0], w1[c1], w1[c2],
                   w1[c3], w1[c4], w2[c0], w2[c1], w2[c2], w2[c3], w2[c4], w3[c0], w3[c1],
                   w3[c2], nq, spec)
        for i in range(nb):
            wi = work[i]
            _sum_pass(w0[c0], w0[c1], w0[c2], w0[c3], w0[c4], w1[c0], w1[c1], w1[c2], w1[c3],
                      w1[c4], w2[c0], w2[c1], w2[c2], w2[c3], w2[c4], w3[c0], w3[c1], w3[c2],
                      wi[W_COLX], wi[W_COLY], wi[W_CI], wi[W_JT], wi[W_SX], wi[W_CY],
                      wi[W_FX], wi[W_FY], wi[W_FTH], wi[W_FI], wi[W_BX], wi[W_BY],
                      wi[W_BTH], b[i, B_INV], spec)
        for l in range(L):
            _, lane = _rotor_start(t, s, p, d, l, nq, motor, envelope)
            acc = (w0[c0, l], w0[c1, l], w0[c2, l], w0[c3, l], w0[c4, l], w1[c0, l], w1[c1, l],
                   w1[c2, l], w1[c3, l], w1[c4, l], w2[c0, l], w2[c1, l], w2[c2, l],
                   w2[c3, l], w2[c4, l], w3[c0, l], w3[c1, l], w3[c2, l])
            ax, ay, ath = _solve_rotor(acc, lane, p, l, gravity, motor)
            _write_lane(s, b, ds, work, l, nb, nq, lane, ax, ay, ath, motor)
        return
    for l in range(L):
        acc, lane = _rotor_start(t, s, p, d, l, nq, motor, envelope)
        for i in range(nb):
            terms = (work[i, W_COLX, l], work[i, W_COLY, l], work[i, W_CI, l],
                     work[i, W_JT, l], work[i, W_SX, l], work[i, W_CY, l], work[i, W_FX, l],
                     work[i, W_FY, l], work[i, W_FTH, l], work[i, W_FI, l], work[i, W_BX, l],
                     work[i, W_BY, l], work[i, W_BTH, l])
            acc = _add_ball(acc, terms, b[i, B_INV, l], motor)
        ax, ay, ath = _solve_rotor(acc, lane, p, l, gravity, motor)
        _write_lane(s, b, ds, work, l, nb, nq, lane, ax, ay, ath, motor)


def spec_of(p: np.ndarray, d: np.ndarray) -> int:
    """The ``SPEC_*`` bits of packed parameters ``p`` (one environment) and its drive rows
    ``d`` (one row or a table; every row of a run has the same mode); with ``p`` of many
    environments (R, N_PARAMS) and their tables ``d`` (R, rows, N_DRIVE), the union of theirs."""
    p = np.asarray(p)
    rows = np.asarray(d).reshape(-1, np.shape(d)[-1])
    spec = 0
    if np.any(p[..., P_EXT] != 0.0):
        spec |= SPEC_EXT
    for column, bit in ((P_KC, SPEC_CONTACT), (P_DLAW, SPEC_DRAG), (P_FRIC, SPEC_FRICTION),
                        (P_GRAV, SPEC_GRAVITY)):
        if np.any(p[..., column] != 0.0):
            spec |= bit
    if np.any(p[..., P_ECC] != 0.0):
        spec |= SPEC_ECC
    if np.any(p[..., P_ROLL] != 0.0):
        spec |= SPEC_ROLL
    if np.any(rows[:, dl.D_MODE] == dl.MODE_MOTOR):
        spec |= SPEC_MOTOR
        if np.any(rows[:, dl.D_WNL] != 0.0) or np.any(rows[:, dl.D_PLIM] != 0.0):
            spec |= SPEC_ENVELOPE
    return spec


_SPEC_WORDS = ((SPEC_EXT, "extended effects"), (SPEC_CONTACT, "contact"),
               (SPEC_DRAG, "fluid drag"), (SPEC_FRICTION, "friction"), (SPEC_GRAVITY, "gravity"),
               (SPEC_ECC, "race eccentricity"), (SPEC_ROLL, "rolling resistance"),
               (SPEC_MOTOR, "motor"), (SPEC_ENVELOPE, "motor envelope"),
               (SPEC_ONE_LANE, "one lane"))


def describe_spec(spec: int) -> str:
    """The ``SPEC_*`` bits in words, for the compile notices: ``36 (rolling resistance, one
    lane)``."""
    words = [name for bit, name in _SPEC_WORDS if spec & bit]
    return f"{spec} ({', '.join(words) or 'none'})"


EFFECTS = ("effects", describe_spec)  # the name of a literal ``spec`` argument (Specialised)


def make_work(n_balls: int, lanes: int = 1, dtype=np.float64) -> np.ndarray:
    """Scratch array for :func:`accelerations_block` (contact forces per ball and lane), in
    the precision ``dtype`` of the right-hand side."""
    return np.zeros((n_balls, WORK_COLUMNS, lanes), dtype=dtype)


@njit(cache=True, error_model="numpy")
def state_derivative(t, s, p, b, d, ds, spec):
    """ds/dt of one environment (1-D arrays: state, parameters, one drive row): the block
    kernel on one lane (the general kernel: ``spec`` at run time)."""
    nb = b.shape[0]
    ns = s.shape[0]
    tt = np.full(1, t)
    work = np.zeros((nb, WORK_COLUMNS, 1))
    accelerations_block(tt, s.reshape((ns, 1)), p.reshape((p.shape[0], 1)),
                        b.reshape((nb, b.shape[1], 1)), d.reshape((d.shape[0], 1)),
                        ds.reshape((ns, 1)), work, nb, spec)


def accelerations(t, s, p, b, d, qdd=None, work=None):
    """Generalised accelerations (length 3 + n) of one environment at state ``s`` under drive
    row ``d`` (a convenience for tests and analysis; the kernels use
    :func:`accelerations_block`).  Returns the motor torque [N m] (0 if prescribed) when
    ``qdd`` is given (filled in place), else the accelerations."""
    s = np.ascontiguousarray(s, dtype=float)
    ds = np.empty_like(s)
    spec = spec_of(p, d)
    state_derivative(float(t), s, np.ascontiguousarray(p, float), np.ascontiguousarray(b, float),
                     np.ascontiguousarray(d, float), ds, spec)
    nq = s.shape[0] // 2
    if qdd is None:
        return ds[nq:].copy()
    qdd[:] = ds[nq:]
    if spec & SPEC_MOTOR:
        return dl.motor_torque(float(t), float(s[nq + 2]), np.ascontiguousarray(d, float),
                               bool(spec & SPEC_ENVELOPE))
    return 0.0


@njit(cache=True)
def total_energy(s, p, b):
    """Kinetic plus potential energy [J] of state ``s`` (rotor spin included): support springs,
    gravity and the ball-ball contact penalty when those effects are on."""
    nq = 3 + b.shape[0]
    q = s[:nq]
    v = s[nq:]
    mm = mass_matrix(q, p, b)
    e = 0.5 * v @ (mm @ v) + potential_energy(q, p)
    if p[P_GRAV] != 0.0:
        e += gravity_energy(q, p, b)
    if p[P_KC] != 0.0:
        e += _contact.contact_energy(q, b, B_RADIUS, p[P_R], p[P_KC])
    return e


@njit(cache=True, error_model="numpy", noalias=True)
def _drag_rate_pass(t, s, p, b, d, out, i, nq, spec):
    """Ball ``i``'s relaxation rate [1/s] in every lane (:func:`drag_rates_block`), into the
    row ``out``: a lane loop per ball, the ball's row an argument of its own (compiled
    ``noalias``, as :func:`_ball_pass`), so that the lane loop vectorises; a lane loop around
    the ball loop stayed scalar."""
    ext = (spec & SPEC_EXT) != 0
    roll = (spec & SPEC_ROLL) != 0
    motor = (spec & SPEC_MOTOR) != 0
    for l in range(lanes_of(s, spec)):
        if motor:
            th = s[2, l]
            w = s[nq + 2, l]
        else:
            th, w, _ = dl.prescribed_law(t[l] - d[dl.D_T0, l], d[dl.D_TH0, l], d[dl.D_W0, l],
                                         d[dl.D_ALPHA, l])
        big_r = p[P_R, l]
        m = b[i, B_MASS, l]
        rate = b[i, B_BETA, l]
        dph = s[nq + 3 + i, l]
        if roll:
            tnh = el.tanh(big_r * dph / p[P_UREG, l])
            rate += (b[i, B_MUR, l] * m * big_r ** 3 * (w + dph) ** 2 * (1.0 - tnh * tnh)
                     / p[P_UREG, l])
        if ext:
            if (spec & SPEC_DRAG) != 0 and p[P_DLAW, l] != 0.0:
                drag, slope = _fluids.race_drag(big_r * dph, p[P_DLAW, l], b[i, B_KLIN, l],
                                                b[i, B_KQUAD, l], b[i, B_REU, l],
                                                p[P_CD0, l], p[P_CD1, l], p[P_CD2, l],
                                                p[P_CD3, l], p[P_CDINF, l])
                rate += big_r * big_r * slope
            if (spec & SPEC_FRICTION) != 0 and p[P_FRIC, l] != 0.0:
                normal = m * big_r * (w + dph) ** 2
                if p[P_GRAV, l] != 0.0:
                    sp, cp = el.sincos(th + s[3 + i, l])
                    normal += m * (p[P_GX, l] * cp + p[P_GY, l] * sp)
                rate += big_r * big_r * abs(normal) * friction_secant(
                    big_r * dph, p[P_MUK, l], p[P_MUS, l], p[P_UFR, l], p[P_USTR, l])
        out[l] = rate / b[i, B_II, l]


@njit(cache=True, error_model="numpy", noalias=True)
def drag_rates_block(t, s, p, b, d, lam, nb, spec):
    """Relaxation rates [1/s] of the ball relative speeds, written into ``lam`` (state rows x
    lanes; every other row 0): for ball i, lam[ph_i'] = (beta_i + d(resisting force) /
    d(ph_i')) / I_i, the race drag plus

    * the slope of the smoothed rolling resistance, mu_r m R^3 (th' + ph')^2 sech^2(R ph'/u*)
      / u*, which grows with the rotor speed squared;
    * the slope of the nonlinear fluid drag, R^2 dF/du (the Stokes coefficient at low Re);
    * friction: R^2 |N| mu(u) / u, the *secant* of the friction law (equal to the tangent
      mu_s |N| / u_reg at u = 0, where stick makes it very stiff).  The secant rather than the
      tangent because a sliding ball that comes to rest within a step must see its friction
      as a strong damper, not as the near-zero slope of the saturated tanh;
    * ball-ball contact: a bound on the contact eigenvalue, sqrt(sum k (1/m_i + 1/m_j)) over
      the touching neighbours (added directly as a rate).  It is oscillatory rather than a
      relaxation, so it is not integrated exactly by ``etdrk4``; it is here so that the RK4
      step rule keeps h omega_c inside RK4's stability region.

    This is the stiff, nearly diagonal part of the Jacobian (the coupling through the rotor,
    of relative size m_i / M, is left out); the exponential integrator treats it exactly and
    the step-size rule of the explicit methods bounds h * lam.  Lanes, and arrays that must
    not overlap, as in :func:`accelerations_block`."""
    nq = 3 + nb
    for j in range(2 * nq):
        for l in range(lanes_of(s, spec)):
            lam[j, l] = 0.0
    for i in range(nb):
        _drag_rate_pass(t, s, p, b, d, lam[nq + 3 + i], i, nq, spec)
    ext = (spec & SPEC_EXT) != 0
    if ext and (spec & SPEC_CONTACT) != 0:
        # a lane loop of its own: the ball passes, without it, have no branches and no calls
        for l in range(lanes_of(s, spec)):
            if p[P_KC, l] != 0.0:
                _contact.add_contact_rates_lane(s, l, b, B_RADIUS, B_MEFF, p[P_R, l],
                                                p[P_KC, l], p[P_ZC, l], p[P_REACH, l], lam,
                                                nq + 3)


@njit(cache=True, error_model="numpy")
def drag_rates(t, s, p, b, d, lam, spec):
    """:func:`drag_rates_block` of one environment (1-D arrays)."""
    nb = b.shape[0]
    ns = s.shape[0]
    tt = np.full(1, t)
    drag_rates_block(tt, s.reshape((ns, 1)), p.reshape((p.shape[0], 1)),
                     b.reshape((nb, b.shape[1], 1)), d.reshape((d.shape[0], 1)),
                     lam.reshape((ns, 1)), nb, spec)
