"""The task registry: one row per environment id, which everything else reads.

A task is a registered environment id with its action model (:mod:`abb_gym.envs.actions`),
its default scene and preset, the preset fields it fixes, where its documentation and
classes live, and what the rest of the package needs to know about it (whether the
open-loop baselines and their tuner apply, the registered ``max_episode_steps``).  The
environments, ``episode_steps``, the tuner, replay, video, the kernel warm-up and the
command line all read :data:`TASKS`; none spells an id of its own.

Adding a task is one :func:`register` call (a row below for a shipped task) plus, when it
needs them, a module that documents it and an action model.  Light on purpose: ``import
abb_gym`` registers the ids through this module without loading numba; the environments are
imported when one is made.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any, Mapping

import gymnasium as gym

from .display import SINGLE_METADATA

__all__ = ["Task", "TASKS", "register", "get", "task_ids", "DEFAULT_ENV_ID", "env_class",
           "vector_class", "make_single", "make_vector"]


@dataclass(frozen=True)
class Task:
    """One environment id (module docstring).

    ``action``: the action model's name (:data:`abb_gym.envs.actions.ACTION_MODELS`).
    ``single_class``/``vector_class``: ``"module:Class"`` of the environments (None: the
    generic :class:`~abb_gym.envs.base.BalancerEnv` / :class:`~abb_gym.envs.vector.
    BalancerVectorEnv` bound to this task).  ``settings``: preset fields the task fixes
    (merged over the preset and the keyword overrides).  ``registered_steps``: the registered
    ``max_episode_steps`` (None: ``gym.make`` wraps the environment in a ``TimeLimit`` of its
    own episode length, which depends on the scene and preset).  ``open_loop``: the open-loop
    speed-profile baselines (``baseline:*``, the tuner, ``replay:``) drive it; ``baselines_on``:
    the id a baseline runs on when this task's action cannot express it (None: this one).
    ``one_step``: an episode is one step (one action decides the whole run).
    ``test_preset``: the held-out preset a trained agent is evaluated on."""

    env_id: str
    action: str
    summary: str
    single_class: str | None = None
    vector_class: str | None = None
    default_scene: str = "yoshida_odd"
    default_preset: str = "train"
    settings: Mapping[str, Any] = field(default_factory=dict)
    registered_steps: int | None = None
    open_loop: bool = True
    baselines_on: str | None = None
    one_step: bool = False
    test_preset: str = "test"

    @property
    def name(self) -> str:
        """The id without namespace and version: ``RunUpSpeed``."""
        return self.env_id.split("/")[-1].rsplit("-v", 1)[0]


#: every registered task, by id, in registration order
TASKS: dict[str, Task] = {}


def _load(path: str) -> Any:
    module, _, name = path.partition(":")
    return getattr(importlib.import_module(module), name)


def env_class(task: Task) -> type:
    """The single environment class of ``task``."""
    if task.single_class is not None:
        return _load(task.single_class)
    from .base import BalancerEnv
    return BalancerEnv


def vector_class(task: Task) -> type:
    """The native vector environment class of ``task``."""
    if task.vector_class is not None:
        return _load(task.vector_class)
    from .vector import BalancerVectorEnv
    return BalancerVectorEnv


def _own_limit(env: Any) -> gym.Env:
    """``env`` inside a ``TimeLimit`` of its own episode length [control intervals]."""
    setup = env.setup
    steps = setup.max_steps if setup.backstop <= 0 else min(setup.max_steps, setup.backstop)
    return gym.wrappers.TimeLimit(env, max_episode_steps=int(steps))


def make_single(env_id: str, **kwargs: Any) -> gym.Env:
    """The single environment of ``env_id`` made with ``kwargs``: inside a ``TimeLimit`` of
    its own episode length unless the task registers a ``max_episode_steps``
    (:mod:`abb_gym.envs`)."""
    task = get(env_id)
    env = env_class(task)(task=env_id, **kwargs)
    return env if task.registered_steps is not None else _own_limit(env)


def make_vector(env_id: str, **kwargs: Any):
    """The native vector environment of ``env_id`` made with ``kwargs``."""
    return vector_class(get(env_id))(task=env_id, **kwargs)


# gym.register takes entry points as "module:attribute" text (an id's spec stays
# JSON-serialisable and picklable), so each registered task gets two attributes of this
# module, made on demand by its __getattr__: make_<Name> and make_<Name>_vector
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


def register(task: Task) -> Task:
    """Add ``task`` to :data:`TASKS` and register its id with gymnasium (once)."""
    TASKS[task.env_id] = task
    if task.env_id not in gym.registry:
        gym.register(id=task.env_id, entry_point=f"{__name__}:make_{task.name}",
                     vector_entry_point=f"{__name__}:make_{task.name}_vector",
                     max_episode_steps=task.registered_steps)
    return task


def get(env_id: Any) -> Task:
    """The task of ``env_id`` (a ValueError naming the registered ids otherwise)."""
    if isinstance(env_id, Task):
        return env_id
    if not isinstance(env_id, str) or env_id not in TASKS:
        raise ValueError(f"unknown environment {env_id!r:.80}: env_id must be one of "
                         f"{list(TASKS)}")
    return TASKS[env_id]


def task_ids(open_loop: bool | None = None, action: str | None = None) -> list[str]:
    """The registered ids, optionally only those the open-loop baselines drive
    (``open_loop=True``) or of one action model."""
    return [t.env_id for t in TASKS.values()
            if (open_loop is None or t.open_loop == open_loop)
            and (action is None or t.action == action)]


#: registered ``max_episode_steps`` of DwellProfile-v0: its episodes are one step; a limit of
#: 1 would make gymnasium's TimeLimit report every terminated episode as truncated too
DWELL_MAX_EPISODE_STEPS = 2

RUN_UP_TORQUE = register(Task(
    "abb_gym/RunUpTorque-v0", "torque", "run up by commanding the motor torque",
    single_class="abb_gym.envs.torque:RunUpTorqueEnv",
    vector_class="abb_gym.envs.vector:RunUpTorqueVectorEnv"))
RUN_UP_SPEED = register(Task(
    "abb_gym/RunUpSpeed-v0", "speed", "draw the run-up speed profile step by step",
    single_class="abb_gym.envs.speed:RunUpSpeedEnv",
    vector_class="abb_gym.envs.vector:RunUpSpeedVectorEnv"))
DWELL_PROFILE = register(Task(
    "abb_gym/DwellProfile-v0", "dwell", "choose the dwell of a run-up profile, then watch "
    "the whole run", single_class="abb_gym.envs.dwell:DwellProfileEnv",
    vector_class="abb_gym.envs.vector:DwellProfileVectorEnv",
    registered_steps=DWELL_MAX_EPISODE_STEPS, open_loop=False,
    baselines_on="abb_gym/RunUpSpeed-v0", one_step=True))
SPIN_REDISTRIBUTE = register(Task(
    "abb_gym/SpinRedistribute-v0", "speed", "spin a washer whose laundry redistributes when "
    "the drum tumbles", single_class="abb_gym.envs.spin:SpinRedistributeEnv",
    vector_class="abb_gym.envs.spin:SpinRedistributeVectorEnv", default_scene="washer",
    default_preset="laundry", test_preset="laundry_test",
    settings={"redistribution": {"enabled": True}}))

#: the id that tools default to
DEFAULT_ENV_ID = RUN_UP_SPEED.env_id
