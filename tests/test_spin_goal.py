"""The goal check of SpinRedistribute (:mod:`abb_gym.evaluation.spin_goal`) on constructed
evaluations whose answer is known."""
from __future__ import annotations

import numpy as np
import pytest

from abb_gym.evaluation.evaluate import EvaluationResult
from abb_gym.evaluation.spin_goal import gap_closed, goal_check, goal_lines

SPIN = "abb_gym/SpinRedistribute-v0"


def _result(policy, returns, residual=0.1, run_up=40.0):
    eps = [{"episode": k, "seed": k, "return": float(r), "residual_vibration": residual,
            "run_up_time": run_up, "at_speed": True} for k, r in enumerate(returns)]
    return EvaluationResult(policy, SPIN, "washer_reduced", "laundry_test", 0, episodes=eps)


def _set(ppo_shift, n=60, seed=0):
    rng = np.random.default_rng(seed)
    base = -4.0 + rng.normal(0.0, 1.0, n)          # the open loop's returns
    oracle = base + 2.0 + rng.normal(0.0, 0.1, n)  # a gap of 2 per episode
    return {"ppo:x": _result("ppo:x", base + ppo_shift + rng.normal(0.0, 0.1, n)),
            "replay:ppo:x": _result("replay:ppo:x", base),
            "baseline:knots (tuned)": _result("baseline:knots (tuned)", base),
            "baseline:retry_at_spin (tuned)": _result("baseline:retry_at_spin", base + 1.0,
                                                      run_up=55.0),
            "baseline:redistribute_low (tuned)": _result("baseline:redistribute_low",
                                                         base + 0.8, run_up=42.0),
            "baseline:laundry_oracle": _result("baseline:laundry_oracle", oracle,
                                               residual=0.05, run_up=36.0)}


def test_the_share_of_the_gap_is_the_ratio_of_mean_differences():
    s = _set(1.5)
    g = gap_closed(s["ppo:x"], s["baseline:knots (tuned)"], s["baseline:laundry_oracle"])
    assert g["mean"] == pytest.approx(0.75, abs=0.03)
    assert g["ci_low"] < g["mean"] < g["ci_high"] and g["ci_high"] - g["ci_low"] < 0.1


def test_a_policy_closing_three_quarters_meets_the_goal_and_one_closing_a_quarter_not():
    good, weak = goal_check(_set(1.5), "ppo:x"), goal_check(_set(0.5), "ppo:x")
    assert good["goal_met"] and all(good["met"].values())
    assert not weak["goal_met"] and not weak["met"]["gap"] and not weak["met"]["rules"]
    assert weak["met"]["feedback"]  # still better than its replay
    assert "goal met: yes" in goal_lines(good) and "goal met: no" in goal_lines(weak)
    # the strongest open loop: a replay better than knots moves the share down
    s = _set(1.5)
    s["replay:ppo:x"] = _result("replay:ppo:x", [e["return"] + 1.0 for e in
                                                 s["replay:ppo:x"].episodes])
    best = goal_check(s, "ppo:x")["gap_closed_best_open_loop"]
    assert best["open_loop"] == "replay:ppo:x" and best["mean"] == pytest.approx(0.5, abs=0.05)


def test_missing_evaluations_are_named():
    s = _set(1.0)
    del s["baseline:laundry_oracle"]
    with pytest.raises(ValueError, match="laundry_oracle"):
        goal_check(s, "ppo:x")
