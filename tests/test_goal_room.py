"""The goal's room (:func:`abb_gym.baselines.oracle.goal_room`): the least mean residual a
planner that knows each machine reaches at a mean run-up no longer than the baseline's.

A pure selection over run-ups already made, so it is tested on made-up rows: against brute
force on small cases (always within the time budget; the exact optimum when the run-up times
lie on a grid the selection does not have to round), and on the cases where a wrong choice is
easy to make (a slower, cleaner option that the time budget allows only because another
machine runs up faster; options that did not settle)."""
import itertools
import math

import numpy as np
import pytest

from abb_gym.baselines.oracle import goal_room
from abb_gym.evaluation.evaluate import EvaluationResult
from abb_gym.evaluation.report import paired_gap

try:
    from hypothesis import given, strategies as st
except ImportError:  # pragma: no cover - the test extra installs hypothesis
    st = None


def _row(k, residual, time):
    from abb_gym.evaluation.evaluate import METRICS
    return {key: 0.0 for key in METRICS} | {
        "episode": k, "residual_vibration": residual, "run_up_time": time,
        "at_speed": float(math.isfinite(residual))}


def _baseline(points):
    result = EvaluationResult("baseline:knots", "abb_gym/RunUpSpeed-v0", "s", "test", 0)
    result.episodes = [_row(k, r, t) for k, (r, t) in enumerate(points)]
    return result


def _run(points):
    return {"machines": [_row(k, r, t) | {"params": {"x": 1}, "candidates": 3}
                         for k, (r, t) in enumerate(points)]}


def _mean(result, key):
    return float(np.mean([e[key] for e in result.episodes]))


def _exact(base, runs):
    """Brute force: the least mean residual over every choice that fits the time budget."""
    per_machine = [[base[k]] + [run[k] for run in runs] for k in range(len(base))]
    budget = np.mean([t for _, t in base])
    best = math.inf
    for choice in itertools.product(*per_machine):
        if np.mean([t for _, t in choice]) <= budget + 1e-12:
            best = min(best, float(np.mean([r for r, _ in choice])))
    return best


def test_takes_the_cleaner_slower_profile_where_the_time_budget_allows():
    # machine 0 can be 0.2 s slower for a residual of 0.1 instead of 0.5; machine 1 can be
    # 0.2 s faster at a residual of 0.3 instead of 0.2: the faster one pays for the slower
    base = [(0.5, 6.0), (0.2, 6.0)]
    slow_clean = [(0.1, 6.2), (0.2, 6.4)]
    fast = [(0.55, 5.9), (0.3, 5.8)]
    room = goal_room(_baseline(base), [_run(slow_clean), _run(fast)])
    chosen = [(e["residual_vibration"], e["run_up_time"]) for e in room.episodes]
    assert chosen == [(0.1, 6.2), (0.3, 5.8)]
    assert [e["source"] for e in room.episodes] == [0, 1]
    assert _mean(room, "run_up_time") <= 6.0
    assert _mean(room, "residual_vibration") == pytest.approx(0.2)
    assert "params" not in room.episodes[0] and "candidates" not in room.episodes[0]
    # paired with the baseline machine by machine, as every gap line is
    gap = paired_gap(room, _baseline(base), "residual_vibration")
    assert gap["mean"] == pytest.approx(-0.15) and gap["n"] == 2


def test_without_better_options_it_is_the_baseline():
    base = [(0.5, 6.0), (0.2, 6.0), (0.3, 7.0)]
    worse = [(0.6, 6.0), (0.2, 6.5), (0.4, 6.9)]
    room = goal_room(_baseline(base), [_run(worse)])
    assert [e["source"] for e in room.episodes] == [-1, -1, -1]
    assert _mean(room, "residual_vibration") == pytest.approx(np.mean([r for r, _ in base]))


def test_a_run_up_that_never_settled_is_never_chosen():
    base = [(0.5, 6.0), (0.4, 6.0)]
    unsettled = [(math.nan, math.nan), (0.0, math.nan)]
    room = goal_room(_baseline(base), [_run(unsettled)])
    assert [e["source"] for e in room.episodes] == [-1, -1]


def test_a_machine_the_baseline_did_not_settle_keeps_the_baselines_run():
    # machine 1: the baseline failed at 2 s (no residual); the oracle settles it at 6 s.  Taking
    # the oracle there would spend 4 s of the budget and add a machine to the mean: the
    # baseline's run stays, and the 1 s it saved elsewhere is not spent on it
    base = [(0.5, 7.0), (math.nan, 2.0)]
    oracle = [(0.1, 8.0), (0.1, 6.0)]
    room = goal_room(_baseline(base), [_run(oracle)])
    assert [e["source"] for e in room.episodes] == [-1, -1]
    assert math.isnan(room.episodes[1]["residual_vibration"])
    # with budget to spare on the settled machine, it is used there only
    room = goal_room(_baseline([(0.5, 8.0), (math.nan, 2.0)]), [_run(oracle)])
    assert [e["source"] for e in room.episodes] == [0, -1]


def test_a_baseline_without_a_run_up_time_is_refused_by_name():
    with pytest.raises(ValueError, match="no run_up_time on machine 1"):
        goal_room(_baseline([(0.5, 6.0), (math.nan, math.nan)]), [])


if st is not None:
    def _cases(point, machines, runs):
        """A baseline of ``machines`` points and ``runs`` oracle runs on the same machines."""
        return st.integers(1, machines).flatmap(lambda n: st.tuples(
            st.lists(point, min_size=n, max_size=n),
            st.lists(st.lists(point, min_size=n, max_size=n), min_size=1, max_size=runs)))

    _anywhere = st.tuples(st.floats(0.01, 1.0), st.floats(1.0, 10.0))
    # run-up times in steps of 10 ms: the selection's rounding of time changes loses nothing
    _on_grid = st.tuples(st.floats(0.01, 1.0), st.integers(100, 1000).map(lambda t: t / 100))

    @given(_cases(_anywhere, 4, 2))
    def test_feasible_and_never_better_than_brute_force(case):
        base, runs = case
        room = goal_room(_baseline(base), [_run(r) for r in runs])
        assert _mean(room, "run_up_time") <= np.mean([t for _, t in base]) + 1e-9
        assert _mean(room, "residual_vibration") <= np.mean([r for r, _ in base]) + 1e-12
        assert _mean(room, "residual_vibration") >= _exact(base, runs) - 1e-12
        # every chosen row is one of that machine's options
        for k, e in enumerate(room.episodes):
            options = [base[k]] + [r[k] for r in runs]
            assert (e["residual_vibration"], e["run_up_time"]) in options

    @given(_cases(_on_grid, 5, 3))
    def test_the_exact_optimum_when_run_up_times_lie_on_a_grid(case):
        base, runs = case
        room = goal_room(_baseline(base), [_run(r) for r in runs])
        assert _mean(room, "residual_vibration") == pytest.approx(_exact(base, runs),
                                                                  abs=1e-12)


def test_the_chart_draws_labelled_points_under_their_own_label(tmp_path, monkeypatch):
    import matplotlib.figure

    from abb_gym.evaluation.report import plot_pareto
    legends = []
    save = matplotlib.figure.Figure.savefig

    def spy(fig, *args, **kwargs):
        legends.extend(t.get_text() for ax in fig.axes if ax.get_legend()
                       for t in ax.get_legend().get_texts())
        return save(fig, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", spy)
    knots = _baseline([(0.5, 6.0), (0.3, 6.5)])
    points = [{"family": "room", "label": "goal room: least residual at knots' run-up time",
               "run_up_time": 6.2, "residual_vibration": 0.3, "at_speed": 1.0},
              {"family": "swept", "run_up_time": 6.0, "residual_vibration": 0.6}]
    assert plot_pareto([knots], points, tmp_path / "p.png").stat().st_size > 10_000
    assert "goal room: least residual at knots' run-up time" in legends
    assert "swept: swept" in legends
