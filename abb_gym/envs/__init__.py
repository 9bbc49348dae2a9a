"""Gymnasium environments of the automatic ball balancer (registered on import).

Every id is a row of the task registry (:mod:`abb_gym.envs.tasks`), which the environments,
the tools and the documentation read:

==================================  ====================  ==========================================
id                                  action                module
==================================  ====================  ==========================================
``abb_gym/RunUpTorque-v0``          motor torque          :mod:`abb_gym.envs.torque`
``abb_gym/RunUpSpeed-v0``           rotor acceleration    :mod:`abb_gym.envs.speed`
``abb_gym/DwellProfile-v0``         dwell parameters      :mod:`abb_gym.envs.dwell`
``abb_gym/SpinRedistribute-v0``     rotor acceleration    :mod:`abb_gym.envs.spin`
==================================  ====================  ==========================================

Each id has a native vector environment (:mod:`abb_gym.envs.vector`)::

    import gymnasium as gym, abb_gym
    env = gym.make("abb_gym/RunUpSpeed-v0", scene="spannan_discoidal", preset="test")
    envs = gym.make_vec("abb_gym/RunUpSpeed-v0", num_envs=1024,
                        vectorization_mode="vector_entry_point")

Shared observation, reward and episode rules: :mod:`abb_gym.envs.base`; presets:
:mod:`abb_gym.envs.config`.

**Episode length and** ``max_episode_steps``.  A RunUp* episode lasts ``episode_length``
(automatic: ``2.5 w_op / alpha_max + settle_time``), which depends on the scene, the preset and
the overrides: 850 steps of 10 ms on the default ``yoshida_odd``/``train``, 552 to 15 808 on
the shipped scenes.  One registered number cannot match them all, and gymnasium's
``TimeLimit`` cuts every episode that is longer than the registered number.  So the RunUp* and
SpinRedistribute ids register no ``max_episode_steps``; instead ``gym.make`` returns the
environment inside a ``TimeLimit`` of exactly its own episode length, and ``env.spec.max_episode_steps`` is the real
episode (850 for ``gym.make("abb_gym/RunUpSpeed-v0")``; :func:`episode_steps` without making
one).  The environment truncates itself at the same step (and pays the terminal residual
term), so the wrapper only reports it.  ``gym.make(..., max_episode_steps=N)`` and
``gym.make_vec(..., max_episode_steps=N)`` still cut episodes at ``N`` steps.
``DwellProfile-v0`` episodes are one step on every scene; it registers 2 (a ``TimeLimit`` of 1
would flag every terminated episode as truncated as well).

**No** ``reward_threshold``.  The return is a cost (vibration, time to speed, effort,
residual vibration, failure) normalised by the scene's own reference run-up; its value
depends on the scene, the preset and the reward weights, and no level of it means "solved"
(less residual vibration is always better).  Agents are compared with the tuned baselines on
the seeded test set instead (:mod:`abb_gym.evaluation`).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_names
from .display import SINGLE_METADATA
from .tasks import DWELL_MAX_EPISODE_STEPS, TASKS  # importing the registry registers the ids

if TYPE_CHECKING:  # the names below load on first use (:func:`__getattr__`)
    from .base import BalancerEnv
    from .config import EnvConfig, PresetError, list_presets, load_preset
    from .dwell import DwellProfileEnv
    from .speed import RunUpSpeedEnv
    from .spin import SpinRedistributeEnv, SpinRedistributeVectorEnv
    from .torque import RunUpTorqueEnv
    from .vector import (BalancerVectorEnv, DwellProfileVectorEnv, RunUpSpeedVectorEnv,
                         RunUpTorqueVectorEnv)

# name -> module that defines it.  Loaded on first use, so that ``import abb_gym`` registers
# the ids without importing numba or compiling anything (``import abb_gym`` under 0.5 s)
_LAZY = {"BalancerEnv": "base", "EnvConfig": "config", "PresetError": "config",
         "list_presets": "config", "load_preset": "config", "DwellProfileEnv": "dwell",
         "RunUpSpeedEnv": "speed", "RunUpTorqueEnv": "torque", "BalancerVectorEnv": "vector",
         "DwellProfileVectorEnv": "vector", "RunUpSpeedVectorEnv": "vector",
         "RunUpTorqueVectorEnv": "vector", "SpinRedistributeEnv": "spin",
         "SpinRedistributeVectorEnv": "spin"}


__getattr__, __dir__ = lazy_names(__name__, _LAZY)


__all__ = ["BalancerEnv", "RunUpTorqueEnv", "RunUpSpeedEnv", "DwellProfileEnv",
           "SpinRedistributeEnv", "BalancerVectorEnv", "RunUpTorqueVectorEnv",
           "RunUpSpeedVectorEnv", "DwellProfileVectorEnv", "SpinRedistributeVectorEnv",
           "EnvConfig", "PresetError", "load_preset", "list_presets", "ENV_IDS", "TASKS",
           "DWELL_MAX_EPISODE_STEPS", "episode_steps", "SINGLE_METADATA"]

#: the registered ids (the task registry's, :mod:`abb_gym.envs.tasks`)
ENV_IDS = tuple(TASKS)


def episode_steps(env_id: str | None = None, **kwargs) -> int:
    """Steps of one episode of ``env_id`` (default: the tools' default id) made with
    ``kwargs`` (scene, preset, overrides): ``env.spec.max_episode_steps`` of ``gym.make(env_id,
    **kwargs)`` without building the environment's buffers.  Each step is one control
    interval [s] (DwellProfile: one step)."""
    from . import tasks
    from .checks import check_flag
    from .display import check_display
    from .setup import EnvSetup
    task = tasks.get(tasks.DEFAULT_ENV_ID if env_id is None else env_id)
    kw = dict(kwargs)
    # no effect on the length, but checked as gym.make checks them: a keyword gym.make
    # refuses is refused here too, never silently ignored
    check_display(kw.pop("render_mode", None), SINGLE_METADATA["render_modes"],
                  kw.pop("info_level", "lean"))
    check_flag(kw.pop("record_history", False), "record_history")
    setup = EnvSetup(task, kw.pop("scene", None), kw.pop("preset", None),
                     kw.pop("observe_balls", False), kw.pop("max_episode_steps", None), kw)
    if setup.actions.whole_episode_action:
        return 1
    return setup.max_steps if setup.backstop <= 0 else min(setup.max_steps, setup.backstop)
