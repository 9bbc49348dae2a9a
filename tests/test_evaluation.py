"""Baseline policies in the environments, the seeded evaluation, tuning, and the report."""
import json
import math

import gymnasium as gym
import numpy as np
import pytest
import yaml

from abb_gym import SpeedProfile, simulate
from abb_gym.baselines import families, profiles, tuner
from abb_gym.cli import main
from abb_gym.baselines.baseline_policy import BaselinePolicy, make_baseline
from abb_gym.envs.actions import dwell_action, dwell_profile
from abb_gym.evaluation.evaluate import (METRICS, EvaluationResult, evaluate, policy_env_id,
                                         summarise)
from abb_gym.evaluation.statistics import share_ci
from abb_gym.evaluation.report import pareto_front, write_report

SPEED = "abb_gym/RunUpSpeed-v0"


def rollout(env_id, family, n=2, **params):
    env = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point",
                       scene="yoshida_odd", preset="nominal", info_level="full")
    obs, info = env.reset(seed=3, options={"ball_angles": np.tile([0.4, -0.7], (n, 1))})
    setup = env.unwrapped.setup
    pol = make_baseline(family, setup.scene, setup.operating_speed, params=params or None,
                        use_tuned=False)
    pol.reset(env, np.ones(n, bool))
    hist, done = [], np.zeros(n, bool)
    while not done.all():
        obs, r, term, trunc, info = env.step(pol.act(obs, info))
        done |= term | trunc
        hist.append((info["time"][0], info["whirl_radius"][0], info["rotor_speed"][0],
                     np.array(info["ball_angles"][0])))
    return env.unwrapped.episode_scene(0), pol._profile(0), hist


@pytest.mark.parametrize("family", ["speed_dwell", "accel_dwell", "speed_reduction"])
def test_speed_baseline_reproduces_simulate(family):
    """The deadbeat speed command executes the profile exactly (breakpoints on control
    instants), so the environment run equals simulate with that profile to rounding."""
    scene, prof, hist = rollout(SPEED, family)
    t = np.array([h[0] for h in hist])
    tr = simulate(scene, prof, t[-1], output_dt=0.01, ball_angles0=[0.4, -0.7])
    wr = np.array([h[1] for h in hist])
    np.testing.assert_allclose(tr.whirl_radius[1:len(t) + 1], wr, rtol=0, atol=1e-9 * wr.max())
    np.testing.assert_allclose(tr.rotor_speed[1:len(t) + 1], [h[2] for h in hist], atol=1e-9)


def test_torque_baseline_tracks_the_profile_within_the_limit():
    scene, prof, hist = rollout("abb_gym/RunUpTorque-v0", "speed_dwell")
    t = np.array([h[0] for h in hist])
    w = np.array([h[2] for h in hist])
    assert np.max(np.abs(w - prof.speed(t))) < 0.02 * scene.drive_operating_speed
    assert w[-1] == pytest.approx(scene.drive_operating_speed, rel=0.01)


def test_dwell_action_encodes_the_profile():
    env = gym.make("abb_gym/DwellProfile-v0", scene="yoshida_odd", preset="nominal")
    env.reset(seed=0)
    setup = env.unwrapped.setup
    prof = profiles.build("accel_dwell", setup.scene, dwell_speed=110.0, dwell_time=0.4,
                          dwell_accel=10.0)
    a = dwell_action(setup, prof)
    back, params = dwell_profile(setup, a)
    assert params["dwell_speed"] == pytest.approx(110.0)
    assert params["dwell_time"] == pytest.approx(0.4)
    assert params["dwell_acceleration"] == pytest.approx(10.0)


def test_dwell_action_refuses_a_profile_it_does_not_encode():
    """Only ramp - dwell - ramp at the environment's run-up acceleration is a DwellProfile
    action; the first ramp alone matching is not enough (the round trip must give the
    profile back)."""
    setup = gym.make("abb_gym/DwellProfile-v0", scene="yoshida_odd",
                     preset="nominal").unwrapped.setup
    alpha = setup.dwell_acceleration
    good = profiles.build("accel_dwell", setup.scene, dwell_speed=110.0, dwell_time=0.4,
                          dwell_accel=10.0)
    other_final_ramp = SpeedProfile(segments=good.segments[:2] + (
        ((setup.operating_speed - good.speed(good.breakpoints[2])) / (0.5 * alpha),
         0.5 * alpha),))
    knots = families.build_family("knots").profile(setup.scene)
    with pytest.raises(ValueError, match="no DwellProfile action encodes it"):
        dwell_action(setup, other_final_ramp)
    with pytest.raises(ValueError, match="DwellProfile action"):
        dwell_action(setup, knots)
    dwell_action(setup, good)


def test_dwell_profile_evaluation_runs_inexpressible_baselines_on_runup_speed():
    """On DwellProfile, baseline:knots and the closed-loop baselines run on RunUpSpeed on the
    same machines (the same numbers as evaluating them there), and a PPO agent's own
    results stay on DwellProfile."""
    dwell = "abb_gym/DwellProfile-v0"
    assert policy_env_id(dwell, "yoshida_odd", "test", "baseline:knots") == SPEED
    assert policy_env_id(dwell, "yoshida_odd", "test", "replay:baseline:retry") == SPEED
    assert policy_env_id(SPEED, "yoshida_odd", "test", "baseline:knots") == SPEED
    on_dwell = evaluate(dwell, "yoshida_odd", "baseline:knots", episodes=3, seed=5)
    on_speed = evaluate(SPEED, "yoshida_odd", "baseline:knots", episodes=3, seed=5)
    assert on_dwell.env_id == SPEED
    assert [e["return"] for e in on_dwell.episodes] == [e["return"] for e in on_speed.episodes]
    setup = gym.make(dwell, scene="yoshida_odd", preset="test").unwrapped.setup
    expressible = BaselinePolicy("dwell", dwell_profile(setup, [0.0, -1 / 3, 0.0])[0])
    assert expressible.acts_on(setup)


def test_evaluation_is_deterministic_and_independent_of_chunking():
    a = evaluate(SPEED, "yoshida_odd", "baseline:speed_dwell", episodes=6, seed=11,
                 chunk_size=6)
    b = evaluate(SPEED, "yoshida_odd", "baseline:speed_dwell", episodes=6, seed=11,
                 chunk_size=4)
    for ea, eb in zip(a.episodes, b.episodes):
        assert ea["return"] == eb["return"] and ea["residual_vibration"] == eb["residual_vibration"]
    c = evaluate(SPEED, "yoshida_odd", "baseline:speed_dwell", episodes=6, seed=12)
    assert [e["return"] for e in c.episodes] != [e["return"] for e in a.episodes]


@pytest.mark.parametrize("policy", ["baseline:knots", "baseline:retry",
                                    "replay:baseline:resonance_dwell"])
def test_a_policy_that_reads_no_info_is_evaluated_on_the_lean_info_with_the_same_metrics(
        policy, monkeypatch):
    """Policies that declare ``reads_info = False`` (open loop, closed loop on the observation,
    replays, agents) run on the lean info; every metric of every episode is the same as on the
    full info of every step (the final info of an episode holds every key either way)."""
    from abb_gym.envs.vector import BalancerVectorEnv
    levels = []
    step = BalancerVectorEnv.step

    def spy(self, actions):
        levels.append(self.info_level)
        return step(self, actions)

    monkeypatch.setattr(BalancerVectorEnv, "step", spy)
    lean = evaluate(SPEED, "yoshida_odd", policy, episodes=3, seed=4)
    assert set(levels) == {"lean"}
    levels.clear()
    full = evaluate(SPEED, "yoshida_odd", policy, episodes=3, seed=4, info_level="full")
    assert set(levels) == {"full"}
    assert json.dumps(lean.episodes, sort_keys=True) == json.dumps(full.episodes, sort_keys=True)
    assert len(lean.episodes) == 3 and all("run_up_time" in e for e in lean.episodes)


class _ReadsTime:
    """A policy that reads ``info["time"]`` (as the Policy protocol allows by default)."""
    name = "reads-time"

    def reset(self, env, mask):
        pass

    def act(self, obs, info):
        return np.where(np.asarray(info["time"]) < 1.0, 1.0, 0.2).astype(np.float32)[:, None]


def test_a_policy_that_reads_info_keeps_the_full_info_also_when_replayed(monkeypatch):
    """Without ``reads_info = False`` a policy gets every key at every step, and so does a
    policy recorded for a replay (the replay itself reads none)."""
    from abb_gym.evaluation import registry
    monkeypatch.setitem(registry._LOADERS, "readstime", lambda arg, **_: _ReadsTime())
    own = evaluate(SPEED, "yoshida_odd", "readstime:x", episodes=2, seed=4)
    replay = evaluate(SPEED, "yoshida_odd", "replay:readstime:x", episodes=2, seed=4)
    assert len(own.episodes) == len(replay.episodes) == 2


def test_summary_confidence_intervals():
    p, lo, hi = share_ci(5, 10)
    assert p == 0.5 and lo == pytest.approx(0.2366, abs=1e-3) and hi == pytest.approx(0.7634, abs=1e-3)
    from abb_gym.evaluation.evaluate import METRICS
    eps = [dict({k: v for k in METRICS}, ball_settling_time=math.nan, balanced=v > 1,
                nonsynchronous_whirl=False, at_speed=True, **{"return": -v})
           for v in (1.0, 2.0, 3.0)]
    s = summarise(eps)
    assert s["residual_vibration"]["mean"] == 2.0
    # t(0.975, 2) = 4.303, s = 1, n = 3: half width 2.484
    assert s["residual_vibration"]["ci_high"] == pytest.approx(2.0 + 4.3027 / math.sqrt(3), rel=1e-4)
    assert s["ball_settling_time"]["n"] == 0 and math.isnan(s["ball_settling_time"]["mean"])
    assert s["balanced"]["mean"] == pytest.approx(2 / 3)
    # a non-negative metric's interval never goes below zero
    eps = [dict(eps[0], residual_vibration=v) for v in (0.0, 0.0, 3.0)]
    assert summarise(eps)["residual_vibration"]["ci_low"] == 0.0
    assert share_ci(0, 10)[1] == 0.0 and share_ci(10, 10)[2] == pytest.approx(1.0)


def test_pareto_front():
    pts = np.array([[1.0, 5.0], [2.0, 3.0], [2.5, 4.0], [3.0, 1.0], [4.0, 1.0], [np.nan, 0.0]])
    assert list(pareto_front(pts)) == [0, 1, 3]


def test_tuner_improves_on_the_default_and_sweep_points(tmp_path):
    """CMA-ES never returns worse than the default (the default is always a candidate, on
    the same seeded episodes), writes only where told, and the report carries every metric."""
    r = tuner.tune("yoshida_odd", families=("speed_dwell", "knots"), budget=12, episodes=4,
                   popsize=5, progress=False)
    assert "path" not in r and "CMA-ES" in r["optimiser"]
    path = tuner.write_tuned(r, tmp_path / "baselines")
    assert path == tmp_path / "baselines" / "yoshida_odd.yaml" and path.exists()
    with pytest.raises(ValueError, match="exists; pass --force"):
        tuner.write_tuned(r, path)
    tuner.write_tuned(r, path, force=True)
    for fam in ("speed_dwell", "knots"):
        entry = r["families"][fam]
        assert entry["mean_return"] >= entry["default_mean_return"]
        families.build_family(fam, **entry["params"])  # the declared fields validate it
    rows = tuner.sweep("yoshida_odd", families=("ramp",), n=3, episodes=2)
    assert len(rows) == 3 and all(np.isfinite(r["run_up_time"]) for r in rows)
    res = [evaluate(SPEED, "yoshida_odd", "baseline:ramp", episodes=3, seed=0)]
    paths = write_report(res, tmp_path, rows)
    for key in ("summary", "episodes", "json", "timeseries", "pareto"):
        assert paths[key].exists()
    data = json.loads(paths["json"].read_text())
    assert data["policies"][0]["summary"]["episodes"] == 3
    for key in ("run_up_time", "first_at_speed", "at_speed", "residual_vibration"):
        assert key in data["policies"][0]["summary"] and key in data["policies"][0]["episodes"][0]


def test_restart_populations_double_up_to_a_tenth_of_the_budget():
    # cma's default for 7 parameters (knots) is 4 + int(3 ln 7) = 9
    assert tuner.restart_popsizes(7, None, 240, 3) == [9, 18, 24, 24]
    assert tuner.restart_popsizes(7, 5, 1000, 2) == [5, 10, 20]
    assert tuner.restart_popsizes(1, None, 12, 1) == [4, 4]  # the cap never cuts the first


def test_restarts_keep_the_first_search_and_the_best_of_all():
    """Restarts add searches from random points: the first search is the one a tuning without
    restarts runs (same seed, same candidates), every search is reported, and the result is
    the best of them, on the same seeded episodes."""
    kw = dict(families=("speed_dwell",), budget=6, episodes=2, popsize=3, progress=False,
              seed=11)
    alone = tuner.tune("yoshida_odd", **kw)["families"]["speed_dwell"]
    both = tuner.tune("yoshida_odd", restarts=2, **kw)["families"]["speed_dwell"]
    assert "searches" not in alone
    runs = both["searches"]
    assert [r["start"] for r in runs] == ["centre", "random", "random"]
    assert runs[0]["best_return"] == alone["mean_return"]
    assert both["mean_return"] == max(r["best_return"] for r in runs)
    assert both["candidates"] == sum(r["candidates"] for r in runs) <= 18
    again = tuner.evaluate_candidates("yoshida_odd", "speed_dwell", [both["params"]], 2, 11,
                                      "train")[0]
    assert again["return"] == pytest.approx(both["mean_return"], abs=1e-5)  # rounded to 5


def test_a_tuning_from_given_parameters_is_never_worse_than_them():
    from abb_gym.baselines.baseline_policy import tuned_parameters
    start = tuned_parameters("yoshida_odd", "knots")
    r = tuner.tune("yoshida_odd", families=("knots",), budget=4, episodes=2, seed=3,
                   progress=False, start={"knots": start})
    entry = r["families"]["knots"]
    ref = tuner.evaluate_candidates("yoshida_odd", "knots", [start], 2, 3, "train")[0]
    assert entry["mean_return"] >= round(ref["return"], 5)
    assert entry["searches"][0]["start"] == "tuned" and "refines" in r["optimiser"]
    with pytest.raises(ValueError, match="start names 'ramp'"):
        tuner.tune("yoshida_odd", families=("knots",), budget=2, episodes=1, progress=False,
                   start={"ramp": {}})
    for bad in (-1, 101, True, 1.5):
        with pytest.raises(ValueError, match="restarts must be an integer from 0 to 100"):
            tuner.tune("yoshida_odd", families=("ramp",), budget=2, episodes=1,
                       progress=False, restarts=bad)


def test_a_failure_is_never_counted_as_a_success(tmp_path, monkeypatch):
    """The first wave's speed_reduction never finished an episode yet sat on the Pareto
    front: a run-up that never completes has at_speed False, its run-up time is the episode
    limit, no residual, and it stays off the front.  (Here a speed_reduction whose plateau
    outlasts the episode, from a user configuration folder.)"""
    from abb_gym import resources
    (tmp_path / "cfg" / "baselines").mkdir(parents=True)
    (tmp_path / "cfg" / "baselines" / "yoshida_odd.yaml").write_text(
        "scene: yoshida_odd\nfamilies:\n  speed_reduction:\n    params:\n"
        "      plateau_time: 100.0\n")
    monkeypatch.setenv(resources.ENV_VAR, str(tmp_path / "cfg"))
    res = evaluate(SPEED, "yoshida_odd", "baseline:speed_reduction", episodes=3, seed=0)
    assert "(tuned)" in res.policy
    setup_length = gym.make(SPEED).unwrapped.setup.episode_length
    ok = evaluate(SPEED, "yoshida_odd", "baseline:ramp", episodes=3, seed=0)
    for e in res.episodes:
        if not e["at_speed"]:
            assert e["run_up_time"] == pytest.approx(setup_length)
            assert math.isnan(e["residual_vibration"])
    s = res.summary()
    assert s["at_speed"]["mean"] < 1.0
    paths = write_report([res, ok], tmp_path)
    text = paths["summary"].read_text()
    assert "at_speed" in text
    from abb_gym.evaluation.report import plot_pareto
    assert plot_pareto([res, ok], [{"family": "x", "run_up_time": 1.0,
                                    "residual_vibration": 0.01, "at_speed": 0.5}],
                       tmp_path / "p.png").exists()


def test_replay_reproduces_the_recorded_policy_on_its_machine():
    """replay:SPEC records SPEC on the nominal machine: on that machine it is SPEC, action for
    action; the report's feedback value of SPEC is then exactly zero."""
    from abb_gym.evaluation.report import feedback_values
    for spec in ("baseline:retry", "baseline:knots"):
        a = evaluate(SPEED, "yoshida_odd", spec, episodes=2, seed=0, preset="nominal")
        b = evaluate(SPEED, "yoshida_odd", f"replay:{spec}", episodes=2, seed=0,
                     preset="nominal")
        assert [e["return"] for e in a.episodes] == [e["return"] for e in b.episodes]
        assert [e["residual_vibration"] for e in a.episodes] == \
            [e["residual_vibration"] for e in b.episodes]
        fb = feedback_values([a, b])[spec]
        assert fb["return"]["mean"] == 0.0 and fb["residual_vibration"]["mean"] == 0.0


def test_closed_loop_baselines_react_to_the_vibration():
    """retry dips and runs up again when the vibration at speed stays above its threshold
    (here: any vibration), and holds otherwise; resonance_dwell dwells near the critical
    speed it finds from the vibration peak."""
    from abb_gym.evaluation.evaluate import Chunk, run_chunk
    scene = gym.make(SPEED).unwrapped.scene
    chunk = Chunk(SPEED, "yoshida_odd", "nominal", "x", 0, (0,), record=(0,))
    always = make_baseline("retry", scene, params={"threshold": 1e-9, "max_retries": 1,
                                                   "check_time": 0.3})
    never = make_baseline("retry", scene, params={"threshold": 1e3, "check_time": 0.3})
    ep_a, roll_a = run_chunk(chunk, always)
    ep_n, roll_n = run_chunk(chunk, never)
    assert ep_a[0]["run_up_time"] > ep_n[0]["run_up_time"] + 1.0  # it dipped once
    assert roll_a[0].rotor_speed.max() == pytest.approx(scene.drive_operating_speed)
    res = make_baseline("resonance_dwell", scene, params={"dwell_time": 1.0})
    ep_r, roll_r = run_chunk(chunk, res)
    w = roll_r[0].rotor_speed
    dwell = np.isclose(np.diff(w), 0.0) & (w[1:] > 0.5 * scene.critical_speed) & \
        (w[1:] < 0.99 * scene.drive_operating_speed)
    assert dwell.sum() * 0.01 == pytest.approx(1.0, abs=0.02)
    held = w[1:][dwell]
    assert abs(held.mean() / scene.critical_speed - 1) < 0.25


def test_evaluate_cli(tmp_path, capsys):
    rc = main(["evaluate", "--policy", "baseline:speed_dwell", "--policy", "baseline:ramp",
               "--episodes", "3", "--out", str(tmp_path)])
    assert rc == 0
    out = capsys.readouterr().out
    assert "baseline:speed_dwell" in out and "residual_vibration" in out
    assert (tmp_path / "pareto.png").exists() and (tmp_path / "timeseries.png").exists()
    assert main(["evaluate", "--policy", "baseline:magic", "--episodes", "2",
                 "--out", str(tmp_path)]) == 2
    assert main(["evaluate", "--policy", "nonsense", "--out", str(tmp_path)]) == 2


def test_tuner_survives_a_flat_objective(monkeypatch):
    """Every candidate scoring the same (a family that never reaches speed on a scene) ends
    the search instead of failing inside CMA-ES."""
    def flat(scene_name, family, candidates, *args, **kwargs):
        return [{"family": family, "params": c, "return": -5.0, "run_up_time": 1.0,
                 "residual_vibration": 1.0, "peak_whirl": 1.0, "at_speed": 0.0,
                 "balanced": 0.0} for c in candidates]
    monkeypatch.setattr(tuner, "_evaluate_candidates", flat)
    # seed 0 and budget 20: the CMA-ES run (cma seed 1) that failed on spannan_cfrp's ramp
    result = tuner.tune("yoshida_odd", families=("ramp", "knots"), budget=20, episodes=1,
                        seed=0, progress=False)
    assert set(result["families"]) == {"ramp", "knots"}
    assert all(1 <= f["candidates"] <= 21 for f in result["families"].values())


def test_a_nan_return_never_wins_nor_blocks_a_finite_one(monkeypatch):
    """Every comparison of the search ranks returns one way (tuner.return_score): a first
    candidate (the default) with no finite return is beaten by any finite one found later,
    in the first search and across restarts."""
    calls = []

    def nan_first(scene_name, family, candidates, *args, **kwargs):
        rows = []
        for c in candidates:
            calls.append(c)
            value = math.nan if len(calls) == 1 else -float(len(calls))
            rows.append({"family": family, "params": c, "return": value, "run_up_time": 1.0,
                         "residual_vibration": 1.0, "peak_whirl": 1.0, "at_speed": 1.0,
                         "balanced": 0.0})
        return rows
    monkeypatch.setattr(tuner, "_evaluate_candidates", nan_first)
    result = tuner.tune("yoshida_odd", families=("ramp",), budget=6, episodes=1, seed=0,
                        progress=False, restarts=1, popsize=2)
    entry = result["families"]["ramp"]
    assert math.isfinite(entry["mean_return"]) and entry["mean_return"] == -2.0
    assert math.isnan(entry["default_mean_return"])


def test_tune_per_machine_tunes_each_test_machine_alone():
    """The oracle of the feedback gap: machine k is test episode k (seed + k), its default
    profile is one of its candidates, so its best return is never below the default's there."""
    rows = tuner.tune_per_machine("yoshida_odd", "knots", episodes=2, seed=7, preset="test",
                                  budget=8, progress=False)
    assert [r["seed"] for r in rows] == [7, 8] and all(r["candidates"] == 8 for r in rows)
    assert [r["episode"] for r in rows] == [0, 1]
    for r in rows:
        default = tuner.evaluate_candidates("yoshida_odd", "knots", [{}], 1, r["seed"], "test")[0]
        assert r["return"] >= default["return"]
        # every metric an evaluation reports, from the best candidate's own episode
        assert set(METRICS) <= set(r)
        mine = tuner.evaluate_candidates("yoshida_odd", "knots", [r["params"]], 1, r["seed"],
                                         "test")[0]
        for key in ("return", "run_up_time", "residual_vibration", "peak_whirl"):
            assert r[key] == pytest.approx(mine[key], rel=1e-12, nan_ok=True)


@pytest.mark.parametrize("ball_draws", [0, 2])
def test_tune_per_machine_gives_the_same_rows_with_machines_in_worker_processes(ball_draws):
    """With an executor each machine's search is a task of its own in another process: the
    rows (every metric, the parameters, the candidates tried) equal the serial run's bit for
    bit, in machine order, warm start and reward included."""
    from abb_gym.baselines.baseline_policy import tuned_parameters
    from abb_gym.execution import Executor
    kw = dict(episodes=3, seed=11, preset="test", budget=7, progress=False,
              start=tuned_parameters("yoshida_odd", "knots"), ball_draws=ball_draws,
              env_kwargs={"reward": {"residual": 9.0}})
    serial = tuner.tune_per_machine("yoshida_odd", "knots", **kw)
    spread = tuner.tune_per_machine("yoshida_odd", "knots",
                                    executor=Executor(workers=2, progress=False), **kw)
    assert [r["episode"] for r in spread] == [0, 1, 2]
    assert json.dumps(spread, sort_keys=True) == json.dumps(serial, sort_keys=True)
    # the searches differ between machines (else equal rows would prove little)
    assert len({json.dumps(r["params"], sort_keys=True) for r in serial}) == 3


def test_oracle_is_an_evaluation_result_of_the_same_machines():
    """The oracle run becomes an EvaluationResult whose episode k is machine k of the test set
    (seed + k), so paired gaps against evaluate() pair the same machines; a stored run is
    reused only for the same scene, preset, seed, reward, budget and enough machines."""
    from abb_gym.baselines.oracle import oracle_matches, oracle_result, run_oracle
    from abb_gym.evaluation.report import family_table, paired_gap
    reward = {"reward": {"residual": 6.0}}
    run = run_oracle("yoshida_odd", "test", episodes=3, seed=5, budget=3, env_kwargs=reward,
                     progress=False)
    oracle = oracle_result(run)
    knots = evaluate("abb_gym/RunUpSpeed-v0", "yoshida_odd", "baseline:knots", 3, 5, "test",
                     **reward)
    assert [e["episode"] for e in oracle.episodes] == [e["episode"] for e in knots.episodes]
    assert oracle.policy == "oracle:knots per machine"
    assert set(oracle.summary()) == set(knots.summary())
    gap = paired_gap(oracle, knots, "return")
    want = np.mean([o["return"] - k["return"] for o, k in zip(oracle.episodes, knots.episodes)])
    assert gap["mean"] == pytest.approx(want) and gap["n"] == 3
    # pairs by episode, not by position
    shuffled = EvaluationResult(knots.policy, knots.env_id, "yoshida_odd", "test", 5,
                                episodes=knots.episodes[::-1])
    assert paired_gap(oracle, shuffled, "return")["mean"] == pytest.approx(want)
    assert oracle_result(run, episodes=2).summary()["episodes"] == 2
    assert oracle_matches(run, "yoshida_odd", "test", 5, 3, 3, reward)
    assert oracle_matches(run, "yoshida_odd", "test", 5, 2, 3, reward)
    assert not oracle_matches(run, "yoshida_odd", "test", 5, 4, 3, reward)      # too few
    assert not oracle_matches(run, "yoshida_odd", "test", 5, 3, 3, {})          # reward
    assert not oracle_matches(run, "yoshida_odd", "test", 5, 3, 4, reward)      # budget
    assert not oracle_matches(run, "yoshida_odd", "varied_test", 5, 3, 3, reward)
    assert not oracle_matches({"scene": "yoshida_odd"}, "yoshida_odd", "test", 5, 3, 3, reward)
    # a warm start that changed (a re-tuned baseline) makes the stored run stale
    started = dict(run, start=json.loads(json.dumps({"knot_speeds": (200.0, 210.0)})))
    assert oracle_matches(started, "yoshida_odd", "test", 5, 3, 3, reward,
                          start={"knot_speeds": (200.0, 210.0)})
    assert not oracle_matches(started, "yoshida_odd", "test", 5, 3, 3, reward,
                              start={"knot_speeds": (200.0, 211.0)})
    assert not oracle_matches(started, "yoshida_odd", "test", 5, 3, 3, reward)
    table = family_table({"open loop": knots, "oracle": oracle}).splitlines()
    assert table[0].split("|")[2].strip() == "open loop"
    assert "oracle:knots per machine" in table[2]
    assert [line.split("|")[1].strip() for line in table[3:]] == [
        "at_speed [share]", "run_up_time [s]", "residual_vibration [W_r/e]", "return [-]"]
    with pytest.raises(ValueError, match="share no episode"):
        paired_gap(oracle, EvaluationResult("x", knots.env_id, "yoshida_odd", "test", 5), "return")


def test_the_oracle_takes_the_best_run_per_machine():
    """Runs from different starts on the same machines combine machine by machine into the
    best return (the first run's on a tie); runs of other machines or rewards are refused."""
    from abb_gym.baselines.oracle import best_of_runs, oracle_result

    def run(start, returns, **changes):
        base = {"scene": "yoshida_odd", "preset": "test", "seed": 5, "family": "knots",
                "budget": 3, "env_kwargs": {}, "start": start,
                "machines": [{"episode": k, "return": r, "residual_vibration": -r,
                              "params": {"s": start}, "candidates": 3}
                             for k, r in enumerate(returns)]}
        return base | changes
    a = run({"knot_speeds": [1.0]}, [-1.0, -5.0, -2.0, float("nan")])
    b = run({"knot_speeds": [2.0]}, [-3.0, -4.0, -2.0, -9.0])
    best = best_of_runs([a, b])
    assert [m["return"] for m in best["machines"]] == [-1.0, -4.0, -2.0, -9.0]
    assert [m["start_index"] for m in best["machines"]] == [0, 1, 0, 1]
    assert best["starts"] == [a["start"], b["start"]]
    assert [e["residual_vibration"] for e in oracle_result(best).episodes] == [1.0, 4.0, 2.0, 9.0]
    assert "start_index" not in oracle_result(best).episodes[0]
    assert len(best_of_runs([a, run(None, [0.0, 0.0])])["machines"]) == 2
    for key, value in (("seed", 6), ("env_kwargs", {"reward": {"residual": 6.0}}),
                       ("budget", 4), ("preset", "varied_test")):
        with pytest.raises(ValueError, match=f"differ in '{key}'"):
            best_of_runs([a, run(None, [0.0], **{key: value})])
    with pytest.raises(ValueError, match="at least one run"):
        best_of_runs([])


def test_oracle_starts_come_from_the_baselines_file(tmp_path, monkeypatch):
    from abb_gym import resources
    from abb_gym.baselines.baseline_policy import oracle_starts, tuned_parameters
    from abb_gym.configuration import ConfigError
    assert oracle_starts("yoshida_odd", "knots") == []  # the shipped train-preset file
    folder = tmp_path / "baselines"
    folder.mkdir()
    entry = {"params": {"knot_speeds": [100.0, 200.0], "knot_times": [0.1, 0.2]},
             "oracle_starts": [{"knot_speeds": [150.0], "knot_times": [0.5]}]}
    (folder / "yoshida_odd.yaml").write_text(yaml.safe_dump({"families": {"knots": entry}}))
    monkeypatch.setenv(resources.ENV_VAR, str(tmp_path))
    (start,) = oracle_starts("yoshida_odd", "knots")
    assert start["knot_speeds"] == [150.0] and start["knot_times"] == [0.5]
    entry["oracle_starts"] = [{"knot_speeds": [-1.0], "knot_times": [0.5]}]
    (folder / "yoshida_odd.yaml").write_text(yaml.safe_dump({"families": {"knots": entry}}))
    with pytest.raises(ConfigError, match="knot_speeds"):
        oracle_starts("yoshida_odd", "knots")
    entry["oracle_starts"] = {"knot_speeds": [150.0]}
    (folder / "yoshida_odd.yaml").write_text(yaml.safe_dump({"families": {"knots": entry}}))
    with pytest.raises(ConfigError, match="oracle_starts must be a list"):
        oracle_starts("yoshida_odd", "knots")
    # a family entry, its params or the families themselves in the wrong shape are named
    for data, field in (({"families": {"knots": [entry]}}, r"families\.knots must be a mapping"),
                        ({"families": {"knots": {"params": [1.0]}}},
                         r"families\.knots\.params must be a mapping"),
                        ({"families": ["knots"]}, "families must be a mapping")):
        (folder / "yoshida_odd.yaml").write_text(yaml.safe_dump(data))
        for read in (oracle_starts, tuned_parameters):
            with pytest.raises(ConfigError, match=field):
                read("yoshida_odd", "knots")
    # the shipped varied files list the earlier tunings: spannan_cfrp's the ten-search and the
    # one-search tuning on the preset's own imbalance range, yoshida_odd's the one-search one
    monkeypatch.setenv(resources.ENV_VAR,
                       str(resources.shipped_folder("baselines").parent / "varied"))
    assert {scene: len(oracle_starts(scene, "knots")) for scene in ("spannan_cfrp", "yoshida_odd")
            } == {"spannan_cfrp": 2, "yoshida_odd": 1}


def test_tune_per_machine_from_a_start_never_ends_below_it():
    """Warm-started from the tuned knots, the oracle is at least that profile on every
    machine: it is one of the candidates, and the search refines it."""
    from abb_gym.baselines.baseline_policy import tuned_parameters
    start = tuned_parameters("yoshida_odd", "knots")
    rows = tuner.tune_per_machine("yoshida_odd", "knots", episodes=2, seed=3, preset="test",
                                  budget=8, progress=False, start=start)
    for r in rows:
        ref = tuner.evaluate_candidates("yoshida_odd", "knots", [start], 1, r["seed"], "test")[0]
        assert r["return"] >= ref["return"]
    x = tuner.unit_from_params("knots", start, tuner.search_scales("yoshida_odd"))
    back = tuner.params_from_unit("knots", x, tuner.search_scales("yoshida_odd"))
    np.testing.assert_allclose(back["knot_speeds"], start["knot_speeds"], rtol=1e-9)


def test_ball_angles_drawn_as_the_preset_draws_them():
    from abb_gym.envs.episodes import draw_ball_angles
    from abb_gym.envs.setup import EnvSetup
    setup = EnvSetup("abb_gym/RunUpSpeed-v0", "yoshida_odd", "test")
    lo, hi = setup.config.randomize.ball_angles
    angles = draw_ball_angles(setup, np.random.default_rng(3))
    assert angles.shape == (setup.scene.ball_count,)
    assert np.all((angles >= lo) & (angles <= hi)) and len(set(angles.tolist())) == len(angles)
    np.testing.assert_array_equal(angles, draw_ball_angles(setup, np.random.default_rng(3)))
    with pytest.raises(ValueError, match="'nominal' fixes the initial ball angles"):
        draw_ball_angles(EnvSetup("abb_gym/RunUpSpeed-v0", "yoshida_odd", "nominal"), np.random.default_rng(3))


def test_balls_elsewhere_replays_the_same_machines_with_only_the_balls_moved():
    """The oracle's profiles replayed with the balls started elsewhere: the machines are the
    test set's (a reset option with a machine's own angles repeats its episode to the bit),
    only the ball angles move, and both profiles run on the same draws (a profile against
    itself differs by exactly 0)."""
    from abb_gym.baselines.baseline_policy import tuned_parameters
    from abb_gym.baselines.oracle import balls_elsewhere
    from abb_gym.evaluation.report import paired_gap
    knots = tuned_parameters("yoshida_odd", "knots")
    cand = tuple(sorted((k, tuple(v) if isinstance(v, list) else v) for k, v in knots.items()))
    env = gym.make(tuner.ENV_ID, scene="yoshida_odd", preset="test")
    exact, own_angles = [], []
    for k in (0, 1):
        (row,) = tuner._run_candidates(tuner.CandidateTask(tuner.ENV_ID, "yoshida_odd", "test",
                                                           "knots", (cand,), (k,), 0))
        exact.append(row)
        _, info = env.reset(seed=k)
        angles = tuple(float(a) for a in info["initial_ball_angles"])
        (again,) = tuner._run_candidates(tuner.CandidateTask(
            tuner.ENV_ID, "yoshida_odd", "test", "knots", (cand,), (k,), 0,
            reset_options=(("ball_angles", angles),)))
        assert again["return"] == row["return"]
        assert again["residual_vibration"] == row["residual_vibration"]
    run = {"scene": "yoshida_odd", "preset": "test", "seed": 0, "family": "knots",
           "env_kwargs": {}, "machines": [dict(r, episode=k, params=knots)
                                          for k, r in enumerate(exact)]}
    oracle, compare = balls_elsewhere(run, knots, draws=2, progress=False)
    assert [e["episode"] for e in oracle.episodes] == [0, 1]
    assert all(e["draws"] == 2 for e in oracle.episodes)
    for key in ("return", "residual_vibration", "run_up_time"):
        gap = paired_gap(oracle, compare, key)
        assert gap["mean"] == 0.0 and gap["n"] == 2
    # the balls did move: the same profile on the same machines scores otherwise
    assert [e["return"] for e in oracle.episodes] != [r["return"] for r in exact]
    # and the draws are the same on every call
    again, _ = balls_elsewhere(run, knots, draws=2, progress=False)
    assert again.episodes == oracle.episodes
    # in worker processes (one task per machine and draw) the results are the same, each
    # profile in its own result (the family's default against the tuned knots)
    from abb_gym.execution import Executor
    serial = balls_elsewhere(run, {}, draws=2, progress=False)
    spread = balls_elsewhere(run, {}, draws=2, executor=Executor(workers=2, progress=False))
    assert json.dumps([r.episodes for r in spread]) == json.dumps([r.episodes for r in serial])
    assert json.dumps(serial[0].episodes) != json.dumps(serial[1].episodes)
    with pytest.raises(ValueError, match="draws must be an integer >= 1"):
        balls_elsewhere(run, knots, draws=0)


def test_candidates_scored_on_several_ball_starts_take_the_mean_over_all():
    """A search that knows the machine but not its balls scores each candidate on several
    ball starts: the mean over the option sets is the mean of the separate runs."""
    from abb_gym.baselines.baseline_policy import tuned_parameters
    knots = tuned_parameters("yoshida_odd", "knots")
    starts = ((("ball_angles", (0.3, -2.0)),), (("ball_angles", (1.5, 2.5)),))
    both = tuner._evaluate_candidates("yoshida_odd", "knots", [knots, {}], 1, 4, "test", None,
                                      option_sets=starts)
    alone = [tuner._evaluate_candidates("yoshida_odd", "knots", [knots, {}], 1, 4, "test",
                                        None, option_sets=(o,)) for o in starts]
    assert alone[0][0]["return"] != alone[1][0]["return"]  # the balls' start matters
    for c in range(2):
        for key in ("return", "run_up_time", "peak_whirl"):
            assert both[c][key] == pytest.approx((alone[0][c][key] + alone[1][c][key]) / 2,
                                                 rel=1e-12)
    with pytest.raises(ValueError, match="ball_draws must be an integer >= 0"):
        tuner.tune_per_machine("yoshida_odd", episodes=1, budget=1, ball_draws=-1)


def test_a_report_records_the_environment_keywords(tmp_path):
    """The integrator (and every other keyword but the reward) is part of the test set: the
    same policy on the same seeds gives other episodes under another integrator, so the
    report says which one ran."""
    import json
    res = evaluate(SPEED, "yoshida_odd", "baseline:ramp", episodes=2, seed=0,
                   integrator="etdrk4", control_interval=0.05)
    assert res.env_kwargs == {"integrator": "etdrk4", "control_interval": 0.05}
    paths = write_report([res], tmp_path)
    assert json.loads(paths["json"].read_text())["env_kwargs"] == res.env_kwargs
    assert "Environment keywords: control_interval=0.05, integrator=etdrk4." in (
        paths["summary"].read_text())
