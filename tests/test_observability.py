"""What a drive's measurements tell about where the balls started
(:mod:`abb_gym.evaluation.observability`)."""
import math

import numpy as np
import pytest

from abb_gym.evaluation.observability import (TARGETS, ball_start_observability, r2_score,
                                              table)

pytest.importorskip("torch")


def test_r2_score_is_one_for_a_perfect_fit_and_zero_for_the_mean():
    y = np.array([[1.0, 2.0], [3.0, -1.0], [0.0, 0.5]])
    assert r2_score(y, y) == 1.0
    assert r2_score(np.tile(y.mean(0), (3, 1)), y) == pytest.approx(0.0, abs=1e-15)
    assert math.isnan(r2_score(np.zeros(3), np.ones(3)))


def test_the_imbalance_is_read_and_a_number_no_machine_carries_is_not():
    """The total imbalance at the start is what a balancing machine reads at low speed: the
    regressor must find it in the first half second of measurements; the control target is
    drawn apart from the machines, so it must score no better than its mean."""
    rows = ball_start_observability("yoshida_odd", "train", "test",
                                    env_kwargs={"control_interval": 0.05}, train_machines=256,
                                    test_machines=64, decisions=(10,), epochs=60,
                                    progress=False)
    (row,) = rows
    assert row.decisions == 10 and row.time == pytest.approx(0.5)
    assert row.rotor_speed > 0.0
    assert set(row.scores) == set(TARGETS)
    assert row.scores["total_imbalance"]["r2"] > 0.5
    assert row.scores["control"]["r2"] < 0.1
    for s in row.scores.values():
        assert s["ci_low"] <= s["r2"] <= s["ci_high"]
    assert "| 10 | 0.50 |" in table(rows)


@pytest.mark.parametrize("kwargs, message", [
    ({"train_machines": 4}, "train_machines must be an integer >= 8"),
    ({"test_machines": 2.5}, "test_machines must be an integer >= 8"),
    ({"epochs": 0}, "epochs must be an integer >= 1"),
    ({"decisions": (0, 4)}, "decisions must be integers >= 1"),
    ({"decisions": ()}, "decisions must be integers >= 1"),
])
def test_bad_sizes_are_refused_by_name(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ball_start_observability("yoshida_odd", "train", "test", progress=False, **kwargs)
