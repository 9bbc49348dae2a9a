"""Hand-designed run-up profiles from the literature, as :class:`SpeedProfile` builders.

Families (each a function ``family(scene, **params) -> SpeedProfile``; every profile ends at
the scene's operating speed and holds it):

=====================  =====================================================================
family                 profile
=====================  =====================================================================
``ramp``               linear run-up at ``accel`` to the operating speed, no dwell
``speed_dwell``        Yoshida sec. 4.2: a constant-speed dwell of ``dwell_time`` at
                       ``dwell_speed``
``accel_dwell``        Yoshida sec. 4.3: a dwell of ``dwell_time`` at a lower acceleration
                       ``dwell_accel`` (> 0, default half the run-up rate) starting at
                       ``dwell_speed``
``decel_dwell``        Yoshida Fig. 4.18: the same with a deceleration (``dwell_accel`` < 0,
                       default minus half the run-up rate), cut at standstill
``speed_reduction``    temporary speed reduction (Machines 2020, 8(4), 74): run up to the
                       operating speed, hold ``settle_time``, decelerate at ``accel`` to a
                       plateau ``plateau_speed`` above the critical speed, hold it
                       ``plateau_time``, and return to the operating speed
=====================  =====================================================================

Speeds in rad/s, times in s, accelerations in rad/s^2.  Defaults follow Yoshida's scaling rule
(sec. 4.5): the dwell starts at the critical speed and its length scales with the rotor's time
scale, 0.5 s at 100 rad/s, so ``dwell_time = 50 / omega_c``; the run-up acceleration defaults
to half the scene's ``drive_max_acceleration`` (Yoshida's 40 of 80 rad/s^2).  The plateau of the
speed reduction defaults to 1.3 omega_c, held 50 / omega_c after a hold of the same length.
For other parameter changes the thesis re-tunes the dwell by simulation: that is what
:mod:`abb_gym.baselines.tuner` does.
"""
from __future__ import annotations

from typing import Any, Callable

from ..physics.drives import SpeedProfile
from ..physics.scene import Scene


def default_accel(scene: Scene) -> float:
    return 0.5 * scene.drive_max_acceleration


def default_dwell_time(scene: Scene) -> float:
    """Yoshida's 0.5 s dwell at omega_c = 100 rad/s, scaled with 1/omega_c [s]."""
    return 50.0 / scene.critical_speed


def _check_speed(name: str, value: float, scene: Scene) -> None:
    if not 0 <= value <= scene.drive_operating_speed:
        raise ValueError(f"{name} must be in [0, drive_operating_speed = "
                         f"{scene.drive_operating_speed:g}] rad/s (got {value:g})")


def ramp(scene: Scene, accel: float | None = None) -> SpeedProfile:
    return SpeedProfile.ramp(accel or default_accel(scene), scene.drive_operating_speed)


def speed_dwell(scene: Scene, dwell_speed: float | None = None, dwell_time: float | None = None,
                accel: float | None = None) -> SpeedProfile:
    return accel_dwell(scene, dwell_speed, dwell_time, 0.0, accel)


def accel_dwell(scene: Scene, dwell_speed: float | None = None, dwell_time: float | None = None,
                dwell_accel: float | None = None, accel: float | None = None) -> SpeedProfile:
    dwell_speed = scene.critical_speed if dwell_speed is None else dwell_speed
    _check_speed("dwell_speed", dwell_speed, scene)
    dwell_time = default_dwell_time(scene) if dwell_time is None else dwell_time
    accel = accel or default_accel(scene)
    dwell_accel = 0.5 * accel if dwell_accel is None else dwell_accel  # Yoshida: 20 of 40
    end = dwell_speed + dwell_accel * dwell_time
    if end > scene.drive_operating_speed:  # the dwell would overshoot: cut it at the top speed
        dwell_time = (scene.drive_operating_speed - dwell_speed) / dwell_accel
    elif end < 0:  # a deceleration would reverse the rotor: cut it at standstill
        dwell_time = dwell_speed / -dwell_accel
    return SpeedProfile.dwell(accel, dwell_speed, dwell_time, dwell_accel,
                              scene.drive_operating_speed)


def decel_dwell(scene: Scene, dwell_speed: float | None = None, dwell_time: float | None = None,
                dwell_accel: float | None = None, accel: float | None = None) -> SpeedProfile:
    if dwell_accel is None:
        dwell_accel = -0.5 * (accel or default_accel(scene))  # Yoshida Fig. 4.18: -20 of 40
    if dwell_accel >= 0:
        raise ValueError(f"dwell_accel of a deceleration dwell must be < 0 [rad/s^2] "
                         f"(got {dwell_accel:g})")
    return accel_dwell(scene, dwell_speed, dwell_time, dwell_accel, accel)


def speed_reduction(scene: Scene, plateau_speed: float | None = None,
                    plateau_time: float | None = None, settle_time: float | None = None,
                    accel: float | None = None) -> SpeedProfile:
    op = scene.drive_operating_speed
    plateau_speed = 1.3 * scene.critical_speed if plateau_speed is None else plateau_speed
    _check_speed("plateau_speed", plateau_speed, scene)
    plateau_time = default_dwell_time(scene) if plateau_time is None else plateau_time
    settle_time = default_dwell_time(scene) if settle_time is None else settle_time
    accel = accel or default_accel(scene)
    for name, v in (("plateau_time", plateau_time), ("settle_time", settle_time),
                    ("accel", accel)):
        if not v >= 0:
            raise ValueError(f"{name} must be >= 0 (got {v})")
    drop = (op - plateau_speed) / accel
    return SpeedProfile(segments=((op / accel, accel), (settle_time, 0.0), (drop, -accel),
                                  (plateau_time, 0.0), (drop, accel)))


FAMILIES: dict[str, Callable[..., SpeedProfile]] = {
    "ramp": ramp,
    "speed_dwell": speed_dwell,
    "accel_dwell": accel_dwell,
    "decel_dwell": decel_dwell,
    "speed_reduction": speed_reduction,
}


def build(name: str, scene: Scene, **params: Any) -> SpeedProfile:
    """The profile of baseline family ``name`` for ``scene`` (unknown names raise)."""
    if name not in FAMILIES:
        raise ValueError(f"unknown baseline {name!r}; available: {', '.join(FAMILIES)}")
    return FAMILIES[name](scene, **params)


def duration(profile: SpeedProfile) -> float:
    """Time [s] until the last acceleration segment ends (the hold starts)."""
    return float(profile.breakpoints[-1])
