"""Yoshida's equations (2-9)-(2-11) written out literally in numpy, for two balls and a
prescribed rotor angle.

This is what a user would write without abb-gym: a numpy right-hand side for
``scipy.integrate.solve_ivp``.  It serves twice: as the independent check that the compiled
model contains Yoshida's equations as a special case (``tests/test_model.py``), and as the
speed baseline of ``abb-gym bench speed``.  It shares no code with :mod:`abb_gym.physics.model`.
"""
from __future__ import annotations

import numpy as np

from ..physics.scene import Scene


def yoshida_accelerations(scene: Scene, q, v, psi, dpsi, ddpsi):
    """Accelerations [x'', y'', psi'', ph_1'', ph_2''] from Yoshida (2-9)-(2-11).

    Yoshida's sign(psi_i' - psi') is smoothed as tanh(R (psi_i' - psi') / u*) with the scene's
    ``rolling_regularization_speed`` u*, as in the compiled model (a tiny u* gives sign()).

    ``q = [x, y, psi, ph_1, ph_2]`` and ``v`` its rates; ph_i = psi_i - psi.  The rotor angle,
    speed and acceleration are prescribed (``psi``, ``dpsi``, ``ddpsi``).
    """
    m = scene.ball_mass[0]
    a = scene.ball_radius[0]
    inertia = scene.ball_inertia_factor[0] * m * a ** 2
    big_r, k, c, cb = scene.race_radius, scene.support_stiffness_x, scene.support_damping_x, \
        scene.ball_drag[0]
    beta_b = scene.ball_rolling_resistance[0]
    big_m = scene.total_mass
    m0e = scene.imbalance
    x, y = q[0], q[1]
    dx, dy = v[0], v[1]
    psis = psi + q[3:5]
    dpsis = dpsi + v[3:5]
    # unknowns: x'', y'', psi_1'', psi_2''
    mat = np.zeros((4, 4))
    rhs = np.zeros(4)
    mat[0, 0] = big_m
    rhs[0] = -c * dx - k * x + m0e * (ddpsi * np.sin(psi) + dpsi ** 2 * np.cos(psi))
    mat[1, 1] = big_m
    rhs[1] = -c * dy - k * y + m0e * (-ddpsi * np.cos(psi) + dpsi ** 2 * np.sin(psi))
    for i in range(2):
        mat[0, 2 + i] = -m * big_r * np.sin(psis[i])
        rhs[0] += m * big_r * dpsis[i] ** 2 * np.cos(psis[i])
        mat[1, 2 + i] = m * big_r * np.cos(psis[i])
        rhs[1] += m * big_r * dpsis[i] ** 2 * np.sin(psis[i])
        sgn = np.tanh(big_r * (dpsis[i] - dpsi) / scene.rolling_regularization_speed)
        # (m + I/a^2) R psi_i'' - m (x'' sin - y'' cos) + c_b R (psi_i' - psi')
        #   = -m (beta_b/a) (R psi_i'^2 - x'' cos - y'' sin) sgn + ((R + a)/a^2) I psi''
        row = 2 + i
        mat[row, 2 + i] = (m + inertia / a ** 2) * big_r
        mat[row, 0] = -m * np.sin(psis[i]) - m * beta_b / a * sgn * np.cos(psis[i])
        mat[row, 1] = m * np.cos(psis[i]) - m * beta_b / a * sgn * np.sin(psis[i])
        rhs[row] = (-cb * big_r * (dpsis[i] - dpsi)
                    - m * beta_b / a * big_r * dpsis[i] ** 2 * sgn
                    + (big_r + a) / a ** 2 * inertia * ddpsi)
    sol = np.linalg.solve(mat, rhs)
    return np.array([sol[0], sol[1], ddpsi, sol[2] - ddpsi, sol[3] - ddpsi])


def yoshida_rhs(scene: Scene, profile):
    """``f(t, s)`` for ``solve_ivp`` with the rotor angle from a SpeedProfile (state as in
    :mod:`abb_gym.physics.model`: ``[q, q']``, 10 entries)."""

    def rhs(t, s):
        psi, dpsi, ddpsi = profile.angle(t), profile.speed(t), profile.acceleration(t)
        qdd = yoshida_accelerations(scene, s[:5], s[5:], psi, dpsi, ddpsi)
        out = np.empty(10)
        out[:5] = s[5:]
        out[2] = dpsi
        out[5:] = qdd
        return out

    return rhs
