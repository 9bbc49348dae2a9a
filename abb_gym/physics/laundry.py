"""Laundry that redistributes when the drum tumbles (washing machines), compiled.

A washing machine's load imbalance is its laundry: a random lump stuck to the drum wall by
the centrifugal force.  Below the satellisation speed the laundry does not stick: it tumbles
and lands in a new arrangement, a new imbalance of new size and phase.  Washing-machine
firmware uses that on purpose: it senses the imbalance at the distribution speed (90-100
rpm) or at spin, and redistributes (drops to a tumble, then runs up again) when the load is
larger than the balancer can take.

**The tumble speed.**  A piece of laundry on the wall of a drum of radius R turning at w
presses on the wall with ``m (w^2 R - g sin b)``, b its height angle above the horizontal
through the axis; it leaves the wall where that vanishes, ``sin b = w^2 R / g``.  At
``w >= sqrt(g / R)`` (satellisation) it never leaves.  Below, it leaves at ``b`` and falls
across the drum; it lands somewhere new (a redistribution, not a slide back down the wall)
when it falls from low enough on the rising side to cross the drum: taken here as ``b <=
40 deg``, so ``w^2 R / g <= sin 40 deg = 0.64`` and ``w_tumble = 0.8 sqrt(g / R)``
(:func:`tumble_speed`; 4.91 rad/s, 47 rpm, on the washer's 0.26 m track).  Firmware tumbles
at 40-60 rpm, which agrees.

**What the model does** (:func:`redistribute`), once the drum has stayed below the tumble
speed for the tumble time:

* the imbalance takes a new size U0 and a new angle from the drum's reference mark, drawn
  from the same distribution as the episode's first (:mod:`abb_gym.envs.redistribution`);
  the rotor angle ``th`` (measured to the imbalance) moves with it, so the drum itself does
  not turn: ``th' = th - phase_old + phase_new``;
* the balls come to rest at the bottom of the race, side by side and touching, centred on
  the lowest point (:func:`resting_angles`), at rest in the fixed frame (``ph_i' = -th'``):
  at tumble speed the balls lie at the bottom and the drum turns under them;
* the housing keeps its position and velocity, the drum its speed.

Simplifications: the redistribution is instantaneous and happens at the end of the tumble
time (real laundry rearranges over a few falls); the laundry's mass stays on the rotor (only
its distribution changes: the supported mass, the critical speeds and the rotor's polar
inertia are unchanged); the load is one lump in the balancing plane (no couple imbalance);
the tumbling laundry's own forces on the drum are not modelled.
"""
from __future__ import annotations

import math

from .._numba import njit
from . import model as mdl

__all__ = ["DETACHMENT_ANGLE", "tumble_speed", "resting_angles", "redistribute",
           "effective_capacity"]

#: highest angle above the horizontal [rad] at which laundry that leaves the wall still falls
#: across the drum (module docstring)
DETACHMENT_ANGLE = math.radians(40.0)
TWO_PI = 2.0 * math.pi


def tumble_speed(gravity: float, radius: float) -> float:
    """Drum speed [rad/s] below which the laundry tumbles: ``sqrt(sin(40 deg) g / R)``, about
    ``0.8 sqrt(g / R)`` (module docstring); ``gravity`` [m/s^2], ``radius`` [m]."""
    return math.sqrt(math.sin(DETACHMENT_ANGLE) * gravity / radius)


@njit(cache=True)
def resting_angles(p, b, out, start=0):
    """Write into ``out[start:start + balls]`` the fixed-frame angles [rad] of the balls at
    rest at the bottom of the race: in index order, neighbours touching (centre chord
    ``r_k + r_k+1``), the group centred on the lowest point (the direction of gravity; -pi/2
    without gravity).  (An offset, not a slice: the environment step runs without reference
    counts, :mod:`abb_gym._numba`.)"""
    nb = b.shape[0]
    big_r = p[mdl.P_R]
    gx = p[mdl.P_GX]
    gy = p[mdl.P_GY]
    low = math.atan2(gy, gx) if (gx != 0.0 or gy != 0.0) else -0.5 * math.pi
    span = 0.0
    for k in range(nb - 1):
        chord = b[k, mdl.B_RADIUS] + b[k + 1, mdl.B_RADIUS]
        span += 2.0 * math.asin(min(1.0, 0.5 * chord / big_r))
    angle = low - 0.5 * span
    for k in range(nb):
        out[start + k] = angle
        if k + 1 < nb:
            chord = b[k, mdl.B_RADIUS] + b[k + 1, mdl.B_RADIUS]
            angle += 2.0 * math.asin(min(1.0, 0.5 * chord / big_r))


@njit(cache=True)
def redistribute(s, p, b, imbalance, phase, phase_old):
    """The laundry lands anew (module docstring): the state ``s`` and the packed parameters
    ``p`` of one machine take the imbalance ``imbalance`` [kg m] at ``phase`` [rad] from the
    reference mark (it was at ``phase_old``); the balls come to rest at the bottom of the
    race.  The ball angles are written in [-pi, pi)."""
    nq = s.shape[0] // 2
    nb = nq - 3
    th = s[2] - phase_old + phase
    w = s[nq + 2]
    s[2] = th
    p[mdl.P_U0] = imbalance
    resting_angles(p, b, s, 3)
    for k in range(nb):
        ph = s[3 + k] - th
        s[3 + k] = ph - TWO_PI * math.floor((ph + math.pi) / TWO_PI)
        s[nq + 3 + k] = -w


def effective_capacity(scene) -> float:
    """The largest imbalance [kg m] the balls of ``scene`` can cancel once contact keeps them
    apart: ``|sum m_i R e^(i phi_i)|`` with the balls clumped side by side, touching
    (:func:`resting_angles`' spacing), less than the nominal ``sum m_i R`` because the clump
    spans an arc (on the washer's twelve 19 mm balls: 0.806 rad, 0.968 of the nominal).
    Without ball contact the model lets balls pass through each other: the nominal capacity.
    A larger imbalance leaves ``U - C_eff`` whatever the drive does."""
    import numpy as np

    if scene.contact_stiffness <= 0.0:
        return scene.balancing_capacity
    p, b = mdl.pack_parameters(scene)
    angles = np.zeros(scene.ball_count)
    resting_angles(p, b, angles, 0)
    mr = np.asarray(scene.ball_mass, float) * scene.race_radius
    return float(abs(np.sum(mr * np.exp(1j * angles))))
