"""The comparison script of the checkout, ``agents/evaluate.py`` (a repository tool: the wheel
does not ship ``agents/*.py``): each agent is compared on its own held-out machines, with its
own reward, against baselines tuned on its training preset, and every agent (on ``test`` as on
``varied_test``) gets the oracle and the feedback-gap table, which regenerate the READMEs'
marked sections."""
from __future__ import annotations

import argparse
import importlib.util
import json
from pathlib import Path

import pytest
import yaml

pytest.importorskip("stable_baselines3")

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "agents" / "evaluate.py"
pytestmark = pytest.mark.skipif(not SCRIPT.is_file(), reason="needs the checkout's agents/")


@pytest.fixture(scope="module")
def script():
    spec = importlib.util.spec_from_file_location("agents_evaluate", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_each_agent_is_compared_on_its_own_held_out_machines(script):
    plain = script.AgentSetting("runup_speed_yoshida_odd", None)
    assert (plain.preset, plain.train_preset, plain.configs) == ("test", "train", None)
    assert plain.env_kwargs == {"reward": {"residual": 6.0}}
    varied = script.AgentSetting("runup_speed_yoshida_odd_varied", None)
    assert (varied.preset, varied.train_preset) == ("varied_test", "varied")
    assert varied.configs.name == "varied"
    # only the families tuned on varied: no fallback to parameters tuned on another preset
    assert varied.families(["knots", "speed_dwell", "retry"]) == ["knots", "retry"]
    assert script.AgentSetting("runup_speed_yoshida_odd_varied", "test").preset == "test"
    with pytest.raises(ValueError, match="tune-baselines --scene yoshida_odd --preset nowhere"):
        script.preset_configs("nowhere", "yoshida_odd")


def test_feedback_gap_of_a_varied_agent_regenerates_both_readmes(script, tmp_path, capsys):
    readme = tmp_path / "README.md"
    readme.write_text(f"intro\n{script.GAP_BEGIN}\nold gap\n{script.GAP_END}\nend\n")
    agents_readme = tmp_path / "agents.md"
    agents_readme.write_text(f"head\n{script.BEGIN}\nold tables\n{script.END}\ntail\n")
    out = tmp_path / "results"
    rc = script.main(["runup_speed_yoshida_odd_varied", "--episodes", "2", "--oracle-budget",
                      "3", "--elsewhere-draws", "2", "--machine-oracle-budget", "3",
                      "--machine-oracle-draws", "2", "--room-factors", "3",
                      "--room-budget", "2", "--baselines", "knots", "retry",
                      "resonance_dwell", "--out", str(out), "--readme", str(agents_readme),
                      "--gap-readme", str(readme), "--workers", "1"])
    assert rc == 0
    gap = readme.read_text()
    assert gap.startswith("intro\n") and gap.endswith("end\n") and "old gap" not in gap
    assert "#### Feedback gap: yoshida_odd, varied_test" in gap
    header = next(line for line in gap.splitlines() if line.startswith("|  "))
    assert [c.strip() for c in header.split("|")[2:-1]] == list(script.GAP_COLUMNS)
    tables = agents_readme.read_text()
    assert "old tables" not in tables and "oracle:knots per machine" in tables
    assert "Goal against knots" in tables

    report = json.loads((out / "runup_speed_yoshida_odd_varied" / "comparison.json").read_text())
    assert report["preset"] == "varied_test" and report["train_preset"] == "varied"
    assert report["env_kwargs"] == {"reward": {"residual": 6.0}}
    columns = report["feedback_gap"]["columns"]
    assert columns["best open loop"].startswith("baseline:knots")
    assert columns["oracle"] == "oracle:knots per machine"
    elsewhere = ("oracle - knots, balls started elsewhere (2 draws per machine, both on the "
                 "same draws)")
    gaps = report["feedback_gap"]["gaps"]
    (room,) = [k for k in gaps if k.startswith("goal room - knots")]
    (room_unknown,) = [k for k in gaps if k.startswith("goal room, balls unknown - knots")]
    scaled_lines = ["oracle at residual weight 18 - knots",
                    "oracle with the balls unknown at residual weight 18 - knots"]
    assert set(gaps) == {
        "oracle - knots", "PPO - knots", "feedback value (replay - PPO)", elsewhere,
        "oracle, balls unknown - knots", *scaled_lines, room, room_unknown}
    # the goal's rooms: each oracle again at 3 x the agent's weight 6, its return (at another
    # weight) left out; a room holds the run-up time to knots' and never leaves more residual
    for key in scaled_lines + [room, room_unknown]:
        assert set(gaps[key]) == {"residual_vibration", "run_up_time"}
        assert f"- {key}: residual_vibration " in gap
    for key in (room, room_unknown):
        assert gaps[key]["run_up_time"]["mean"] <= 1e-9
        assert gaps[key]["residual_vibration"]["mean"] <= 0.0
        assert "the goal asks -20 %" in key
    assert ("least residual among knots and the oracle at residual weights 6, 18 (at 18: 2 "
            "candidates from the tuned knots), at") in room
    assert ("least residual among knots and the oracle with the balls unknown at residual "
            "weights 6, 18 (at 18: 3 candidates from the tuned knots, each on 2 ball starts)"
            ) in room_unknown
    (scaled_unknown,) = [r for r in json.loads(
        (out / "oracle" / "yoshida_odd_varied_test_seed0_balls_unknown.json").read_text()
    )["runs"] if r["env_kwargs"] == {"reward": {"residual": 18.0}}]
    assert (scaled_unknown["budget"], scaled_unknown["ball_draws"]) == (3, 2)
    assert columns["oracle, balls unknown"] == "oracle:knots per machine, balls unknown"
    (unknown,) = [r for r in json.loads(
        (out / "oracle" / "yoshida_odd_varied_test_seed0_balls_unknown.json").read_text()
    )["runs"] if r["env_kwargs"] == {"reward": {"residual": 6.0}}]
    assert unknown["ball_draws"] == 2 and unknown["budget"] == 3
    assert len(unknown["machines"]) == 2
    # paired machine by machine: one pair per test machine, whatever the draws
    assert all(v["n"] == 2 for v in report["feedback_gap"]["gaps"][elsewhere].values())
    assert f"- {elsewhere}: return " in gap
    # the baselines are those tuned on varied, not the shipped ones tuned on train
    evaluation = json.loads((out / "runup_speed_yoshida_odd_varied" /
                             "evaluation.json").read_text())
    knots = next(p for p in evaluation["policies"] if p["policy"].startswith("baseline:knots"))
    tuned = yaml.safe_load((REPO / "configs" / "varied" / "baselines" /
                            "yoshida_odd.yaml").read_text())["families"]["knots"]["params"]
    assert set(knots["params"]) == set(tuned)
    for key, value in tuned.items():
        assert knots["params"][key] == pytest.approx(value)
    assert "oracle:knots per machine" in [p["policy"] for p in evaluation["policies"]]
    assert (out / "runup_speed_yoshida_odd_varied" / "pareto.png").stat().st_size > 10_000

    # the stored oracle serves the same machines again, and is recomputed for other ones
    stored = out / "oracle" / "yoshida_odd_varied_test_seed0.json"
    before = stored.stat().st_mtime_ns
    args = argparse.Namespace(out=str(out), seed=0, episodes=2, oracle_budget=3)
    setting = script.AgentSetting("runup_speed_yoshida_odd_varied", None)
    capsys.readouterr()
    with script.configs_folder(setting.configs):
        run = script.oracle_run(setting, args)
    assert "reusing" in capsys.readouterr().out and stored.stat().st_mtime_ns == before
    assert len(run["machines"]) == 2
    # one run per start: the tuned knots and the earlier tuning the varied file lists; beside
    # them the run at 3 x the residual weight, from the tuned knots only
    every = json.loads(stored.read_text())["runs"]
    runs = [r for r in every if r["env_kwargs"] == setting.env_kwargs]
    assert len(runs) == len(run["starts"]) == 2 and run["starts"][0] == tuned
    (scaled,) = [r for r in every if r not in runs]
    assert scaled["env_kwargs"] == {"reward": {"residual": 18.0}}
    assert scaled["start"] == tuned and len(scaled["machines"]) == 2
    assert scaled["budget"] == 2 and all(r["budget"] == 3 for r in runs)
    for k, row in enumerate(run["machines"]):
        assert row["return"] == max(r["machines"][k]["return"] for r in runs)


def test_a_train_agent_gets_the_oracle_of_its_test_machines_kept_beside_other_rewards(
        script, tmp_path):
    out = tmp_path / "results"
    stored = out / "oracle" / "yoshida_odd_test_seed0.json"
    stored.parent.mkdir(parents=True)
    other = {"scene": "yoshida_odd", "preset": "test", "seed": 0, "family": "knots",
             "budget": 3, "env_kwargs": {"reward": {"residual": 1.0}}, "start": None,
             "machines": [{"return": 0.0}, {"return": 0.0}]}
    stored.write_text(json.dumps({"runs": [other]}))
    readme = tmp_path / "README.md"
    readme.write_text(f"{script.GAP_BEGIN}\n{script.GAP_END}\n")
    (tmp_path / "agents.md").write_text(f"{script.BEGIN}\n{script.END}\n")
    rc = script.main(["runup_speed_yoshida_odd", "--episodes", "2", "--oracle-budget", "3",
                      "--machine-oracle-budget", "0", "--elsewhere-draws", "0",
                      "--room-factors", "--baselines", "knots", "retry", "--out", str(out),
                      "--workers", "1",
                      "--readme", str(tmp_path / "agents.md"), "--gap-readme", str(readme)])
    assert rc == 0
    assert "#### Feedback gap: yoshida_odd, test (RunUpSpeed-v0, trained on train)" \
        in readme.read_text()
    report = json.loads((out / "runup_speed_yoshida_odd" / "comparison.json").read_text())
    assert report["feedback_gap"]["columns"]["oracle"] == "oracle:knots per machine"
    # switched off, the oracle with the balls unknown, the replay elsewhere and the goal's
    # room are left out
    assert "oracle, balls unknown" not in report["feedback_gap"]["columns"]
    assert set(report["feedback_gap"]["gaps"]) == {
        "oracle - knots", "PPO - knots", "feedback value (replay - PPO)"}
    assert not (out / "oracle" / "yoshida_odd_test_seed0_balls_unknown.json").exists()
    # the oracle refined the knots tuned on train (the shipped file), and the run of the
    # other reward is still in the file, untouched, after this agent's run was added
    runs = json.loads(stored.read_text())["runs"]
    assert [r["env_kwargs"] for r in runs] == [{"reward": {"residual": 6.0}}, other["env_kwargs"]]
    assert runs[1] == other
    tuned = yaml.safe_load((REPO / "configs" / "baselines" / "yoshida_odd.yaml").read_text())
    assert runs[0]["start"] == tuned["families"]["knots"]["params"]


def test_a_gap_table_names_the_environments_only_when_they_differ(script):
    from types import SimpleNamespace as Run
    speed, torque = Run(env_id="abb_gym/RunUpSpeed-v0"), Run(env_id="abb_gym/RunUpTorque-v0")
    assert script._env_note({"best open loop": speed, "oracle": speed}) == ""
    note = script._env_note({"best open loop": torque, "PPO": torque, "oracle": speed})
    assert note == ("  Environments (the same machines): best open loop on RunUpTorque-v0, "
                    "PPO on RunUpTorque-v0, oracle on RunUpSpeed-v0.")


def test_training_section_has_every_agents_cost_and_curves(script, tmp_path):
    from abb_gym.plots import plot_training_curves
    from abb_gym.rl import trained_dir
    agents = sorted(d.name for d in trained_dir().iterdir() if (d / "agent.yml").exists())
    readme = tmp_path / "agents" / "README.md"
    readme.parent.mkdir()
    text = script.training_section(agents, tmp_path / "agents" / "results", readme)
    rows = [line for line in text.splitlines() if line.startswith("| `")]
    assert [r.split("`")[1] for r in rows] == agents
    for row, agent in zip(rows, agents):
        run = yaml.safe_load((trained_dir() / agent / "config.yml").read_text())["_run"]
        assert f"{run['wall_time_s']:.0f} s" in row
    assert "](results/training_curves.png)" in text
    assert (tmp_path / "agents" / "results" / "training_curves.png").stat().st_size > 20_000
    with pytest.raises(ValueError, match="lacks the column"):
        plot_training_curves({"x": {"timesteps": [1.0], "return": [0.0]}}, tmp_path / "x.png")
    with pytest.raises(ValueError, match="no training curves"):
        plot_training_curves({}, tmp_path / "x.png")


@pytest.mark.parametrize("flag", ["--oracle-budget", "--machine-oracle-budget",
                                  "--machine-oracle-draws", "--elsewhere-draws"])
def test_a_negative_count_is_refused_by_name(script, tmp_path, capsys, flag):
    rc = script.main(["runup_speed_yoshida_odd", "--episodes", "2", flag, "-1",
                      "--out", str(tmp_path)])
    assert rc == 2
    assert f"{flag} must be >= 0 (got -1)" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())  # refused before anything ran


def test_a_room_budget_below_one_is_refused_by_name(script, tmp_path, capsys):
    rc = script.main(["runup_speed_yoshida_odd", "--episodes", "2", "--room-budget", "0",
                      "--out", str(tmp_path)])
    assert rc == 2
    assert "--room-budget must be >= 1 (got 0)" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("factor", ["1", "0", "-2", "nan", "1e5"])
def test_a_room_factor_out_of_range_is_refused_by_name(script, tmp_path, capsys, factor):
    rc = script.main(["runup_speed_yoshida_odd", "--episodes", "2", "--room-factors", "3",
                      factor, "--out", str(tmp_path)])
    assert rc == 2
    assert "--room-factors must lie in (0, 10000] and differ from 1" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())  # refused before anything ran
