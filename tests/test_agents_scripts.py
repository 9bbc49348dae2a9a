"""The comparison script of the checkout, ``agents/evaluate.py`` (a repository tool: the wheel
does not ship ``agents/*.py``), end to end: every agent (on ``test`` as on ``varied_test``)
gets the oracle and the feedback-gap table; the tables go to the documentation pages, and to
the READMEs' marked sections only when asked.  Its functions are tested in
``tests/test_feedback_gap.py`` and ``tests/test_rl_comparison.py``."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest
import yaml

pytest.importorskip("stable_baselines3")

from abb_gym.evaluation.feedback_gap import GAP_COLUMNS, GapStudy  # noqa: E402
from abb_gym.evaluation.results_pages import COMPARISON_MARKERS, GAP_MARKERS  # noqa: E402
from abb_gym.rl.comparison import agent_setting, configs_folder, oracle_run  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "agents" / "evaluate.py"
pytestmark = pytest.mark.skipif(not SCRIPT.is_file(), reason="needs the checkout's agents/")


@pytest.fixture(scope="module")
def script():
    spec = importlib.util.spec_from_file_location("agents_evaluate", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_feedback_gap_of_a_varied_agent_regenerates_both_readmes(script, tmp_path, capsys):
    readme = tmp_path / "README.md"
    readme.write_text(f"intro\n{GAP_MARKERS[0]}\nold gap\n{GAP_MARKERS[1]}\nend\n")
    agents_readme = tmp_path / "agents.md"
    agents_readme.write_text(f"head\n{COMPARISON_MARKERS[0]}\nold tables\n"
                             f"{COMPARISON_MARKERS[1]}\ntail\n")
    out, pages = tmp_path / "results", tmp_path / "pages"
    rc = script.main(["runup_speed_yoshida_odd_varied", "--episodes", "2", "--oracle-budget",
                      "3", "--elsewhere-draws", "2", "--machine-oracle-budget", "3",
                      "--machine-oracle-draws", "2", "--room-factors", "3",
                      "--room-budget", "2", "--baselines", "knots", "retry",
                      "resonance_dwell", "--out", str(out), "--readme", str(agents_readme),
                      "--gap-readme", str(readme), "--workers", "1", "--pages", str(pages)])
    assert rc == 0
    gap = readme.read_text()
    assert gap.startswith("intro\n") and gap.endswith("end\n") and "old gap" not in gap
    assert "#### Feedback gap: yoshida_odd, varied_test" in gap
    header = next(line for line in gap.splitlines() if line.startswith("|  "))
    assert [c.strip() for c in header.split("|")[2:-1]] == list(GAP_COLUMNS)
    tables = agents_readme.read_text()
    assert "old tables" not in tables and "oracle:knots per machine" in tables
    assert "Goal against knots" in tables
    # the same tables on the agent's page, its headings at the page's levels
    page = (pages / "runup_speed_yoshida_odd_varied.md").read_text()
    assert page.startswith("# runup_speed_yoshida_odd_varied: RunUpSpeed-v0 on yoshida_odd")
    assert "\n## Feedback gap: yoshida_odd, varied_test" in page and "Goal against knots" in page
    assert (pages / "runup_speed_yoshida_odd_varied_pareto.png").stat().st_size > 10_000
    assert "(runup_speed_yoshida_odd_varied.md)" in (pages / "index.md").read_text()
    assert not (pages / "training.md").exists()  # an agent named: not every agent's training

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
    study = GapStudy(out=out, seed=0, episodes=2, oracle_budget=3)
    setting = agent_setting("runup_speed_yoshida_odd_varied")
    capsys.readouterr()
    with configs_folder(setting.configs):
        run = oracle_run(setting, study)
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
    readme.write_text("\n".join(GAP_MARKERS) + "\n")
    (tmp_path / "agents.md").write_text("\n".join(COMPARISON_MARKERS) + "\n")
    rc = script.main(["runup_speed_yoshida_odd", "--episodes", "2", "--oracle-budget", "3",
                      "--machine-oracle-budget", "0", "--elsewhere-draws", "0",
                      "--room-factors", "--baselines", "knots", "retry", "--out", str(out),
                      "--workers", "1", "--pages", str(tmp_path / "pages"),
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


@pytest.mark.parametrize("flag", ["--out", "--pages"])
def test_an_empty_output_folder_is_refused_in_one_line(script, tmp_path, monkeypatch, capsys,
                                                       flag):
    monkeypatch.chdir(tmp_path)  # an empty --out would have written here
    rc = script.main(["runup_speed_yoshida_odd", "--episodes", "2", "--oracle-budget", "0",
                      "--baselines", "knots", "--workers", "1", flag, ""])
    assert rc == 2
    assert capsys.readouterr().err == f"evaluate: error: {flag} must be a folder path (got '')\n"
    assert not any(tmp_path.iterdir())


def test_an_agent_name_after_readme_is_refused_in_one_line(script, tmp_path, capsys):
    rc = script.main(["--readme", "runup_speed_yoshida_odd", "--out", str(tmp_path)])
    assert rc == 2
    assert capsys.readouterr().err == ("evaluate: error: --readme runup_speed_yoshida_odd is "
                                       "not a file (agent names go before --readme)\n")
    assert not any(tmp_path.iterdir())


@pytest.fixture
def repository(script, tmp_path, monkeypatch):
    """A repository whose READMEs hold the marked sections, with one shipped agent, as the
    script's own (``agents/evaluate.py`` with no agent named evaluates every shipped one)."""
    from abb_gym.evaluation.results_pages import TRAINING_MARKERS
    from abb_gym.rl import trained_dir
    repo = tmp_path / "repo"
    (repo / "agents").mkdir(parents=True)
    (repo / "README.md").write_text(f"intro\n{GAP_MARKERS[0]}\nold gap\n{GAP_MARKERS[1]}\n")
    (repo / "agents" / "README.md").write_text(
        f"{TRAINING_MARKERS[0]}\nold training\n{TRAINING_MARKERS[1]}\n"
        f"{COMPARISON_MARKERS[0]}\nold tables\n{COMPARISON_MARKERS[1]}\n")
    shipped = tmp_path / "trained"
    shipped.mkdir()
    (shipped / "runup_speed_yoshida_odd").symlink_to(trained_dir() / "runup_speed_yoshida_odd")
    monkeypatch.setattr("abb_gym.rl.agent.trained_dir", lambda: shipped)
    monkeypatch.setattr(script, "REPO", repo)
    return repo


def test_by_default_the_tables_go_to_the_docs_pages_and_no_readme_is_rewritten(
        script, repository, tmp_path):
    readmes = {p: p.read_text() for p in (repository / "README.md",
                                          repository / "agents" / "README.md")}
    rc = script.main(["--episodes", "2", "--oracle-budget", "0", "--baselines", "knots",
                      "--out", str(tmp_path / "out"), "--workers", "1"])
    assert rc == 0
    assert {p: p.read_text() for p in readmes} == readmes
    pages = repository / "docs" / "results"
    assert sorted(p.name for p in pages.glob("*.md")) == [
        "index.md", "runup_speed_yoshida_odd.md", "training.md"]
    page = (pages / "runup_speed_yoshida_odd.md").read_text()
    assert page.startswith("# runup_speed_yoshida_odd: RunUpSpeed-v0 on yoshida_odd\n")
    assert "Goal against knots" in page and "| baseline:knots (tuned) " in page
    assert page.endswith("(runup_speed_yoshida_odd_pareto.png)\n")
    training = (pages / "training.md").read_text()
    assert "| `runup_speed_yoshida_odd` |" in training and "](training_curves.png)" in training
    assert (pages / "training_curves.png").stat().st_size > 10_000
    index = (pages / "index.md").read_text()
    assert "(runup_speed_yoshida_odd.md)" in index and "(training.md)" in index


def test_readme_alone_regenerates_the_repositorys_readmes(script, repository, tmp_path):
    rc = script.main(["--episodes", "2", "--oracle-budget", "2", "--machine-oracle-budget", "0",
                      "--elsewhere-draws", "0", "--room-factors", "--baselines", "knots",
                      "retry", "--out", str(tmp_path / "out"), "--workers", "1", "--readme"])
    assert rc == 0
    readme = (repository / "README.md").read_text()
    assert readme.startswith("intro\n") and "old gap" not in readme
    assert "#### Feedback gap: yoshida_odd, test (RunUpSpeed-v0, trained on train)" in readme
    tables = (repository / "agents" / "README.md").read_text()
    assert "old tables" not in tables and "old training" not in tables
    assert "### runup_speed_yoshida_odd: RunUpSpeed-v0 on yoshida_odd" in tables
    assert "](../../out/training_curves.png)" in tables
