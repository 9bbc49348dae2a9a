"""The load-change-at-speed study (abb_gym.evaluation.load_change): the state change, the
case draws, the dips, the rule, the oracle and the summary on constructed rows, and the
premise on the washer: stuck balls stay after a small change, a dip frees them."""
import math

import numpy as np
import pytest

from abb_gym import SpeedProfile, load_scene
from abb_gym.evaluation import load_change as lc
from abb_gym.physics.rotor import residual_imbalance


@pytest.fixture(scope="module")
def washer():
    return load_scene("washer_reduced", **lc.STICK_FRICTION)


def test_change_load_moves_the_imbalance_and_keeps_the_balls_on_the_rotor(washer):
    nb = washer.ball_count
    nq = 3 + nb
    rng = np.random.default_rng(3)
    state = rng.normal(size=2 * nq)
    state[2] = 2.5
    state[3:nq] = rng.uniform(-3, 3, nb)
    machine, after = lc.change_load(washer, state, 0.03, 0.7)
    assert machine.imbalance == pytest.approx(0.03, rel=1e-12)
    assert machine.ball_count == nb and machine.rotor_mass == washer.rotor_mass
    # the imbalance direction in the fixed frame moves by the phase change, the balls' does not
    assert math.remainder(after[2] - state[2] - 0.7, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
    fixed = np.remainder(after[2] + after[3:nq] - state[2] - state[3:nq] + math.pi,
                         2 * math.pi) - math.pi
    np.testing.assert_allclose(fixed, 0.0, atol=1e-12)
    # position, velocities and speeds are kept; angles wrapped into [-pi, pi)
    np.testing.assert_array_equal(after[[0, 1]], state[[0, 1]])
    np.testing.assert_array_equal(after[nq:], state[nq:])
    assert np.all(np.abs(after[2:nq]) <= math.pi)
    # no phase change: the balls' residual is the one of the new size at the same place
    same, kept = lc.change_load(washer, state, washer.imbalance, 0.0)
    assert residual_imbalance(same, kept[3:nq]) == pytest.approx(
        residual_imbalance(washer, state[3:nq]), rel=1e-12)


def test_cases_are_seeded_and_in_their_ranges(washer):
    a = lc.draw_cases(washer, 50, seed=4)
    assert a == lc.draw_cases(washer, 50, seed=4)
    assert a != lc.draw_cases(washer, 50, seed=5)
    cap = washer.balancing_capacity
    for c in a:
        assert 0.2 * cap <= c.imbalance_before <= 0.9 * cap
        assert 0.2 * cap <= c.imbalance_after <= 0.9 * cap
        assert -math.pi <= c.angle_before < math.pi and -math.pi <= c.phase_change < math.pi
    with pytest.raises(ValueError, match="n must be"):
        lc.draw_cases(washer, 0, seed=0)
    with pytest.raises(ValueError, match="after must be a range"):
        lc.draw_cases(washer, 3, seed=0, after=(0.5, 0.2))


def test_a_dip_goes_down_holds_and_comes_back_to_the_operating_speed():
    dip = lc.Dip(30.0, 4.0)
    segs = dip.segments(130.0, 5.0)
    profile = SpeedProfile(segs, initial_speed=130.0)
    t_end = sum(s[0] for s in segs)
    assert t_end == pytest.approx(dip.duration(130.0, 5.0)) == pytest.approx(44.0)
    assert profile.speed(20.0) == pytest.approx(30.0)
    assert profile.speed(22.0) == pytest.approx(30.0)
    assert profile.speed(t_end) == pytest.approx(130.0)
    assert profile.speed(t_end + 10.0) == pytest.approx(130.0)


def _row(observation, residuals, times):
    return {"observation": observation, "residual": dict(residuals), "time_off": dict(times),
            "oracle_rerun": min(residuals.values())}


TIMES = {"hold": 0.0, "short": 10.0, "long": 30.0}


def test_oracle_rule_and_summary_on_constructed_cases():
    # dipping pays only when the vibration seen at the decision is high (> 3)
    rows = [_row(obs, {"hold": obs, "short": 2.0 + 0.1 * k, "long": 2.45}, TIMES)
            for k, obs in enumerate((1.0, 1.5, 2.0, 4.0, 5.0, 6.0))]
    assert [lc.oracle_choice(r) for r in rows] == ["hold"] * 3 + ["short"] * 2 + ["long"]
    # a tie goes to the shorter reaction
    assert lc.oracle_choice(_row(3.0, {"hold": 2.0, "short": 2.0, "long": 2.0}, TIMES)) == "hold"
    threshold, reaction = lc.tune_rule(rows)
    assert reaction == "short" and 2.0 < threshold < 4.0
    assert [lc.apply_rule(r, threshold, reaction) for r in rows] == ["hold"] * 3 + ["short"] * 3
    # a time cost large enough makes holding always better
    assert lc.apply_rule(rows[-1], *lc.tune_rule(rows, time_weight=1.0)) == "hold"
    s = lc.summarise(rows, threshold, reaction)
    hold = np.array([1.0, 1.5, 2.0, 4.0, 5.0, 6.0])
    oracle = np.array([1.0, 1.5, 2.0, 2.3, 2.4, 2.45])
    rule = np.array([1.0, 1.5, 2.0, 2.3, 2.4, 2.5])
    assert s["residual"]["hold"]["mean"] == pytest.approx(hold.mean())
    assert s["residual"]["oracle"]["mean"] == pytest.approx(oracle.mean())
    assert s["residual"]["rule"]["mean"] == pytest.approx(rule.mean())
    assert s["gap"]["mean"] == pytest.approx((hold - oracle).mean() / hold.mean())
    assert s["gap"]["ci_low"] <= s["gap"]["mean"] <= s["gap"]["ci_high"]
    assert s["rule_closes"]["mean"] == pytest.approx((hold - rule).mean()
                                                     / (hold - oracle).mean())
    assert s["time_off"]["rule"]["mean"] == pytest.approx(30.0 / 6)
    assert s["reacted"] == {"hold": 0.0, "rule": 0.5, "oracle": 0.5}
    assert s["difference"]["hold - oracle"]["mean"] == pytest.approx((hold - oracle).mean())
    with pytest.raises(ValueError, match="at least one"):
        lc.summarise([], threshold, reaction)
    with pytest.raises(ValueError, match="at least one"):
        lc.tune_rule([])


def test_stuck_balls_stay_after_a_small_change_and_a_dip_frees_them(washer):
    """The study's premise on the washer with its friction: after a change whose whirl stays
    inside the static dead band the balls hold (creep below u_reg atanh(0.99) t / R), and a
    dip below sqrt(g / (mu_s R)) = 97 rad/s, where gravity shakes them every turn, frees them
    and lowers the whirl.  Without friction the same change moves them at once."""
    timing = lc.Timing(settle_time=2.0)
    cap = washer.balancing_capacity
    case = lc.LoadChange(0.5 * cap, 0.4, 0.55 * cap, 0.1)
    moved = {}
    for name, scene in (("stick", washer),
                        ("free", washer.replace(friction_kinetic=0.0, friction_static=0.0))):
        settled = lc.settle(scene, case, timing)
        machine, state = lc.change_load(scene, settled.states[-1], case.imbalance_after,
                                        case.phase_change)
        held = lc.continue_run(machine, state, (), 3.0, timing)
        moved[name] = np.abs(held.ball_angles[-1] - held.ball_angles[0]).max()
        if name == "stick":
            dip = lc.Dip(75.0)
            segs = dip.segments(machine.drive_operating_speed, machine.drive_max_acceleration)
            dipped = lc.continue_run(machine, state, segs, dip.duration(
                machine.drive_operating_speed, machine.drive_max_acceleration) + 2.0, timing)
            freed = np.abs(dipped.ball_angles[-1] - dipped.ball_angles[0]).max()
            whirl_held = lc.whirl_about_rest(held)[-100:].mean()
            whirl_dipped = lc.whirl_about_rest(dipped)[-100:].mean()
    creep = (lc.STICK_FRICTION["friction_regularization_speed"] * math.atanh(0.99) * 3.0
             / washer.race_radius)
    assert moved["stick"] < creep
    assert moved["free"] > 100 * creep
    assert freed > 100 * creep
    assert whirl_dipped < 0.7 * whirl_held


def test_run_case_reports_every_reaction_and_refuses_what_does_not_fit(washer):
    timing = lc.Timing(settle_time=1.0, decision_delay=1.0, horizon=8.0, window=1.0, step=2e-3)
    cap = washer.balancing_capacity
    case = lc.LoadChange(0.4 * cap, 0.0, 0.8 * cap, 2.0)
    dip = lc.Dip(115.0)
    row = lc.run_case(washer, case, (dip,), timing)
    assert set(row["residual"]) == set(row["time_off"]) == {"hold", dip.label}
    assert row["time_off"] == {"hold": 0.0, dip.label: pytest.approx(dip.duration(
        washer.drive_operating_speed, washer.drive_max_acceleration))}
    assert all(v > 0 and math.isfinite(v) for v in row["residual"].values())
    # the change is seen: the whirl at the decision is well above the settled one
    assert row["observation"] > 1.5 * row["whirl_before"]
    assert row["balancer_off"] > row["balancer_off_before"]  # 0.8 against 0.4 capacities
    assert math.isfinite(row["oracle_rerun"])
    with pytest.raises(ValueError, match="longer than the horizon"):
        lc.run_case(washer, case, (lc.Dip(20.0),), timing)
    with pytest.raises(ValueError, match="below the operating speed"):
        lc.run_case(washer, case, (lc.Dip(200.0),), timing)
    with pytest.raises(ValueError, match="at least one Dip"):
        lc.run_case(washer, case, (), timing)


def test_paired_bootstrap_interval_agrees_with_scipy():
    """The hand-written paired bootstrap (which can leave out resamples without a ratio)
    against scipy.stats.bootstrap's percentile interval on data where every resample has one:
    the bounds agree within the Monte-Carlo error of 5000 resamples (0.01, on a ratio of 0.54
    whose interval is 0.09 wide)."""
    from scipy.stats import bootstrap
    rng = np.random.default_rng(0)
    hold = rng.uniform(100, 600, 60)
    oracle = hold * rng.uniform(0.1, 0.7, 60)
    mine = lc._bootstrap_ratio(hold, oracle, hold)
    ref = bootstrap((hold, oracle), lambda a, b, axis=-1: np.mean(a - b, axis=axis)
                    / np.mean(a, axis=axis), paired=True, vectorized=True, n_resamples=5000,
                    method="percentile", random_state=1).confidence_interval
    assert mine[0] == pytest.approx(ref.low, abs=0.01)
    assert mine[1] == pytest.approx(ref.high, abs=0.01)
    assert mine[1] - mine[0] > 0.05


@pytest.mark.slow
def test_stick_study_script_writes_its_page(tmp_path):
    """``agents/stick_study.py`` (a repository tool) end to end on one training and one test
    case: the page with its table, verdict and command, the figure, the CSV and the JSON."""
    import importlib.util
    import json
    from pathlib import Path
    script = Path(__file__).resolve().parents[1] / "agents" / "stick_study.py"
    if not script.is_file():
        pytest.skip("needs the checkout's agents/")
    spec = importlib.util.spec_from_file_location("stick_study", script)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    page = tmp_path / "stick.md"
    assert module.main(["--cases", "2", "--train-cases", "1", "--check-step", "1",
                        "--workers", "1", "--out", str(page)]) == 0
    text = page.read_text()
    assert "| no reaction (hold the speed) |" in text and "**Verdict:" in text
    assert "python agents/stick_study.py --cases 2 --train-cases 1" in text
    assert page.with_suffix(".png").stat().st_size > 20_000
    data = json.loads(page.with_suffix(".json").read_text())
    assert len(data["test"]) == 2 and len(data["train"]) == 1 and len(data["half_step"]) == 1
    assert len(page.with_suffix(".csv").read_text().splitlines()) == 3
