"""Closed-loop baselines, as engineers build them: controllers that watch the machine.

Each family decides a speed reference from what the environment observes - the rotor speed
(``obs[0] * w_op``) and the filtered vibration amplitude (``obs[3]``, in units of the
observation scale ``A_v``, the resonance amplitude of the machine with its balancer off) -
and nothing else; the baseline policy turns the reference into the environment's action
(:mod:`abb_gym.baselines.baseline_policy`).  Parameters are declared once (unit, bounds,
search box; :mod:`abb_gym.baselines.profiles` explains the scales, plus ``aop``: the balancer-
off amplitude at the operating speed over ``A_v``).

=====================  =====================================================================
family                 controller
=====================  =====================================================================
``retry``              unbalance detection and retry, as washing-machine firmware does it:
                       run up at ``accel``; ``check_time`` after reaching the operating
                       speed, if the filtered vibration is above ``threshold``, dip to
                       ``dip_speed``, hold ``dip_time`` and run up again, at most
                       ``max_retries`` times
``resonance_dwell``    resonance tracking for machines whose critical speed is not known in
                       advance: run up at ``accel`` while tracking the vibration's peak; once
                       the amplitude has fallen ``drop`` below a peak of at least
                       ``min_amplitude``, the speed at the peak is the critical speed: go back
                       to ``dwell_ratio`` times it, dwell ``dwell_time``, then run up
``retry_at_spin``      ``retry`` for a washer whose laundry redistributes: the dip stops the
                       drum (``dip_speed`` 0, below the tumble speed) for ``dip_time``, longer
                       than the tumble time, so each retry lands the laundry anew
``redistribute_low``   the firmware's unbalance check at the distribution speed: run up to
                       ``distribution_speed`` (below the critical speed), hold it
                       ``measure_time``; if the filtered vibration is above ``threshold``,
                       stop the drum for ``tumble_hold`` (the laundry redistributes) and
                       measure again, at most ``max_redistributions`` times; then run up
=====================  =====================================================================

The two laundry rules act on ``abb_gym/SpinRedistribute-v0`` (:mod:`abb_gym.envs.spin`): their
defaults read the preset's tumble time; their thresholds are tuned on the ``laundry`` preset
(``abb-gym tune-baselines``).

The check of ``retry`` must come before the environment's settling window ends (an unbroken
``settle_time`` in the band completes the run-up), so ``check_time`` is searched below it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Sequence

import numpy as np

from ..configuration import declare
from .profiles import Family, default_accel

__all__ = ["CLOSED_LOOP", "Retry", "ResonanceDwell", "RetryAtSpin", "RedistributeLow",
           "Controller"]


def _accel():
    return declare(None, unit="rad/s^2", gt=0.0, le=1e6, nullable=True,
                   doc="run-up acceleration (default half the drive's largest)",
                   search=(0.2, 1.0, "amax"))


class Controller:
    """A vectorised controller: one parameter set and one state per sub-environment."""

    def __init__(self, families: Sequence[Family], setup: Any):
        self.n = len(families)
        self.dt = setup.control_interval
        self.wop = setup.operating_speed
        scene = setup.scene
        self.accel = np.array([default_accel(scene) if f.accel is None else f.accel
                               for f in families])
        self.ref = np.zeros(self.n)
        self.phase = np.zeros(self.n, dtype=np.int64)
        self.timer = np.zeros(self.n)

    def reset(self, mask: np.ndarray) -> None:
        self.ref[mask] = 0.0
        self.phase[mask] = 0
        self.timer[mask] = 0.0

    def _toward(self, i: int, target: float) -> bool:
        """Move reference ``i`` toward ``target`` at its acceleration; True once there."""
        step = self.accel[i] * self.dt
        if self.ref[i] < target:
            self.ref[i] = min(self.ref[i] + step, target)
        else:
            self.ref[i] = max(self.ref[i] - step, target)
        return self.ref[i] == target

    def references(self, obs: np.ndarray) -> np.ndarray:
        """The speed reference [rad/s] at the end of the coming control interval."""
        raise NotImplementedError


class _RetryController(Controller):
    RUNUP, CHECK, DIP, DIP_HOLD, HOLD = range(5)

    def __init__(self, families, setup):
        super().__init__(families, setup)
        wc = setup.scene.critical_speed
        settle = setup.config.settle_time
        self.check_time = np.array([0.5 * settle if f.check_time is None else f.check_time
                                    for f in families])
        self.threshold = np.array([np.inf if f.threshold is None else f.threshold
                                   for f in families])
        self.dip_speed = np.array([wc if f.dip_speed is None else f.dip_speed for f in families])
        self.dip_time = np.array([50.0 / wc if f.dip_time is None else f.dip_time
                                  for f in families])
        self.max_retries = np.array([1 if f.max_retries is None else f.max_retries
                                     for f in families])
        self.retries = np.zeros(self.n, dtype=np.int64)

    def reset(self, mask):
        super().reset(mask)
        self.retries[mask] = 0

    def references(self, obs):
        amp = obs[:, 3]
        for i in range(self.n):
            ph = self.phase[i]
            if ph == self.RUNUP:
                if self._toward(i, self.wop):
                    self.phase[i], self.timer[i] = self.CHECK, 0.0
            elif ph == self.CHECK:
                self.timer[i] += self.dt
                if self.timer[i] >= self.check_time[i] - 1e-12:
                    if amp[i] > self.threshold[i] and self.retries[i] < self.max_retries[i]:
                        self.retries[i] += 1
                        self.phase[i] = self.DIP
                    else:
                        self.phase[i] = self.HOLD
            elif ph == self.DIP:
                if self._toward(i, self.dip_speed[i]):
                    self.phase[i], self.timer[i] = self.DIP_HOLD, 0.0
            elif ph == self.DIP_HOLD:
                self.timer[i] += self.dt
                if self.timer[i] >= self.dip_time[i] - 1e-12:
                    self.phase[i] = self.RUNUP
        return self.ref.copy()


class _ResonanceController(Controller):
    RAMP, MOVE, DWELL, FINAL = range(4)

    def __init__(self, families, setup):
        super().__init__(families, setup)
        self.drop = np.array([0.2 if f.drop is None else f.drop for f in families])
        self.min_amp = np.array([0.2 if f.min_amplitude is None else f.min_amplitude
                                 for f in families])
        self.ratio = np.array([1.0 if f.dwell_ratio is None else f.dwell_ratio
                               for f in families])
        wc = setup.scene.critical_speed
        self.dwell_time = np.array([50.0 / wc if f.dwell_time is None else f.dwell_time
                                    for f in families])
        self.peak = np.zeros(self.n)
        self.w_peak = np.zeros(self.n)
        self.target = np.zeros(self.n)

    def reset(self, mask):
        super().reset(mask)
        self.peak[mask] = 0.0
        self.w_peak[mask] = 0.0

    def references(self, obs):
        amp = obs[:, 3]
        w = obs[:, 0] * self.wop
        for i in range(self.n):
            ph = self.phase[i]
            if ph == self.RAMP:
                if amp[i] > self.peak[i]:
                    self.peak[i], self.w_peak[i] = amp[i], w[i]
                if self.peak[i] >= self.min_amp[i] and amp[i] < (1 - self.drop[i]) * self.peak[i]:
                    self.target[i] = min(self.ratio[i] * self.w_peak[i], self.wop)
                    self.phase[i] = self.MOVE
                elif self._toward(i, self.wop):
                    self.phase[i] = self.FINAL  # no resonance seen on the way up
            elif ph == self.MOVE:
                if self._toward(i, self.target[i]):
                    self.phase[i], self.timer[i] = self.DWELL, 0.0
            elif ph == self.DWELL:
                self.timer[i] += self.dt
                if self.timer[i] >= self.dwell_time[i] - 1e-12:
                    self.phase[i] = self.FINAL
            else:
                self._toward(i, self.wop)
        return self.ref.copy()


@dataclass(frozen=True)
class Retry(Family):
    name: ClassVar[str] = "retry"
    closed_loop: ClassVar[bool] = True
    accel: float | None = _accel()
    check_time: float | None = declare(None, unit="s", gt=0.0, le=1e3, nullable=True,
                                       doc="time at the operating speed before the check "
                                           "(default half the settling window)",
                                       search=(0.05, 0.9, "settle"))
    threshold: float | None = declare(None, gt=0.0, le=1e3, nullable=True,
                                      doc="filtered vibration (obs[3], x A_v) above which it "
                                          "retries (default: never)", search=(0.2, 2.0, "aop"))
    dip_speed: float | None = declare(None, unit="rad/s", ge=0.0, le=1e5, nullable=True,
                                      doc="speed of the dip (default the critical speed)",
                                      search=(0.6, 1.5, "wc"))
    dip_time: float | None = declare(None, unit="s", ge=0.0, le=1e4, nullable=True,
                                     doc="hold at the dip speed (default 50 / omega_c)",
                                     search=(0.1, 3.0, "td"))
    max_retries: int | None = declare(None, kind="integer", ge=0, le=10, nullable=True,
                                      doc="most retries (default 1)")

    @staticmethod
    def controller(families, setup) -> Controller:
        return _RetryController(families, setup)


@dataclass(frozen=True)
class ResonanceDwell(Family):
    name: ClassVar[str] = "resonance_dwell"
    closed_loop: ClassVar[bool] = True
    accel: float | None = _accel()
    drop: float | None = declare(None, gt=0.0, lt=1.0, nullable=True,
                                 doc="fall of the amplitude below its peak that marks the "
                                     "resonance passed (default 0.2)", search=(0.05, 0.6, "1"))
    min_amplitude: float | None = declare(None, ge=0.0, le=1e3, nullable=True,
                                          doc="smallest peak (obs[3], x A_v) taken for the "
                                              "resonance (default 0.2)",
                                          search=(0.02, 0.6, "1"))
    dwell_ratio: float | None = declare(None, gt=0.0, le=10.0, nullable=True,
                                        doc="dwell speed / speed at the peak (default 1)",
                                        search=(0.8, 1.3, "1"))
    dwell_time: float | None = declare(None, unit="s", ge=0.0, le=1e4, nullable=True,
                                       doc="dwell length (default 50 / omega_c)",
                                       search=(0.1, 3.0, "td"))

    @staticmethod
    def controller(families, setup) -> Controller:
        return _ResonanceController(families, setup)


def _tumble_time(setup: Any) -> float:
    """The preset's tumble time [s] (the redistribution's; 4 s without one)."""
    return float(setup.config.redistribution.tumble_time)


class _RetryAtSpinController(_RetryController):
    def __init__(self, families, setup):
        super().__init__(families, setup)
        hold = _tumble_time(setup) + 1.0
        self.dip_speed = np.array([0.0 if f.dip_speed is None else f.dip_speed
                                   for f in families])
        self.dip_time = np.array([hold if f.dip_time is None else f.dip_time for f in families])
        self.max_retries = np.array([3 if f.max_retries is None else f.max_retries
                                     for f in families])


class _RedistributeLowController(Controller):
    TO_DIST, MEASURE, STOP, TUMBLE, RUNUP = range(5)

    def __init__(self, families, setup):
        super().__init__(families, setup)
        wc = setup.scene.critical_speed
        self.w_dist = np.array([0.6 * wc if f.distribution_speed is None
                                else min(f.distribution_speed, self.wop) for f in families])
        self.measure_time = np.array([5.0 if f.measure_time is None else f.measure_time
                                      for f in families])
        self.threshold = np.array([np.inf if f.threshold is None else f.threshold
                                   for f in families])
        hold = _tumble_time(setup) + 1.0
        self.tumble_hold = np.array([hold if f.tumble_hold is None else f.tumble_hold
                                     for f in families])
        self.max_redist = np.array([3 if f.max_redistributions is None
                                    else f.max_redistributions for f in families])
        self.done = np.zeros(self.n, dtype=np.int64)

    def reset(self, mask):
        super().reset(mask)
        self.done[mask] = 0

    def references(self, obs):
        amp = obs[:, 3]
        for i in range(self.n):
            ph = self.phase[i]
            if ph == self.TO_DIST:
                if self._toward(i, self.w_dist[i]):
                    self.phase[i], self.timer[i] = self.MEASURE, 0.0
            elif ph == self.MEASURE:
                self.timer[i] += self.dt
                if self.timer[i] >= self.measure_time[i] - 1e-12:
                    if amp[i] > self.threshold[i] and self.done[i] < self.max_redist[i]:
                        self.done[i] += 1
                        self.phase[i] = self.STOP
                    else:
                        self.phase[i] = self.RUNUP
            elif ph == self.STOP:
                if self._toward(i, 0.0):
                    self.phase[i], self.timer[i] = self.TUMBLE, 0.0
            elif ph == self.TUMBLE:
                self.timer[i] += self.dt
                if self.timer[i] >= self.tumble_hold[i] - 1e-12:
                    self.phase[i] = self.TO_DIST
            else:
                self._toward(i, self.wop)
        return self.ref.copy()


@dataclass(frozen=True)
class RetryAtSpin(Retry):
    name: ClassVar[str] = "retry_at_spin"
    threshold: float | None = declare(None, gt=0.0, le=1e3, nullable=True,
                                      doc="filtered vibration at spin (obs[3], x A_v) above "
                                          "which it retries (default: never)",
                                      search=(0.005, 0.3, "aop"))
    dip_speed: float | None = declare(None, unit="rad/s", ge=0.0, le=1e5, nullable=True,
                                      doc="speed of the dip (default 0: the drum stops, below "
                                          "the tumble speed)")
    dip_time: float | None = declare(None, unit="s", ge=0.0, le=1e4, nullable=True,
                                     doc="hold at the dip speed (default the preset's tumble "
                                         "time + 1 s)")
    max_retries: int | None = declare(None, kind="integer", ge=0, le=10, nullable=True,
                                      doc="most retries (default 3)")

    @staticmethod
    def controller(families, setup) -> Controller:
        return _RetryAtSpinController(families, setup)


@dataclass(frozen=True)
class RedistributeLow(Family):
    name: ClassVar[str] = "redistribute_low"
    closed_loop: ClassVar[bool] = True
    accel: float | None = _accel()
    distribution_speed: float | None = declare(
        None, unit="rad/s", gt=0.0, le=1e5, nullable=True,
        doc="speed of the unbalance check, below the critical speed (default 0.6 omega_c)",
        search=(0.3, 0.9, "wc"))
    measure_time: float | None = declare(None, unit="s", gt=0.0, le=1e3, nullable=True,
                                         doc="hold at the distribution speed before the check "
                                             "(default 5 s)", search=(1.0, 10.0, "1"))
    threshold: float | None = declare(None, gt=0.0, le=1e3, nullable=True,
                                      doc="filtered vibration (obs[3], x A_v) above which the "
                                          "laundry is redistributed (default: never)",
                                      search=(0.02, 1.0, "1"))
    tumble_hold: float | None = declare(None, unit="s", ge=0.0, le=1e4, nullable=True,
                                        doc="time at rest that redistributes (default the "
                                            "preset's tumble time + 1 s)")
    max_redistributions: int | None = declare(None, kind="integer", ge=0, le=10,
                                              nullable=True,
                                              doc="most redistributions (default 3)")

    @staticmethod
    def controller(families, setup) -> Controller:
        return _RedistributeLowController(families, setup)


CLOSED_LOOP: dict[str, type[Family]] = {f.name: f for f in (Retry, ResonanceDwell, RetryAtSpin,
                                                            RedistributeLow)}
