"""A load change at operating speed with stuck balls: hold, a detect-and-react rule, an oracle.

**The question.**  A machine runs at its operating speed with its balls settled against the
load.  Then the load changes size and phase (a washer's laundry sheds water and shifts during
spin; a basket centrifuge's cake drains).  With Coulomb stick (``friction_static >
friction_kinetic``, :mod:`abb_gym.physics.friction`) the balls hold where they were as long as
the new whirl's pull on them stays below the static limit, so the residual after the change
can stay large for good.  Does a drive that detects the rise and reacts (a speed dip, after
which the balls settle again) gain much over one that just holds the speed, and how close does
a hand rule come to an oracle that knows the change?

**Why a dip frees the balls.**  At speed a ball's tangential pull from a whirl of radius A is
``m Omega^2 A sin(angle)`` against a static limit ``mu_s m R Omega^2``: both grow with
``Omega^2``, so holding the speed never frees a ball that the whirl did not free at once
(``A |sin| < mu_s R``).  Nearer the critical speed the same residual imbalance makes a larger
whirl (the resonance factor), so a dip towards it pulls the balls loose; they slide towards the
balanced position and stop again when the pull falls below the kinetic limit.  On a horizontal
axis gravity pulls each ball once per revolution with ``m g sin(...)``, a share ``g / (R
Omega^2)`` of its normal force: below ``sqrt(g / (mu_s R))`` that beats the static limit and
shakes the balls loose every turn, so there a shallow dip is enough.  The rotor's deceleration
pulls every ball the same way (``m R alpha`` against ``mu_s m R Omega^2``), which only turns
the whole group.

**The pieces** (each a plain :func:`~abb_gym.physics.simulate.simulate` run with ``etdrk4``,
which takes the stiff stick law exactly at its ordinary step):

1. :func:`settle`: run-up from rest at the drive's largest acceleration to the operating speed,
   then a hold of ``settle_time``; the balls start at rest at the bottom of the race
   (:func:`abb_gym.physics.laundry.resting_angles`), the load at a random angle.
2. :func:`change_load`: the rotor's imbalance takes its new size (the scene's
   ``rotor_eccentricity``) and moves by ``phase_change`` relative to the rotor, so the rotor
   angle, measured to the imbalance, moves with it and the balls, stuck to the rotor, keep
   their place on it: ``th' = th + dphi``, ``ph_i' = ph_i - dphi`` (the rotor-angle rule of
   :func:`abb_gym.physics.laundry.redistribute`, without the new resting place of the balls).
   Position, velocities and speeds are kept.
3. :func:`continue_run`: the run goes on from that state under a speed profile: a hold, or a
   :class:`Dip` (down at the largest acceleration to a dip speed, a hold there, back up).

**Policies**, all deciding at ``decision_delay`` after the change (the rule needs a window of
vibration to see the rise; the oracle is given the same instant, so the comparison isolates
knowing from detecting):

* *no reaction*: hold the operating speed;
* *rule*: if the mean whirl over the last second before the decision exceeds a threshold,
  take one fixed dip of the family; threshold and dip tuned on separate training cases
  (:func:`tune_rule`);
* *oracle*: per case, the best of "hold" and every dip of the family (the lowest residual;
  ties to the shorter reaction).

**Metrics** per case and policy: the residual whirl (the mean whirl radius about the rest
position over the ``window`` before ``horizon`` after the change) [m], and the time off the
operating speed [s].  :func:`summarise` gives means with 95 % intervals, paired differences,
the gap ``(hold - oracle) / hold`` and the share of it the rule closes, with paired bootstrap
intervals.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass

import numpy as np

from ..physics import SpeedProfile, simulate
from ..physics import model as mdl
from ..physics.laundry import resting_angles
from ..physics.rotor import reference_amplitudes, static_deflection
from ..physics.scene import Scene
from .statistics import LEVEL, mean_interval, paired_interval

__all__ = ["STICK_FRICTION", "LoadChange", "Dip", "Timing", "DEFAULT_FAMILY", "PERTURBATION",
           "draw_cases", "settle", "change_load", "continue_run", "whirl_about_rest",
           "run_case", "run_cases", "settled_residual", "settled_residuals", "tune_rule",
           "apply_rule", "oracle_choice", "summarise"]

#: The friction of the study's scene (added to ``washer_reduced`` by ``agents/stick_study.py``;
#: the reasons are in ``docs/stick-study.md``): kinetic 1e-3 (Spannan's rolling resistance of
#: hard surfaces, a/r_b ~ 1e-3, the resistance a rolling ball meets), static 4e-3 (above the
#: 2.4e-3 with which gravity pulls a ball once per revolution at 1200 rpm on the 0.26 m track,
#: g / (R Omega^2), below which a horizontal-axis machine shakes its balls loose every turn);
#: a held ball creeps at u_reg atanh(F / F_s) (5.5 um/s at half the limit, 15 um/s at 90 %:
#: under 1 mm of track, 4e-3 rad, in a minute), and the Stribeck speed is the scenes' default.
STICK_FRICTION = {"friction_kinetic": 1.0e-3, "friction_static": 4.0e-3,
                  "friction_regularization_speed": 1.0e-5, "friction_stribeck_speed": 1.0e-3}

TWO_PI = 2.0 * math.pi


def _wrap(angle):
    """Angle(s) [rad] in [-pi, pi) (the kernels' inputs must stay within +-1000 rad)."""
    return np.asarray(angle, float) - TWO_PI * np.floor((np.asarray(angle, float) + math.pi)
                                                        / TWO_PI)


@dataclass(frozen=True)
class LoadChange:
    """One case: the load before the change (size [kg m]; its angle [rad] in the fixed frame
    at t = 0, from the x axis, gravity pointing at -pi/2) and after it (size [kg m]; its move
    relative to the rotor [rad], in the sense of rotation)."""

    imbalance_before: float
    angle_before: float
    imbalance_after: float
    phase_change: float


@dataclass(frozen=True)
class Dip:
    """A reaction: down at the drive's largest acceleration to ``speed`` [rad/s], ``hold`` [s]
    there, back up to the operating speed, then hold it."""

    speed: float
    hold: float = 0.0

    def segments(self, operating_speed: float, accel: float) -> tuple:
        """The (duration [s], acceleration [rad/s^2]) segments of the dip."""
        ramp = (operating_speed - self.speed) / accel
        return ((ramp, -accel), (self.hold, 0.0), (ramp, accel))

    def duration(self, operating_speed: float, accel: float) -> float:
        """Time off the operating speed [s]."""
        return 2.0 * (operating_speed - self.speed) / accel + self.hold

    @property
    def label(self) -> str:
        return f"dip to {self.speed:g} rad/s, hold {self.hold:g} s"


@dataclass(frozen=True)
class Timing:
    """Times of a case [s] and the integration: the hold at speed before the change, the
    decision after it, the evaluation ``horizon`` after it and the averaging ``window``
    before that; the ``etdrk4`` step [s] and the output interval [s].

    The step: where the balls stop after a breakaway is sensitive to small differences (a
    ball that holds or slips at the edge of the static limit), so single cases differ from
    step to step, while the means over many cases converge; ``docs/stick-study.md`` shows
    1e-3 s against 5e-4 s.  The scenes' default (1.7 ms on the washer, set by the contact)
    is coarser."""

    settle_time: float = 15.0
    decision_delay: float = 3.0
    horizon: float = 60.0
    window: float = 2.0
    step: float = 1.0e-3
    output_dt: float = 5.0e-3


def draw_cases(scene: Scene, n: int, seed: int, before=(0.2, 0.9), after=(0.2, 0.9)
               ) -> list[LoadChange]:
    """``n`` cases from ``numpy.random.default_rng(seed)``: sizes before and after uniform in
    the given ranges [fractions of the balancing capacity sum m_i R], the angle before and the
    phase change uniform in [-pi, pi)."""
    if not (isinstance(n, (int, np.integer)) and n >= 1):
        raise ValueError(f"n must be a positive integer (got {n!r})")
    for name, (lo, hi) in (("before", before), ("after", after)):
        if not 0.0 < lo <= hi:
            raise ValueError(f"{name} must be a range (low, high) with 0 < low <= high "
                             f"[fractions of the capacity] (got {(lo, hi)!r})")
    rng = np.random.default_rng(seed)
    cap = scene.balancing_capacity
    cases = []
    for _ in range(n):
        u0, a0, u1, d = rng.uniform((before[0], -math.pi, after[0], -math.pi),
                                    (before[1], math.pi, after[1], math.pi))
        cases.append(LoadChange(float(u0 * cap), float(a0), float(u1 * cap), float(d)))
    return cases


def _with_imbalance(scene: Scene, imbalance: float) -> Scene:
    return scene.replace(rotor_eccentricity=imbalance / scene.rotor_mass)


def settle(scene: Scene, case: LoadChange, timing: Timing = Timing()):
    """Run-up from rest and hold of ``timing.settle_time`` (module docstring); returns the
    :class:`~abb_gym.physics.trajectory.Trajectory` of the machine with the load before the
    change (its last state is the state at the change)."""
    machine = _with_imbalance(scene, case.imbalance_before)
    p, b = mdl.pack_parameters(machine)
    fixed = np.zeros(machine.ball_count)
    resting_angles(p, b, fixed, 0)
    nq = 3 + machine.ball_count
    state = np.zeros(2 * nq)
    state[0:2] = static_deflection(machine)
    state[2] = case.angle_before
    state[3:nq] = fixed - case.angle_before
    w, acc = machine.drive_operating_speed, machine.drive_max_acceleration
    return continue_run(machine, state, ((w / acc, acc),), w / acc + timing.settle_time,
                        timing)


def change_load(scene: Scene, state: np.ndarray, imbalance: float, phase_change: float):
    """(scene, state) after the load change (module docstring): the scene with the new
    ``imbalance`` [kg m], the state with the rotor angle moved by ``phase_change`` [rad] and
    the balls kept in place on the rotor."""
    nq = 3 + scene.ball_count
    s = np.array(state, float)
    s[2] = _wrap(s[2] + phase_change)
    s[3:nq] = _wrap(s[3:nq] - phase_change)
    return _with_imbalance(scene, imbalance), s


def continue_run(scene: Scene, state: np.ndarray, segments, t_end: float,
                 timing: Timing = Timing()):
    """Simulate ``t_end`` [s] from ``state`` (the first-order state of
    :func:`~abb_gym.physics.simulate.initial_state`) under the speed ``segments`` ((duration
    [s], acceleration [rad/s^2]) from the state's speed, held after the last) with ``etdrk4``
    at ``timing.step``.  The angles are wrapped to [-pi, pi) first (a long hold at speed
    turns the rotor far beyond the +-1000 rad the initial angles may take)."""
    nq = 3 + scene.ball_count
    drive = SpeedProfile(segments, initial_speed=float(state[nq + 2]),
                         initial_angle=float(_wrap(state[2])))
    return simulate(scene, drive, t_end, method="etdrk4", dt=timing.step,
                    output_dt=timing.output_dt, ball_angles0=_wrap(state[3:nq]),
                    ball_speeds0=state[nq + 3:], x0=state[0:2], v0=state[nq:nq + 2])


def whirl_about_rest(trajectory) -> np.ndarray:
    """Whirl radius about the rest position (the static sag under gravity) [m]."""
    sx, sy = static_deflection(trajectory.scene)
    return np.hypot(trajectory.x - sx, trajectory.y - sy)


def _mean_over(trajectory, start: float, end: float) -> float:
    w = whirl_about_rest(trajectory)
    keep = (trajectory.t > start + 1e-9) & (trajectory.t <= end + 1e-9)
    return float(np.mean(w[keep]))


#: The reactions the rule and the oracle choose from.  Deep dips, held 0 or 5 s: below both
#: of the washer's critical speeds (12 rad/s: the balls go to the heavy side and pass both
#: resonances again), just above them (25) and halfway (50).  Shallow dips, held 0, 5 or 15 s:
#: around sqrt(g / (mu_s R)) = 97 rad/s, below which gravity's once-per-revolution pull beats
#: the static limit and shakes the balls loose every turn (75, 85, 90, 95), and one that stays
#: above it (105).
DEFAULT_FAMILY = (tuple(Dip(speed, hold) for speed in (12.0, 25.0, 50.0) for hold in (0.0, 5.0))
                  + tuple(Dip(speed, hold) for speed in (75.0, 85.0, 90.0, 95.0, 105.0)
                          for hold in (0.0, 5.0, 15.0)))
#: [rad] added to ball k's angle (k = 1, 2, ...) for the oracle's re-run (:func:`run_case`)
PERTURBATION = 1.0e-7


def run_case(scene: Scene, case: LoadChange, family=DEFAULT_FAMILY, timing: Timing = Timing()
             ) -> dict:
    """One case: settle, change the load, then hold and every dip of ``family`` from the
    decision time.  Returns the whirl [m] before the change (``whirl_before``) and of the
    machine with its balancer off at operating speed with the load before and after the
    change (``balancer_off_before``, ``balancer_off``), the
    observation the rule sees (mean whirl over the second before the decision) [m], and per
    reaction (``"hold"`` and each dip's label) the residual [m] and the time off speed [s].

    ``oracle_rerun``: the oracle's choice run again from the decision state with every ball
    moved by :data:`PERTURBATION` x its number [rad], far below anything a drive controls.
    Where balls stop after a breakaway is partly chance; a best-of-family pick also selects
    lucky outcomes, and the re-run shows how much of the oracle's residual survives."""
    if not family:
        raise ValueError("family must hold at least one Dip")
    settled = settle(scene, case, timing)
    before = _mean_over(settled, settled.t[-1] - timing.window, settled.t[-1])
    machine, state = change_load(scene, settled.states[-1], case.imbalance_after,
                                 case.phase_change)
    w, acc = machine.drive_operating_speed, machine.drive_max_acceleration
    t_d = timing.decision_delay
    seen = continue_run(machine, state, (), t_d, timing)
    observation = _mean_over(seen, t_d - 1.0, t_d)
    at_decision = seen.states[-1]
    left = timing.horizon - t_d
    out = {"case": asdict(case), "whirl_before": before, "observation": observation,
           "balancer_off_before": float(reference_amplitudes(
               settled.scene, w, case.imbalance_before)[1]),
           "balancer_off": float(reference_amplitudes(machine, w, case.imbalance_after)[1]),
           "residual": {}, "time_off": {}}
    reactions = {"hold": ()}
    for dip in family:
        if not 0.0 < dip.speed < w:
            raise ValueError(f"{dip.label}: the dip speed must be in (0, {w:g}) rad/s, below "
                             f"the operating speed")
        if dip.duration(w, acc) > left - timing.window:
            raise ValueError(f"{dip.label} takes {dip.duration(w, acc):g} s, longer than the "
                             f"horizon {timing.horizon:g} s allows after the decision and "
                             f"before the window; raise Timing.horizon")
        reactions[dip.label] = dip.segments(w, acc)
    for label, segments in reactions.items():
        tr = continue_run(machine, at_decision, segments, left, timing)
        out["residual"][label] = _mean_over(tr, left - timing.window, left)
        out["time_off"][label] = float(sum(seg[0] for seg in segments))
    nudged = at_decision.copy()
    nudged[3:3 + machine.ball_count] += PERTURBATION * np.arange(1, machine.ball_count + 1)
    tr = continue_run(machine, nudged, reactions[oracle_choice(out)], left, timing)
    out["oracle_rerun"] = _mean_over(tr, left - timing.window, left)
    return out


def settled_residual(scene: Scene, case: LoadChange, timing: Timing = Timing()
                     ) -> tuple[float, float]:
    """(whirl [m] at the end of :func:`settle`, averaged over ``timing.window``; the whirl [m]
    of the same machine with its balancer off at operating speed): does a run-up from rest
    still balance?"""
    tr = settle(scene, case, timing)
    off = reference_amplitudes(tr.scene, tr.scene.drive_operating_speed,
                               case.imbalance_before)[1]
    return _mean_over(tr, tr.t[-1] - timing.window, tr.t[-1]), float(off)


def _settled_task(task) -> tuple[float, float]:
    return settled_residual(*task)


def run_cases(scene: Scene, cases, family=DEFAULT_FAMILY, timing: Timing = Timing(),
              executor=None, desc: str = "load changes") -> list[dict]:
    """:func:`run_case` for every case, on ``executor`` (:mod:`abb_gym.execution`; None: this
    process, with a progress bar), in case order; each row also holds the CPU time of its
    task [s] (``cpu_seconds``)."""
    return _map(_case_task, [(scene, case, tuple(family), timing) for case in cases],
                executor, desc)


def settled_residuals(scene: Scene, cases, timing: Timing = Timing(), executor=None,
                      desc: str = "run-ups") -> list[tuple[float, float]]:
    """:func:`settled_residual` for every case, as :func:`run_cases` runs them."""
    return _map(_settled_task, [(scene, case, timing) for case in cases], executor, desc)


def _map(fn, tasks, executor, desc):
    if executor is None:
        from ..progress import ProgressBar
        return [fn(t) for t in ProgressBar(tasks, desc=desc)]
    return executor.map(fn, tasks, desc=desc)


def _case_task(task) -> dict:
    start = time.process_time()
    row = run_case(*task)
    row["cpu_seconds"] = time.process_time() - start
    return row


def oracle_choice(row: dict) -> str:
    """The reaction of ``row`` (a :func:`run_case` result) with the lowest residual; ties
    (within 1e-12 m) go to the shorter time off speed."""
    return min(row["residual"], key=lambda k: (round(row["residual"][k] / 1e-12),
                                               row["time_off"][k]))


def apply_rule(row: dict, threshold: float, reaction: str) -> str:
    """The rule's reaction in ``row``: ``reaction`` if the observation exceeds ``threshold``
    [m], else ``"hold"``."""
    return reaction if row["observation"] > threshold else "hold"


def tune_rule(rows: list[dict], time_weight: float = 0.0) -> tuple[float, str]:
    """(threshold [m], reaction) minimising the mean over ``rows`` (training cases) of the
    residual [m] plus ``time_weight`` [m/s] x the time off speed [s]; the thresholds tried
    are the midpoints between the sorted observations (and 0 and beyond the largest)."""
    if not rows:
        raise ValueError("tune_rule needs at least one training case")
    obs = np.sort([r["observation"] for r in rows])
    cuts = np.concatenate([[0.0], 0.5 * (obs[1:] + obs[:-1]), [2.0 * obs[-1]]])
    best = None
    for reaction in rows[0]["residual"]:
        if reaction == "hold":
            continue
        for cut in cuts:
            cost = np.mean([r["residual"][k] + time_weight * r["time_off"][k]
                            for r in rows for k in (apply_rule(r, cut, reaction),)])
            if best is None or cost < best[0] - 1e-15:
                best = (cost, float(cut), reaction)
    return best[1], best[2]


#: resamples of the paired bootstrap intervals of :func:`summarise`
BOOTSTRAP_RESAMPLES = 5000


def _bootstrap_ratio(a, b, den, seed: int = 0) -> tuple[float, float]:
    """Paired percentile bootstrap interval (:data:`~abb_gym.evaluation.statistics.LEVEL`) of
    ``mean(a - b) / mean(den)``: the cases are drawn with replacement, the same cases for all
    three arrays.  A resample whose ``mean(den)`` is 0 (possible with few cases) has no ratio
    and is left out, which ``scipy.stats.bootstrap`` cannot do (it returns NaN bounds then)."""
    a, b, den = (np.asarray(v, float) for v in (a, b, den))
    idx = np.random.default_rng(seed).integers(0, len(a), size=(BOOTSTRAP_RESAMPLES, len(a)))
    num = (a[idx] - b[idx]).mean(axis=1)
    d = den[idx].mean(axis=1)
    ratio = num[d != 0] / d[d != 0]
    if ratio.size == 0:
        return math.nan, math.nan
    tail = 50.0 * (1.0 - LEVEL)
    low, high = np.percentile(ratio, [tail, 100.0 - tail])
    return float(low), float(high)


def summarise(rows: list[dict], threshold: float, reaction: str) -> dict:
    """Table of the three policies on ``rows`` (test cases): per policy the residual [m] and
    the time off speed [s] with 95 % intervals and the share of cases it reacted in; the
    paired differences; the gap (hold - oracle) / hold and the share of it the rule closes,
    with paired bootstrap intervals; the oracle's perturbed re-run; and every reaction taken
    in every case (``fixed``)."""
    if not rows:
        raise ValueError("summarise needs at least one case")
    pol = {"hold": ["hold"] * len(rows),
           "rule": [apply_rule(r, threshold, reaction) for r in rows],
           "oracle": [oracle_choice(r) for r in rows]}
    res = {k: np.array([r["residual"][c] for r, c in zip(rows, v)]) for k, v in pol.items()}
    tim = {k: np.array([r["time_off"][c] for r, c in zip(rows, v)]) for k, v in pol.items()}
    out = {"n": len(rows), "threshold": threshold, "reaction": reaction,
           "residual": {k: mean_interval(v, nonnegative=True) for k, v in res.items()},
           "time_off": {k: mean_interval(v, nonnegative=True) for k, v in tim.items()},
           "reacted": {k: float(np.mean([c != "hold" for c in v])) for k, v in pol.items()},
           "difference": {"hold - oracle": paired_interval(res["hold"], res["oracle"]),
                          "hold - rule": paired_interval(res["hold"], res["rule"]),
                          "rule - oracle": paired_interval(res["rule"], res["oracle"])},
           "choices": pol,
           "oracle_rerun": mean_interval([r["oracle_rerun"] for r in rows], nonnegative=True),
           "fixed": {k: mean_interval([r["residual"][k] for r in rows], nonnegative=True)
                     for k in rows[0]["residual"]}}
    gain = float(np.mean(res["hold"] - res["oracle"]))
    gap = gain / float(np.mean(res["hold"]))
    closed = float(np.mean(res["hold"] - res["rule"])) / gain if gain > 0 else math.nan
    out["gap"] = {"mean": gap}
    out["rule_closes"] = {"mean": closed}
    if len(rows) >= 2:
        out["gap"]["ci_low"], out["gap"]["ci_high"] = _bootstrap_ratio(
            res["hold"], res["oracle"], res["hold"])
        out["rule_closes"]["ci_low"], out["rule_closes"]["ci_high"] = _bootstrap_ratio(
            res["hold"], res["rule"], res["hold"] - res["oracle"])
    return out
