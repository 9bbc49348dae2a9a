"""Redistribution of the laundry in the environments (preset section ``redistribution``).

With ``redistribution.enabled`` (``abb_gym/SpinRedistribute-v0`` fixes it on), a drum that
stays below the tumble speed for ``tumble_time`` without a break redistributes its laundry:
the imbalance takes the next of the episode's drawn values and the balls come to rest at the
bottom of the race (the physics and its simplifications: :mod:`abb_gym.physics.laundry`).
The compiled step checks it at the end of every control interval
(:func:`abb_gym.envs.kernel._tumble`); the observation counts the redistributions so far.

**The draws.**  Each episode draws ``max_count`` redistributions when it starts, from the
episode's own generator, after its other numbers (:mod:`abb_gym.envs.episodes`): for each,
the episode parameters declared ``per_event`` (the imbalance as a ratio of the balancing
capacity and its phase from the reference mark), uniform over the preset's ``randomize``
ranges, as the episode's first laundry is drawn.  The balls start at rest at the bottom of the
race, as after every redistribution, unless the preset draws their angles or a reset option
gives them (:func:`start_at_rest`).  Drawing them up front keeps every episode
a function of its seed alone, whatever the policy does, and lets the single and the vector
environment agree bit for bit.  After the last one, tumbling leaves the laundry where it
lies.  The reset option ``redistributions`` (an array of shape (k, 2), k <= ``max_count``:
imbalance [kg m] and phase [rad] of the first k) fixes them.

**The tumble speed** is ``redistribution.tumble_speed``, or by default ``sqrt(sin(40 deg) g /
R) = 0.8 sqrt(g / R)`` with R the race radius (the balancer ring sits at the drum's rim:
:func:`abb_gym.physics.laundry.tumble_speed` derives it).  Redistribution needs gravity in the
balancing plane (a horizontal-axis scene); other scenes are refused.
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from ..physics import laundry
from ..physics import model as mdl
from .config import PresetError
from .episode_parameters import PARAMETERS
from .layout import (C_REDIST, C_REDIST_MAX, C_TUMBLE_SPEED, C_TUMBLE_TIME, S_NREDIST,
                     S_REDIST, S_TUMBLE)

__all__ = ["OPTION", "check", "events", "tumble_speed", "write_constants", "draws",
           "apply_option", "prepare", "DRAWS", "resting_angles", "start_at_rest"]

#: the reset option that fixes the redistributions
OPTION = "redistributions"
#: the episode parameters drawn again at each redistribution, in the order of a draw
EVENT_PARAMETERS = tuple(par for par in PARAMETERS if par.per_event)
#: the keys of the draws (arrays over rows x redistributions)
DRAWS = tuple(f"redistribution_{par.name}" for par in EVENT_PARAMETERS)


def check(setup: Any) -> None:
    """Raise PresetError if redistribution is on for a scene without gravity in the balancing
    plane (the laundry cannot tumble)."""
    if setup.config.redistribution.enabled and setup.scene.gravity_acceleration <= 0.0:
        raise PresetError(f"environment preset {setup.config.name!r}: field "
                          f"'redistribution.enabled' needs a horizontal-axis scene (gravity in "
                          f"the balancing plane, where laundry can tumble); scene "
                          f"{setup.scene.name!r} has gravity_acceleration = 0")


def events(setup: Any) -> int:
    """Redistributions drawn per episode (0 without redistribution)."""
    r = setup.config.redistribution
    return int(r.max_count) if r.enabled else 0


def tumble_speed(setup: Any) -> float:
    """The drum speed [rad/s] below which the laundry tumbles (module docstring)."""
    r = setup.config.redistribution
    if r.tumble_speed is not None:
        return float(r.tumble_speed)
    return laundry.tumble_speed(setup.scene.gravity_acceleration, setup.scene.race_radius)


def write_constants(setup: Any, cfg: np.ndarray) -> None:
    """The compiled step's constants of the redistribution."""
    r = setup.config.redistribution
    if not r.enabled:
        return
    cfg[C_REDIST] = 1.0
    cfg[C_TUMBLE_SPEED] = tumble_speed(setup)
    cfg[C_TUMBLE_TIME] = r.tumble_time
    cfg[C_REDIST_MAX] = r.max_count


def draws(setup: Any, rngs: Sequence[np.random.Generator]) -> dict[str, np.ndarray]:
    """The redistributions of each row, drawn from its generator (module docstring): arrays
    (rows x redistributions) under :data:`DRAWS`; {} without redistribution."""
    k = events(setup)
    if k == 0:
        return {}
    sc = setup.scene
    rz = setup.config.randomize
    n = len(rngs)
    drawn = [par for par in EVENT_PARAMETERS if getattr(rz, par.randomize) is not None]
    u = (np.array([rng.random(k * len(drawn)) for rng in rngs]).reshape(n, k, len(drawn))
         if drawn and n else np.zeros((n, k, 0)))
    out = {}
    for key, par in zip(DRAWS, EVENT_PARAMETERS):
        span = getattr(rz, par.randomize)
        if span is None:
            out[key] = np.full((n, k), float(par.nominal(sc)))
        else:
            lo, hi = float(span[0]), float(span[1])
            out[key] = par.drawn(sc, lo + (hi - lo) * u[:, :, drawn.index(par)])
    return out


def apply_option(setup: Any, values: dict[str, Any], given: Any) -> None:
    """The reset option ``redistributions`` (module docstring) into one row's draws."""
    k = events(setup)
    if k == 0:
        raise ValueError(f"reset option {OPTION!r} needs redistribution.enabled (the "
                         f"SpinRedistribute task)")
    try:
        a = np.asarray(given, dtype=float)
    except (TypeError, ValueError):
        a = None
    if a is None or a.ndim != 2 or a.shape[1] != len(DRAWS) or a.shape[0] > k \
            or not np.all(np.isfinite(a)) or np.any(a[:, 0] < 0.0):
        raise ValueError(f"reset option {OPTION!r} must be an array of shape (k, 2), k <= "
                         f"redistribution.max_count = {k}: imbalance [kg m] >= 0 and phase "
                         f"[rad] of each of the first k redistributions (got "
                         f"{' '.join(repr(given).split())[:80]})")
    for j, key in enumerate(DRAWS):
        column = np.array(values[key], dtype=float)
        column[:a.shape[0]] = a[:, j]
        values[key] = column


def resting_angles(setup: Any) -> np.ndarray:
    """The balls' fixed-frame angles [rad] at rest at the bottom of the nominal scene's race
    (:func:`abb_gym.physics.laundry.resting_angles`)."""
    p, b = mdl.pack_parameters(setup.scene)
    out = np.zeros(setup.scene.ball_count)
    laundry.resting_angles(p, b, out, 0)
    return out


def start_at_rest(setup: Any, values: dict[str, Any], given: bool = False) -> None:
    """With redistribution, the balls of an episode whose preset does not draw their angles
    (``randomize.ball_angles: null``) and whose reset options do not give them (``given``)
    start at rest at the bottom of the race, as after every redistribution: their angles
    from the imbalance are the resting angles less the imbalance phase (``values``: one row's
    draws or arrays over rows)."""
    if given or not events(setup) or setup.config.randomize.ball_angles is not None:
        return
    phase = np.asarray(values["imbalance_phase"], float)
    rest = resting_angles(setup)
    angles = rest[None, :] - phase.reshape(-1, 1)
    angles = np.array([[math.remainder(v, 2.0 * math.pi) for v in row] for row in angles])
    values["ball_angles"] = angles.reshape(np.shape(values["ball_angles"]))


def prepare(setup: Any, st: np.ndarray, values: Mapping[str, Any], n: int) -> np.ndarray:
    """Write the redistributions into the rows' bookkeeping ``st`` (n rows); returns them as
    (n, redistributions, 2): imbalance [kg m], phase [rad] (reduced to [-pi, pi])."""
    k = events(setup)
    out = np.zeros((n, k, 2))
    if k == 0:
        return out
    out[:, :, 0] = np.asarray(values[DRAWS[0]], float).reshape(n, k)
    phase = np.asarray(values[DRAWS[1]], float).reshape(n, k)
    out[:, :, 1] = [[math.remainder(v, 2.0 * math.pi) for v in row] for row in phase]
    st[:, S_TUMBLE] = 0.0
    st[:, S_NREDIST] = 0.0
    st[:, S_REDIST:S_REDIST + 2 * k] = out.reshape(n, 2 * k)
    return out
