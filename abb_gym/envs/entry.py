"""The entry points of the registered ids: ``gym.make`` and ``gym.make_vec`` call these.

:mod:`abb_gym.envs.tasks` declares each task; this module builds its environments from the
classes the task names (:func:`~abb_gym.envs.tasks.load_named`).
``gym.register`` takes entry points as ``"module:attribute"`` text (an id's spec stays
JSON-serialisable and picklable), so each registered task has two attributes here, made on
demand: ``make_<Name>`` and ``make_<Name>_vector``.
"""
from __future__ import annotations

from typing import Any

import gymnasium as gym

from .display import SINGLE_METADATA
from .learning import advise
from .tasks import TASKS, get, load_named

__all__ = ["make_single", "make_vector"]


def make_single(env_id: str, **kwargs: Any) -> gym.Env:
    """The single environment of ``env_id`` made with ``kwargs``: inside a ``TimeLimit`` of
    its own episode length [control intervals] unless the task registers a
    ``max_episode_steps`` (:mod:`abb_gym.envs`)."""
    task = get(env_id)
    env = load_named(task.single_class)(task=env_id, **kwargs)
    advise(task)
    if task.registered_steps is not None:
        return env
    setup = env.setup
    steps = setup.max_steps if setup.backstop <= 0 else min(setup.max_steps, setup.backstop)
    return gym.wrappers.TimeLimit(env, max_episode_steps=int(steps))


def make_vector(env_id: str, **kwargs: Any):
    """The native vector environment of ``env_id`` made with ``kwargs``."""
    task = get(env_id)
    env = load_named(task.vector_class)(task=env_id, **kwargs)
    advise(task)
    return env


def _maker(name: str):
    for task in TASKS.values():
        if name == f"make_{task.name}":
            def single(**kwargs: Any) -> gym.Env:
                return make_single(task.env_id, **kwargs)
            single.metadata = SINGLE_METADATA  # gym.make checks render_mode against it
            single.__doc__ = f"Entry point of ``{task.env_id}`` (:func:`make_single`)."
            return single
        if name == f"make_{task.name}_vector":
            def vector(**kwargs: Any):
                return make_vector(task.env_id, **kwargs)
            vector.__doc__ = f"Vector entry point of ``{task.env_id}`` (:func:`make_vector`)."
            return vector
    return None


def __getattr__(name: str) -> Any:
    maker = _maker(name) if name.startswith("make_") else None
    if maker is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return maker
