"""The feedback-gap study of a trained agent, from evaluation results: the goal check, the
agent's table and the feedback-gap section.

An agent is compared on its own held-out machines, with its own reward weights, against its
open-loop replay (the difference is its **feedback value**), the strongest open-loop baseline
(:data:`STRONGEST_OPEN_LOOP`, CMA-ES-tuned speed knots), the closed-loop hand designs
(:data:`CLOSED_LOOP`) and the per-machine oracle (:mod:`abb_gym.baselines.oracle`).  The runs
themselves are made by :mod:`abb_gym.rl.comparison`; this module turns their
:class:`~abb_gym.evaluation.evaluate.EvaluationResult` into numbers and Markdown, and needs
neither the agent nor the baselines.

The goal check (the project's "Tasks where feedback pays" goal), against ``baseline:knots``
on the same machines (:func:`goal_check`):

* residual vibration (mean W_r/e over the settling window, at the operating speed) at least
  :data:`RESIDUAL_GOAL` (20 %) lower, with the paired difference knots - PPO and its 95 %
  interval;
* settled run-up time (start of the final stay in the operating band) no longer, as often at
  speed;
* feedback value: the open-loop replay's residual at least :data:`FEEDBACK_GOAL` (10 %)
  worse, and its paired difference positive at 95 % confidence.

The feedback-gap table (:func:`gap_section`) puts the families side by side
(:data:`GAP_COLUMNS`: best open loop | closed-loop hand design | PPO | oracle | oracle, balls
unknown), followed by the paired gaps of each against ``knots`` and, when measured, the
goal's room (:func:`room_lines`: the least residual a planner that knows each machine reaches
at knots' run-up time).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

from ..tables import markdown_table
from .evaluate import EvaluationResult
from .replay import feedback_value
from .report import cell, family_table, paired_gap

__all__ = ["STRONGEST_OPEN_LOOP", "CLOSED_LOOP", "DEFAULT_BASELINES", "RESIDUAL_GOAL",
           "FEEDBACK_GOAL", "PAIRED_METRICS", "ROOM_METRICS", "GAP_COLUMNS", "AgentSetting",
           "GapStudy", "goal_check", "goal_line", "agent_table", "agent_section", "paired_gaps",
           "env_note", "gap_section", "room_points", "room_lines"]

STRONGEST_OPEN_LOOP = "knots"
CLOSED_LOOP = ("retry", "resonance_dwell")
DEFAULT_BASELINES = (STRONGEST_OPEN_LOOP, *CLOSED_LOOP, "speed_dwell", "accel_dwell",
                     "decel_dwell", "speed_reduction", "ramp")
RESIDUAL_GOAL = 0.20   # at least 20 % lower residual than knots
FEEDBACK_GOAL = 0.10   # the replay at least 10 % worse than the agent
PAIRED_METRICS = ("return", "residual_vibration", "run_up_time")
# the goal's room is compared in residual and run-up time: its runs' returns are at other
# reward weights
ROOM_METRICS = ("residual_vibration", "run_up_time")
GAP_COLUMNS = ("best open loop", "closed loop, hand-designed", "PPO (drive measurements)",
               "oracle", "oracle, balls unknown")


@dataclass(frozen=True)
class AgentSetting:
    """Where and how an agent is compared: its folder, environment, scene, training preset,
    held-out preset and reward weights (from its config.yml; built by
    :func:`abb_gym.rl.comparison.agent_setting`), and the folder of the baselines tuned on its
    training preset (None: the shipped ``configs/baselines``)."""

    folder: Path
    env_id: str
    scene: str
    train_preset: str
    preset: str
    env_kwargs: dict[str, Any]
    configs: Path | None


@dataclass(frozen=True)
class GapStudy:
    """The settings of an agent's comparison (``agents/evaluate.py``'s options)."""

    episodes: int = 100  # test machines (episode k: seed + k)
    seed: int = 0
    preset: str | None = None  # None: the agent's held-out preset
    baselines: tuple[str, ...] = DEFAULT_BASELINES
    oracle_budget: int = 60  # CMA-ES candidates per machine of the oracle (0: no oracle)
    machine_oracle_budget: int = 24  # ... of the oracle with the balls unknown (0: none)
    machine_oracle_draws: int = 3  # ball starts each of its candidates is scored on (0: none)
    elsewhere_draws: int = 4  # ball-angle draws per machine with the balls elsewhere (0: none)
    room_factors: tuple[float, ...] = (3.0,)  # multiples of the residual weight (): no room
    room_budget: int | None = None  # candidates per machine at those weights (None: oracle's)
    out: Path = Path("agents/results")  # report folder; the oracle's runs in out/oracle

    @property
    def room_oracle_budget(self) -> int:
        """CMA-ES candidates per machine of the oracle at a scaled residual weight."""
        return self.oracle_budget if self.room_budget is None else self.room_budget


def goal_check(ppo: EvaluationResult, replay: EvaluationResult, knots: EvaluationResult
               ) -> dict:
    """The goal of the module docstring from three :class:`EvaluationResult` on the same
    machines."""
    s_ppo, s_knots = ppo.summary(), knots.summary()
    r_ppo = s_ppo["residual_vibration"]["mean"]
    r_knots = s_knots["residual_vibration"]["mean"]
    t_ppo = s_ppo["run_up_time"]["mean"]
    t_knots = s_knots["run_up_time"]["mean"]
    feedback = feedback_value(ppo.episodes, replay.episodes)["residual_vibration"]
    reduction = 1.0 - r_ppo / r_knots
    return {
        "residual": {"ppo": r_ppo, "knots": r_knots, "reduction": reduction,
                     "knots_minus_ppo": paired_gap(knots, ppo, "residual_vibration")},
        "run_up_time": {"ppo": t_ppo, "knots": t_knots,
                        "ppo_minus_knots": paired_gap(ppo, knots, "run_up_time")},
        "at_speed": {"ppo": s_ppo["at_speed"]["mean"], "knots": s_knots["at_speed"]["mean"]},
        "feedback_value": feedback,
        "goal_residual": bool(reduction >= RESIDUAL_GOAL),
        "goal_run_up_time": bool(t_ppo <= t_knots and s_ppo["at_speed"]["mean"]
                                 >= s_knots["at_speed"]["mean"]),
        "goal_feedback": bool(feedback["ci_low"] > 0
                              and feedback["mean"] >= FEEDBACK_GOAL * r_ppo),
    }


def _cell(stat: dict, digits: int = 3) -> str:
    return cell(stat, digits, digits)


def agent_table(results: Sequence[EvaluationResult]) -> str:
    """One row per policy: environment, at-speed share, settled run-up time, residual, and
    the balancing metrics of a hold at the operating speed after the run (time to balance,
    residual after the hold: :mod:`abb_gym.evaluation.metrics`), which separate unfinished
    settling from a residual that control left."""
    rows = []
    for r in results:
        s = r.summary()
        rows.append({"policy": r.policy, "env": r.env_id.split("/")[-1].removesuffix("-v0"),
                     "at speed": _cell(s["at_speed"], 2),
                     "settled run-up [s]": _cell(s["run_up_time"]),
                     "residual [W_r/e]": _cell(s["residual_vibration"]),
                     "time to balance [s]": _cell(s["time_to_balance"]),
                     "residual after hold [W_r/e]": _cell(s["residual_after_hold"]),
                     "peak speed [w_op]": _cell(s["peak_speed"]),
                     "return": _cell(s["return"])})
    return markdown_table(rows)


def goal_line(check: dict) -> str:
    """The goal check of :func:`goal_check` as one sentence, each part met or NOT met."""
    res, run, fb = check["residual"], check["run_up_time"], check["feedback_value"]
    yes = {True: "met", False: "NOT met"}
    if not math.isfinite(res["ppo"]):  # no episode settled: no residual to compare
        return (f"NOT met: PPO never held the operating speed (at speed "
                f"{check['at_speed']['ppo']:.2f} against {check['at_speed']['knots']:.2f}; "
                f"settled run-up {run['ppo']:.2f} s, the episode limit, against "
                f"{run['knots']:.2f} s)")
    return (f"residual {res['ppo']:.3f} vs knots {res['knots']:.3f} W_r/e "
            f"({100 * res['reduction']:+.0f} %, knots - PPO {_cell(res['knots_minus_ppo'])}; "
            f">= 20 %: {yes[check['goal_residual']]}); settled run-up {run['ppo']:.2f} vs "
            f"{run['knots']:.2f} s (no longer, as often at speed: "
            f"{yes[check['goal_run_up_time']]}); feedback value (replay - PPO residual) "
            f"{_cell(fb)} W_r/e (>= 10 % and > 0 at 95 %: {yes[check['goal_feedback']]})")


def agent_section(setting: AgentSetting, study: GapStudy, shown: Sequence[EvaluationResult],
                  check: dict, gap_text: str = "") -> str:
    """An agent's Markdown section: its table of every policy on the same machines, the goal
    line (``check``: :func:`goal_check`, empty without knots) and the feedback-gap section
    ``gap_text`` (:func:`gap_section`, empty without the oracle)."""
    where = (f"preset {setting.preset}" + ("" if setting.configs is None else
                                            f", baselines tuned on {setting.train_preset}"))
    text = (f"### {setting.folder.name}: {setting.env_id.split('/')[-1]} on {setting.scene}"
            f"\n\n{study.episodes} test episodes ({where}, seed {study.seed}), mean "
            f"[95 % CI]; the same machines for every row.\n\n"
            + agent_table(shown) + "\n")
    if check:
        text += f"\nGoal against knots: {goal_line(check)}.\n"
    if gap_text:
        text += "\n" + gap_text
    return text


def paired_gaps(a: EvaluationResult, b: EvaluationResult) -> dict:
    """The paired differences ``a - b`` of :data:`PAIRED_METRICS`, machine by machine."""
    return {k: paired_gap(a, b, k) for k in PAIRED_METRICS}


def env_note(columns: dict) -> str:
    """A sentence naming the environments when the table's families ran on different ones
    (the oracle plans speed profiles on RunUpSpeed; a RunUpTorque agent's baselines run on
    RunUpTorque through its speed loop), all on the same machines."""
    envs = {label: r.env_id.split("/")[-1] for label, r in columns.items()}
    if len(set(envs.values())) == 1:
        return ""
    return ("  Environments (the same machines): " + ", ".join(
        f"{label} on {env}" for label, env in envs.items()) + ".")


def gap_section(setting: AgentSetting, study: GapStudy, by_spec: dict, ppo_spec: str,
                oracle: EvaluationResult, elsewhere: dict | None = None,
                unknown: EvaluationResult | None = None, room: dict | None = None
                ) -> tuple[str, dict]:
    """The feedback-gap table (the families side by side) and its paired gaps, from the
    results ``by_spec`` (policy spec -> result: the agent ``ppo_spec``, its replay and the
    baselines) and the ``oracle``; ``elsewhere``: the oracle - knots gap with the balls
    started elsewhere (:func:`abb_gym.rl.comparison.elsewhere_gap`); ``unknown``: the oracle
    that knows the machine but not its balls (a fifth column); ``room``: the goal's room
    (:func:`abb_gym.rl.comparison.goal_room_of`)."""
    ppo, replay = by_spec[ppo_spec], by_spec[f"replay:{ppo_spec}"]
    knots = by_spec[f"baseline:{STRONGEST_OPEN_LOOP}"]
    closed = [by_spec[f"baseline:{b}"] for b in CLOSED_LOOP if f"baseline:{b}" in by_spec]
    best_closed = max(closed, key=lambda r: r.summary()["return"]["mean"])
    columns = dict(zip(GAP_COLUMNS, (knots, best_closed, ppo, oracle, unknown)))
    if unknown is None:
        del columns[GAP_COLUMNS[-1]]
    gaps = {"oracle - knots": paired_gaps(oracle, knots),
            "PPO - knots": paired_gaps(ppo, knots),
            "feedback value (replay - PPO)": feedback_value(ppo.episodes, replay.episodes)}
    if unknown is not None:
        gaps["oracle, balls unknown - knots"] = paired_gaps(unknown, knots)
    if elsewhere is not None:
        gaps[f"oracle - knots, balls started elsewhere ({study.elsewhere_draws} draws per "
             f"machine, both on the same draws)"] = elsewhere
    if room is not None:
        gaps.update(room_lines(room))
    reward = setting.env_kwargs.get("reward", {})
    text = (f"#### Feedback gap: {setting.scene}, {setting.preset} "
            f"({setting.env_id.split('/')[-1]}, trained on {setting.train_preset})\n\n"
            f"{study.episodes} machines (seed {study.seed}), reward weights "
            f"{reward or 'default'}, mean [95 % CI].  Best open loop and closed-loop hand "
            f"design (the better return of {', '.join(CLOSED_LOOP)}) tuned on "
            f"{setting.train_preset}; the oracle tunes knots on each machine alone "
            f"({study.oracle_budget} candidates from each start: the tuned knots and the "
            f"earlier tunings its baselines file lists; the best per machine)"
            + ("" if unknown is None else
               f"; the oracle with the balls unknown knows the machine but not where its balls"
               f" start ({study.machine_oracle_budget} candidates from the tuned knots, each "
               f"scored on {study.machine_oracle_draws} ball starts drawn as the preset draws "
               f"them, then run on the machine as drawn)")
            + f".  Agent: `{setting.folder.name}`."
            + env_note(columns) + "\n\n" + family_table(columns) + "\n\n")
    for name, gap in gaps.items():
        text += f"- {name}: " + ", ".join(
            f"{k} {_cell(v)}" for k, v in gap.items()
            if k in PAIRED_METRICS) + "\n"
    return text, {"columns": {k: r.policy for k, r in columns.items()}, "gaps": gaps}


def _oracle_label(room: dict) -> str:
    """"oracle" or "oracle with the balls unknown", after the room's label."""
    return "oracle" + room["label"][len("goal room"):].replace(", balls", " with the balls")


def room_points(rooms: dict) -> list[dict]:
    """The goal's rooms (:func:`abb_gym.rl.comparison.goal_room_of`) as points of the
    report's chart of residual against run-up time."""
    points = []
    for room in rooms["rooms"]:
        for label, result in ([(f"{_oracle_label(room)} at residual weight {w:g}", r)
                               for w, r in room["frontier"]]
                              + [(f"{room['label']}: least residual at knots' run-up time",
                                  room["room"])]):
            s = result.summary()
            points.append({"family": label, "label": label, "at_speed": s["at_speed"]["mean"],
                           **{k: s[k]["mean"] for k in ("run_up_time", "residual_vibration")}})
    return points


def room_lines(rooms: dict) -> dict:
    """The paired gaps (:data:`ROOM_METRICS`: residual, run-up; not the return, which is at
    other weights) of each oracle at each scaled weight and of each goal's room against
    knots, keyed by the line's text.  ``rooms``: ``{"knots": result, "rooms": [room, ...],
    "weight": the agent's residual weight}``, each room ``{"label", "search", "frontier":
    [(weight, result), ...], "room": result}``."""
    knots = rooms["knots"]
    k_mean = knots.summary()["residual_vibration"]["mean"]
    lines = {}
    for room in rooms["rooms"]:
        for w, r in room["frontier"]:
            lines[f"{_oracle_label(room)} at residual weight {w:g} - knots"] = {
                k: paired_gap(r, knots, k) for k in ROOM_METRICS}
        r_mean = room["room"].summary()["residual_vibration"]["mean"]
        gap = {k: paired_gap(room["room"], knots, k) for k in ROOM_METRICS}
        cut = gap["residual_vibration"]
        weights = ", ".join(f"{w:g}" for w, _ in room["frontier"])
        lines[f"{room['label']} - knots (per machine the least residual among knots and the "
              f"{_oracle_label(room)} at residual weights {rooms['weight']:g}, {weights} (at "
              f"{weights}: {room['search']}), at a mean run-up no longer than knots': "
              f"{r_mean:.4g} against {k_mean:.4g} W_r/e, "
              f"{100 * cut['mean'] / k_mean:+.0f} % [{100 * cut['ci_low'] / k_mean:+.0f}, "
              f"{100 * cut['ci_high'] / k_mean:+.0f}] of knots' mean; the goal asks -20 %)"
              ] = gap
    return lines
