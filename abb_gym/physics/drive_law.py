"""Drive laws: how a drive row sets the rotor spin (compiled, one place for each law).

A run's drive is a table of rows, one per segment of piecewise-constant drive law; row ``j``
holds from its start time ``D_T0`` until the next row's.  Two modes:

* ``MODE_PRESCRIBED`` - the rotor angle is prescribed (infinite drive inertia):
  ``th = th0 + w0 tau + alpha tau^2 / 2``, ``w = w0 + alpha tau``, ``th'' = alpha`` with
  ``tau = t - t0`` (:func:`prescribed_state`).
* ``MODE_MOTOR`` - the rotor spin is a degree of freedom driven by the motor torque
  ``T = clip(T_cmd + g (w_target(t) - w), -T_max(w), T_max(w))``, ``w_target = tw0 + talpha
  tau`` (:func:`motor_torque`), where ``T_max(w)`` is the torque limit, optionally falling
  linearly to 0 at a no-load speed and capped by a power limit (:func:`available_torque`).

Every user of a drive law calls these functions: the equations of motion
(:mod:`abb_gym.physics.model`), the integrators (pinning the prescribed angle at segment
ends), the environments (writing a row per control interval with :func:`write_prescribed_row`
and :func:`write_motor_row`) and the Python drive classes (:mod:`abb_gym.physics.drives`
evaluates speeds and torques through :func:`prescribed_profile` and :func:`motor_torques`).

Row layout (``N_DRIVE`` columns; units SI):

=========  ==========  ===========================================================
column     unit        meaning
=========  ==========  ===========================================================
D_T0       s           start time of the row
D_TH0      rad         prescribed: rotor angle at D_T0
D_W0       rad/s       prescribed: rotor speed at D_T0
D_ALPHA    rad/s^2     prescribed: rotor acceleration
D_MODE     -           MODE_PRESCRIBED (0) or MODE_MOTOR (1)
D_TORQUE   N m         motor: torque command
D_GAIN     N m s       motor: speed-loop gain g
D_TW0      rad/s       motor: target speed at D_T0
D_TALPHA   rad/s^2     motor: target acceleration
D_TLIM     N m         motor: torque limit
D_WNL      rad/s       motor: no-load speed of a linear torque-speed envelope (0 = none)
D_PLIM     W           motor: power limit (0 = none)
=========  ==========  ===========================================================

A row with ``D_WNL`` or ``D_PLIM`` set needs the envelope: ``model.spec_of`` then sets
``SPEC_ENVELOPE``, and only kernels compiled with that bit evaluate it.
"""
from __future__ import annotations

import numpy as np
from .._numba import njit
from . import elementary as el

(D_T0, D_TH0, D_W0, D_ALPHA, D_MODE, D_TORQUE, D_GAIN, D_TW0, D_TALPHA, D_TLIM, D_WNL,
 D_PLIM) = range(12)
N_DRIVE = 12
MODE_PRESCRIBED = 0.0
MODE_MOTOR = 1.0


@njit(cache=True, inline="always")
def prescribed_law(tau, th0, w0, alpha):
    """(angle [rad], speed [rad/s], acceleration [rad/s^2]) a time ``tau`` [s] into a
    prescribed row that starts at angle ``th0``, speed ``w0`` with acceleration ``alpha``
    (scalars only: the vector kernels call it inside their lane loops)."""
    return th0 + w0 * tau + el.like(alpha, 0.5) * alpha * tau * tau, w0 + alpha * tau, alpha


@njit(cache=True, inline="always")
def prescribed_state(t, d):
    """(angle [rad], speed [rad/s], acceleration [rad/s^2]) of prescribed row ``d`` at ``t``."""
    return prescribed_law(t - d[D_T0], d[D_TH0], d[D_W0], d[D_ALPHA])


@njit(cache=True, inline="always")
def available_torque(lim, w, no_load_speed, power):
    """Torque limit [N m] at speed ``w`` [rad/s]: ``lim`` falling linearly to 0 at
    ``no_load_speed`` and capped by ``|T w| <= power`` [W] (each only when > 0)."""
    if no_load_speed > 0.0:
        lim *= max(el.like(lim, 0.0), el.like(lim, 1.0) - abs(w) / no_load_speed)
    if power > 0.0 and abs(w) * lim > power:
        lim = power / abs(w)
    return lim


@njit(cache=True, inline="always")
def motor_torque(t, w, d, envelope):
    """Motor torque [N m] of motor row ``d`` at time ``t`` and rotor speed ``w``.

    ``envelope`` (a compile-time constant at every call site) applies the torque-speed
    envelope of :func:`available_torque`; without it the torque is clipped to ``D_TLIM``.
    Leaving it out of the plain kernel keeps that kernel's code small enough for LLVM to
    inline it whole (a branch here cost ~10 % of a right-hand side)."""
    return motor_law(t - d[D_T0], w, d[D_TORQUE], d[D_GAIN], d[D_TW0], d[D_TALPHA], d[D_TLIM],
                     d[D_WNL], d[D_PLIM], envelope)


@njit(cache=True, inline="always")
def motor_law(tau, w, command, gain, w_target0, target_accel, limit, no_load_speed, power,
              envelope):
    """Motor torque [N m] a time ``tau`` [s] into a motor row, at rotor speed ``w``:
    ``clip(command + gain (w_target0 + target_accel tau - w), -T_max, T_max)`` (scalars only,
    for the lane loops; :func:`motor_torque` reads them from a row)."""
    torque = command + gain * (w_target0 + target_accel * tau - w)
    lim = limit
    if envelope:
        lim = available_torque(lim, w, no_load_speed, power)
    return lim if torque > lim else (-lim if torque < -lim else torque)


@njit(cache=True)
def pin_prescribed(t, s, lane, d, nq, angle_offset=0.0):
    """Set the rotor angle and speed of lane ``lane`` of state block ``s`` (state rows x
    lanes; a single state is a block of one lane) to the exact prescribed law of row ``d`` at
    ``t``: no drift of a prescribed rotor angle over many steps.  ``angle_offset`` [rad]: the
    block holds the rotor angle less this (a float32 block: :mod:`abb_gym.physics.batch`)."""
    if d[D_MODE] == MODE_PRESCRIBED:
        th, w, _ = prescribed_state(t, d)
        s[2, lane] = th - angle_offset  # (exact, th itself, at no offset)
        s[nq + 2, lane] = w


@njit(cache=True, inline="always")
def write_prescribed_row(d, t0, th0, w0, alpha):
    """Fill row ``d``: prescribed spin from ``t0`` at angle ``th0``, speed ``w0``, acceleration
    ``alpha``."""
    d[D_T0] = t0
    d[D_TH0] = th0
    d[D_W0] = w0
    d[D_ALPHA] = alpha
    d[D_MODE] = MODE_PRESCRIBED


@njit(cache=True, inline="always")
def write_motor_row(d, t0, torque, torque_limit):
    """Fill row ``d``: a constant motor torque command [N m] from ``t0``, limit ``torque_limit``."""
    d[D_T0] = t0
    d[D_MODE] = MODE_MOTOR
    d[D_TORQUE] = torque
    d[D_GAIN] = 0.0
    d[D_TW0] = 0.0
    d[D_TALPHA] = 0.0
    d[D_TLIM] = torque_limit


@njit(cache=True, inline="always")
def _row_index(t, rows):
    """Index of the row that holds ``t`` (the first row for earlier times)."""
    k = np.searchsorted(rows[:, D_T0], t, side="right") - 1
    return max(k, 0)


@njit(cache=True)
def prescribed_profile(t, rows):
    """(angle, speed, acceleration) arrays of a prescribed drive table at times ``t``."""
    th = np.empty(t.shape[0])
    w = np.empty(t.shape[0])
    alpha = np.empty(t.shape[0])
    for k in range(t.shape[0]):
        th[k], w[k], alpha[k] = prescribed_state(t[k], rows[_row_index(t[k], rows)])
    return th, w, alpha


@njit(cache=True)
def motor_torques(t, w, rows):
    """Motor torque [N m] of a motor drive table at times ``t`` and rotor speeds ``w``."""
    out = np.empty(t.shape[0])
    for k in range(t.shape[0]):
        out[k] = motor_torque(t[k], w[k], rows[_row_index(t[k], rows)], True)
    return out


@njit(cache=True)
def prescribed_speeds(t, tables, n_rows):
    """Speed [rad/s] of prescribed drive table ``e`` at time ``t[e]``, for every ``e``:
    ``tables`` (E, R, N_DRIVE) with ``n_rows[e]`` valid rows each (many profiles at once)."""
    out = np.empty(t.shape[0])
    for e in range(t.shape[0]):
        rows = tables[e, :n_rows[e]]
        out[e] = prescribed_state(t[e], rows[_row_index(t[e], rows)])[1]
    return out
