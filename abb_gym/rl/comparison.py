"""A trained agent against the strongest baselines and the per-machine oracle on its held-out
machines: the runs of the feedback-gap study (``agents/evaluate.py``).

For each agent, on the agent's environment and scene, the held-out test machines its config
names (preset ``test``, or ``varied_test`` for an agent trained on ``varied``; episode k:
seed + k) with the agent's own reward weights (:func:`agent_setting`), under

* ``ppo:<agent>`` and ``replay:ppo:<agent>`` (its own actions on the nominal machine, replayed
  open-loop: the difference is the agent's **feedback value**);
* ``baseline:knots``, the strongest open-loop profile (CMA-ES-tuned speed knots);
* the closed-loop hand-designed baselines ``retry`` and ``resonance_dwell``;
* the dwell families, ``speed_reduction`` and ``ramp``.

The baselines are tuned on the agent's training preset, with its reward: ``configs/baselines``
for ``train``, ``configs/<preset>/baselines`` for another (``configs/varied/baselines``); a
family with no parameters tuned on that preset is left out (:func:`tuned_families`).  For
every agent, on ``test`` as on ``varied_test``, the **oracle** (:mod:`abb_gym.baselines.oracle`:
``knots`` tuned by CMA-ES on each test machine alone, from the tuned ``knots``) joins the
table, and a **feedback-gap** table puts the families side by side
(:func:`abb_gym.evaluation.feedback_gap.gap_section`): best open loop | closed-loop hand design
| PPO | oracle | oracle, balls unknown (the oracle that knows the machine but not where its
balls start: ``knots`` tuned on each machine, each candidate scored on
``machine_oracle_draws`` ball starts drawn as the preset draws them, kept in
``..._balls_unknown.json``).  The oracle's runs are kept in
``<out>/oracle/<scene>_<preset>_seed<seed>.json`` and reused while scene, preset, seed,
reward, budget and start match, so agents that share them (the three yoshida_odd ``train``
agents) share one oracle; a file holds the runs of every reward its agents use
(``oracle_budget`` 0: no oracle).  The machines' searches run on the executor given (local
processes or Ray), with the same rows either way.

The oracle plans on each machine as drawn, the balls' initial angles included, which no drive
measures.  The gap section therefore also replays each machine's oracle profile, and the tuned
``knots`` beside it, with the balls started elsewhere (``elsewhere_draws`` sets of angles per
machine, drawn as the preset draws them: :func:`abb_gym.baselines.oracle.balls_elsewhere`):
what is left of the oracle's gain there did not come from knowing where the balls start
(:func:`elsewhere_gap`; ``elsewhere_draws`` 0: not measured).

The oracle plans at the agent's reward, which trades residual against run-up time at its
weights; the goal asks for less residual at no longer run-up time.  The **goal's room**
(:func:`goal_room_of`) answers how much of that a planner that knows each machine can have:
the oracle again at ``room_factors`` times the agent's residual weight (from the tuned
``knots``, kept in the oracle's file), then per machine the least residual among ``knots``,
the oracle and those runs at a mean settled run-up no longer than knots'
(:func:`abb_gym.baselines.oracle.goal_room`).  The same for the oracle with the balls unknown
(at the same weights, with its own budget and draws) gives the room of a planner that knows
the machine but not where its balls start.  The lines give residual and run-up time against
``knots``, not the return (the runs' returns are at other weights); ``pareto.png`` shows them
as stars (``room_factors`` empty: not measured).

On DwellProfile, the baselines its one action cannot express (every one above after tuning,
since they carry their own run-up acceleration) run on RunUpSpeed, on the same machines
(:func:`abb_gym.evaluation.evaluate.policy_env_id`); the tables mark the environment.

:func:`compare_agent` writes the report of ``abb-gym evaluate`` to ``<out>/<agent>/``
(summary.md, episodes.csv, evaluation.json, timeseries.png, and pareto.png: residual against
settled run-up time, every family in one chart) and ``<out>/<agent>/comparison.json``, and
returns the agent's Markdown section (:mod:`abb_gym.evaluation.results_pages` publishes it).
"""
from __future__ import annotations

import csv
import json
import os
from pathlib import Path
from typing import Iterable

import numpy as np

from ..evaluation.feedback_gap import (STRONGEST_OPEN_LOOP, AgentSetting, GapStudy,
                                       agent_section, gap_section, goal_check, paired_gaps,
                                       room_points)
from ..tables import markdown_table

__all__ = ["agent_setting", "preset_configs", "configs_folder", "tuned_families",
           "scaled_residual", "oracle_run", "elsewhere_gap", "goal_room_of", "compare_agent",
           "training_section"]


def agent_setting(agent: str | Path, preset: str | None = None) -> AgentSetting:
    """Where and how ``agent`` (a shipped agent's name or a run folder) is compared: its
    environment, scene, training preset, held-out preset (``preset`` if given, else its
    config's evaluation preset) and reward weights (from its config.yml), and the baselines
    tuned on its training preset (:func:`preset_configs`)."""
    from .agent import resolve_agent_path
    from .agent_files import check_folder
    from .config import load_config
    from .env_factory import eval_env_kwargs
    folder = resolve_agent_path(agent)
    files = check_folder(folder)
    env_id, scene = files.env_id, files.manifest["scene"]
    cfg = load_config(folder / "config.yml", env_id)
    held_out = eval_env_kwargs(cfg)
    train_preset = cfg.env_kwargs.get("preset", "train")
    return AgentSetting(folder=folder, env_id=env_id, scene=scene, train_preset=train_preset,
                        preset=preset or held_out["preset"],
                        env_kwargs={"reward": held_out["reward"]} if "reward" in held_out
                        else {},
                        configs=preset_configs(train_preset, scene))


def preset_configs(train_preset: str, scene: str) -> Path | None:
    """The configuration folder of baselines tuned on ``train_preset`` (``configs/<preset>``),
    or None for ``train`` and wherever the shipped ``configs/baselines/<scene>.yaml`` was
    tuned on ``train_preset`` (a scene used with one preset only, such as the laundry's)."""
    import yaml

    from ..resources import shipped_folder
    if train_preset == "train":
        return None
    shipped = shipped_folder("baselines") / f"{scene}.yaml"
    if shipped.is_file() and (yaml.safe_load(shipped.read_text()) or {}).get(
            "preset") == train_preset:
        return None
    folder = shipped_folder("baselines").parent / train_preset
    if not (folder / "baselines" / f"{scene}.yaml").is_file():
        raise ValueError(f"no baselines tuned on preset {train_preset!r} for {scene}: tune them "
                         f"with abb-gym tune-baselines --scene {scene} --preset {train_preset} "
                         f"--out {folder / 'baselines'}")
    return folder


def configs_folder(folder: Path | None):
    """A block that searches ``folder`` for configuration files (the baselines an agent is
    compared with) before the shipped ones; None: the shipped ones alone."""
    from unittest import mock

    from ..resources import ENV_VAR
    return mock.patch.dict(os.environ, {} if folder is None else {ENV_VAR: str(folder)})


def tuned_families(setting: AgentSetting, wanted: Iterable[str]) -> list[str]:
    """The baseline families of ``wanted`` tuned on the agent's training preset (all of them
    for ``train``, whose untuned families run their defaults)."""
    if setting.configs is None:
        return list(wanted)
    from ..baselines.baseline_policy import tuned_parameters
    with configs_folder(setting.configs):
        return [f for f in wanted if tuned_parameters(setting.scene, f) is not None]


def scaled_residual(env_kwargs: dict, factor: float) -> dict:
    """``env_kwargs`` with the reward's residual weight multiplied by ``factor``."""
    from ..envs.config import RewardWeights
    reward = dict(env_kwargs.get("reward", {}))
    reward["residual"] = float(reward.get("residual", RewardWeights().residual)) * factor
    return {**env_kwargs, "reward": reward}


def oracle_run(setting: AgentSetting, study: GapStudy, ball_draws: int = 0,
               residual_factor: float = 1.0, executor=None) -> dict:
    """The oracle of the agent's test machines: machine by machine the best of the per-machine
    searches from each start (the tuned knots, then the ``oracle_starts`` of its baselines
    file; :func:`abb_gym.baselines.oracle.best_of_runs`).  Each start's run is reused from
    ``<out>/oracle/`` if it matches, else computed on ``executor`` (minutes: a progress bar
    counts the candidates) and stored.  With ``ball_draws`` > 0 the oracle that knows the
    machine but not where its balls start (``study.machine_oracle_budget`` candidates, each
    scored on ``ball_draws`` ball starts; from the tuned knots only, since each candidate costs
    ``ball_draws`` run-ups), kept in ``..._balls_unknown.json``.  With ``residual_factor``
    != 1 the oracle of the agent's reward with its residual weight scaled (from the tuned knots
    only), kept in the oracle's file beside the agent's own reward.  Call it inside
    :func:`configs_folder` of the agent's baselines."""
    from ..baselines.baseline_policy import oracle_starts, tuned_parameters
    from ..baselines.oracle import best_of_runs, oracle_matches, run_oracle
    suffix = "_balls_unknown" if ball_draws else ""
    path = (Path(study.out) / "oracle"
            / f"{setting.scene}_{setting.preset}_seed{study.seed}{suffix}.json")
    budget = (study.machine_oracle_budget if ball_draws
              else study.oracle_budget if residual_factor == 1 else study.room_oracle_budget)
    env_kwargs = (setting.env_kwargs if residual_factor == 1
                  else scaled_residual(setting.env_kwargs, residual_factor))
    starts = [tuned_parameters(setting.scene, STRONGEST_OPEN_LOOP)]
    if not ball_draws and residual_factor == 1:
        starts += oracle_starts(setting.scene, STRONGEST_OPEN_LOOP)
    stored = []
    if path.is_file():
        data = json.loads(path.read_text())
        stored = data["runs"] if "runs" in data else [data]
    runs, computed = [], False
    for k, start in enumerate(starts):
        run = next((r for r in stored if oracle_matches(
            r, setting.scene, setting.preset, study.seed, study.episodes, budget,
            env_kwargs, start=start, ball_draws=ball_draws)), None)
        if run is not None:
            print(f"oracle: reusing start {k + 1} of {len(starts)} from {path}", flush=True)
        else:
            unknown = f", each on {ball_draws} ball starts" if ball_draws else ""
            reward = "" if residual_factor == 1 else f", reward {env_kwargs['reward']}"
            print(f"oracle: tuning knots on each of {study.episodes} machines "
                  f"({budget} candidates each{unknown}{reward}, start {k + 1} of "
                  f"{len(starts)}) -> {path}", flush=True)
            run = run_oracle(setting.scene, setting.preset, study.episodes, study.seed,
                             budget, env_kwargs=env_kwargs, start=start,
                             ball_draws=ball_draws, executor=executor)
            computed = True
        runs.append(run)
    if computed:  # another reward's runs (another agent's oracle) stay in the file
        kept = runs + [r for r in stored if r.get("env_kwargs") != env_kwargs]
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"runs": kept}, indent=1, default=float))
    return best_of_runs(runs)


_ELSEWHERE: dict = {}


def elsewhere_gap(setting: AgentSetting, run: dict, study: GapStudy, executor=None) -> dict:
    """The paired gap oracle - knots with the balls started elsewhere (return, residual,
    run-up), computed once per scene, preset, seed and reward in a process (the yoshida_odd
    ``train`` agents share it)."""
    from ..baselines.baseline_policy import tuned_parameters
    from ..baselines.oracle import balls_elsewhere
    key = (setting.scene, setting.preset, study.seed, study.episodes, study.elsewhere_draws,
           json.dumps(setting.env_kwargs, sort_keys=True))
    if key not in _ELSEWHERE:
        print(f"oracle: {setting.scene} {setting.preset}, each machine's profile and knots "
              f"with the balls started elsewhere ({study.elsewhere_draws} draws)", flush=True)
        oracle, knots = balls_elsewhere(run, tuned_parameters(setting.scene, STRONGEST_OPEN_LOOP),
                                        study.elsewhere_draws, study.episodes,
                                        executor=executor)
        _ELSEWHERE[key] = paired_gaps(oracle, knots)
    return _ELSEWHERE[key]


def goal_room_of(setting: AgentSetting, study: GapStudy, run: dict, by_spec: dict,
                 unknown_run: dict | None = None, executor=None) -> dict:
    """The goal's room on the agent's test machines: the oracle again at each of
    ``study.room_factors`` times the agent's residual weight (:func:`oracle_run`,
    ``study.room_oracle_budget`` candidates), and the least residual that the runs of the
    oracle (``run``, the best of its starts, and those) and ``knots`` reach together at a mean
    run-up no longer than knots' (:func:`abb_gym.baselines.oracle.goal_room`).  With
    ``unknown_run`` (the oracle with the balls unknown) the same for that oracle, at the same
    weights: the room of a planner that knows the machine but not where its balls start.
    Returns ``{"knots": result, "rooms": [room, ...], "weight": the agent's residual
    weight}``, each room ``{"label", "search", "frontier": [(weight, result), ...], "room":
    result}`` (:func:`abb_gym.evaluation.feedback_gap.room_lines` writes it out)."""
    from ..baselines.oracle import goal_room, oracle_result
    knots = by_spec[f"baseline:{STRONGEST_OPEN_LOOP}"]
    kinds = [("goal room", run, 0, f"{study.room_oracle_budget} candidates from the tuned "
                                   f"knots")]
    if unknown_run is not None:
        kinds.append(("goal room, balls unknown", unknown_run, study.machine_oracle_draws,
                      f"{study.machine_oracle_budget} candidates from the tuned knots, each "
                      f"on {study.machine_oracle_draws} ball starts"))
    rooms = []
    for label, first, draws, search in kinds:
        runs, frontier = [first], []
        for factor in study.room_factors:
            scaled = oracle_run(setting, study, draws, residual_factor=factor,
                                executor=executor)
            runs.append(scaled)
            frontier.append((scaled["env_kwargs"]["reward"]["residual"],
                             oracle_result(scaled, study.episodes)))
        room = goal_room(knots, [dict(r, machines=r["machines"][:study.episodes])
                                 for r in runs])
        rooms.append({"label": label, "search": search, "frontier": frontier, "room": room})
    weight = scaled_residual(setting.env_kwargs, 1.0)["reward"]["residual"]
    return {"knots": knots, "rooms": rooms, "weight": weight}


def compare_agent(agent: str, study: GapStudy, executor=None) -> tuple[str, str, dict]:
    """Evaluate ``agent`` (a shipped agent's name or a run folder) and its comparison (the
    module docstring); writes its report to ``<out>/<agent>/`` and returns (its Markdown
    section, the feedback-gap part of it or "", the report of ``comparison.json``)."""
    from ..baselines.oracle import oracle_result
    from ..evaluation.evaluate import evaluate
    from ..evaluation.report import write_report

    setting = agent_setting(agent, study.preset)
    ppo_spec = f"ppo:{agent}"
    with configs_folder(setting.configs):
        baselines = tuned_families(setting, study.baselines)
        specs = [ppo_spec, f"replay:{ppo_spec}"] + [f"baseline:{b}" for b in baselines]
        results = [evaluate(setting.env_id, setting.scene, spec, study.episodes, study.seed,
                            setting.preset, **setting.env_kwargs) for spec in specs]
        by_spec = dict(zip(specs, results))
        oracle = elsewhere = unknown = room = None
        if study.oracle_budget > 0 and STRONGEST_OPEN_LOOP in baselines:
            run = oracle_run(setting, study, executor=executor)
            oracle = oracle_result(run, study.episodes)
            if study.elsewhere_draws > 0:
                elsewhere = elsewhere_gap(setting, run, study, executor)
            unknown_run = None
            if study.machine_oracle_draws > 0 and study.machine_oracle_budget > 0:
                unknown_run = oracle_run(setting, study, study.machine_oracle_draws,
                                         executor=executor)
                unknown = oracle_result(unknown_run, study.episodes)
            if study.room_factors:
                room = goal_room_of(setting, study, run, by_spec, unknown_run, executor)
    shown = results + [r for r in (oracle, unknown) if r is not None]
    out = Path(study.out) / setting.folder.name
    write_report(shown, out, room_points(room) if room else None)
    check = {}
    if STRONGEST_OPEN_LOOP in baselines:
        check = goal_check(results[0], results[1], by_spec[f"baseline:{STRONGEST_OPEN_LOOP}"])
    gap_text, gap = "", {}
    if oracle is not None:
        gap_text, gap = gap_section(setting, study, by_spec, ppo_spec, oracle, elsewhere,
                                    unknown, room)
    text = agent_section(setting, study, shown, check, gap_text)
    report = {"agent": setting.folder.name, "env_id": setting.env_id, "scene": setting.scene,
              "episodes": study.episodes, "seed": study.seed, "preset": setting.preset,
              "train_preset": setting.train_preset, "env_kwargs": setting.env_kwargs,
              "summaries": {r.policy: dict(r.summary(), env_id=r.env_id) for r in shown},
              "goal": check, "feedback_gap": gap}
    (out / "comparison.json").write_text(json.dumps(report, indent=1, default=float))
    print("\n" + text, flush=True)
    return text, gap_text, report


def training_section(agents: Iterable[str], png: Path, page: Path | None) -> str:
    """Every agent's training cost (its config.yml ``_run``) and its learning curves (its
    ``evaluations.csv``, drawn to ``png``) as Markdown, the chart linked relative to the
    Markdown file ``page`` (None: by its path)."""
    from ..plots import plot_training_curves
    from .agent import resolve_agent_path
    from .agent_files import check_folder
    rows, curves = [], {}
    for agent in agents:
        folder = resolve_agent_path(agent)
        run = check_folder(folder).run
        penv = run["policy_env"]
        rows.append({"agent": f"`{folder.name}`",
                     "env, scene": f"{run['env_id'].split('/')[-1].removesuffix('-v0')}, "
                                   f"{penv['scene']}",
                     "env steps": f"{run['env_steps'] / 1e6:.2f} M"
                                  if run["env_steps"] >= 1e5 else f"{run['env_steps']:,}",
                     "decision interval": f"{penv['control_interval'] * 1e3:g} ms"
                                          if penv.get("kind") != "dwell" else "one per run-up",
                     "wall time": f"{run['wall_time_s']:.0f} s "
                                  f"({run['wall_time_s'] / 60:.1f} min)",
                     "env-steps/s": f"{run['env_steps_per_s']:,.0f}"})
        with open(folder / "evaluations.csv", newline="") as fh:
            table = list(csv.DictReader(fh))
        curves[folder.name] = {k: np.array([float(r[k]) for r in table]) for k in table[0]}
    png = plot_training_curves(curves, Path(png))
    link = os.path.relpath(png, Path(page).parent) if page is not None else str(png)
    return (markdown_table(rows) + f"\n\n![learning curves of every shipped agent]({link})\n\n"
            "The curves are the held-out evaluations during training (64 episodes of the "
            "agent's evaluation preset every 250 k steps; the DwellProfile agent's every few "
            "thousand run-ups), each in its own reward; agents trained before the settled-run-up "
            "metrics existed measured the residual with the first wave's definition.\n")
