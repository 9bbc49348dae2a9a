"""The goal of "Spin with redistribution" checked on an evaluation of SpinRedistribute.

A trained policy meets the goal on a test set when, paired over the same episodes (the same
laundry loads and redistribution draws):

* it closes at least half of the return gap between the best single open-loop profile
  (``baseline:knots``) and the laundry oracle: ``(R_policy - R_knots) / (R_oracle - R_knots)
  >= 0.5``, judged on the ratio's 95 % bootstrap interval (its low end);
* its return is above both hand rules (``retry_at_spin``, ``redistribute_low``): the paired
  return difference's 95 % interval above 0;
* its feedback value is positive: its return minus that of its own open-loop replay, the
  interval above 0.

Beside the goal it reports the share of the gap closed against the strongest open loop seen,
the better of ``knots`` and the policy's replay (a comparison is only as strong as its
strongest rival).

The stretch goal compares the oracle's residual with the policy's at no more than the
low-speed rule's time.  The intervals: a paired bootstrap over episodes for the ratio (2000
resamples, seeded; a ratio of means has no closed-form interval), Student-t for the paired
differences (:func:`abb_gym.evaluation.statistics.paired_interval`).
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from .evaluate import EvaluationResult
from .replay import paired_by_episode
from .report import base_name, cell
from .statistics import mean_interval

__all__ = ["GAP_GOAL", "RULES", "gap_closed", "goal_check", "goal_lines"]

#: the share of the knots-to-oracle return gap a policy must close
GAP_GOAL = 0.5
#: the hand rules a policy must beat
RULES = ("baseline:retry_at_spin", "baseline:redistribute_low")
OPEN_LOOP = "baseline:knots"
ORACLE = "baseline:laundry_oracle"
RESAMPLES = 2000


def _finite(result: EvaluationResult, key: str) -> np.ndarray:
    values = np.array([float(e[key]) for e in result.episodes if e.get(key) is not None])
    return values[np.isfinite(values)]


def _returns(result: EvaluationResult) -> dict[int, float]:
    return {int(e["episode"]): float(e["return"]) for e in result.episodes}


def gap_closed(policy: EvaluationResult, open_loop: EvaluationResult, oracle: EvaluationResult,
               seed: int = 0) -> dict[str, float]:
    """``(R_policy - R_open_loop) / (R_oracle - R_open_loop)`` of the mean returns over the
    episodes all three ran, with a paired bootstrap 95 % interval (resampling episodes)."""
    p, k, o = _returns(policy), _returns(open_loop), _returns(oracle)
    common = sorted(set(p) & set(k) & set(o))
    if not common:
        raise ValueError("the three evaluations share no episode")
    rp, rk, ro = (np.array([d[e] for e in common]) for d in (p, k, o))
    gap = ro - rk

    def ratio(idx):
        denominator = gap[idx].mean(axis=-1)
        return (rp[idx] - rk[idx]).mean(axis=-1) / np.where(denominator != 0, denominator,
                                                            np.nan)

    rng = np.random.default_rng(seed)
    boot = ratio(rng.integers(0, len(common), size=(RESAMPLES, len(common))))
    boot = boot[np.isfinite(boot)]
    mean = float(ratio(np.arange(len(common))))
    low, high = (np.percentile(boot, [2.5, 97.5]) if boot.size else (np.nan, np.nan))
    return {"mean": mean, "ci_low": float(low), "ci_high": float(high), "n": len(common)}


def goal_check(results: Mapping[str, EvaluationResult], policy: str) -> dict:
    """The goal of the module docstring for ``policy`` among ``results`` (by policy name
    without the tuned/default tag; the open loop, the oracle, both rules and
    ``replay:<policy>`` must be there)."""
    by = {base_name(k): v for k, v in results.items()}
    missing = [n for n in (policy, OPEN_LOOP, ORACLE, *RULES, f"replay:{policy}")
               if n not in by]
    if missing:
        raise ValueError(f"goal_check needs the evaluations of {missing}")
    me = by[policy]
    gap = gap_closed(me, by[OPEN_LOOP], by[ORACLE])
    rules = {r: paired_by_episode(me.episodes, by[r].episodes, "return") for r in RULES}
    feedback = paired_by_episode(me.episodes, by[f"replay:{policy}"].episodes, "return")
    # the strongest open loop seen: knots or the policy's own actions replayed open-loop
    replay = by[f"replay:{policy}"]
    best_open = max((by[OPEN_LOOP], replay), key=lambda r: np.mean(list(_returns(r).values())))
    gap_best = gap_closed(me, best_open, by[ORACLE])
    met = {"gap": bool(gap["ci_low"] >= GAP_GOAL),
           "rules": all(v["ci_low"] > 0 for v in rules.values()),
           "feedback": bool(feedback["ci_low"] > 0)}
    oracle_residual = mean_interval(_finite(by[ORACLE], "residual_vibration"))
    stretch = bool(np.mean(_finite(me, "residual_vibration")) <= oracle_residual["ci_high"]
                   and np.mean(_finite(me, "run_up_time"))
                   <= np.mean(_finite(by["baseline:redistribute_low"], "run_up_time")))
    return {"policy": policy, "gap_closed": gap,
            "gap_closed_best_open_loop": {**gap_best, "open_loop": base_name(best_open.policy)},
            "return_minus_rule": rules,
            "feedback_value": feedback, "met": met, "goal_met": all(met.values()),
            "stretch_met": stretch}


def goal_lines(check: dict) -> str:
    """The goal check as Markdown bullets."""
    yes = {True: "yes", False: "no"}
    met = check["met"]
    lines = [f"- share of the knots-to-oracle return gap closed: {cell(check['gap_closed'])} "
             f"(goal: at least {GAP_GOAL:.0%} at 95 %): {yes[met['gap']]}"]
    best = check["gap_closed_best_open_loop"]
    lines.append(f"- the same against the strongest open loop seen ({best['open_loop']}): "
                 f"{cell(best)}")
    for rule, diff in check["return_minus_rule"].items():
        lines.append(f"- return minus {rule}'s, paired: {cell(diff)} (goal: above 0 at 95 %)")
    lines.append(f"- both rules beaten: {yes[met['rules']]}")
    lines.append(f"- feedback value (return minus its open-loop replay's, paired): "
                 f"{cell(check['feedback_value'])}: {yes[met['feedback']]}")
    lines.append(f"- stretch (the oracle's residual at no more than redistribute_low's time): "
                 f"{yes[check['stretch_met']]}")
    lines.append(f"- **goal met: {yes[check['goal_met']]}**")
    return "\n".join(lines)
