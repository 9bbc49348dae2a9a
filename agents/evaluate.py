#!/usr/bin/env python
"""Evaluate the shipped PPO agents against the strongest baselines on held-out machines, and
measure the feedback gap.

A thin script over :mod:`abb_gym.evaluation` (the same episodes, metrics and report as
``abb-gym evaluate``).  For each agent it evaluates, on the agent's environment and scene, the
held-out test machines its config names (preset ``test``, or ``varied_test`` for an agent
trained on ``varied``; episode k: seed + k) with the agent's own reward weights, under

* ``ppo:<agent>`` and ``replay:ppo:<agent>`` (its own actions on the nominal machine, replayed
  open-loop: the difference is the agent's **feedback value**);
* ``baseline:knots``, the strongest open-loop profile (CMA-ES-tuned speed knots);
* the closed-loop hand-designed baselines ``retry`` and ``resonance_dwell``;
* the dwell families, ``speed_reduction`` and ``ramp``.

The baselines are tuned on the agent's training preset, with its reward: ``configs/baselines``
for ``train``, ``configs/<preset>/baselines`` for another (``configs/varied/baselines``); a
family with no parameters tuned on that preset is left out.  For every agent, on ``test`` as
on ``varied_test``, the **oracle** (:mod:`abb_gym.baselines.oracle`: ``knots`` tuned by CMA-ES
on each test machine alone, from the tuned ``knots``) joins the table, and a **feedback-gap**
table puts the families side by side: best open loop | closed-loop hand design | PPO |
oracle | oracle, balls unknown (the oracle that knows the machine but not where its balls start:
``knots`` tuned on each machine, each candidate scored on ``--machine-oracle-draws`` ball starts
drawn as the preset draws them, kept in ``..._balls_unknown.json``).  The oracle's runs are
kept in ``<out>/oracle/<scene>_<preset>_seed<seed>.json`` and reused while scene, preset,
seed, reward, budget and start match, so agents that share them (the three yoshida_odd
``train`` agents) share one oracle; a file holds the runs of every reward its agents use
(``--oracle-budget 0``: no oracle).  The machines' searches run in parallel, on
``--workers`` local processes (default: every core) or on Ray (``--ray``), with the same rows
either way.

The oracle plans on each machine as drawn, the balls' initial angles included, which no drive
measures.  The gap section therefore also replays each machine's oracle profile, and the tuned
``knots`` beside it, with the balls started elsewhere (``--elsewhere-draws`` sets of angles per
machine, drawn as the preset draws them: :func:`abb_gym.baselines.oracle.balls_elsewhere`):
what is left of the oracle's gain there did not come from knowing where the balls start
(``--elsewhere-draws 0``: not measured).

The oracle plans at the agent's reward, which trades residual against run-up time at its
weights; the goal below asks for less residual at no longer run-up time.  The **goal's room**
answers how much of that a planner that knows each machine can have: the oracle again at
``--room-factors`` times the agent's residual weight (from the tuned ``knots``, kept in the
oracle's file), then per machine the least residual among ``knots``, the oracle and those runs
at a mean settled run-up no longer than knots' (:func:`abb_gym.baselines.oracle.goal_room`).
The same for the oracle with the balls unknown (at the same weights, with its own budget and
draws) gives the room of a planner that knows the machine but not where its balls start.  The
lines give residual and run-up time against ``knots``, not the return (the runs' returns are
at other weights); ``pareto.png`` shows them as stars (``--room-factors`` with no value: not
measured).

On DwellProfile, the baselines its one action cannot express (every one above after tuning,
since they carry their own run-up acceleration) run on RunUpSpeed, on the same machines
(:func:`abb_gym.evaluation.evaluate.policy_env_id`); the tables mark the environment.

It writes the report of ``abb-gym evaluate`` to ``<out>/<agent>/`` (summary.md, episodes.csv,
evaluation.json, timeseries.png, and pareto.png: residual against settled run-up time, every
family in one chart), ``<out>/<agent>/comparison.json`` and ``<out>/comparison.md``.  Run
without agent names, it evaluates every shipped agent.  ``--readme FILE`` regenerates FILE's
marked sections (``<!-- comparison:begin/end -->``: every table; ``<!-- training:begin/end
-->``: the training cost and curves), ``--gap-readme FILE`` the feedback-gap tables alone
(``<!-- feedback-gap:begin/end -->``).

The goal check (the project's "Tasks where feedback pays" goal), per agent, against
``baseline:knots`` on the same machines:

* residual vibration (mean W_r/e over the settling window, at the operating speed) at least
  20 % lower, with the paired difference knots - PPO and its 95 % interval;
* settled run-up time (start of the final stay in the operating band) no longer;
* feedback value: the open-loop replay's residual at least 10 % worse, and its paired
  difference positive at 95 % confidence.

    python agents/evaluate.py                                # every shipped agent
    python agents/evaluate.py runup_speed_yoshida_odd --episodes 200 --seed 0
    python agents/evaluate.py runs/x/s0-... --baselines knots retry --readme notes.md
"""
import argparse
import json
import os
import sys
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

REPO = Path(__file__).resolve().parents[1]
STRONGEST_OPEN_LOOP = "knots"
CLOSED_LOOP = ("retry", "resonance_dwell")
DEFAULT_BASELINES = (STRONGEST_OPEN_LOOP, *CLOSED_LOOP, "speed_dwell", "accel_dwell",
                     "decel_dwell", "speed_reduction", "ramp")
RESIDUAL_GOAL = 0.20   # at least 20 % lower residual than knots
FEEDBACK_GOAL = 0.10   # the replay at least 10 % worse than the agent
BEGIN, END = "<!-- comparison:begin -->", "<!-- comparison:end -->"
GAP_BEGIN, GAP_END = "<!-- feedback-gap:begin -->", "<!-- feedback-gap:end -->"
TRAINING_BEGIN, TRAINING_END = "<!-- training:begin -->", "<!-- training:end -->"
PAIRED_METRICS = ("return", "residual_vibration", "run_up_time")
ROOM_METRICS = ("residual_vibration", "run_up_time")
GAP_COLUMNS = ("best open loop", "closed loop, hand-designed", "PPO (drive measurements)",
               "oracle", "oracle, balls unknown")


def goal_check(ppo, replay, knots) -> dict:
    """The goal of the module docstring from three :class:`EvaluationResult` on the same
    machines."""
    from abb_gym.evaluation.replay import feedback_value
    from abb_gym.evaluation.report import paired_gap

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
    from abb_gym.evaluation.report import cell
    return cell(stat, digits, digits)


def agent_table(results) -> str:
    """One row per policy: environment, at-speed share, settled run-up time, residual."""
    from abb_gym.tables import markdown_table
    rows = []
    for r in results:
        s = r.summary()
        rows.append({"policy": r.policy, "env": r.env_id.split("/")[-1].removesuffix("-v0"),
                     "at speed": _cell(s["at_speed"], 2),
                     "settled run-up [s]": _cell(s["run_up_time"]),
                     "residual [W_r/e]": _cell(s["residual_vibration"]),
                     "peak speed [w_op]": _cell(s["peak_speed"]),
                     "return": _cell(s["return"])})
    return markdown_table(rows)


def goal_line(check: dict) -> str:
    import math
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


class AgentSetting:
    """Where and how an agent is compared: its environment, scene, training preset, held-out
    preset and reward weights (from its config.yml), and the baselines tuned on its training
    preset."""

    def __init__(self, agent: str, preset: str | None):
        from abb_gym.rl.agent import resolve_agent_path
        from abb_gym.rl.agent_files import check_folder
        from abb_gym.rl.config import eval_env_kwargs, load_config
        self.folder = resolve_agent_path(agent)
        files = check_folder(self.folder)
        self.env_id, self.scene = files.env_id, files.manifest["scene"]
        cfg = load_config(self.folder / "config.yml", self.env_id)
        held_out = eval_env_kwargs(cfg)
        self.train_preset = cfg.env_kwargs.get("preset", "train")
        self.preset = preset or held_out["preset"]
        self.env_kwargs = {"reward": held_out["reward"]} if "reward" in held_out else {}
        self.configs = preset_configs(self.train_preset, self.scene)

    def families(self, wanted) -> list[str]:
        """The baseline families of ``wanted`` tuned on the training preset (all of them for
        ``train``, whose untuned families run their defaults)."""
        if self.configs is None:
            return list(wanted)
        from abb_gym.baselines.baseline_policy import tuned_parameters
        with configs_folder(self.configs):
            return [f for f in wanted if tuned_parameters(self.scene, f) is not None]


def preset_configs(train_preset: str, scene: str) -> Path | None:
    """The configuration folder of baselines tuned on ``train_preset`` (``configs/<preset>``),
    or None for ``train`` (the shipped ``configs/baselines``)."""
    from abb_gym.resources import shipped_folder
    if train_preset == "train":
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

    from abb_gym.resources import ENV_VAR
    return mock.patch.dict(os.environ, {} if folder is None else {ENV_VAR: str(folder)})


def scaled_residual(env_kwargs: dict, factor: float) -> dict:
    """``env_kwargs`` with the reward's residual weight multiplied by ``factor``."""
    from abb_gym.envs.config import RewardWeights
    reward = dict(env_kwargs.get("reward", {}))
    reward["residual"] = float(reward.get("residual", RewardWeights().residual)) * factor
    return {**env_kwargs, "reward": reward}


def oracle_executor(args):
    """Where the oracle's per-machine searches and its replays with the balls elsewhere run:
    ``--workers`` local processes (default: every core), or Ray with ``--ray`` /
    ``--ray-address``; the results do not depend on it
    (:func:`abb_gym.baselines.tuner.tune_per_machine`,
    :func:`abb_gym.baselines.oracle.balls_elsewhere`)."""
    from abb_gym.execution.cli import executor_from_args
    return executor_from_args(args)


def oracle_run(setting: AgentSetting, args, ball_draws: int = 0,
               residual_factor: float = 1.0) -> dict:
    """The oracle of the agent's test machines: machine by machine the best of the per-machine
    searches from each start (the tuned knots, then the ``oracle_starts`` of its baselines
    file; :func:`abb_gym.baselines.oracle.best_of_runs`).  Each start's run is reused from
    ``<out>/oracle/`` if it matches, else computed (minutes: a progress bar counts the
    candidates) and stored.  With ``ball_draws`` > 0 the oracle that knows the machine but not
    where its balls start (``--machine-oracle-budget`` candidates, each scored on
    ``ball_draws`` ball starts; from the tuned knots only, since each candidate costs
    ``ball_draws`` run-ups), kept in ``..._balls_unknown.json``.  With ``residual_factor``
    != 1 the oracle of the agent's reward with its residual weight scaled (from the tuned knots
    only), kept in the oracle's file beside the agent's own reward."""
    from abb_gym.baselines.baseline_policy import oracle_starts, tuned_parameters
    from abb_gym.baselines.oracle import best_of_runs, oracle_matches, run_oracle
    suffix = "_balls_unknown" if ball_draws else ""
    path = (Path(args.out) / "oracle"
            / f"{setting.scene}_{setting.preset}_seed{args.seed}{suffix}.json")
    budget = (args.machine_oracle_budget if ball_draws
              else args.oracle_budget if residual_factor == 1 else room_budget(args))
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
            r, setting.scene, setting.preset, args.seed, args.episodes, budget,
            env_kwargs, start=start, ball_draws=ball_draws)), None)
        if run is not None:
            print(f"oracle: reusing start {k + 1} of {len(starts)} from {path}", flush=True)
        else:
            unknown = f", each on {ball_draws} ball starts" if ball_draws else ""
            reward = "" if residual_factor == 1 else f", reward {env_kwargs['reward']}"
            print(f"oracle: tuning knots on each of {args.episodes} machines "
                  f"({budget} candidates each{unknown}{reward}, start {k + 1} of "
                  f"{len(starts)}) -> {path}", flush=True)
            run = run_oracle(setting.scene, setting.preset, args.episodes, args.seed,
                             budget, env_kwargs=env_kwargs, start=start,
                             ball_draws=ball_draws, executor=oracle_executor(args))
            computed = True
        runs.append(run)
    if computed:  # another reward's runs (another agent's oracle) stay in the file
        kept = runs + [r for r in stored if r.get("env_kwargs") != env_kwargs]
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"runs": kept}, indent=1, default=float))
    return best_of_runs(runs)


def paired_gaps(a, b) -> dict:
    """The paired differences ``a - b`` of :data:`PAIRED_METRICS`, machine by machine."""
    from abb_gym.evaluation.report import paired_gap
    return {k: paired_gap(a, b, k) for k in PAIRED_METRICS}


def _env_note(columns: dict) -> str:
    """A sentence naming the environments when the table's families ran on different ones
    (the oracle plans speed profiles on RunUpSpeed; the torque agent's baselines run on
    RunUpTorque through its speed loop), all on the same machines."""
    envs = {label: r.env_id.split("/")[-1] for label, r in columns.items()}
    if len(set(envs.values())) == 1:
        return ""
    return ("  Environments (the same machines): " + ", ".join(
        f"{label} on {env}" for label, env in envs.items()) + ".")


_ELSEWHERE: dict = {}


def elsewhere_gap(setting: AgentSetting, run: dict, args) -> dict:
    """The paired gap oracle - knots with the balls started elsewhere (return, residual,
    run-up), computed once per scene, preset, seed and reward in a process (the yoshida_odd
    ``train`` agents share it)."""
    from abb_gym.baselines.baseline_policy import tuned_parameters
    from abb_gym.baselines.oracle import balls_elsewhere
    key = (setting.scene, setting.preset, args.seed, args.episodes, args.elsewhere_draws,
           json.dumps(setting.env_kwargs, sort_keys=True))
    if key not in _ELSEWHERE:
        print(f"oracle: {setting.scene} {setting.preset}, each machine's profile and knots "
              f"with the balls started elsewhere ({args.elsewhere_draws} draws)", flush=True)
        oracle, knots = balls_elsewhere(run, tuned_parameters(setting.scene, STRONGEST_OPEN_LOOP),
                                        args.elsewhere_draws, args.episodes,
                                        executor=oracle_executor(args))
        _ELSEWHERE[key] = paired_gaps(oracle, knots)
    return _ELSEWHERE[key]


def goal_room_of(setting: AgentSetting, args, run: dict, by_spec: dict,
                 unknown_run: dict | None = None) -> dict:
    """The goal's room on the agent's test machines: the oracle again at each of
    ``--room-factors`` times the agent's residual weight (:func:`oracle_run`, ``--room-budget``
    candidates), and the least residual that the runs of the oracle (``run``, the best of its
    starts, and those) and ``knots`` reach together at a mean run-up no longer than knots'
    (:func:`abb_gym.baselines.oracle.goal_room`).  With ``unknown_run`` (the oracle with the
    balls unknown) the same for that oracle, at the same weights: the room of a planner that
    knows the machine but not where its balls start.  Returns ``{"knots": result, "rooms":
    [room, ...], "weight": the agent's residual weight}``, each room ``{"label", "search",
    "frontier": [(weight, result), ...], "room": result}``."""
    from abb_gym.baselines.oracle import goal_room, oracle_result
    knots = by_spec[f"baseline:{STRONGEST_OPEN_LOOP}"]
    kinds = [("goal room", run, 0, f"{room_budget(args)} candidates from the tuned knots")]
    if unknown_run is not None:
        kinds.append(("goal room, balls unknown", unknown_run, args.machine_oracle_draws,
                      f"{args.machine_oracle_budget} candidates from the tuned knots, each "
                      f"on {args.machine_oracle_draws} ball starts"))
    rooms = []
    for label, first, draws, search in kinds:
        runs, frontier = [first], []
        for factor in args.room_factors:
            scaled = oracle_run(setting, args, draws, residual_factor=factor)
            runs.append(scaled)
            frontier.append((scaled["env_kwargs"]["reward"]["residual"],
                             oracle_result(scaled, args.episodes)))
        room = goal_room(knots, [dict(r, machines=r["machines"][:args.episodes])
                                 for r in runs])
        rooms.append({"label": label, "search": search, "frontier": frontier, "room": room})
    weight = scaled_residual(setting.env_kwargs, 1.0)["reward"]["residual"]
    return {"knots": knots, "rooms": rooms, "weight": weight}


def room_budget(args) -> int:
    """CMA-ES candidates per machine of the oracle at a scaled residual weight."""
    return args.oracle_budget if args.room_budget is None else args.room_budget


def _oracle_label(room: dict) -> str:
    """"oracle" or "oracle with the balls unknown", after the room's label."""
    return "oracle" + room["label"][len("goal room"):].replace(", balls", " with the balls")


def room_points(rooms: dict) -> list[dict]:
    """The goal's rooms as points of the report's chart of residual against run-up time."""
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
    """The paired gaps (residual, run-up; not the return, which is at other weights) of each
    oracle at each scaled weight and of each goal's room against knots."""
    from abb_gym.evaluation.report import paired_gap
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


def gap_section(setting: AgentSetting, by_spec: dict, ppo_spec: str, oracle, args,
                elsewhere: dict | None = None, unknown=None, room: dict | None = None
                ) -> tuple[str, dict]:
    """The feedback-gap table (the families side by side) and its paired gaps; ``elsewhere``:
    the oracle - knots gap with the balls started elsewhere (:func:`elsewhere_gap`);
    ``unknown``: the oracle that knows the machine but not its balls (a fifth column);
    ``room``: the goal's room (:func:`goal_room_of`)."""
    from abb_gym.evaluation.replay import feedback_value
    from abb_gym.evaluation.report import family_table
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
        gaps[f"oracle - knots, balls started elsewhere ({args.elsewhere_draws} draws per "
             f"machine, both on the same draws)"] = elsewhere
    if room is not None:
        gaps.update(room_lines(room))
    reward = setting.env_kwargs.get("reward", {})
    text = (f"#### Feedback gap: {setting.scene}, {setting.preset} "
            f"({setting.env_id.split('/')[-1]}, trained on {setting.train_preset})\n\n"
            f"{args.episodes} machines (seed {args.seed}), reward weights {reward or 'default'}"
            f", mean [95 % CI].  Best open loop and closed-loop hand design (the better return "
            f"of {', '.join(CLOSED_LOOP)}) tuned on {setting.train_preset}; the oracle tunes "
            f"knots on each machine alone ({args.oracle_budget} candidates from each start: the "
            f"tuned knots and the earlier tunings its baselines file lists; the best per "
            f"machine)"
            + ("" if unknown is None else
               f"; the oracle with the balls unknown knows the machine but not where its balls"
               f" start ({args.machine_oracle_budget} candidates from the tuned knots, each "
               f"scored on {args.machine_oracle_draws} ball starts drawn as the preset draws "
               f"them, then run on the machine as drawn)")
            + f".  Agent: `{setting.folder.name}`."
            + _env_note(columns) + "\n\n" + family_table(columns) + "\n\n")
    for name, gap in gaps.items():
        text += f"- {name}: " + ", ".join(
            f"{k} {_cell(v)}" for k, v in gap.items()
            if k in PAIRED_METRICS) + "\n"
    return text, {"columns": {k: r.policy for k, r in columns.items()}, "gaps": gaps}


def evaluate_agent(agent: str, args) -> tuple[str, str, dict]:
    """(comparison text, feedback-gap text or "", report) of one agent."""
    from abb_gym.baselines.oracle import oracle_result
    from abb_gym.evaluation.evaluate import evaluate
    from abb_gym.evaluation.report import write_report

    setting = AgentSetting(agent, args.preset)
    ppo_spec = f"ppo:{agent}"
    with configs_folder(setting.configs):
        baselines = setting.families(args.baselines)
        specs = [ppo_spec, f"replay:{ppo_spec}"] + [f"baseline:{b}" for b in baselines]
        results = [evaluate(setting.env_id, setting.scene, spec, args.episodes, args.seed,
                            setting.preset, **setting.env_kwargs) for spec in specs]
        by_spec = dict(zip(specs, results))
        oracle = elsewhere = unknown = room = None
        if args.oracle_budget > 0 and STRONGEST_OPEN_LOOP in baselines:
            run = oracle_run(setting, args)
            oracle = oracle_result(run, args.episodes)
            if args.elsewhere_draws > 0:
                elsewhere = elsewhere_gap(setting, run, args)
            unknown_run = None
            if args.machine_oracle_draws > 0 and args.machine_oracle_budget > 0:
                unknown_run = oracle_run(setting, args, args.machine_oracle_draws)
                unknown = oracle_result(unknown_run, args.episodes)
            if args.room_factors:
                room = goal_room_of(setting, args, run, by_spec, unknown_run)
    shown = results + [r for r in (oracle, unknown) if r is not None]
    out = Path(args.out) / setting.folder.name
    write_report(shown, out, room_points(room) if room else None)
    check = {}
    if STRONGEST_OPEN_LOOP in baselines:
        check = goal_check(results[0], results[1], by_spec[f"baseline:{STRONGEST_OPEN_LOOP}"])
    where = (f"preset {setting.preset}" + ("" if setting.configs is None else
                                            f", baselines tuned on {setting.train_preset}"))
    text = (f"### {setting.folder.name}: {setting.env_id.split('/')[-1]} on {setting.scene}"
            f"\n\n{args.episodes} test episodes ({where}, seed {args.seed}), mean "
            f"[95 % CI]; the same machines for every row.\n\n"
            + agent_table(shown) + "\n")
    if check:
        text += f"\nGoal against knots: {goal_line(check)}.\n"
    gap_text, gap = "", {}
    if oracle is not None:
        gap_text, gap = gap_section(setting, by_spec, ppo_spec, oracle, args, elsewhere,
                                    unknown, room)
        text += "\n" + gap_text
    report = {"agent": setting.folder.name, "env_id": setting.env_id, "scene": setting.scene,
              "episodes": args.episodes, "seed": args.seed, "preset": setting.preset,
              "train_preset": setting.train_preset, "env_kwargs": setting.env_kwargs,
              "summaries": {r.policy: dict(r.summary(), env_id=r.env_id) for r in shown},
              "goal": check, "feedback_gap": gap}
    (out / "comparison.json").write_text(json.dumps(report, indent=1, default=float))
    print("\n" + text, flush=True)
    return text, gap_text, report


def training_section(agents: list[str], out: Path, readme: Path | None) -> str:
    """Every agent's training cost (its config.yml ``_run``) and its learning curves (its
    ``evaluations.csv``, drawn to ``<out>/training_curves.png``) as Markdown."""
    import csv

    import numpy as np

    from abb_gym.plots import plot_training_curves
    from abb_gym.rl.agent import resolve_agent_path
    from abb_gym.rl.agent_files import check_folder
    from abb_gym.tables import markdown_table
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
    png = plot_training_curves(curves, Path(out) / "training_curves.png")
    link = os.path.relpath(png, readme.parent) if readme is not None else str(png)
    return (markdown_table(rows) + f"\n\n![learning curves of every shipped agent]({link})\n\n"
            "The curves are the held-out evaluations during training (64 episodes of the "
            "agent's evaluation preset every 250 k steps; the DwellProfile agent's every few "
            "thousand run-ups), each in its own reward; agents trained before the settled-run-up "
            "metrics existed measured the residual with the first wave's definition.\n")


def replace_between_markers(path: Path, text: str, begin: str = BEGIN, end: str = END
                            ) -> None:
    """Replace what lies between the markers ``begin`` and ``end`` of ``path`` by ``text``."""
    old = path.read_text()
    if begin not in old or end not in old:
        raise ValueError(f"{path} has no {begin} ... {end} section to regenerate")
    head, rest = old.split(begin, 1)
    tail = rest.split(end, 1)[1]
    path.write_text(f"{head}{begin}\n{text}\n{end}{tail}")


def main(argv=None) -> int:
    from abb_gym.execution.cli import add_executor_arguments
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "),
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("agents", nargs="*",
                   help="shipped agent names (agents/trained/<name>) or run folders; default: "
                        "every shipped agent")
    p.add_argument("--episodes", type=int, default=100, help="test episodes per policy")
    p.add_argument("--seed", type=int, default=0, help="seed of the test set")
    p.add_argument("--preset", default=None,
                   help="environment preset of the test set (default: the agent's held-out "
                        "preset, test or the one its config names)")
    p.add_argument("--baselines", nargs="*", default=list(DEFAULT_BASELINES),
                   help="baseline families to compare with")
    p.add_argument("--oracle-budget", type=int, default=60,
                   help="CMA-ES candidates per machine of the oracle (0: no oracle)")
    p.add_argument("--machine-oracle-budget", type=int, default=24,
                   help="CMA-ES candidates per machine of the oracle that knows the machine but "
                        "not where its balls start (0: none)")
    p.add_argument("--machine-oracle-draws", type=int, default=3,
                   help="ball starts each candidate of that oracle is scored on (0: none)")
    p.add_argument("--elsewhere-draws", type=int, default=4,
                   help="ball-angle draws per machine on which the oracle's profiles and knots "
                        "run again with the balls started elsewhere (0: not measured)")
    p.add_argument("--room-factors", type=float, nargs="*", default=[3.0],
                   help="the oracle again at these multiples of the agent's residual weight "
                        "(from the tuned knots), for the goal's room: the least residual a "
                        "planner that knows each machine reaches at knots' run-up time (no "
                        "value: not measured)")
    p.add_argument("--room-budget", type=int, default=None,
                   help="CMA-ES candidates per machine of the oracle at those weights "
                        "(default: --oracle-budget)")
    p.add_argument("--out", default="agents/results", help="report folder")
    add_executor_arguments(p, resume=False)
    p.add_argument("--readme", type=Path, default=None,
                   help="regenerate the comparison section of this Markdown file")
    p.add_argument("--gap-readme", type=Path, default=None,
                   help="regenerate the feedback-gap section of this Markdown file")
    args = p.parse_args(argv)
    from abb_gym.rl.agent import trained_dir
    agents = args.agents or sorted(d.name for d in trained_dir().iterdir()
                                   if (d / "model.zip").exists())
    try:
        if args.episodes < 2:
            raise ValueError(f"--episodes must be >= 2 for confidence intervals "
                             f"(got {args.episodes})")
        if args.room_budget is not None and args.room_budget < 1:
            raise ValueError(f"--room-budget must be >= 1 (got {args.room_budget})")
        for flag in ("oracle_budget", "machine_oracle_budget", "machine_oracle_draws",
                     "elsewhere_draws"):
            if getattr(args, flag) < 0:
                raise ValueError(f"--{flag.replace('_', '-')} must be >= 0 "
                                 f"(got {getattr(args, flag)})")
        for factor in args.room_factors:
            if not factor > 0 or factor == 1 or factor > 1e4:
                raise ValueError(f"--room-factors must lie in (0, 10000] and differ from 1 "
                                 f"(the agent's own weight is the oracle's; got {factor})")
        oracle_executor(args)  # inconsistent --workers / --ray options, before anything runs
        for flag, path in (("--readme", args.readme), ("--gap-readme", args.gap_readme)):
            if path is not None and not path.is_file():
                raise ValueError(f"{flag} {path} is not a file")
        parts = [evaluate_agent(a, args) for a in agents]
    except ValueError as exc:
        print(f"evaluate: error: {exc}", file=sys.stderr)
        return 2
    body = "\n".join(text for text, _, _ in parts)
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "comparison.md").write_text(body)
    written = [str(Path(args.out) / "comparison.md")]
    if args.readme is not None:
        replace_between_markers(args.readme, body)
        if TRAINING_BEGIN in args.readme.read_text():
            replace_between_markers(args.readme, training_section(agents, Path(args.out),
                                                                  args.readme),
                                    TRAINING_BEGIN, TRAINING_END)
        written.append(str(args.readme))
    gaps = "\n".join(gap for _, gap, _ in parts if gap)
    if args.gap_readme is not None and gaps:
        replace_between_markers(args.gap_readme, gaps, GAP_BEGIN, GAP_END)
        written.append(str(args.gap_readme))
    print("wrote " + ", ".join(written))
    return 0


if __name__ == "__main__":
    sys.exit(main())
