"""The feedback-gap study's numbers and tables (:mod:`abb_gym.evaluation.feedback_gap`) and
where they are published (:mod:`abb_gym.evaluation.results_pages`).

Both are pure functions of evaluation results, so they are tested on made-up episodes whose
means and paired differences are known by construction (the runs that make real results are
tested in ``tests/test_rl_comparison.py`` and ``tests/test_agents_scripts.py``)."""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from abb_gym.evaluation.evaluate import METRICS, EvaluationResult
from abb_gym.evaluation.feedback_gap import (GAP_COLUMNS, AgentSetting, GapStudy, agent_section,
                                             env_note, gap_section, goal_check, goal_line,
                                             room_lines, room_points)
from abb_gym.evaluation.results_pages import (COMPARISON_MARKERS, GAP_MARKERS, agent_page,
                                              replace_between_markers, write_agent_page,
                                              write_index, write_training_page)

SPEED = "abb_gym/RunUpSpeed-v0"


def _result(policy: str, residual, run_up, ret=None, env_id: str = SPEED,
            at_speed=None) -> EvaluationResult:
    """A result whose episode k has residual[k], run-up time run_up[k] (and return ret[k])."""
    result = EvaluationResult(policy, env_id, "yoshida_odd", "test", 0)
    for k, (r, t) in enumerate(zip(residual, run_up)):
        row = {key: 0.0 for key in METRICS}
        row.update(episode=k, residual_vibration=r, run_up_time=t,
                   at_speed=float(math.isfinite(r)) if at_speed is None else at_speed[k],
                   peak_speed=1.0, **{"return": -r if ret is None else ret[k]})
        result.episodes.append(row)
    return result


KNOTS = ([0.40, 0.50, 0.60, 0.50], [6.0, 6.0, 6.0, 6.0])


def _setting(env_id: str = SPEED, configs: Path | None = None) -> AgentSetting:
    return AgentSetting(folder=Path("/agents/agent_x"), env_id=env_id, scene="yoshida_odd",
                        train_preset="varied", preset="varied_test",
                        env_kwargs={"reward": {"residual": 6.0}}, configs=configs)


def test_the_goal_is_met_only_with_20_percent_less_residual_no_later_and_feedback_that_pays():
    knots = _result("baseline:knots", *KNOTS)
    # 25 % less residual at the same run-up time; its replay 0.15 W_r/e worse on every machine
    ppo = _result("ppo:a", [0.30, 0.375, 0.45, 0.375], [6.0] * 4)
    replay = _result("replay:ppo:a", [0.45, 0.525, 0.60, 0.525], [6.0] * 4)
    check = goal_check(ppo, replay, knots)
    assert check["residual"]["reduction"] == pytest.approx(0.25)
    assert check["residual"]["knots_minus_ppo"]["mean"] == pytest.approx(0.125)
    assert check["feedback_value"]["mean"] == pytest.approx(0.15)
    assert check["goal_residual"] and check["goal_run_up_time"] and check["goal_feedback"]
    line = goal_line(check)
    assert "(-25 %" not in line and "(+25 %" in line and "NOT met" not in line

    # 15 % less residual (short of 20 %), 0.1 s later, a replay no worse than the agent
    ppo = _result("ppo:a", [0.34, 0.425, 0.51, 0.425], [6.1] * 4)
    check = goal_check(ppo, ppo, knots)
    assert check["residual"]["reduction"] == pytest.approx(0.15)
    assert not (check["goal_residual"] or check["goal_run_up_time"] or check["goal_feedback"])
    assert goal_line(check).count("NOT met") == 3


def test_an_agent_that_never_settles_fails_the_goal_in_one_sentence():
    knots = _result("baseline:knots", *KNOTS)
    ppo = _result("ppo:a", [math.nan] * 4, [8.5] * 4)
    check = goal_check(ppo, ppo, knots)
    line = goal_line(check)
    assert line.startswith("NOT met: PPO never held the operating speed (at speed 0.00 "
                           "against 1.00; settled run-up 8.50 s, the episode limit")


def test_the_gap_table_puts_the_families_side_by_side_with_their_paired_gaps():
    knots = _result("baseline:knots (tuned)", *KNOTS)
    retry = _result("baseline:retry (tuned)", [0.9] * 4, [7.0] * 4)
    dwell = _result("baseline:resonance_dwell (tuned)", [0.8] * 4, [6.5] * 4)
    ppo = _result("ppo:a", [0.45, 0.55, 0.65, 0.55], [6.0] * 4)
    replay = _result("replay:ppo:a", [0.45, 0.55, 0.65, 0.55], [6.0] * 4)
    oracle = _result("oracle:knots per machine", [0.35, 0.45, 0.55, 0.45], [5.9] * 4)
    by_spec = {"ppo:a": ppo, "replay:ppo:a": replay, "baseline:knots": knots,
               "baseline:retry": retry, "baseline:resonance_dwell": dwell}
    study = GapStudy(episodes=4, seed=0, oracle_budget=7, elsewhere_draws=2)
    text, gap = gap_section(_setting(), study, by_spec, "ppo:a", oracle)
    assert text.startswith("#### Feedback gap: yoshida_odd, varied_test (RunUpSpeed-v0, "
                           "trained on varied)\n\n4 machines (seed 0), reward weights "
                           "{'residual': 6.0}")
    assert "(7 candidates from each start" in text and "Environments" not in text
    header = next(line for line in text.splitlines() if line.startswith("|  "))
    assert [c.strip() for c in header.split("|")[2:-1]] == list(GAP_COLUMNS[:-1])
    # the closed-loop column is the better return of the hand designs
    assert gap["columns"]["closed loop, hand-designed"] == dwell.policy
    assert set(gap["gaps"]) == {"oracle - knots", "PPO - knots",
                                "feedback value (replay - PPO)"}
    assert gap["gaps"]["oracle - knots"]["residual_vibration"]["mean"] == pytest.approx(-0.05)
    assert gap["gaps"]["PPO - knots"]["residual_vibration"]["mean"] == pytest.approx(0.05)
    assert gap["gaps"]["feedback value (replay - PPO)"]["residual_vibration"]["mean"] == 0.0
    assert "- oracle - knots: return " in text

    # with the oracle that does not know the balls, the replay elsewhere and the room
    unknown = _result("oracle:knots per machine, balls unknown", [0.38, 0.48, 0.58, 0.48],
                      [6.0] * 4)
    elsewhere = {"return": gap["gaps"]["oracle - knots"]["return"]}
    rooms = {"knots": knots, "weight": 6.0, "rooms": [
        {"label": "goal room", "search": "3 candidates from the tuned knots",
         "frontier": [(18.0, oracle)], "room": oracle}]}
    text, gap = gap_section(_setting(), study, by_spec, "ppo:a", oracle, elsewhere, unknown,
                            rooms)
    assert gap["columns"]["oracle, balls unknown"] == unknown.policy
    assert ("oracle - knots, balls started elsewhere (2 draws per machine, both on the same "
            "draws)") in gap["gaps"]
    assert "oracle at residual weight 18 - knots" in gap["gaps"]
    (room,) = [k for k in gap["gaps"] if k.startswith("goal room - knots")]
    assert "at residual weights 6, 18 (at 18: 3 candidates from the tuned knots)" in room
    assert "0.45 against 0.5 W_r/e, -10 % [" in room


def test_the_goals_room_is_compared_in_residual_and_run_up_only():
    knots = _result("baseline:knots", *KNOTS)
    scaled = _result("oracle at 18", [0.2, 0.3, 0.4, 0.3], [6.5] * 4)
    room = _result("room", [0.3, 0.4, 0.5, 0.4], [6.0] * 4)
    rooms = {"knots": knots, "weight": 6.0, "rooms": [
        {"label": "goal room, balls unknown", "search": "s", "frontier": [(18.0, scaled)],
         "room": room}]}
    lines = room_lines(rooms)
    assert list(lines)[0] == "oracle with the balls unknown at residual weight 18 - knots"
    for gap in lines.values():
        assert set(gap) == {"residual_vibration", "run_up_time"}
    assert lines[list(lines)[0]]["run_up_time"]["mean"] == pytest.approx(0.5)
    points = room_points(rooms)
    assert [p["label"] for p in points] == [
        "oracle with the balls unknown at residual weight 18",
        "goal room, balls unknown: least residual at knots' run-up time"]
    assert points[1]["residual_vibration"] == pytest.approx(0.4)


def test_a_gap_table_names_the_environments_only_when_they_differ():
    speed = _result("x", [0.1], [1.0])
    torque = _result("x", [0.1], [1.0], env_id="abb_gym/RunUpTorque-v0")
    assert env_note({"best open loop": speed, "oracle": speed}) == ""
    note = env_note({"best open loop": torque, "PPO": torque, "oracle": speed})
    assert note == ("  Environments (the same machines): best open loop on RunUpTorque-v0, "
                    "PPO on RunUpTorque-v0, oracle on RunUpSpeed-v0.")


def test_an_agent_section_says_where_its_baselines_were_tuned():
    knots = _result("baseline:knots (tuned)", *KNOTS)
    study = GapStudy(episodes=4, seed=3)
    plain = agent_section(_setting(), study, [knots], {})
    assert plain.startswith("### agent_x: RunUpSpeed-v0 on yoshida_odd\n\n4 test episodes "
                            "(preset varied_test, seed 3)")
    assert "Goal against knots" not in plain and "| baseline:knots (tuned) " in plain
    tuned = agent_section(_setting(configs=Path("/configs/varied")), study, [knots], {},
                          "#### Feedback gap: x\n")
    assert "(preset varied_test, baselines tuned on varied, seed 3)" in tuned
    assert tuned.endswith("\n\n#### Feedback gap: x\n")


def test_a_marked_section_is_replaced_and_the_rest_kept(tmp_path):
    readme = tmp_path / "README.md"
    begin, end = GAP_MARKERS
    readme.write_text(f"intro\n{begin}\nold\n{end}\ntail\n")
    replace_between_markers(readme, "new", GAP_MARKERS)
    assert readme.read_text() == f"intro\n{begin}\nnew\n{end}\ntail\n"
    with pytest.raises(ValueError, match="has no <!-- comparison:begin -->"):
        replace_between_markers(readme, "new", COMPARISON_MARKERS)


def test_an_agent_page_starts_at_level_one_with_its_chart_beside_it(tmp_path):
    section = ("### agent_x: RunUpSpeed-v0 on yoshida_odd\n\n4 test episodes\n\n| a |\n\n"
               "#### Feedback gap: yoshida_odd\n\n- oracle - knots: return 1\n")
    page = agent_page(section, "agent_x_pareto.png")
    assert page.startswith("# agent_x: RunUpSpeed-v0 on yoshida_odd\n\nGenerated by ")
    assert "\n## Feedback gap: yoshida_odd\n" in page and "###" not in page
    assert page.endswith("(agent_x_pareto.png)\n")
    chart = tmp_path / "pareto.png"
    chart.write_bytes(b"png")
    pages = tmp_path / "docs" / "results"
    path = write_agent_page(pages, "agent_x", section, chart)
    assert path == pages / "agent_x.md" and (pages / "agent_x_pareto.png").read_bytes() == b"png"
    # without its chart (no report written), the page has no image
    assert "![" not in write_agent_page(pages, "agent_y", section, tmp_path / "no.png"
                                        ).read_text()


def test_the_index_lists_every_agent_page_in_the_folder(tmp_path):
    pages = tmp_path / "results"
    write_agent_page(pages, "b_agent", "### b_agent: RunUpTorque-v0 on yoshida_odd\n\nx\n")
    write_agent_page(pages, "a_agent", "### a_agent: RunUpSpeed-v0 on spannan_cfrp\n\nx\n")
    index = write_index(pages).read_text()
    assert index.startswith("# Results: trained agents against the baselines\n")
    assert "at least 20 % below" in index and "at least 10 % of the agent's residual" in index
    links = [line for line in index.splitlines() if line.startswith("- [")]
    assert links == ["- [a_agent: RunUpSpeed-v0 on spannan_cfrp](a_agent.md)",
                     "- [b_agent: RunUpTorque-v0 on yoshida_odd](b_agent.md)"]
    write_training_page(pages, "| agent |\n")
    links = [line for line in write_index(pages).read_text().splitlines()
             if line.startswith("- [")]
    assert links[-1] == "- [Training cost and learning curves](training.md)" and len(links) == 3
