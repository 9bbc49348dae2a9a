"""Gymnasium environments of the automatic ball balancer (registered on import).

==============================  ====================  ==========================================
id                              action                module
==============================  ====================  ==========================================
``abb_gym/RunUpTorque-v0``      motor torque          :mod:`abb_gym.envs.torque`
``abb_gym/RunUpSpeed-v0``       rotor acceleration    :mod:`abb_gym.envs.speed`
``abb_gym/DwellProfile-v0``     dwell parameters      :mod:`abb_gym.envs.dwell`
==============================  ====================  ==========================================

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
``TimeLimit`` cuts every episode that is longer than the registered number.  So the RunUp* ids
register no ``max_episode_steps``; instead ``gym.make`` returns the environment inside a
``TimeLimit`` of exactly its own episode length, and ``env.spec.max_episode_steps`` is the real
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

import gymnasium as gym

from .._lazy import lazy_names
from .display import SINGLE_METADATA

if TYPE_CHECKING:  # the names below load on first use (:func:`__getattr__`)
    from .base import BalancerEnv
    from .config import EnvConfig, PresetError, list_presets, load_preset
    from .dwell import DwellProfileEnv
    from .speed import RunUpSpeedEnv
    from .torque import RunUpTorqueEnv
    from .vector import (BalancerVectorEnv, DwellProfileVectorEnv, RunUpSpeedVectorEnv,
                         RunUpTorqueVectorEnv)

# name -> module that defines it.  Loaded on first use, so that ``import abb_gym`` registers
# the ids without importing numba or compiling anything (``import abb_gym`` under 0.5 s:
# ``abb-gym bench speed`` measures it)
_LAZY = {"BalancerEnv": "base", "EnvConfig": "config", "PresetError": "config",
         "list_presets": "config", "load_preset": "config", "DwellProfileEnv": "dwell",
         "RunUpSpeedEnv": "speed", "RunUpTorqueEnv": "torque", "BalancerVectorEnv": "vector",
         "DwellProfileVectorEnv": "vector", "RunUpSpeedVectorEnv": "vector",
         "RunUpTorqueVectorEnv": "vector"}


__getattr__, __dir__ = lazy_names(__name__, _LAZY)


__all__ = ["BalancerEnv", "RunUpTorqueEnv", "RunUpSpeedEnv", "DwellProfileEnv",
           "BalancerVectorEnv", "RunUpTorqueVectorEnv", "RunUpSpeedVectorEnv",
           "DwellProfileVectorEnv", "EnvConfig", "PresetError", "load_preset", "list_presets",
           "ENV_IDS", "DWELL_MAX_EPISODE_STEPS", "episode_steps", "make_runup_torque",
           "make_runup_speed"]

ENV_IDS = ("abb_gym/RunUpTorque-v0", "abb_gym/RunUpSpeed-v0", "abb_gym/DwellProfile-v0")
#: registered ``max_episode_steps`` of DwellProfile-v0 (one-step episodes; module docstring)
DWELL_MAX_EPISODE_STEPS = 2


def _own_limit(env: BalancerEnv) -> gym.Env:
    """``env`` inside a ``TimeLimit`` of its own episode length [control intervals]."""
    setup = env.setup
    steps = setup.max_steps if setup.backstop <= 0 else min(setup.max_steps, setup.backstop)
    return gym.wrappers.TimeLimit(env, max_episode_steps=int(steps))


def make_runup_torque(**kwargs) -> gym.Env:
    """Entry point of ``abb_gym/RunUpTorque-v0``: the environment in a ``TimeLimit`` of its
    own episode length (module docstring)."""
    from .torque import RunUpTorqueEnv
    return _own_limit(RunUpTorqueEnv(**kwargs))


def make_runup_speed(**kwargs) -> gym.Env:
    """Entry point of ``abb_gym/RunUpSpeed-v0``: the environment in a ``TimeLimit`` of its
    own episode length (module docstring)."""
    from .speed import RunUpSpeedEnv
    return _own_limit(RunUpSpeedEnv(**kwargs))


# gym.make checks render_mode against the entry point's metadata
make_runup_torque.metadata = SINGLE_METADATA  # type: ignore[attr-defined]
make_runup_speed.metadata = SINGLE_METADATA  # type: ignore[attr-defined]


def episode_steps(env_id: str = "abb_gym/RunUpSpeed-v0", **kwargs) -> int:
    """Steps of one episode of ``env_id`` made with ``kwargs`` (scene, preset, overrides):
    ``env.spec.max_episode_steps`` of ``gym.make(env_id, **kwargs)`` without building the
    environment's buffers.  Each step is one control interval [s] (DwellProfile: one step)."""
    from .display import check_display
    from .setup import EnvSetup, check_flag
    kinds = {"abb_gym/RunUpTorque-v0": "torque", "abb_gym/RunUpSpeed-v0": "speed",
             "abb_gym/DwellProfile-v0": "dwell"}
    if not isinstance(env_id, str) or env_id not in kinds:
        raise ValueError(f"env_id must be one of {list(kinds)} (got {env_id!r:.80})")
    kw = dict(kwargs)
    # no effect on the length, but checked as gym.make checks them: a keyword gym.make
    # refuses is refused here too, never silently ignored
    check_display(kw.pop("render_mode", None), SINGLE_METADATA["render_modes"],
                  kw.pop("info_level", "lean"))
    check_flag(kw.pop("record_history", False), "record_history")
    setup = EnvSetup(kinds[env_id], kw.pop("scene", "yoshida_odd"), kw.pop("preset", "train"),
                     kw.pop("observe_balls", False), kw.pop("max_episode_steps", None), kw)
    if kinds[env_id] == "dwell":
        return 1
    return setup.max_steps if setup.backstop <= 0 else min(setup.max_steps, setup.backstop)


_REGISTRATIONS = (
    ("abb_gym/RunUpTorque-v0", "abb_gym.envs:make_runup_torque",
     "abb_gym.envs.vector:RunUpTorqueVectorEnv", None),
    ("abb_gym/RunUpSpeed-v0", "abb_gym.envs:make_runup_speed",
     "abb_gym.envs.vector:RunUpSpeedVectorEnv", None),
    ("abb_gym/DwellProfile-v0", "abb_gym.envs.dwell:DwellProfileEnv",
     "abb_gym.envs.vector:DwellProfileVectorEnv", DWELL_MAX_EPISODE_STEPS),
)

for _id, _entry, _vector, _steps in _REGISTRATIONS:
    if _id not in gym.registry:
        gym.register(id=_id, entry_point=_entry, vector_entry_point=_vector,
                     max_episode_steps=_steps)
