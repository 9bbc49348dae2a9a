"""``replay:SPEC``: what a policy does without feedback.

:class:`ReplayPolicy` runs policy ``SPEC`` once on the nominal machine - the environment the
evaluation uses, with every randomisation of its preset switched off (the scene as loaded) -
records the actions it takes, and then plays that sequence open-loop on every test machine
(holding the last action once the sequence is used up).  On the nominal machine the replay is
the policy, action for action.

A closed-loop policy's **feedback value** is the paired difference replay minus policy over the
same test episodes (:func:`feedback_value`): what watching the machine adds to its own best
guess of a fixed action sequence.  A policy whose replay scores as well as itself does not use
feedback.
"""
from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from .registry import resolve
from .statistics import paired_interval

__all__ = ["ReplayPolicy", "load_replay", "record_actions", "feedback_value",
           "paired_by_episode"]

FEEDBACK_METRICS = ("residual_vibration", "run_up_time", "return")


def _nominal_env(env: Any, info_level: str | None = None):
    """A one-environment copy of ``env`` on the nominal machine (no randomisation), with
    ``info_level`` (default: ``env``'s)."""
    from ..envs.config import load_preset
    setup = env.unwrapped.setup
    config = load_preset(setup.config, randomize={k: None for k in
                                                  setup.config.randomize.__dataclass_fields__})
    return gym.make_vec(env.spec.id if env.spec else setup.task.env_id, num_envs=1,
                        vectorization_mode="vector_entry_point", scene=setup.scene,
                        preset=config, observe_balls=setup.observe_balls,
                        info_level=info_level or getattr(env.unwrapped, "info_level", "full"))


def record_actions(policy: Any, env: Any) -> np.ndarray:
    """The actions ``policy`` takes in one episode of the one-environment vector ``env``,
    reset without a seed (the nominal machine has nothing to draw)."""
    obs, info = env.reset(seed=0)
    policy.reset(env, np.ones(1, bool))
    actions = []
    while True:
        act = np.asarray(policy.act(obs, info), dtype=np.float32)
        actions.append(act[0].copy())
        obs, _, term, trunc, info = env.step(act)
        if term[0] or trunc[0]:
            return np.array(actions)


class ReplayPolicy:
    """Policy ``spec`` recorded on the nominal machine, replayed open-loop (module docstring)."""

    reads_info = False  # the recorded actions, in order

    def __init__(self, spec: str, env_id: str | None = None, scene: Any = None):
        self.spec = spec
        self.env_id = env_id
        self.scene = scene
        self.name = f"replay:{spec}"
        self.actions: np.ndarray | None = None
        self._count: np.ndarray | None = None

    def reset(self, env: Any, mask: np.ndarray) -> None:
        if self.actions is None:
            inner = resolve(self.spec, self.env_id or env.unwrapped.setup.task.env_id, self.scene)
            # the recorded policy gets the full info unless it reads none (the replay itself
            # reads none, so the evaluation may have made env's info lean)
            reads = getattr(inner, "reads_info", True) is not False
            nominal = _nominal_env(env, "full" if reads else None)
            self.actions = record_actions(inner, nominal)
            nominal.close()
            self.name = f"replay:{getattr(inner, 'name', self.spec)}"
            self.params = dict(getattr(inner, "params", None) or {})
        if self._count is None or self._count.shape[0] != env.num_envs:
            self._count = np.zeros(env.num_envs, dtype=np.int64)
        self._count[np.asarray(mask, bool)] = 0

    def act(self, obs: np.ndarray, info: dict | None = None) -> np.ndarray:
        k = np.minimum(self._count, len(self.actions) - 1)
        self._count += 1
        return self.actions[k]


def load_replay(arg: str, env_id: str | None = None, scene: Any = None, **_: Any) -> ReplayPolicy:
    """The policy of ``replay:SPEC`` (the ``abb_gym.policies`` entry point)."""
    if ":" not in arg:
        raise ValueError(f"replay needs a policy to record, e.g. replay:ppo:NAME or "
                         f"replay:baseline:retry (got replay:{arg})")
    return ReplayPolicy(arg, env_id, scene)


def feedback_value(policy_episodes: list[dict], replay_episodes: list[dict]
                   ) -> dict[str, dict[str, float]]:
    """Paired difference replay minus policy, per metric of :data:`FEEDBACK_METRICS`, with a
    95 % interval, over the episodes both ran (matched by episode index).  Positive residual
    and run-up time differences mean the policy is better than its replay; for the return, a
    negative difference does."""
    return {key: paired_by_episode(replay_episodes, policy_episodes, key)
            for key in FEEDBACK_METRICS}


def paired_by_episode(a: list[dict], b: list[dict], key: str) -> dict[str, float]:
    """Paired difference ``a - b`` of metric ``key`` over the episodes both lists hold (matched
    by episode index: the same machines), with its 95 % interval (NaN without a pair)."""
    by_episode = {e["episode"]: e for e in b}
    pairs = [(e, by_episode[e["episode"]]) for e in a if e["episode"] in by_episode]
    return paired_interval([float(x[key]) for x, _ in pairs], [float(y[key]) for _, y in pairs])
