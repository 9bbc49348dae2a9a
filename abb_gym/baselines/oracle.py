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
with restarts on 2026-11-23 waited 47 s instead of 40 s), an oracle refining only it fell below
a PPO agent in return, which an upper bound must not.  :func:`best_of_runs` therefore takes, machine by
machine, the best of runs from several starts (the tuned profile and the earlier tunings a
baselines file lists as ``oracle_starts``): every run is a search on the same machine, so the
best of them is still what a planner that knows the machine reaches with this family.
"""
from __future__ import annotations

import copy
from typing import Any

from ..evaluation.evaluate import EvaluationResult
from .tuner import ENV_ID, return_score, tune_per_machine

__all__ = ["run_oracle", "oracle_result", "oracle_matches", "oracle_name", "best_of_runs"]


def oracle_name(family: str = "knots") -> str:
    """The policy name of the oracle in tables and charts."""
    return f"oracle:{family} per machine"


def run_oracle(scene: str, preset: str, episodes: int = 100, seed: int = 0, budget: int = 60,
               env_kwargs: dict[str, Any] | None = None, start: dict[str, Any] | None = None,
               family: str = "knots", executor=None, progress: bool = True) -> dict[str, Any]:
    """Tune ``family`` on each of the ``episodes`` test machines of ``preset`` (``budget``
    CMA-ES candidates per machine, from ``start`` if given) with the reward of ``env_kwargs``.
    Returns the run: its inputs and one row per machine (every evaluation metric, ``params``,
    ``candidates``)."""
    rows = tune_per_machine(scene, family, episodes, seed, preset, budget,
                            env_kwargs=env_kwargs, executor=executor, progress=progress,
                            start=start)
    return {"scene": scene, "preset": preset, "seed": int(seed), "family": family,
            "budget": int(budget), "env_kwargs": copy.deepcopy(env_kwargs or {}),
            "start": copy.deepcopy(start), "machines": rows}


def oracle_matches(run: dict[str, Any], scene: str, preset: str, seed: int, episodes: int,
                   budget: int, env_kwargs: dict[str, Any] | None = None,
                   family: str = "knots", start: dict[str, Any] | None = None) -> bool:
    """True if the stored ``run`` covers these machines (the first ``episodes`` of the same
    seeded test set) with the same reward, family, budget and warm start (a re-tuned baseline
    is a new start: the oracle must again be at least the baseline on every machine)."""
    try:
        return (run["scene"] == scene and run["preset"] == preset and run["seed"] == seed
                and run["family"] == family and run["budget"] == budget
                and run["env_kwargs"] == (env_kwargs or {})
                and _same_params(run.get("start"), start)
                and len(run["machines"]) >= episodes)
    except (KeyError, TypeError):
        return False


_SAME_MACHINES = ("scene", "preset", "seed", "family", "budget", "env_kwargs")


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
            if run[key] != first[key]:
                raise ValueError(f"oracle runs differ in {key!r}: {first[key]!r} and "
                                 f"{run[key]!r}")
    n = min(len(run["machines"]) for run in runs)
    machines = []
    for k in range(n):
        rows = [run["machines"][k] for run in runs]
        best = max(range(len(rows)), key=lambda i: (return_score(rows[i]), -i))
        machines.append(dict(rows[best], start_index=best))
    out = {key: copy.deepcopy(first[key]) for key in _SAME_MACHINES}
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
    name = oracle_name(run.get("family", "knots"))
    result = EvaluationResult(name, env_id, run["scene"], run["preset"], run["seed"])
    for row in machines:
        result.episodes.append({k: v for k, v in row.items()
                                if k not in ("params", "candidates", "start_index")}
                               | {"policy": name})
    return result
