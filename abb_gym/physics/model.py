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
  ``N_i = m_i [R (th'+ph_i')^2 + E th'^2 cos(gam-ph_i) + E th'' sin(gam-ph_i)
               - x'' cos(th+ph_i) - y'' sin(th+ph_i)]``
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
from numba import njit

from . import contact as _contact
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
N_PARAMS = 31
EXTENDED_EFFECTS = frozenset({"gravity", "ball_contact", "fluid_drag", "virtual_mass",
                              "friction"})
# per-ball parameter matrix columns: mass [kg], radius [m], spin inertia [kg m^2], race drag
# torque coefficient [N m s], rolling-resistance offset / radius [-]; added relative inertia
# of the virtual mass [kg m^2], Stokes drag coefficient [N s/m], rho pi r^2 / 2 [kg/m],
# Reynolds number per relative speed 2 r / nu [s/m], effective track mass I_i / R^2 [kg]
B_MASS, B_RADIUS, B_INERTIA, B_BETA, B_MUR = range(5)
B_VM, B_KLIN, B_KQUAD, B_REU, B_MEFF = range(5, 10)
N_BALL_PARAMS = 10
# scratch columns of accelerations(): 0-7 the ball rows, 8-9 the contact forces
WORK_COLUMNS = 10
W_QC = 8  # generalised contact force on the ball [N m]
W_NC = 9  # outward radial contact force on the ball [N]


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
    return p, b


@njit(cache=True, inline="always")
def _ball_coupling(th, ph, p, b, i):
    """Mass-matrix entries of ball i: (col_x, col_y, c_i, I_i, spin-inertia share of Jt)."""
    m = b[i, B_MASS]
    r = b[i, B_RADIUS]
    ji = b[i, B_INERTIA]
    big_r = p[P_R]
    mr = m * big_r
    s = math.sin(th + ph)
    c = math.cos(th + ph)
    ci = mr * big_r - ji * big_r / r
    jt = ji + mr * big_r
    if p[P_ECC] != 0.0:
        e = p[P_E]
        cg = math.cos(p[P_GAM] - ph)
        ci += e * mr * cg
        jt += m * e * e + 2.0 * e * mr * cg
    return -mr * s, mr * c, ci, ji * big_r * big_r / (r * r) + mr * big_r, jt


@njit(cache=True)
def mass_matrix(q, p, b):
    """Symmetric mass matrix M(q) of size 3 + n (kinetic energy T = q'^T M q' / 2)."""
    n = b.shape[0]
    nq = 3 + n
    th = q[2]
    mm = np.zeros((nq, nq))
    total = p[P_MASS]
    sx = p[P_U0] * math.sin(th)
    cy = p[P_U0] * math.cos(th)
    jt = p[P_J]
    for i in range(n):
        if p[P_ECC] != 0.0:
            sx += p[P_E] * b[i, B_MASS] * math.sin(th + p[P_GAM])
            cy += p[P_E] * b[i, B_MASS] * math.cos(th + p[P_GAM])
        colx, coly, ci, ii, jti = _ball_coupling(th, q[3 + i], p, b, i)
        sx -= colx
        cy += coly
        jt += jti
        k = 3 + i
        mm[0, k] = mm[k, 0] = colx
        mm[1, k] = mm[k, 1] = coly
        mm[2, k] = mm[k, 2] = ci
        # the virtual mass of the fluid (0 unless that effect is on) adds to the relative
        # inertia only: the fluid moves with the rotor otherwise
        mm[k, k] = ii + b[i, B_VM]
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
    sx = p[P_MASS] * q[0] + p[P_U0] * math.cos(th)
    sy = p[P_MASS] * q[1] + p[P_U0] * math.sin(th)
    for i in range(b.shape[0]):
        m = b[i, B_MASS]
        sx += m * p[P_R] * math.cos(th + q[3 + i])
        sy += m * p[P_R] * math.sin(th + q[3 + i])
        if p[P_ECC] != 0.0:
            sx += m * p[P_E] * math.cos(th + p[P_GAM])
            sy += m * p[P_E] * math.sin(th + p[P_GAM])
    return -(p[P_GX] * sx + p[P_GY] * sy)



@njit(cache=True, inline="always")
def _accelerations_body(t, s, p, b, d, qdd, work, extended):
    """The equations of motion (module docstring), once.  ``extended`` is a compile-time
    constant: False leaves out every term of the extended effects and the drive envelope,
    so that specialisation compiles to the kernel of a scene that switches nothing on; the
    operations the two specialisations share run in the same order, so a scene without
    extended effects gets bit-identical results from both (``tests/test_model.py``)."""
    n = b.shape[0]
    nq = 3 + n
    x, y = s[0], s[1]
    vx, vy = s[nq], s[nq + 1]
    th, w, alpha, torque = dl.drive_state(t, s, d, nq, extended)
    prescribed = d[dl.D_MODE] == dl.MODE_PRESCRIBED
    ecc = p[P_ECC] != 0.0
    roll = p[P_ROLL] != 0.0
    grav = extended and p[P_GRAV] != 0.0
    touch = extended and p[P_KC] != 0.0
    dlaw = p[P_DLAW] if extended else 0.0
    fric = extended and p[P_FRIC] != 0.0
    resist = roll or fric
    gx = p[P_GX]
    gy = p[P_GY]
    big_r = p[P_R]
    if touch:
        # pair forces first: the contact's radial part loads the race (friction, rolling)
        _contact.ball_contacts(s, nq, b, B_RADIUS, B_MEFF, big_r, p[P_KC], p[P_ZC], work,
                               W_QC, W_NC)
    e = p[P_E]
    gam = p[P_GAM]
    w2 = w * w
    sth = math.sin(th)
    cth = math.cos(th)
    total = p[P_MASS]
    sx = p[P_U0] * sth
    cy = p[P_U0] * cth
    fx = -p[P_CX] * vx - p[P_KX] * x + p[P_U0] * cth * w2
    fy = -p[P_CY] * vy - p[P_KY] * y + p[P_U0] * sth * w2
    fth = torque - p[P_BETA0] * w
    jt = p[P_J]
    if ecc:
        stg = math.sin(th + gam)
        ctg = math.cos(th + gam)
    else:
        stg = 0.0
        ctg = 0.0
    for i in range(n):
        m = b[i, B_MASS]
        ph = s[3 + i]
        dph = s[nq + 3 + i]
        mr = m * big_r
        sp = math.sin(th + ph)
        cp = math.cos(th + ph)
        colx, coly, ci, ii, jti = _ball_coupling(th, ph, p, b, i)
        if extended:
            ii += b[i, B_VM]
        sx -= colx
        cy += coly
        jt += jti
        wrel2 = (w + dph) * (w + dph)
        fx += mr * wrel2 * cp
        fy += mr * wrel2 * sp
        fi = -b[i, B_BETA] * dph
        if dlaw != 0.0:
            drag, slope = _fluids.race_drag(big_r * dph, dlaw, b[i, B_KLIN], b[i, B_KQUAD],
                                            b[i, B_REU], p[P_CD0], p[P_CD1], p[P_CD2],
                                            p[P_CD3], p[P_CDINF])
            fi -= drag * big_r
        if touch:
            fi += work[i, W_QC]
        bx = colx
        by = coly
        bth = ci
        if ecc:
            sgp = math.sin(gam - ph)
            cgp = math.cos(gam - ph)
            sx += e * m * stg
            cy += e * m * ctg
            fx += e * m * ctg * w2
            fy += e * m * stg * w2
            fth -= e * mr * sgp * dph * (2.0 * w + dph)
            fi += mr * e * sgp * w2
        if grav:
            # g m R sin(a - th - ph): the weight's component along the track
            fi += mr * (gy * cp - gx * sp)
        if resist:
            # friction-type forces -coef R N with the race normal force N (module docstring)
            if roll:
                kr = b[i, B_MUR] * mr * math.tanh(big_r * dph / p[P_UREG])
            else:
                kr = 0.0
            if fric:
                kr += mr * friction_coefficient(big_r * dph, p[P_MUK], p[P_MUS], p[P_UFR],
                                                p[P_USTR])
            if grav:
                # |N|: a ball that the weight presses onto the inner wall of the annulus
                # (N < 0) is still resisted; the sign comes from the velocity-dependent part
                n0 = big_r * wrel2 + gx * cp + gy * sp
                if ecc:
                    n0 += e * w2 * cgp
                if touch:
                    n0 += work[i, W_NC] / m
                if n0 < 0.0:
                    kr = -kr
                fi -= kr * (gx * cp + gy * sp)
            fi -= kr * big_r * wrel2
            bx -= kr * cp
            by -= kr * sp
            if ecc:
                fi -= kr * e * w2 * cgp
                bth += kr * e * sgp
            if touch:
                fi -= kr * work[i, W_NC] / m
        work[i, 0] = bx
        work[i, 1] = by
        work[i, 2] = bth
        work[i, 3] = fi
        work[i, 4] = ii
        work[i, 5] = colx
        work[i, 6] = coly
        work[i, 7] = ci
    if grav:
        fx += total * gx
        fy += total * gy
        fth += gy * cy - gx * sx
    # top block [[M, 0, -Sx], [0, M, Cy], [-Sx, Cy, Jt]] and its Schur complement
    a00 = total
    a01 = 0.0
    a10 = 0.0
    a11 = total
    a02 = -sx
    a12 = cy
    a20 = -sx
    a21 = cy
    a22 = jt
    if prescribed:
        fx -= a02 * alpha
        fy -= a12 * alpha
    for i in range(n):
        bx, by, bth, fi, ii = work[i, 0], work[i, 1], work[i, 2], work[i, 3], work[i, 4]
        colx, coly, ci = work[i, 5], work[i, 6], work[i, 7]
        if prescribed:
            fi -= bth * alpha
        inv = 1.0 / ii
        a00 -= colx * bx * inv
        a01 -= colx * by * inv
        a10 -= coly * bx * inv
        a11 -= coly * by * inv
        fx -= colx * fi * inv
        fy -= coly * fi * inv
        if not prescribed:
            a02 -= colx * bth * inv
            a12 -= coly * bth * inv
            a20 -= ci * bx * inv
            a21 -= ci * by * inv
            a22 -= ci * bth * inv
            fth -= ci * fi * inv
    if prescribed:
        det = a00 * a11 - a01 * a10
        ax = (fx * a11 - a01 * fy) / det
        ay = (a00 * fy - a10 * fx) / det
        ath = alpha
    else:
        c00 = a11 * a22 - a12 * a21
        c01 = a12 * a20 - a10 * a22
        c02 = a10 * a21 - a11 * a20
        det = a00 * c00 + a01 * c01 + a02 * c02
        ax = (fx * c00 + a01 * (a12 * fth - fy * a22) + a02 * (fy * a21 - a11 * fth)) / det
        ay = (a00 * (fy * a22 - a12 * fth) + fx * c01 + a02 * (a10 * fth - fy * a20)) / det
        ath = (a00 * (a11 * fth - fy * a21) + a01 * (fy * a20 - a10 * fth) + fx * c02) / det
    qdd[0] = ax
    qdd[1] = ay
    qdd[2] = ath
    for i in range(n):
        qdd[3 + i] = (work[i, 3] - work[i, 0] * ax - work[i, 1] * ay - work[i, 2] * ath) \
            / work[i, 4]
    return torque


@njit(cache=True)
def accelerations_plain(t, s, p, b, d, qdd, work):
    """:func:`accelerations` of a scene without extended effects and a drive row without an
    envelope (the compiled specialisation with ``extended=False``)."""
    return _accelerations_body(t, s, p, b, d, qdd, work, False)


@njit(cache=True)
def accelerations_extended(t, s, p, b, d, qdd, work):
    """:func:`accelerations` with every extended effect evaluated where its flag is set."""
    return _accelerations_body(t, s, p, b, d, qdd, work, True)


@njit(cache=True, inline="always")
def uses_extended(p, d):
    """True if the scene parameters ``p`` or drive row ``d`` need the extended kernel."""
    return p[P_EXT] != 0.0 or dl.needs_envelope(d)


@njit(cache=True, inline="always")
def accelerations(t, s, p, b, d, qdd, work):
    """Fill ``qdd`` (length 3 + n) with the generalised accelerations at state ``s``.

    ``d`` is the drive row of the current segment, ``work`` an (n, WORK_COLUMNS) scratch
    array.  With a prescribed drive, th and th' are taken from the drive law (the state's
    entries are ignored) and qdd[2] is the prescribed acceleration.  Returns the motor torque
    [N m] (0 if prescribed).

    Dispatches to one of the two specialisations of the single body
    :func:`_accelerations_body`: a scene with no extended effect runs the plain one.  (One
    kernel testing a run-time flag per effect measured 10-20 % slower per right-hand side on
    scenes that switch nothing on: code size defeats LLVM's inlining; the dispatch costs ~3 %.)
    """
    if uses_extended(p, d):
        return accelerations_extended(t, s, p, b, d, qdd, work)
    # the plain body inlined here rather than called: as a call it cost ~12 %
    return _accelerations_body(t, s, p, b, d, qdd, work, False)


def make_work(n_balls: int) -> np.ndarray:
    """Scratch array for :func:`accelerations`."""
    return np.zeros((n_balls, WORK_COLUMNS))


@njit(cache=True)
def state_derivative(t, s, p, b, d, ds, qdd, work):
    """ds/dt for the first-order state; with a prescribed drive the th-rows follow the drive."""
    nq = 3 + b.shape[0]
    accelerations(t, s, p, b, d, qdd, work)
    for k in range(nq):
        ds[k] = s[nq + k]
        ds[nq + k] = qdd[k]
    if d[dl.D_MODE] == dl.MODE_PRESCRIBED:
        ds[2] = dl.prescribed_state(t, d)[1]


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


@njit(cache=True, inline="always")
def _drag_rates_body(t, s, p, b, d, lam, extended):
    """:func:`drag_rates`, once; ``extended`` as in :func:`_accelerations_body`."""
    n = b.shape[0]
    nq = 3 + n
    th, w, alpha, torque = dl.drive_state(t, s, d, nq, extended)
    for j in range(2 * nq):
        lam[j] = 0.0
    big_r = p[P_R]
    for i in range(n):
        m = b[i, B_MASS]
        r = b[i, B_RADIUS]
        ii = b[i, B_INERTIA] * big_r * big_r / (r * r) + m * big_r * big_r
        if extended:
            ii += b[i, B_VM]
        rate = b[i, B_BETA]
        dph = s[nq + 3 + i]
        if p[P_ROLL] != 0.0:
            ch = math.cosh(big_r * dph / p[P_UREG])
            rate += b[i, B_MUR] * m * big_r ** 3 * (w + dph) ** 2 / (ch * ch * p[P_UREG])
        if extended:
            if p[P_DLAW] != 0.0:
                drag, slope = _fluids.race_drag(big_r * dph, p[P_DLAW], b[i, B_KLIN],
                                                b[i, B_KQUAD], b[i, B_REU], p[P_CD0],
                                                p[P_CD1], p[P_CD2], p[P_CD3], p[P_CDINF])
                rate += big_r * big_r * slope
            if p[P_FRIC] != 0.0:
                normal = m * big_r * (w + dph) ** 2
                if p[P_GRAV] != 0.0:
                    normal += m * (p[P_GX] * math.cos(th + s[3 + i])
                                   + p[P_GY] * math.sin(th + s[3 + i]))
                rate += big_r * big_r * abs(normal) * friction_secant(
                    big_r * dph, p[P_MUK], p[P_MUS], p[P_UFR], p[P_USTR])
        lam[nq + 3 + i] = rate / ii
        if extended and p[P_KC] != 0.0:
            lam[nq + 3 + i] += _contact.contact_rate(s, i, b, B_RADIUS, B_MEFF, big_r,
                                                     p[P_KC], p[P_ZC])


@njit(cache=True)
def drag_rates_plain(t, s, p, b, d, lam):
    """:func:`drag_rates` without extended effects (``extended=False``)."""
    _drag_rates_body(t, s, p, b, d, lam, False)


@njit(cache=True)
def drag_rates_extended(t, s, p, b, d, lam):
    """:func:`drag_rates` with the extended effects."""
    _drag_rates_body(t, s, p, b, d, lam, True)


@njit(cache=True, inline="always")
def drag_rates(t, s, p, b, d, lam):
    """Relaxation rates [1/s] of the ball relative speeds, written into ``lam`` (state size).

    For ball i, lam[ph_i'] = (beta_i + d(resisting force)/d(ph_i')) / I_i, the race drag plus:

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

    Every other entry is 0.  This is the stiff, nearly diagonal part of the Jacobian (the
    coupling through the rotor, of relative size m_i / M, is left out); the exponential
    integrator treats it exactly and the step-size rule of the explicit methods bounds h * lam.
    Dispatches like :func:`accelerations`.
    """
    if uses_extended(p, d):
        drag_rates_extended(t, s, p, b, d, lam)
    else:
        _drag_rates_body(t, s, p, b, d, lam, False)
