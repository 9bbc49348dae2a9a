"""Drives: how the rotor spin is set.

* :class:`SpeedProfile` prescribes the rotor angle exactly (infinite drive inertia): a sequence
  of constant-acceleration segments, so psi, psi' and psi'' are exact quadratics, constants and
  piecewise constants.  Ramps, constant-speed dwells, constant-acceleration or deceleration
  dwells (Yoshida ch. 3-4) and the hold at operating speed are all such segments.
* :class:`MotorDrive` makes the rotor spin a degree of freedom (Spannan eq. 4.16) driven by a
  motor torque ``T = clip(T_cmd + g (w_target(t) - w), -T_max(w), T_max(w))``.  With ``g = 0``
  it is a torque command; with ``T_cmd = 0`` it is the limited-power drive of Spannan (note
  section 1.5), ``M_0 = beta_0 (w_target - w)``.  The bearing drag of the scene acts in
  addition.  The available torque ``T_max(w)`` is the torque limit, optionally falling
  linearly to 0 at a no-load speed (the torque-speed characteristic of a DC or a
  voltage-limited motor) and capped by a power limit ``|T w| <= P``.

**Limited power and the Sommerfeld effect.**  A drive whose available torque falls with speed
can be captured at the critical speed: near resonance the whirl of the imbalance dissipates
power through the support damping (and the lagging balls through their drag), which shows up
as a load torque on the rotor; where that load exceeds what the motor has left, the run-up
stalls at the critical speed (the speed hunts around it) although the motor's no-load speed
lies far above it.
A stronger drive, or a faster passage, jumps through.  :meth:`MotorDrive.linear_characteristic`
builds the classic open-loop characteristic ``T = T_stall (1 - w / w_no_load)``;
``no_load_speed`` and ``power_limit`` put the same kind of envelope on a speed-controlled
drive.  This matters whenever the drive's power reserve at the critical speed is comparable to
the resonance loss (small motors, heavy imbalance, light support damping); a prescribed speed
profile hides it.

Both produce a segment table for the compiled kernels (one row per segment, see
:mod:`abb_gym.physics.model`), with segment starts at every breakpoint so that fixed-step
integrators never step across a jump of the acceleration.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any, Iterable, Mapping

import numpy as np

from ..configuration import is_bool
from . import drive_law as dl
from .scene import ANGLE_LIMIT, Scene

__all__ = ["SpeedProfile", "MotorDrive"]


def _finite(name: str, value: Any, *, positive: bool = False, nonneg: bool = False,
            unit: str = "", limit: float | None = None) -> float:
    """``value`` as a finite float, or a ValueError naming ``name``, the allowed range and the
    unit.  Only real numbers are accepted: None, text, booleans and sequences are refused
    (``float("40")`` or ``float(True)`` would silently make a number of them)."""
    if limit is not None:
        allowed = f"in [0, {limit:g}]" if nonneg else f"in [-{limit:g}, {limit:g}]"
    elif positive:
        allowed = "> 0"
    elif nonneg:
        allowed = ">= 0"
    else:
        allowed = "finite"
    where = f"{name} must be {allowed}" + (f" [{unit}]" if unit else "")
    if (value is None or is_bool(value) or isinstance(value, (str, bytes))
            or getattr(value, "ndim", 0) != 0):
        raise ValueError(f"{where} (a real number; got {value!r:.80})")
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{where} (a real number; got {value!r:.80})") from None
    if (not math.isfinite(v) or (positive and v <= 0) or (nonneg and v < 0)
            or (limit is not None and abs(v) > limit)):
        raise ValueError(f"{where} (got {v!r})")
    return v


def _angle(name: str, value: Any) -> float:
    """An initial angle [rad] within the scenes' ``ANGLE_LIMIT`` (beyond it the rounding of the
    angle changes the machine: sin(1e16) is not sin(1e16 mod 2 pi))."""
    return _finite(name, value, unit="rad", limit=ANGLE_LIMIT)


def is_sequence(value: Any) -> bool:
    """True for a list-like value whose entries can be listed: not text, not a mapping, not
    a 0-d array (which claims to be iterable but is not)."""
    return (isinstance(value, Iterable) and not isinstance(value, (str, bytes, Mapping))
            and getattr(value, "ndim", 1) != 0)


def _segments(value: Any) -> tuple[tuple[float, float], ...]:
    """``segments`` as a tuple of (duration [s], acceleration [rad/s^2]) pairs of floats."""
    what = ("segments must be a sequence of (duration [s], acceleration [rad/s^2]) pairs, "
            "e.g. [(2.5, 40.0), (1.0, 0.0)]")
    if not is_sequence(value):
        raise ValueError(f"{what} (got {value!r:.80})")
    segs = []
    items = list(value)
    for k, seg in enumerate(items):
        if not is_sequence(seg):
            raise ValueError(f"segments[{k}] must be a pair (duration [s], acceleration "
                             f"[rad/s^2]) (got {seg!r:.80}); {what}")
        pair = list(seg)
        if len(pair) != 2:
            raise ValueError(f"segments[{k}] must be (duration, acceleration), got {seg!r:.80}")
        forever = (isinstance(pair[0], numbers.Real) and not is_bool(pair[0])
                   and pair[0] == math.inf)
        if forever and k != len(items) - 1:
            raise ValueError(f"segments[{k}] duration is infinite; only the last may be")
        dur = math.inf if forever else _finite(f"segments[{k}] duration", pair[0],
                                               nonneg=True, unit="s")
        segs.append((dur, _finite(f"segments[{k}] acceleration", pair[1], unit="rad/s^2")))
    return tuple(segs)


@dataclass(frozen=True)
class SpeedProfile:
    """Piecewise-constant rotor acceleration.

    ``segments`` is a sequence of ``(duration [s], acceleration [rad/s^2])``; after the last
    segment the speed is held (acceleration 0).  A final duration of ``inf`` keeps that segment
    going.  The rotor starts at ``initial_angle`` [rad] and ``initial_speed`` [rad/s].
    """

    segments: tuple[tuple[float, float], ...]
    initial_speed: float = 0.0
    initial_angle: float = 0.0

    def __post_init__(self) -> None:
        segs = _segments(self.segments)
        object.__setattr__(self, "segments", segs)
        # a speed profile that turns the rotor backwards is almost always a typo
        speed = _finite("initial_speed", self.initial_speed, nonneg=True, unit="rad/s")
        object.__setattr__(self, "initial_speed", speed)
        angle = _angle("initial_angle", self.initial_angle)
        object.__setattr__(self, "initial_angle", angle)
        for k, (dur, acc) in enumerate(segs):
            end = speed + acc * dur if math.isfinite(dur) else (speed if acc == 0 else
                                                                 math.copysign(math.inf, acc))
            if end < -1e-12:
                raise ValueError(f"segments[{k}] drives the rotor speed negative "
                                 f"({speed:g} rad/s with {acc:g} rad/s^2 for {dur:g} s)")
            if math.isfinite(dur):
                # the exact quadratics of the kernels need finite speeds and angles at every
                # segment start
                angle += speed * dur + 0.5 * acc * dur * dur
                if not (math.isfinite(end) and math.isfinite(angle)):
                    raise ValueError(f"segments[{k}] ({dur:g} s at {acc:g} rad/s^2) takes the "
                                     f"rotor speed or angle beyond floating point; use "
                                     f"shorter durations or smaller accelerations")
            speed = end

    # ------------------------------------------------------------------ constructors
    @classmethod
    def constant(cls, speed: float, angle: float = 0.0) -> "SpeedProfile":
        """Constant speed [rad/s] from t = 0."""
        speed = _finite("speed", speed, nonneg=True, unit="rad/s")
        return cls(segments=(), initial_speed=speed, initial_angle=_angle("angle", angle))

    @classmethod
    def ramp(cls, accel: float, operating_speed: float | None = None) -> "SpeedProfile":
        """Run-up from rest at ``accel`` [rad/s^2], held at ``operating_speed`` [rad/s] if given."""
        accel = _finite("accel", accel, positive=True, unit="rad/s^2")
        if operating_speed is None:
            return cls(segments=((math.inf, accel),))
        op = _finite("operating_speed", operating_speed, positive=True, unit="rad/s")
        return cls(segments=((op / accel, accel),))

    @classmethod
    def dwell(cls, accel: float, dwell_speed: float, dwell_time: float,
              dwell_accel: float = 0.0, operating_speed: float | None = None) -> "SpeedProfile":
        """Yoshida's variable-speed period.

        Ramp from rest at ``accel`` [rad/s^2] to ``dwell_speed`` [rad/s] (reached at
        t_s = dwell_speed/accel), then ``dwell_time`` [s] at ``dwell_accel`` [rad/s^2] (0: a
        constant-speed dwell, > 0: a constant-acceleration dwell, < 0: a deceleration dwell),
        then ``accel`` again up to ``operating_speed`` [rad/s] (held) or for ever if None.
        """
        accel = _finite("accel", accel, positive=True, unit="rad/s^2")
        dwell_speed = _finite("dwell_speed", dwell_speed, nonneg=True, unit="rad/s")
        dwell_time = _finite("dwell_time", dwell_time, nonneg=True, unit="s")
        dwell_accel = _finite("dwell_accel", dwell_accel, unit="rad/s^2")
        after = dwell_speed + dwell_accel * dwell_time
        if after < -1e-12:
            raise ValueError(f"dwell_accel = {dwell_accel:g} rad/s^2 for dwell_time = "
                             f"{dwell_time:g} s drives the rotor speed negative from "
                             f"dwell_speed = {dwell_speed:g} rad/s (to {after:g} rad/s)")
        segs = [(dwell_speed / accel, accel), (dwell_time, dwell_accel)]
        if operating_speed is None:
            segs.append((math.inf, accel))
        else:
            op = _finite("operating_speed", operating_speed, positive=True, unit="rad/s")
            if op < after:
                raise ValueError(f"operating_speed ({op:g} rad/s) must be >= the speed at the "
                                 f"end of the dwell ({after:g} rad/s)")
            segs.append(((op - after) / accel, accel))
        return cls(segments=tuple(segs))

    # ------------------------------------------------------------------ evaluation
    def _table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Start times, start angles, start speeds and accelerations of all segments + hold."""
        t0, th0, w0, acc = [0.0], [self.initial_angle], [self.initial_speed], []
        for dur, a in self.segments:
            acc.append(a)
            if math.isinf(dur):
                break
            th0.append(th0[-1] + w0[-1] * dur + 0.5 * a * dur * dur)
            w0.append(w0[-1] + a * dur)
            t0.append(t0[-1] + dur)
        else:
            acc.append(0.0)
        return np.array(t0), np.array(th0), np.array(w0), np.array(acc)

    @property
    def breakpoints(self) -> np.ndarray:
        """Times [s] where the acceleration may jump (segment starts, t = 0 included)."""
        return self._table()[0]

    def _evaluate(self, t):
        t = np.asarray(t, dtype=float)
        th, w, alpha = dl.prescribed_profile(np.atleast_1d(t).ravel(),
                                             self.segment_table(math.inf)[1])
        if t.ndim == 0:
            return th[0], w[0], alpha[0]
        return th.reshape(t.shape), w.reshape(t.shape), alpha.reshape(t.shape)

    def angle(self, t):
        """Rotor angle psi(t) [rad]."""
        return self._evaluate(t)[0]

    def speed(self, t):
        """Rotor speed psi'(t) [rad/s]."""
        return self._evaluate(t)[1]

    def acceleration(self, t):
        """Rotor acceleration psi''(t) [rad/s^2] (right-continuous at breakpoints)."""
        return self._evaluate(t)[2]

    def max_speed(self, t_end: float) -> float:
        """Largest speed [rad/s] on [0, t_end]."""
        t0 = self.breakpoints
        ts = np.concatenate([t0[t0 <= t_end], [t_end]])
        return float(np.max(np.abs(self.speed(ts))))

    def segment_table(self, t_end: float, scene: Scene | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:
        """(segment start times, drive rows) for the kernels, covering [0, t_end]."""
        t0, th0, w0, acc = self._table()
        keep = t0 < t_end
        keep[0] = True
        rows = np.zeros((int(keep.sum()), dl.N_DRIVE))
        rows[:, dl.D_T0] = t0[keep]
        rows[:, dl.D_TH0] = th0[keep]
        rows[:, dl.D_W0] = w0[keep]
        rows[:, dl.D_ALPHA] = acc[keep]
        rows[:, dl.D_MODE] = dl.MODE_PRESCRIBED
        return rows[:, dl.D_T0].copy(), rows

    def initial_rotor_state(self) -> tuple[float, float]:
        """(angle [rad], speed [rad/s]) at t = 0."""
        return self.initial_angle, self.initial_speed


@dataclass(frozen=True)
class MotorDrive:
    """Rotor spin as a degree of freedom, driven by a torque-limited motor.

    ``T = clip(torque + speed_gain * (w_target(t) - w), -T_max(w), T_max(w))`` [N m]
    with ``w_target`` a constant [rad/s] or a :class:`SpeedProfile`.  ``torque_limit`` None
    takes the scene's ``drive_torque_limit``.  The available torque is
    ``T_max(w) = min(torque_limit * max(0, 1 - |w| / no_load_speed), power_limit / |w|)``,
    each factor only when given (``no_load_speed`` [rad/s], ``power_limit`` [W]).
    """

    torque: float = 0.0
    speed_gain: float = 0.0
    target: float | SpeedProfile = 0.0
    torque_limit: float | None = None
    initial_speed: float = 0.0
    initial_angle: float = 0.0
    no_load_speed: float | None = None
    power_limit: float | None = None

    def __post_init__(self) -> None:
        # every field is stored as the float it was checked as (an int or numpy scalar
        # passed in must not reach the kernels' tables as something else)
        def put(name: str, value: float | None) -> None:
            object.__setattr__(self, name, value)

        if self.no_load_speed is not None:
            put("no_load_speed", _finite("no_load_speed", self.no_load_speed, positive=True,
                                         unit="rad/s"))
        if self.power_limit is not None:
            put("power_limit", _finite("power_limit", self.power_limit, positive=True,
                                       unit="W"))
        put("torque", _finite("torque", self.torque, unit="N m"))
        put("speed_gain", _finite("speed_gain", self.speed_gain, nonneg=True, unit="N m s"))
        if not isinstance(self.target, SpeedProfile):
            # the rotor spins in the positive sense throughout (ball angles lag from the
            # imbalance); a speed profile enforces the same
            put("target", _finite("target", self.target, nonneg=True, unit="rad/s"))
        if self.torque_limit is not None:
            put("torque_limit", _finite("torque_limit", self.torque_limit, positive=True,
                                        unit="N m"))
        put("initial_speed", _finite("initial_speed", self.initial_speed, nonneg=True,
                                     unit="rad/s"))
        put("initial_angle", _angle("initial_angle", self.initial_angle))

    @classmethod
    def constant_torque(cls, torque: float, torque_limit: float | None = None) -> "MotorDrive":
        """A constant torque command [N m] (clipped to the limit)."""
        return cls(torque=torque, torque_limit=torque_limit)

    @classmethod
    def limited_power(cls, gain: float, target: float | SpeedProfile,
                      torque_limit: float | None = None) -> "MotorDrive":
        """Spannan's drive M_0 = beta_0 (w_target - w) with beta_0 = ``gain`` [N m s]."""
        return cls(speed_gain=_finite("gain", gain, positive=True, unit="N m s"),
                   target=target, torque_limit=torque_limit)

    @classmethod
    def linear_characteristic(cls, stall_torque: float, no_load_speed: float,
                              power_limit: float | None = None, initial_speed: float = 0.0
                              ) -> "MotorDrive":
        """Open-loop motor ``T = stall_torque (1 - w / no_load_speed)`` [N m] (a DC motor on a
        fixed voltage), clipped to +-stall_torque: it brakes above the no-load speed, as such
        a motor does; optionally also capped at ``power_limit`` [W].

        Written as the speed law ``g (w_target - w)`` with ``g = stall / no_load`` and
        ``w_target = no_load_speed``, so that the step rule of :func:`simulate` sees the speed
        the rotor can reach."""
        stall = _finite("stall_torque", stall_torque, positive=True, unit="N m")
        w0 = _finite("no_load_speed", no_load_speed, positive=True, unit="rad/s")
        return cls(speed_gain=stall / w0, target=w0, torque_limit=stall,
                   power_limit=power_limit, initial_speed=initial_speed)

    def limit(self, scene: Scene) -> float:
        return scene.drive_torque_limit if self.torque_limit is None else self.torque_limit

    def segment_table(self, t_end: float, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
        if isinstance(self.target, SpeedProfile):
            t0, _, w0, acc = self.target._table()
            keep = t0 < t_end
            keep[0] = True
            t0, w0, acc = t0[keep], w0[keep], acc[keep]
        else:
            t0, w0, acc = np.zeros(1), np.array([float(self.target)]), np.zeros(1)
        rows = np.zeros((len(t0), dl.N_DRIVE))
        rows[:, dl.D_T0] = t0
        rows[:, dl.D_MODE] = dl.MODE_MOTOR
        rows[:, dl.D_TORQUE] = self.torque
        rows[:, dl.D_GAIN] = self.speed_gain
        rows[:, dl.D_TW0] = w0
        rows[:, dl.D_TALPHA] = acc
        rows[:, dl.D_TLIM] = self.limit(scene)
        rows[:, dl.D_WNL] = self.no_load_speed or 0.0
        rows[:, dl.D_PLIM] = self.power_limit or 0.0
        return t0.copy(), rows

    def torque_at(self, t, speed, scene: Scene):
        """Motor torque [N m] at times ``t`` and rotor speeds ``speed`` (the kernel's law)."""
        t, speed = np.broadcast_arrays(np.asarray(t, dtype=float), np.asarray(speed, dtype=float))
        rows = self.segment_table(math.inf, scene)[1]
        out = dl.motor_torques(t.ravel().copy(), speed.ravel().copy(), rows)
        return out[0] if t.ndim == 0 else out.reshape(t.shape)

    def initial_rotor_state(self) -> tuple[float, float]:
        return self.initial_angle, self.initial_speed
