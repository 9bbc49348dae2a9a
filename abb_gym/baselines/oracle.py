"""The upper bound of the feedback gap: an open-loop profile tuned on each test machine alone.

For each machine of a seeded test set (machine k: the reset with seed ``seed + k``, the machines
:func:`abb_gym.evaluation.evaluate.evaluate` runs), CMA-ES tunes a family (``knots``) on that
machine alone (:func:`abb_gym.baselines.tuner.tune_per_machine`), refining the parameters
tuned on the training distribution (``start``; one of its candidates, so the oracle never
scores below them on any machine).  The oracle knows everything about the machine, the
initial ball angles included, and plans with the simulator: no controller that has to find
the machine out can beat it with this family's profiles.  The profile tuned on the training
distribution (``baseline:knots``) is the lower bound; the gap between the two is the room a
controller that watches the machine has.

A run is a dict (written as JSON by the callers) that :func:`oracle_result` turns into an
:class:`~abb_gym.evaluation.evaluate.EvaluationResult`, so tables, paired intervals and
charts treat the oracle like any evaluated policy.

The per-machine search is local and short (60 candidates by default): it stays in the basin of
its start.  When the tuned profile moved to another basin (the spannan_cfrp ``knots`` re-tuned
with restarts waited 47 s instead of 40 s), an oracle refining only it fell below a PPO agent
in return, which an upper bound must not.  :func:`best_of_runs` therefore takes,
machine by machine, the best of runs from several starts (the tuned profile and the earlier
tunings a baselines file lists as ``oracle_starts``): every run is a search on the same
machine, so the best of them is still what a planner that knows the machine reaches with this
family.

Knowing the machine includes knowing where its balls start, which no drive measures.  Two
measures separate that knowledge from the rest: :func:`balls_elsewhere` replays each machine's
oracle profile with the balls started elsewhere, and :func:`run_oracle` with ``ball_draws``
searches knowing every parameter of the machine but not the balls (each candidate scored on
several ball starts, the best then run on the machine as drawn).  On the shipped scenes and
presets (docs/results.md, "Where the oracle's gain comes from") the oracle's residual
gain over the tuned ``knots`` does not survive without the balls' start, and the machine alone
is worth little more than run-up time.
"""
from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np

from ..evaluation.evaluate import EvaluationResult
from ..progress import ProgressBar
from .tuner import (ENV_ID, CandidateTask, _check_counts, _run_candidates, as_candidate,
                    ball_starts, return_score, tune_per_machine)

__all__ = ["run_oracle", "oracle_result", "oracle_matches", "oracle_name", "best_of_runs",
           "balls_elsewhere", "goal_room"]

# the stream of the ball-angle draws of :func:`balls_elsewhere`, apart from every episode seed
BALLS_ELSEWHERE_STREAM = 0x0BA11


def oracle_name(family: str = "knots", ball_draws: int = 0) -> str:
    """The policy name of the oracle in tables and charts (``ball_draws`` > 0: the oracle
    that knows the machine but not where its balls start)."""
    return f"oracle:{family} per machine" + (", balls unknown" if ball_draws else "")


def run_oracle(scene: str, preset: str, episodes: int = 100, seed: int = 0, budget: int = 60,
               env_kwargs: dict[str, Any] | None = None, start: dict[str, Any] | None = None,
               family: str = "knots", executor=None, progress: bool = True,
               ball_draws: int = 0) -> dict[str, Any]:
    """Tune ``family`` on each of the ``episodes`` test machines of ``preset`` (``budget``
    CMA-ES candidates per machine, from ``start`` if given) with the reward of ``env_kwargs``;
    with ``ball_draws`` > 0 knowing the machine but not where its balls start
    (:func:`~abb_gym.baselines.tuner.tune_per_machine`).  Returns the run: its inputs and one
    row per machine (every evaluation metric, ``params``, ``candidates``)."""
    rows = tune_per_machine(scene, family, episodes, seed, preset, budget,
                            env_kwargs=env_kwargs, executor=executor, progress=progress,
                            start=start, ball_draws=ball_draws)
    return {"scene": scene, "preset": preset, "seed": int(seed), "family": family,
            "budget": int(budget), "env_kwargs": copy.deepcopy(env_kwargs or {}),
            "start": copy.deepcopy(start), "ball_draws": int(ball_draws), "machines": rows}


def oracle_matches(run: dict[str, Any], scene: str, preset: str, seed: int, episodes: int,
                   budget: int, env_kwargs: dict[str, Any] | None = None,
                   family: str = "knots", start: dict[str, Any] | None = None,
                   ball_draws: int = 0) -> bool:
    """True if the stored ``run`` covers these machines (the first ``episodes`` of the same
    seeded test set) with the same reward, family, budget and warm start (a re-tuned baseline
    is a new start: the oracle must again be at least the baseline on every machine)."""
    try:
        return (run["scene"] == scene and run["preset"] == preset and run["seed"] == seed
                and run["family"] == family and run["budget"] == budget
                and run["env_kwargs"] == (env_kwargs or {})
                and _same_params(run.get("start"), start)
                and run.get("ball_draws", 0) == ball_draws
                and len(run["machines"]) >= episodes)
    except (KeyError, TypeError):
        return False


# (runs stored before ``ball_draws`` existed knew the balls: 0)
_SAME_MACHINES = ("scene", "preset", "seed", "family", "budget", "env_kwargs", "ball_draws")


def best_of_runs(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """One oracle run from runs of different starts on the same machines: machine by machine
    the row of the best return (the first run's on a tie), marked with the index of its run
    (``start_index``); ``starts`` lists the runs' starts in order.  Runs that differ in
    machines, reward, family or budget are refused by name."""
    if not runs:
        raise ValueError("best_of_runs needs at least one run")
    first = runs[0]
    for run in runs[1:]:
        for key in _SAME_MACHINES:
            if run.get(key, 0) != first.get(key, 0):
                raise ValueError(f"oracle runs differ in {key!r}: {first.get(key, 0)!r} and "
                                 f"{run.get(key, 0)!r}")
    n = min(len(run["machines"]) for run in runs)
    machines = []
    for k in range(n):
        rows = [run["machines"][k] for run in runs]
        best = max(range(len(rows)), key=lambda i: (return_score(rows[i]), -i))
        machines.append(dict(rows[best], start_index=best))
    out = {key: copy.deepcopy(first.get(key, 0)) for key in _SAME_MACHINES}
    out["starts"] = [copy.deepcopy(run.get("start")) for run in runs]
    out["machines"] = machines
    return out


def _same_params(stored: dict[str, Any] | None, given: dict[str, Any] | None) -> bool:
    """Parameters as stored in JSON (lists) against parameters as given (lists or tuples)."""
    def plain(params):
        return None if params is None else {
            k: list(v) if isinstance(v, (list, tuple)) else v for k, v in params.items()}
    return plain(stored) == plain(given)


def oracle_result(run: dict[str, Any], episodes: int | None = None,
                  env_id: str = ENV_ID) -> EvaluationResult:
    """The oracle run as an evaluation result (its first ``episodes`` machines)."""
    machines = run["machines"] if episodes is None else run["machines"][:episodes]
    name = oracle_name(run.get("family", "knots"), run.get("ball_draws", 0))
    result = EvaluationResult(name, env_id, run["scene"], run["preset"], run["seed"])
    result.episodes.extend(_as_episode(row, name) for row in machines)
    return result


def _as_episode(row: dict[str, Any], policy: str, **extra: Any) -> dict[str, Any]:
    """An oracle run's machine row as an evaluation episode of ``policy``: its metrics, without
    the search's bookkeeping (``params``, ``candidates``, ``start_index``)."""
    return {k: v for k, v in row.items() if k not in ("params", "candidates", "start_index")} \
        | {"policy": policy, **extra}


ELSEWHERE_METRICS = ("return", "residual_vibration", "run_up_time", "peak_whirl", "at_speed")


def balls_elsewhere(run: dict[str, Any], compare: dict[str, Any], draws: int = 4,
                    episodes: int | None = None, progress: bool = True, executor=None
                    ) -> tuple[EvaluationResult, EvaluationResult]:
    """How much of the oracle's gain is knowing where each machine's balls start.

    The oracle plans on the machine exactly as the test episode draws it, the initial ball
    angles included, which no drive measures.  Here each machine ``k`` of ``run`` (its first
    ``episodes``) runs again ``draws`` times, every parameter as drawn but the balls started
    elsewhere: angles drawn as the preset draws them (:func:`~abb_gym.baselines.tuner.
    ball_starts`), from a generator of their own (seeded by the run's seed and ``k``: the same
    draws on every call).  Both the oracle's profile for machine ``k`` and ``compare`` (e.g.
    the tuned ``knots``) run on the same draws.  Returns their results (oracle first), one row per
    machine, each metric of :data:`ELSEWHERE_METRICS` the mean over the draws (``at_speed``
    the share that settled; the residual over the draws that settled, NaN if none did), so that
    :func:`abb_gym.evaluation.report.paired_gap` pairs them machine by machine.  ``executor``
    (an :class:`abb_gym.execution.Executor`) runs the machines' draws as independent tasks
    (each is two run-ups, which the vector environment runs on one core), with the same
    results; without it they run one after another in this process."""
    from ..envs.setup import EnvSetup
    _check_counts(draws=draws)
    machines = run["machines"] if episodes is None else run["machines"][:episodes]
    env_kwargs = run.get("env_kwargs") or {}
    setup = EnvSetup(ENV_ID, run["scene"], run["preset"], overrides=env_kwargs)
    kw = tuple(sorted(env_kwargs.items()))
    name = oracle_name(run.get("family", "knots"))
    results = tuple(EvaluationResult(f"{label}, balls started elsewhere", ENV_ID, run["scene"],
                                     run["preset"], run["seed"])
                    for label in (name, "baseline:knots"))
    tasks = [CandidateTask(ENV_ID, run["scene"], run["preset"], run.get("family", "knots"),
                           (as_candidate(row["params"]), as_candidate(compare)),
                           (int(row["episode"]),), int(run["seed"]), kw, reset_options=options)
             for row in machines
             for options in ball_starts(setup, int(run["seed"]) + int(row["episode"]),
                                        BALLS_ELSEWHERE_STREAM, draws)]
    desc = "oracle, balls started elsewhere"
    if executor is not None:
        runs = executor.map(_run_candidates, tasks, desc=f"{desc}: run-up pairs")
    else:
        with ProgressBar(tasks, desc=desc, unit="run-up pair", disable=not progress) as bar:
            runs = [_run_candidates(task) for task in bar]
    for m, row in enumerate(machines):
        scored = [[], []]
        for episodes_of_draw in runs[m * draws:(m + 1) * draws]:
            for episode in episodes_of_draw:
                scored[episode["candidate"]].append(episode)
        for result, rows in zip(results, scored):
            result.episodes.append(_mean_row(rows, int(row["episode"]), result.policy))
    return results


def _mean_row(rows: list[dict[str, Any]], episode: int, policy: str) -> dict[str, Any]:
    out: dict[str, Any] = {"episode": episode, "policy": policy, "draws": len(rows)}
    for key in ELSEWHERE_METRICS:
        values = np.array([float(r[key]) for r in rows])
        finite = values[np.isfinite(values)]
        out[key] = float(finite.mean()) if finite.size else math.nan
    return out


def goal_room(baseline: EvaluationResult, runs: list[dict[str, Any]],
              key: str = "residual_vibration", cost: str = "run_up_time") -> EvaluationResult:
    """The least mean ``key`` (residual) that a planner knowing each machine reaches at a mean
    ``cost`` (settled run-up time) no longer than ``baseline``'s, on the baseline's machines.

    The goal of "Tasks where feedback pays" asks for a residual 20 % below ``knots`` at no
    longer run-up time.  The oracle of the agents' reward trades residual against run-up
    time at that reward's weights, so its residual alone does not say how much room the goal
    has.  Here every machine may take the profile of any of ``runs`` (oracle runs on the same
    machines, e.g. at several residual weights) or the baseline's own episode: all of them are
    run-ups the planner knows on that machine.  Choosing one per machine to minimise the mean
    ``key`` with the mean ``cost`` held to the baseline's is a multiple-choice knapsack,
    solved exactly by dynamic programming over the summed change of ``cost`` (each option's
    change from the baseline's rounded up to a grid of at most 200,000 steps, at least
    0.1 ms: the choice always fits, and is optimal up to that rounding).  The choice is a real
    run-up on every machine: the figure is reached, not bounded.  Options that did not settle
    (non-finite ``key``) are never chosen.  A machine the baseline did not settle keeps the
    baseline's run: its ``key`` stays out of the mean (as in the baseline's own mean) and its
    ``cost`` (the episode's end) stays in the budget as it was.  Returns the chosen rows as an
    :class:`EvaluationResult` (``source``: -1 for the baseline, else the index in ``runs``),
    paired with ``baseline`` by episode."""
    base = {int(e["episode"]): e for e in baseline.episodes}
    options: dict[int, list[tuple[float, float, int, dict[str, Any]]]] = {}
    for k, row in sorted(base.items()):
        if not math.isfinite(float(row[cost])):
            raise ValueError(f"{baseline.policy!r} has no {cost} on machine {k} "
                             f"({row[cost]!r}): no time to hold")
        options[k] = [(float(row[key]), float(row[cost]), -1, row)]
    for index, run in enumerate(runs):
        for row in run["machines"]:
            k = int(row["episode"])
            if k in options and math.isfinite(float(row[key])) \
                    and math.isfinite(float(row[cost])):
                options[k].append((float(row[key]), float(row[cost]), index, row))
    settled = [opts for opts in options.values() if math.isfinite(opts[0][0])]
    # the baseline's unsettled machines keep its run: the key is averaged over the machines
    # it settled (as its own mean is), and their time counts in the budget as it was
    chosen = iter(_least_sum_within(settled) if settled else [])
    chosen = [opts[0] if not math.isfinite(opts[0][0]) else next(chosen)
              for opts in options.values()]
    name = f"{baseline.policy} room: least {key} at no longer {cost}"
    result = EvaluationResult(name, baseline.env_id, baseline.scene, baseline.preset,
                              baseline.seed)
    result.episodes.extend(_as_episode(row, name, source=source)
                           for _, _, source, row in chosen)
    return result


def _least_sum_within(options: list[list[tuple]], max_states: int = 200_000,
                      finest: float = 1e-4) -> list[tuple]:
    """One option ``(key, cost, ...)`` per machine, the first of each machine's list being its
    baseline, with the least sum of ``key`` among the choices whose summed ``cost`` is no more
    than the baselines' (costs compared on a grid, every change rounded up)."""
    deltas = [np.array([o[1] - opts[0][1] for o in opts]) for opts in options]
    span = sum(float(d.max() - d.min()) for d in deltas)
    step = max(finest, span / max_states)
    # rounded up (less a hair of floating-point noise), so a choice that fits on the grid fits
    shifts = [np.ceil(d / step - 1e-6).astype(np.int64) for d in deltas]
    least = np.zeros(1)  # least summed key by summed shift, index 0 at summed shift `offset`
    offset, picks = 0, []
    for shift, opts in zip(shifts, options):
        lo = int(shift.min())
        new = np.full(least.size + int(shift.max()) - lo, np.inf)
        pick = np.full(new.size, -1, dtype=np.int16)
        for j, option in enumerate(opts):
            at = int(shift[j]) - lo
            candidate = least + option[0]
            better = candidate < new[at:at + least.size]
            new[at:at + least.size][better] = candidate[better]
            pick[at:at + least.size][better] = j
        picks.append(pick)
        least, offset = new, offset + lo
    fits = np.arange(least.size) + offset <= 0  # the baselines' choice (all shifts 0) fits
    index = int(np.argmin(np.where(fits, least, np.inf)))
    chosen = []
    for pick, opts, shift in zip(reversed(picks), reversed(options), reversed(shifts)):
        j = int(pick[index])
        chosen.append(opts[j])
        index -= int(shift[j] - shift.min())
    return chosen[::-1]
