"""Race friction of the balls: regularised Coulomb friction with a static peak (stick).

The ball model has one degree of freedom per ball (its orbit angle, rolling without slip), so
there is no slip velocity in the sense of Spannan's contact element; the friction acts on the
ball's orbit speed relative to the race, ``u = R ph'``, like the rolling resistance does (eq.
5.14 with ``u_orb = eps ph'``).  This is how Spannan's drag-coefficient rig uses its friction
coefficient mu = 0.05 (eq. 6.6: a resistance ``mu F_N`` against the ball's orbital motion), and
it stands for every contact loss of a real race (groove, cage-free sliding, lubricant film).

Law (Spannan eq. 5.7, with the printed literal 1.0 read as the static coefficient mu_s named in
the text, and u2* = ``stribeck_speed``, u3* = ``regularization_speed``)::

    F = -|N| mu(u),  mu(u) = [mu_k + (mu_s - mu_k) exp(-|u| / u_str)] tanh(u / u_reg)

With mu_s = mu_k it is the regularised Coulomb law (5.6).  N is the race normal force of the
ball (the same expression as for the rolling resistance, including gravity and ball-ball
contact when those are on).

**Stick without extra state.**  Spannan's adherence element (5.15) needs a state variable per
ball, and the thesis reports it as faulty (L1800); the kernel's state layout is fixed.  Here
stick comes from the steep regularisation instead (a Karnopp-like law whose "stuck" band is
the tanh width): a ball under a tangential load F below the static limit mu_s |N| finds the
creep speed ``u_c = u_reg atanh(F / (mu_s |N|))`` (for u_reg << u_str) - with u_reg = 1e-6 m/s
and half the limit that is 0.55 um/s, i.e. held for any practical purpose - and once F exceeds
mu_s |N| no creep speed exists and the ball breaks away, after which the friction falls to
mu_k within a few u_str.  The price is stiffness: near u = 0 the friction acts like a viscous
damper of coefficient mu_s |N| / u_reg.  :func:`abb_gym.physics.model.drag_rates` reports it
(as the secant mu(u) |N| / u, which also covers the sliding-to-stuck transition within a step),
so the exponential integrator ``etdrk4`` treats it exactly at the ordinary step, while explicit
RK4 needs steps below ~1.5 u_reg / (mu_s R Omega^2) - use ``etdrk4`` for scenes with stick.

**When it matters.**  Friction and stick decide where the balls come to rest (Spannan L1266:
final positions are set by static friction), so they produce the resting-position scatter,
balls that stop short of the balanced position (residual imbalance), and the benefit of a
temporary speed reduction after the resonance; and they stabilise the Sommerfeld region
(L1090).  Without them a ball drifts until drag and driving force balance exactly.
"""
from __future__ import annotations

import math

from .._numba import njit


@njit(cache=True, inline="always")
def friction_coefficient(u, muk, mus, ureg, ustr):
    """Signed friction coefficient mu(u) [-] at orbit speed ``u`` [m/s] (force = -|N| mu)."""
    peak = muk
    if mus > muk:
        peak = muk + (mus - muk) * math.exp(-abs(u) / ustr)
    return peak * math.tanh(u / ureg)


@njit(cache=True, inline="always")
def friction_secant(u, muk, mus, ureg, ustr):
    """mu(u) / u [s/m], the secant slope of the friction law (finite at u = 0)."""
    peak = muk
    if mus > muk:
        peak = muk + (mus - muk) * math.exp(-abs(u) / ustr)
    x = u / ureg
    if abs(x) < 1e-4:
        return peak * (1.0 - x * x / 3.0) / ureg
    return peak * math.tanh(x) / u
