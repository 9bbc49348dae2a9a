"""Evaluate a policy *object* (e.g. the model being trained) on the seeded test set.

A thin layer over :mod:`abb_gym.evaluation.evaluate`, so that the training callback, the smoke
tests and ``abb-gym evaluate --policy ppo:PATH`` score agents with exactly the same episodes
and metrics: episode ``k`` of a test set with seed ``S`` is the environment reset with seed
``S + k`` on the preset (``test`` by default); metrics per episode as in
:mod:`abb_gym.evaluation.metrics` (``at_speed``: the run-up completed, ``run_up_time`` [s]:
the settled entry, ``residual_vibration`` [W_r/e, or the task's length unit] over the
settling window, ``peak_whirl``,
``balanced``, ``return``, ...).
"""
from __future__ import annotations

from typing import Any

__all__ = ["run_episodes", "brief", "KEY_METRICS"]

KEY_METRICS = ("return", "at_speed", "run_up_time", "residual_vibration", "peak_whirl", "balanced")


def run_episodes(policy: Any, env_id: str, *, episodes: int = 64, seed: int = 0,
                 scene: str = "yoshida_odd", preset: str = "test", chunk_size: int = 32,
                 **env_kwargs: Any) -> list[dict[str, Any]]:
    """Run ``policy`` (an evaluation Policy object) on test episodes ``0 .. episodes-1``.

    :param policy: object with ``reset(env, mask)`` and ``act(obs, info)``.
    :param episodes: number of test episodes (>= 1).
    :param seed: seed of the test set (episode ``k`` is reset with ``seed + k``).
    :param chunk_size: sub-environments per vector environment (episodes run in chunks).
    :param env_kwargs: further ``gym.make_vec`` keywords (``control_interval``, ...).
    :returns: one metrics dict per episode (see the module docstring).
    """
    from ..evaluation.evaluate import chunks, run_chunk

    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes must be an integer >= 1 (got {episodes!r})")
    out: list[dict[str, Any]] = []
    for chunk in chunks(env_id, scene, getattr(policy, "name", "policy"), episodes, seed,
                        preset, chunk_size, record=(), **env_kwargs):
        rows, _ = run_chunk(chunk, policy=policy)
        out.extend(rows)
    return out


def brief(summary: dict[str, Any]) -> dict[str, float]:
    """The means of :data:`KEY_METRICS` from a
    :func:`abb_gym.evaluation.evaluate.summarise` result (flat, for logs)."""
    return {k: float(summary[k]["mean"]) for k in KEY_METRICS if k in summary}
