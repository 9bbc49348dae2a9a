"""Run-up metrics, defined once for environment rollouts and ``simulate`` trajectories.

**The operating band.**  "At operating speed" means ``|w - w_op| <= band * w_op`` with
``band = 0.002`` (+-0.2 %) by default: what the speed loop of a drive with an encoder holds
at steady state (typically 0.1-0.5 % of the set speed).  The first wave's +-1 % let a profile
park 1 % below the operating speed, where the whirl is smaller than at the operating speed,
and measure its "residual" there.

**What is measured.**  A run is followed interval by interval (an environment's control
intervals, or the sample intervals of a trajectory); each interval ``[t0, t1]`` brings the
rotor speed at ``t1``, the time integral of the vibration radius over the interval and its
largest value.  The *vibration radius* is the distance of the rotor centre from its rest
position (the bearing axis, or the static sag under gravity).  From that stream, with the
band and the settling time ``settle_time``:

=======================  ========  ===========================================================
metric                   unit      definition
=======================  ========  ===========================================================
``first_at_speed``       s         end of the first interval that ends in the band
``run_up_time``          s         settled entry: end of the interval that began the final
                                   stay in the band (the stay that is still going, or that
                                   completed); NaN while out of the band
``settled``              bool      the final stay has lasted ``settle_time``: the run-up is
                                   complete (an environment episode ends there)
``residual_vibration``   length    time average of the vibration radius over the settling
                                   window: the first ``settle_time`` of the final stay
                                   (intervals before the entry never count)
``peak_vibration``       length    largest vibration radius before the settled entry (the
                                   whole run while not settled)
``peak_speed``           rad/s     largest rotor speed at an interval end
``time_above_band``      s         time of the intervals that ended above the band
                                   (overspeed)
=======================  ========  ===========================================================

A run that leaves the band starts a new stay when it comes back; a run that parks anywhere
but the operating speed never settles.  The environments call :func:`update` from their
compiled step (the reward's time and residual terms use these same quantities), and
:func:`stream_metrics` feeds a sampled history through the same :func:`update`: one
implementation for both.
"""
from __future__ import annotations

import math

import numpy as np
from .._numba import njit

__all__ = ["BAND", "SETTLE_TIME", "N_ACC", "new_accumulator", "reset", "update", "in_band",
           "run_up_time", "residual", "peak_vibration", "stream_metrics"]

BAND = 0.002  # +-0.2 % of the operating speed
SETTLE_TIME = 1.0  # s; the default settling window of the environments' presets

# accumulator layout (float64)
(R_FIRST, R_ENTRY, R_STAY, R_PEAK, R_PEAK_ENTRY, R_RES_INT, R_RES_T, R_PEAK_SPEED,
 R_OVER_T, R_SETTLED) = range(10)
N_ACC = 10
_EPS = 1e-9


@njit(cache=True, inline="always")
def in_band(w, operating_speed, band):
    """True if speed ``w`` is within ``band * operating_speed`` of the operating speed."""
    return abs(w - operating_speed) <= band * operating_speed


@njit(cache=True)
def reset(acc):
    """Start a run: nothing measured yet."""
    acc[R_FIRST] = np.nan
    acc[R_ENTRY] = np.nan
    acc[R_STAY] = 0.0
    acc[R_PEAK] = 0.0
    acc[R_PEAK_ENTRY] = np.nan
    acc[R_RES_INT] = 0.0
    acc[R_RES_T] = 0.0
    acc[R_PEAK_SPEED] = 0.0
    acc[R_OVER_T] = 0.0
    acc[R_SETTLED] = 0.0


def new_accumulator() -> np.ndarray:
    """A fresh accumulator array."""
    acc = np.empty(N_ACC)
    reset(acc)
    return acc


@njit(cache=True)
def update(acc, t0, t1, w_end, vib_integral, vib_max, operating_speed, band, settle_time):
    """Add interval ``[t0, t1]``: rotor speed ``w_end`` [rad/s] at ``t1``, the time integral
    ``vib_integral`` and the maximum ``vib_max`` of the vibration radius over it.  Returns
    True while the rotor is in the band at ``t1``."""
    dt = t1 - t0
    if abs(w_end) > acc[R_PEAK_SPEED]:
        acc[R_PEAK_SPEED] = abs(w_end)
    if w_end > (1.0 + band) * operating_speed:
        acc[R_OVER_T] += dt
    inside = in_band(w_end, operating_speed, band)
    if acc[R_SETTLED] != 0.0:
        return inside  # the run-up is complete: nothing after it changes the metrics
    if inside:
        if math.isnan(acc[R_FIRST]):
            acc[R_FIRST] = t1
        if math.isnan(acc[R_ENTRY]):
            # a new stay begins at t1; the interval that reached the band is approach
            acc[R_ENTRY] = t1
            acc[R_STAY] = 0.0
            acc[R_RES_INT] = 0.0
            acc[R_RES_T] = 0.0
            acc[R_PEAK_ENTRY] = max(acc[R_PEAK], vib_max)
        else:
            acc[R_STAY] += dt
            acc[R_RES_INT] += vib_integral
            acc[R_RES_T] += dt
        if acc[R_STAY] >= settle_time - _EPS * (1.0 + settle_time):
            acc[R_SETTLED] = 1.0
    else:
        acc[R_ENTRY] = np.nan
        acc[R_STAY] = 0.0
        acc[R_RES_INT] = 0.0
        acc[R_RES_T] = 0.0
    if vib_max > acc[R_PEAK]:
        acc[R_PEAK] = vib_max
    return inside


@njit(cache=True, inline="always")
def run_up_time(acc):
    """Settled entry [s] (start of the current stay in the band), or NaN when out."""
    return acc[R_ENTRY]


@njit(cache=True, inline="always")
def residual(acc):
    """Time-average vibration over the settling window so far (NaN if it is empty)."""
    return acc[R_RES_INT] / acc[R_RES_T] if acc[R_RES_T] > 0.0 else np.nan


@njit(cache=True, inline="always")
def peak_vibration(acc):
    """Largest vibration radius before the settled entry (the whole run while out)."""
    return acc[R_PEAK] if math.isnan(acc[R_PEAK_ENTRY]) else acc[R_PEAK_ENTRY]


@njit(cache=True)
def _stream(t, w, vib, operating_speed, band, settle_time, interval, acc):
    reset(acc)
    start = t[0]
    integral = 0.0
    peak = 0.0
    for k in range(1, t.shape[0]):
        # right-endpoint rule over each sample interval, as the environments' RK4 steps
        integral += vib[k] * (t[k] - t[k - 1])
        peak = max(peak, vib[k])
        end = k == t.shape[0] - 1
        if interval <= 0.0 or end or t[k] >= start + interval * (1.0 - 1e-9):
            update(acc, start, t[k], w[k], integral, peak, operating_speed, band, settle_time)
            start = t[k]
            integral = 0.0
            peak = 0.0


def stream_metrics(t, rotor_speed, vibration, operating_speed: float, band: float = BAND,
                   settle_time: float = SETTLE_TIME, interval: float | None = None
                   ) -> dict[str, float | bool]:
    """The metrics of the module docstring from a sampled history: times [s], rotor speeds
    [rad/s] and vibration radii (any length unit) at the samples.  With ``interval`` [s] the
    samples are grouped into intervals of that length (an environment's control interval:
    the speed is checked at their ends, the vibration integrated over their samples), else
    every sample interval is one."""
    t = np.ascontiguousarray(t, dtype=float)
    w = np.ascontiguousarray(rotor_speed, dtype=float)
    vib = np.ascontiguousarray(vibration, dtype=float)
    acc = np.empty(N_ACC)
    _stream(t, w, vib, float(operating_speed), float(band), float(settle_time),
            float(interval or 0.0), acc)
    return accumulator_metrics(acc)


def accumulator_metrics(acc: np.ndarray) -> dict[str, float | bool]:
    """The metrics held by an accumulator (the module docstring's table)."""
    return {"first_at_speed": float(acc[R_FIRST]), "run_up_time": float(acc[R_ENTRY]),
            "settled": bool(acc[R_SETTLED]), "residual_vibration": float(residual(acc)),
            "peak_vibration": float(peak_vibration(acc)), "peak_speed": float(acc[R_PEAK_SPEED]),
            "time_above_band": float(acc[R_OVER_T])}
