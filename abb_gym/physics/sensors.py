"""What a drive measures: the synchronous (1x) vibration against a once-per-revolution mark.

Balancing machines and drive controllers read the vibration *synchronous with the rotation*:
its amplitude and its phase relative to a reference mark on the rotor (a keyphasor, an
encoder's index pulse).  That phase tells where the residual imbalance is, which is where the
balls stand relative to the rotor.  This module is the one implementation, used by the
compiled integration loop (:func:`abb_gym.physics.batch.advance_block`) and the environments'
observation (:mod:`abb_gym.envs.kernel`).

**Demodulator.**  Write the housing vibration (deflection from the rest position, fixed frame)
as ``z = (x - x_rest) + i (y - y_rest)`` [m] and the angle of the reference mark as
``th_m = th - th_mark`` [rad] (``th`` the model's rotor angle, which points at the primary
imbalance; ``th_mark`` the imbalance's angle from the mark, a property of the rotor).  The
synchronous demodulator multiplies by the reference's complex conjugate,

    u(t) = z(t) e^{-i th_m(t)}      (u_x = dx cos th_m + dy sin th_m,
                                     u_y = -dx sin th_m + dy cos th_m),

which is the vibration seen from the rotor, measured from its mark, and passes ``u`` through a
first-order low-pass of time constant ``lag`` [s] (the tracking filter):

    lag Z' + Z = u.

The filter runs at every integration step (the drive's sampling; a few hundred per control
interval on the shipped scenes): over a step of length ``h`` it holds ``u`` at its value at the
step's end and is advanced exactly, ``Z <- Z + a (u - Z)`` with ``a = 1 - exp(-h / lag)``
(``a = 1`` for ``lag = 0``: ``Z`` is then the demodulated sample at the end of the interval).

**Steady state.**  At constant speed ``W`` with the balls still relative to the rotor (held,
or settled), the rotor is a Jeffcott rotor of mass M (rotor plus balls) carrying the residual
imbalance ``U_r e^{i chi}`` (direction chi from the primary imbalance), so on an isotropic
support (stiffness k, damping c)

    M z'' + c z' + k z = U_r W^2 e^{i (th + chi)},
    z = U_r W^2 / (k - M W^2 + i c W) e^{i (th + chi)} = A e^{i (th + chi - lambda)},
    A = U_r W^2 / sqrt((k - M W^2)^2 + (c W)^2),   lambda = atan2(c W, k - M W^2),

and ``u = A e^{i (th_mark + chi - lambda)}`` is constant: the filter's output converges to it
with no phase error (a low-pass passes a constant unchanged).  Hence

* the measured amplitude ``|Z|`` is the steady whirl radius ``A``;
* the measured phase ``arg Z = th_mark + chi - lambda`` is the direction of the residual
  imbalance from the mark, lagged by the support's phase ``lambda``: 0 well below the critical
  speed, pi/2 at it, approaching pi above (``lambda`` = 0.8 deg at half and 179.2 deg at
  twice the critical speed of ``yoshida_odd``, damping ratio 0.01).

Anything non-synchronous (the free vibration at the natural frequency ``w_n`` while a
transient decays, the backward whirl of an orthotropic support) appears in ``u`` at the
frequencies ``w_n - W`` (and ``-(w_n + W)``, ``-2 W``) and is attenuated by the low-pass by
``1 / sqrt(1 + (f lag)^2)`` at frequency ``f``; ``rotor.jeffcott_response`` gives the steady
value.  Speeding up or slowing down makes ``u`` itself change, and the filter follows it with
its time lag.

**Noise.**  The sensor noise is Gaussian, added to each component of the filtered vector at
every observation (the read-out): ``Z_obs = Z + sigma (n_1 + i n_2)``, ``n_j ~ N(0, 1)``.  The
numbers come from a counter-based generator (:func:`gaussian_pair`: SplitMix64 of a 53-bit key
and the control step, then Box-Muller), so the kernel needs no random state: the key is drawn
per episode from the environment's ``np_random``, and the same key and step give the same
noise in the single and in the vector environment, however the lanes are arranged.
"""
from __future__ import annotations

import math

import numpy as np
from .._numba import njit

from . import elementary as el

__all__ = ["filter_gain", "demodulate", "gaussian_pair", "KEY_BOUND"]

#: noise keys are integers in [0, KEY_BOUND): exact as float64 (they live in float arrays)
KEY_BOUND = 2 ** 53

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_TWO_M53 = 1.0 / 9007199254740992.0  # 2^-53
TWO_PI = 2.0 * math.pi


@njit(cache=True, inline="always")
def filter_gain(h, lag):
    """Gain ``a = 1 - exp(-h / lag)`` of the low-pass over a step ``h`` [s] (1 for lag 0)."""
    if lag <= 0.0:
        return 1.0
    return -math.expm1(-h / lag)


@njit(cache=True, inline="always")
def demodulate(dx, dy, th_mark):
    """The vibration ``(dx, dy)`` [m] (fixed frame) seen from the rotor, measured from its
    reference mark at angle ``th_mark`` [rad]: ``(dx + i dy) e^{-i th_mark}``."""
    s, c = el.sincos(th_mark)
    return dx * c + dy * s, dy * c - dx * s


@njit(cache=True, inline="always")
def _mix(z):
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    return z ^ (z >> _S31)


@njit(cache=True)
def gaussian_pair(key, counter):
    """Two independent standard normal numbers for the integer ``key`` in [0, 2^53) and the
    ``counter`` (>= 0) (SplitMix64, then Box-Muller): a pure function of its inputs."""
    base = np.uint64(np.int64(key)) + np.uint64(np.int64(counter)) * np.uint64(2) * _GOLDEN
    u1 = (_mix(base + _GOLDEN) >> _S11) * _TWO_M53      # [0, 1)
    u2 = (_mix(base + _GOLDEN + _GOLDEN) >> _S11) * _TWO_M53
    r = math.sqrt(-2.0 * math.log(1.0 - u1))            # 1 - u1 in (0, 1]
    s, c = math.sin(TWO_PI * u2), math.cos(TWO_PI * u2)
    return r * c, r * s
