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
:mod:`abb_gym.envs.config`.  The environments truncate themselves at the preset's episode
length (it depends on the scene); the registered ``max_episode_steps`` is a backstop that
never cuts an episode of a shipped preset (RunUp*: 100 000 steps = 1000 s at 10 ms;
DwellProfile: 2, its episodes are one step long).
"""
from __future__ import annotations

import gymnasium as gym

from .base import BalancerEnv
from .config import EnvConfig, PresetError, list_presets, load_preset
from .dwell import DwellProfileEnv
from .speed import RunUpSpeedEnv
from .torque import RunUpTorqueEnv
from .vector import (BalancerVectorEnv, DwellProfileVectorEnv, RunUpSpeedVectorEnv,
                     RunUpTorqueVectorEnv)

__all__ = ["BalancerEnv", "RunUpTorqueEnv", "RunUpSpeedEnv", "DwellProfileEnv",
           "BalancerVectorEnv", "RunUpTorqueVectorEnv", "RunUpSpeedVectorEnv",
           "DwellProfileVectorEnv", "EnvConfig", "PresetError", "load_preset", "list_presets",
           "ENV_IDS", "RUNUP_MAX_EPISODE_STEPS"]

RUNUP_MAX_EPISODE_STEPS = 100_000
ENV_IDS = ("abb_gym/RunUpTorque-v0", "abb_gym/RunUpSpeed-v0", "abb_gym/DwellProfile-v0")

_REGISTRATIONS = (
    ("abb_gym/RunUpTorque-v0", "torque:RunUpTorqueEnv", "vector:RunUpTorqueVectorEnv",
     RUNUP_MAX_EPISODE_STEPS),
    ("abb_gym/RunUpSpeed-v0", "speed:RunUpSpeedEnv", "vector:RunUpSpeedVectorEnv",
     RUNUP_MAX_EPISODE_STEPS),
    ("abb_gym/DwellProfile-v0", "dwell:DwellProfileEnv", "vector:DwellProfileVectorEnv", 2),
)

for _id, _entry, _vector, _steps in _REGISTRATIONS:
    if _id not in gym.registry:
        gym.register(id=_id, entry_point=f"abb_gym.envs.{_entry}",
                     vector_entry_point=f"abb_gym.envs.{_vector}", max_episode_steps=_steps)
