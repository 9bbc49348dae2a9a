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
"""
from __future__ import annotations

import copy
from typing import Any

from ..evaluation.evaluate import EvaluationResult
from .tuner import ENV_ID, tune_per_machine

__all__ = ["run_oracle", "oracle_result", "oracle_matches", "oracle_name"]


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
                                if k not in ("params", "candidates")} | {"policy": name})
    return result
