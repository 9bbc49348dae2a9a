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

from dataclasses import dataclass, field
from typing import Any, Mapping

import gymnasium as gym


__all__ = ["Task", "TASKS", "register", "get", "load_named", "task_ids", "DEFAULT_ENV_ID"]


@dataclass(frozen=True)
class Task:
    """One environment id (module docstring).

    ``action``: the action model's name (:data:`abb_gym.envs.actions.ACTION_MODELS`).
    ``single_class``/``vector_class``: ``"module:Class"`` of the environments (default: the
    generic :class:`~abb_gym.envs.base.BalancerEnv` / :class:`~abb_gym.envs.vector.
    BalancerVectorEnv`, bound to this task by its id; named as text, so that this module
    imports no environment and :func:`load_named` is the one way to a task's class).
    ``settings``: preset fields the task fixes (merged over the preset and the keyword
    overrides).  ``registered_steps``: the registered
    ``max_episode_steps`` (None: ``gym.make`` wraps the environment in a ``TimeLimit`` of its
    own episode length, which depends on the scene and preset).  ``open_loop``: the open-loop
    speed-profile baselines (``baseline:*``, the tuner, ``replay:``) drive it; ``baselines_on``:
    the id a baseline runs on when this task's action cannot express it (None: this one).
    ``one_step``: an episode is one step (one action decides the whole run).
    ``test_preset``: the held-out preset a trained agent is evaluated on.
    ``residual_floor``: ``"module:function"`` of the task's open-loop floor, the least
    residual a policy that never reacts can leave on given episodes (evaluation summaries
    show it beside the policies; None: the task has none)."""

    env_id: str
    action: str
    summary: str
    single_class: str = "abb_gym.envs.base:BalancerEnv"
    vector_class: str = "abb_gym.envs.vector:BalancerVectorEnv"
    default_scene: str = "yoshida_odd"
    default_preset: str = "train"
    settings: Mapping[str, Any] = field(default_factory=dict)
    registered_steps: int | None = None
    open_loop: bool = True
    baselines_on: str | None = None
    one_step: bool = False
    test_preset: str = "test"
    residual_floor: str | None = None

    @property
    def name(self) -> str:
        """The id without namespace and version: ``RunUpSpeed``."""
        return self.env_id.split("/")[-1].rsplit("-v", 1)[0]


#: every registered task, by id, in registration order
TASKS: dict[str, Task] = {}
#: the module of the entry points (:mod:`abb_gym.envs.entry`: it builds the environments,
#: this module only declares them)
ENTRY = "abb_gym.envs.entry"


def register(task: Task) -> Task:
    """Add ``task`` to :data:`TASKS` and register its id with gymnasium (once)."""
    TASKS[task.env_id] = task
    if task.env_id not in gym.registry:
        gym.register(id=task.env_id, entry_point=f"{ENTRY}:make_{task.name}",
                     vector_entry_point=f"{ENTRY}:make_{task.name}_vector",
                     max_episode_steps=task.registered_steps)
    return task


def load_named(path: str) -> Any:
    """The object a task row names by ``"module:name"`` (its classes, its floor)."""
    import importlib
    module, _, name = path.partition(":")
    return getattr(importlib.import_module(module), name)


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
    settings={"redistribution": {"enabled": True}},
    residual_floor="abb_gym.baselines.laundry:open_loop_floor"))

#: the id that tools default to
DEFAULT_ENV_ID = RUN_UP_SPEED.env_id
