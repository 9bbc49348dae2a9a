"""Open-loop baseline families: hand-designed run-up profiles as :class:`SpeedProfile`.

Each family is a frozen dataclass whose parameters are declared once (unit, bounds, search
box of the tuner, meaning; :mod:`abb_gym.configuration`); ``family.profile(scene)`` builds the
profile, which ends at the scene's operating speed and holds it.  ``None`` parameters take the
family default (Yoshida's scaling rule, sec. 4.5: the dwell starts at the critical speed, its
length scales with the rotor's time scale, 0.5 s at 100 rad/s, so ``dwell_time = 50 /
omega_c``; the run-up acceleration is half the scene's ``drive_max_acceleration``, Yoshida's 40
of 80 rad/s^2).

=====================  =====================================================================
family                 profile
=====================  =====================================================================
``ramp``               linear run-up at ``accel`` to the operating speed, no dwell
``speed_dwell``        Yoshida sec. 4.2: a constant-speed dwell of ``dwell_time`` at
                       ``dwell_speed``
``accel_dwell``        Yoshida sec. 4.3: a dwell of ``dwell_time`` at a lower acceleration
                       ``dwell_accel`` (> 0) starting at ``dwell_speed``
``decel_dwell``        Yoshida Fig. 4.18: the same with a deceleration (``dwell_accel`` < 0),
                       cut at standstill
``speed_reduction``    temporary speed reduction (Machines 2020, 8(4), 74): run up to the
                       operating speed, hold ``hold_time``, decelerate to a plateau
                       ``plateau_speed`` above the critical speed, hold it ``plateau_time``,
                       and return to the operating speed
``knots``              the strongest open-loop family: a speed profile through K free knots
                       (speed ``knot_speeds[k]``, reached after ``knot_times[k]`` s more than the
                       drive's fastest slope needs, so holds and slow creeps are possible),
                       then the final approach into the band at ``final_accel``
=====================  =====================================================================

Search boxes are in units of the scene: ``wc`` the lower critical speed, ``td`` Yoshida's dwell
time ``50 / omega_c``, ``amax`` the drive's largest acceleration, ``wop`` the operating speed,
``tref`` the fastest run-up ``w_op / amax``.  Speeds in rad/s, times in s, accelerations in
rad/s^2.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, ClassVar

from ..configuration import ConfigError, declare, specs
from ..configuration import build as build_config
from ..physics.drive_limits import nominal_acceleration
from ..physics.drives import SpeedProfile
from ..physics.scene import Scene

__all__ = ["FAMILIES", "Family", "build", "duration", "default_accel",
           "default_dwell_time", "scales", "Ramp", "SpeedDwell", "AccelDwell", "DecelDwell",
           "SpeedReduction", "Knots"]


def default_accel(scene: Scene) -> float:
    """Half the drive's largest acceleration [rad/s^2] (Yoshida's 40 of 80 rad/s^2): the
    scene's nominal run-up, :func:`abb_gym.physics.drive_limits.nominal_acceleration`."""
    return nominal_acceleration(scene)


def default_dwell_time(scene: Scene) -> float:
    """Yoshida's 0.5 s dwell at omega_c = 100 rad/s, scaled with 1/omega_c [s]."""
    return 50.0 / scene.critical_speed


def scales(scene: Scene) -> dict[str, float]:
    """The units of the search boxes (module docstring)."""
    wop = scene.drive_operating_speed
    return {"wc": scene.critical_speed, "td": default_dwell_time(scene),
            "amax": scene.drive_max_acceleration, "wop": wop,
            "tref": wop / scene.drive_max_acceleration, "1": 1.0}


def _accel(doc: str = "run-up acceleration (default half the drive's largest)"):
    return declare(None, unit="rad/s^2", gt=0.0, le=1e6, nullable=True, doc=doc,
                   search=(0.2, 1.0, "amax"))


class Family:
    """Base of the baseline families (see the module docstring)."""

    name: ClassVar[str] = ""
    closed_loop: ClassVar[bool] = False

    def to_params(self) -> dict[str, Any]:
        """The parameters that are set (YAML-safe)."""
        out = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if v is not None:
                out[f.name] = list(v) if isinstance(v, tuple) else v
        return out

    def _accel(self, scene: Scene) -> float:
        a = getattr(self, "accel", None)
        a = default_accel(scene) if a is None else a
        if a > scene.drive_max_acceleration * (1 + 1e-9):
            raise ConfigError(f"baseline {self.name}: 'accel' must be <= drive_max_acceleration "
                              f"= {scene.drive_max_acceleration:g} rad/s^2 (got {a:g})")
        return a

    def profile(self, scene: Scene) -> SpeedProfile:
        raise NotImplementedError


def _speed_at_most_operating(name: str, value: float, scene: Scene) -> None:
    if not 0 <= value <= scene.drive_operating_speed:
        raise ConfigError(f"field {name!r} must be in [0, drive_operating_speed = "
                          f"{scene.drive_operating_speed:g}] rad/s (got {value:g})")


@dataclass(frozen=True)
class Ramp(Family):
    name: ClassVar[str] = "ramp"
    accel: float | None = _accel()

    def profile(self, scene):
        return SpeedProfile.ramp(self._accel(scene), scene.drive_operating_speed)


@dataclass(frozen=True)
class AccelDwell(Family):
    name: ClassVar[str] = "accel_dwell"
    dwell_speed: float | None = declare(None, unit="rad/s", ge=0.0, le=1e5, nullable=True,
                                        doc="speed at the dwell start (default the critical "
                                            "speed)", search=(0.8, 1.4, "wc"))
    dwell_time: float | None = declare(None, unit="s", ge=0.0, le=1e4, nullable=True,
                                       doc="dwell length (default 50 / omega_c)",
                                       search=(0.2, 2.5, "td"))
    dwell_accel: float | None = declare(None, unit="rad/s^2", ge=-1e6, le=1e6, nullable=True,
                                        doc="acceleration during the dwell (default half the "
                                            "run-up rate)", search=(0.02, 0.5, "amax"))
    accel: float | None = _accel()

    def _default_dwell_accel(self, accel: float) -> float:
        return 0.5 * accel  # Yoshida: 20 of 40

    def profile(self, scene):
        dwell_speed = scene.critical_speed if self.dwell_speed is None else self.dwell_speed
        _speed_at_most_operating("dwell_speed", dwell_speed, scene)
        dwell_time = default_dwell_time(scene) if self.dwell_time is None else self.dwell_time
        accel = self._accel(scene)
        dwell_accel = (self._default_dwell_accel(accel) if self.dwell_accel is None
                       else self.dwell_accel)
        end = dwell_speed + dwell_accel * dwell_time
        if end > scene.drive_operating_speed:  # the dwell would overshoot: cut it at the top
            dwell_time = (scene.drive_operating_speed - dwell_speed) / dwell_accel
        elif end < 0:  # a deceleration would reverse the rotor: cut it at standstill
            dwell_time = dwell_speed / -dwell_accel
        return SpeedProfile.dwell(accel, dwell_speed, dwell_time, dwell_accel,
                                  scene.drive_operating_speed)


@dataclass(frozen=True)
class SpeedDwell(AccelDwell):
    name: ClassVar[str] = "speed_dwell"
    dwell_accel: float | None = declare(None, unit="rad/s^2", ge=0.0, le=0.0, nullable=True,
                                        doc="0: the dwell holds its speed")

    def _default_dwell_accel(self, accel):
        return 0.0


@dataclass(frozen=True)
class DecelDwell(AccelDwell):
    name: ClassVar[str] = "decel_dwell"
    dwell_speed: float | None = declare(None, unit="rad/s", ge=0.0, le=1e5, nullable=True,
                                        doc="speed at the dwell start (default the critical "
                                            "speed)", search=(0.9, 1.6, "wc"))
    dwell_accel: float | None = declare(None, unit="rad/s^2", ge=-1e6, lt=0.0, nullable=True,
                                        doc="deceleration during the dwell (default minus half "
                                            "the run-up rate)", search=(-0.5, -0.02, "amax"))
    dwell_time: float | None = declare(None, unit="s", ge=0.0, le=1e4, nullable=True,
                                       doc="dwell length (default 50 / omega_c)",
                                       search=(0.1, 1.5, "td"))

    def _default_dwell_accel(self, accel):
        return -0.5 * accel  # Yoshida Fig. 4.18: -20 of 40


@dataclass(frozen=True)
class SpeedReduction(Family):
    name: ClassVar[str] = "speed_reduction"
    plateau_speed: float | None = declare(None, unit="rad/s", ge=0.0, le=1e5, nullable=True,
                                          doc="speed of the plateau (default 1.3 omega_c)",
                                          search=(1.05, 2.0, "wc"))
    plateau_time: float | None = declare(None, unit="s", ge=0.0, le=1e4, nullable=True,
                                         doc="time on the plateau (default 50 / omega_c)",
                                         search=(0.2, 4.0, "td"))
    hold_time: float | None = declare(None, unit="s", ge=0.0, le=1e4, nullable=True,
                                      doc="hold at the operating speed before the reduction "
                                          "(default 50 / omega_c)", search=(0.05, 2.0, "td"))
    accel: float | None = _accel()

    def profile(self, scene):
        op = scene.drive_operating_speed
        plateau = 1.3 * scene.critical_speed if self.plateau_speed is None else self.plateau_speed
        plateau = min(plateau, op)
        plateau_time = default_dwell_time(scene) if self.plateau_time is None else self.plateau_time
        hold = default_dwell_time(scene) if self.hold_time is None else self.hold_time
        accel = self._accel(scene)
        drop = (op - plateau) / accel
        return SpeedProfile(segments=((op / accel, accel), (hold, 0.0), (drop, -accel),
                                      (plateau_time, 0.0), (drop, accel)))


KNOTS = 3


def _tuple(n: int, lo: float, hi: float, scale: str, unit: str, doc: str):
    return declare(None, kind="any", unit=unit, nullable=True, doc=doc,
                   search=tuple((lo, hi, scale) for _ in range(n)))


@dataclass(frozen=True)
class Knots(Family):
    name: ClassVar[str] = "knots"
    knot_speeds: tuple[float, ...] | None = _tuple(
        KNOTS, 0.0, 1.0, "wop", "rad/s", "speed of each knot, in [0, w_op] (default: evenly "
                                         "spaced below w_op)")
    knot_times: tuple[float, ...] | None = _tuple(
        KNOTS, 0.0, 1.0, "tref", "s", "time of each segment beyond the drive's fastest slope "
                                      "(default 0: a full-acceleration ramp)")
    final_accel: float | None = _accel("acceleration of the final approach into the band")

    def __post_init__(self):
        for name in ("knot_speeds", "knot_times"):
            v = getattr(self, name)
            if v is None:
                continue
            if isinstance(v, (int, float)) or not all(
                    isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                    and x >= 0 for x in v):
                raise ConfigError(f"baseline knots: field {name!r} must be a list of finite "
                                  f"numbers >= 0 (got {v!r})")
            object.__setattr__(self, name, tuple(float(x) for x in v))
        if (self.knot_speeds is not None and self.knot_times is not None
                and len(self.knot_speeds) != len(self.knot_times)):
            raise ConfigError(f"baseline knots: 'knot_speeds' and 'knot_times' must have the "
                              f"same length (got {len(self.knot_speeds)} and "
                              f"{len(self.knot_times)})")

    def profile(self, scene):
        op = scene.drive_operating_speed
        amax = scene.drive_max_acceleration
        k = len(self.knot_speeds or self.knot_times or ()) or KNOTS
        speeds = self.knot_speeds or tuple(op * (i + 1) / (k + 1) for i in range(k))
        extra = self.knot_times or (0.0,) * k
        for v in speeds:
            _speed_at_most_operating("knot_speeds", v, scene)
        segs = []
        w = 0.0
        for target, more in zip(speeds, extra):
            dw = target - w
            dur = abs(dw) / amax + more
            if dur > 0:
                segs.append((dur, dw / dur))
            w = target
        final = self.final_accel if self.final_accel is not None else default_accel(scene)
        if final > amax * (1 + 1e-9):
            raise ConfigError(f"baseline knots: 'final_accel' must be <= drive_max_acceleration "
                              f"= {amax:g} rad/s^2 (got {final:g})")
        if op > w:
            segs.append(((op - w) / final, final))
        return SpeedProfile(segments=tuple(segs))


FAMILIES: dict[str, type[Family]] = {
    f.name: f for f in (Ramp, SpeedDwell, AccelDwell, DecelDwell, SpeedReduction, Knots)}


def build(name: str, scene: Scene, **params: Any) -> SpeedProfile:
    """The profile of open-loop family ``name`` for ``scene`` (unknown names raise)."""
    if name not in FAMILIES:
        raise ValueError(f"unknown baseline {name!r} (open-loop families: "
                         f"{', '.join(FAMILIES)})")
    return build_config(FAMILIES[name], params, f"baseline {name}").profile(scene)


def duration(profile: SpeedProfile) -> float:
    """Time [s] until the last acceleration segment ends (the hold starts)."""
    return float(profile.breakpoints[-1])


def search_space(cls: type[Family]) -> list[tuple[str, int | None, float, float, str]]:
    """(parameter, index in a tuple parameter or None, low, high, scale) of every searched
    coordinate of a family."""
    out = []
    for name, spec in specs(cls).items():
        if spec.search is None:
            continue
        if isinstance(spec.search[0], tuple):
            out += [(name, i, lo, hi, sc) for i, (lo, hi, sc) in enumerate(spec.search)]
        else:
            lo, hi, sc = spec.search
            out.append((name, None, lo, hi, sc))
    return out
