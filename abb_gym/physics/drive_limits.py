"""The scene's drive limits and the drive a run takes by default.

A scene states what its drive may do: ``drive.operating_speed`` [rad/s] (the speed the
machine runs at), ``drive.max_acceleration`` [rad/s^2] and ``drive.torque_limit`` [N m].
:func:`~abb_gym.physics.simulate.simulate` without a drive runs the scene's nominal run-up
(:func:`nominal_drive`: a ramp at half the largest acceleration, held at the operating
speed), and checks any drive it is given against the limits (:func:`drive_excess` before
the run, :func:`speed_excess` on the rotor speed it reached).

What happens to a drive beyond the limits is the caller's choice, ``drive_limits``:

* ``"warn"`` (the API's default): a :class:`DriveLimitWarning` naming the limit, then the
  run.  The simulation API is also the analyses' tool for spinning a model at any speed
  (constant-speed runs at a speed ratio, thesis reproductions beyond a rating, sweeps), and a
  scene's limits are the machine's rating, not its physics: refusing would break deliberate
  studies, while staying silent let a 150 rad/s machine be ramped to 320 rad/s without a
  word.  A warning is heard and can be filtered (``warnings.simplefilter("ignore",
  DriveLimitWarning)``) without editing code.
* ``"raise"``: a ValueError before the run (what ``abb-gym simulate`` does unless
  ``--allow-beyond-drive-limits``: a typed ``--accel 400`` must not cost a run).
* ``"ignore"``: neither (callers that spin beyond the rating on purpose).
"""
from __future__ import annotations

import math
import warnings
from typing import Any

__all__ = ["DriveLimitWarning", "LIMIT_MODES", "nominal_acceleration", "nominal_drive",
           "default_t_end", "drive_excess", "speed_excess", "enforce"]

LIMIT_MODES = ("warn", "raise", "ignore")
#: a limit is exceeded by more than rounding: 1e-9 relative
TOLERANCE = 1e-9


class DriveLimitWarning(UserWarning):
    """A drive goes beyond the scene's drive limits (the message names the limit)."""


def nominal_acceleration(scene) -> float:
    """The nominal run-up acceleration [rad/s^2]: half the drive's largest (Yoshida's 40 of
    80 rad/s^2 on ``yoshida_odd``), leaving the other half as the margin a speed loop needs."""
    return 0.5 * scene.drive_max_acceleration


def nominal_drive(scene):
    """The scene's nominal run-up: a ramp from rest at :func:`nominal_acceleration`, held at
    ``drive.operating_speed``."""
    from .drives import SpeedProfile
    return SpeedProfile.ramp(nominal_acceleration(scene), scene.drive_operating_speed)


def default_t_end(drive) -> float:
    """The run a drive needs [s]: until its speed profile holds (its last finite segment
    ends) plus the settling window of the environments (:data:`~abb_gym.physics.runup.
    SETTLE_TIME`).  A motor, or a profile that never holds, needs an explicit ``t_end``."""
    from .drives import SpeedProfile
    from .runup import SETTLE_TIME
    if not isinstance(drive, SpeedProfile):
        raise ValueError("t_end is needed for a MotorDrive (its speed has no end known "
                         "before the run) [s]")
    if any(math.isinf(dur) for dur, _ in drive.segments):
        raise ValueError("t_end is needed for a speed profile that never holds a speed (its "
                         "last segment accelerates for ever) [s]")
    return float(sum(dur for dur, _ in drive.segments)) + SETTLE_TIME


def _beyond(value: float, limit: float) -> bool:
    return value > limit * (1.0 + TOLERANCE)


def drive_excess(scene, drive, t_end: float) -> list[str]:
    """What of ``drive`` on [0, ``t_end``] goes beyond ``scene``'s drive limits, one phrase
    per limit (empty: nothing).  A speed profile's speed and acceleration are known exactly;
    a motor's torque command, torque limit and target speed (its speed itself only after the
    run: :func:`speed_excess`)."""
    from .drives import MotorDrive, SpeedProfile
    out = []
    op, amax, tmax = (scene.drive_operating_speed, scene.drive_max_acceleration,
                      scene.drive_torque_limit)
    speed_limit = f"the scene's drive.operating_speed = {op:g} rad/s"
    if isinstance(drive, SpeedProfile):
        speed = drive.max_speed(t_end)
        if _beyond(speed, op):
            out.append(f"the speed reaches {speed:g} rad/s, beyond {speed_limit}")
        starts = drive.breakpoints
        accel = max((abs(a) for (_, a), t0 in zip(drive.segments, starts) if t0 < t_end),
                    default=0.0)
        if _beyond(accel, amax):
            out.append(f"the acceleration {accel:g} rad/s^2 is beyond the scene's "
                       f"drive.max_acceleration = {amax:g} rad/s^2")
    elif isinstance(drive, MotorDrive):
        limit = drive.limit(scene)
        if _beyond(limit, tmax):
            out.append(f"the torque limit {limit:g} N m is beyond the scene's "
                       f"drive.torque_limit = {tmax:g} N m")
        if _beyond(abs(drive.torque), limit):
            out.append(f"the torque command {drive.torque:g} N m is beyond the torque limit "
                       f"{limit:g} N m (it would be clipped to it)")
        if isinstance(drive.target, SpeedProfile):
            out.extend(f"the target's {text}" for text in drive_excess(scene, drive.target,
                                                                        t_end))
        elif _beyond(drive.target, op) and drive.speed_gain > 0:
            out.append(f"the target speed {drive.target:g} rad/s is beyond {speed_limit}")
    return out


def speed_excess(scene, t: Any, rotor_speed: Any) -> str | None:
    """The phrase for a run whose rotor speed [rad/s] went beyond ``drive.operating_speed``
    (at times ``t`` [s]), or None."""
    import numpy as np
    w = np.asarray(rotor_speed, float)
    if w.size == 0:
        return None
    k = int(np.argmax(w))
    op = scene.drive_operating_speed
    if not _beyond(float(w[k]), op):
        return None
    return (f"the rotor speed reached {w[k]:g} rad/s (at t = {float(np.asarray(t)[k]):.4g} s), "
            f"beyond the scene's drive.operating_speed = {op:g} rad/s")


def check_mode(drive_limits: Any) -> str:
    if not isinstance(drive_limits, str) or drive_limits not in LIMIT_MODES:
        raise ValueError(f"drive_limits must be one of {LIMIT_MODES} (got {drive_limits!r:.80})")
    return drive_limits


def enforce(scene, excess: list[str], drive_limits: str, stacklevel: int = 3) -> None:
    """Warn about or refuse ``excess`` (phrases of :func:`drive_excess`) as ``drive_limits``
    says (module docstring)."""
    if not excess or drive_limits == "ignore":
        return
    text = (f"scene {scene.name!r}: the drive goes beyond the scene's drive limits: "
            f"{'; '.join(excess)}")
    if drive_limits == "raise":
        raise ValueError(text)
    warnings.warn(f"{text} (drive_limits='ignore' runs it without this warning)",
                  DriveLimitWarning, stacklevel=stacklevel)
