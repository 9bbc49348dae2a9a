"""The environments a config or an agent needs, and the contract between a policy and its
environment.

The evaluation environment is ``{scene, preset: "test"}`` plus the *policy-relevant* fields of
``env_kwargs`` (:data:`POLICY_FIELDS`: what changes the observation or the meaning of an
action), then ``eval_env_kwargs``; reward weights and randomisation ranges of the training
environment are not carried over, so shaping the reward never changes the test.  (rl_zoo3's
own evaluation uses the training ``env_kwargs`` unless ``--eval-env-kwargs`` is given.)

A trained agent stores the resolved policy-relevant settings of its training environment
(:func:`policy_env_fields`, its ``_run.policy_env``); :func:`observation_kwargs` gives an
environment the agent's observation, and :func:`policy_env_mismatch` names the field in which
an environment differs from it.
"""
from __future__ import annotations

import copy
import math
from typing import TYPE_CHECKING, Any, Mapping

import gymnasium as gym

from ..envs import tasks
from ..envs.observation import LAYOUT_FIELDS

if TYPE_CHECKING:
    from .config import TrainConfig

__all__ = ["OBSERVATION_FIELDS", "POLICY_FIELDS", "eval_env_kwargs", "observation_kwargs",
           "policy_env_fields", "policy_env_mismatch", "make_native_env", "make_sb3_env"]

#: preset fields that shape the observation (the environment must use the agent's values): the
#: observation's declaration names them (:data:`abb_gym.envs.observation.LAYOUT_FIELDS`)
OBSERVATION_FIELDS = LAYOUT_FIELDS
#: preset fields that change the observation or the meaning of an action; a policy needs the
#: same values in evaluation (``control_interval``: the same or an integer fraction of it)
POLICY_FIELDS = ("control_interval", "episode_length", "operating_speed",
                 "vibration_filter_time", "dwell") + OBSERVATION_FIELDS


def eval_env_kwargs(cfg: TrainConfig) -> dict[str, Any]:
    """Keywords of the held-out evaluation environment (see the module docstring)."""
    env = cfg.env_kwargs
    task = tasks.get(cfg.env_id)
    out: dict[str, Any] = {"scene": env.get("scene", task.default_scene),
                           "preset": task.test_preset}
    if "observe_balls" in env:
        out["observe_balls"] = env["observe_balls"]
    for key in POLICY_FIELDS:
        if key in env:
            out[key] = copy.deepcopy(env[key])
    out.update(copy.deepcopy(cfg.eval_env_kwargs))
    return out


def observation_kwargs(policy_env: Mapping[str, Any]) -> dict[str, Any]:
    """The environment keywords that give an agent its observation (``observe_balls`` if set,
    and the :data:`OBSERVATION_FIELDS` it was trained with), from its stored ``policy_env``;
    agents saved before a field existed lack it and use the preset's value."""
    out: dict[str, Any] = {"observe_balls": True} if policy_env.get("observe_balls") else {}
    out.update({k: copy.deepcopy(policy_env[k]) for k in OBSERVATION_FIELDS if k in policy_env})
    # a frame stack holds the last k observations of the environment's own steps: its frames
    # are one control interval apart, so the agent's interval is part of its observation (on
    # a finer environment, holding each action, it would see k frames of a shorter past)
    if int(policy_env.get("frame_stack") or 1) > 1 and "control_interval" in policy_env:
        out["control_interval"] = policy_env["control_interval"]
    return out


def policy_env_fields(native_env: Any) -> dict[str, Any]:
    """The resolved policy-relevant settings of an environment (stored with a trained agent)."""
    setup = native_env.unwrapped.setup
    conf = setup.config.to_dict()
    out = {k: conf[k] for k in POLICY_FIELDS}
    out["control_interval"] = float(setup.control_interval)
    out["episode_length"] = float(setup.episode_length)
    out["operating_speed"] = float(setup.operating_speed)
    out["observe_balls"] = bool(setup.observe_balls)
    out["scene"] = setup.scene.name
    out["kind"] = setup.kind
    return out


def policy_env_mismatch(want: Mapping[str, Any], setup: Any) -> str | None:
    """What differs between an agent's recorded policy-relevant settings ``want`` (its
    ``_run.policy_env``) and an environment's resolved ``setup``, as a sentence naming the
    field, or None.  The control interval is the caller's rule (an evaluation may hold each
    action for an integer number of steps, a warm start may not), so it is not compared here.
    Fields missing from ``want`` (agents of older versions) are not compared."""
    kind = want.get("kind")
    if kind is not None and kind != setup.kind:
        return (f"the action kind of the environment ({setup.kind!r}) differs from the "
                f"agent's ({kind!r})")
    conf = setup.config.to_dict()
    for key in ("vibration_filter_time", "dwell") + OBSERVATION_FIELDS:
        if key in want and conf[key] != want[key]:
            return (f"preset field {key!r} of the environment ({conf[key]!r}) differs from "
                    f"the agent's ({want[key]!r})")
    for key, have in (("operating_speed", setup.operating_speed),
                      ("episode_length", setup.episode_length)):
        value = want.get(key)
        if value is not None and not math.isclose(have, value, rel_tol=1e-9):
            return (f"preset field {key!r} of the environment ({have:g}) differs from the "
                    f"agent's ({value:g})")
    return None


def make_native_env(env_id: str, n_envs: int, env_kwargs: Mapping[str, Any] | None = None):
    """``gym.make_vec(env_id, num_envs=n_envs, vectorization_mode="vector_entry_point", ...)``."""
    import abb_gym  # noqa: F401
    kwargs = dict(env_kwargs or {})
    return gym.make_vec(env_id, num_envs=int(n_envs), vectorization_mode="vector_entry_point",
                        **kwargs)


def make_sb3_env(env_id: str, n_envs: int, env_kwargs: Mapping[str, Any] | None = None, *,
                 bootstrap_truncated: bool = True, info_keys=None):
    """The native vector environment behind the SB3 adapter
    (:class:`abb_gym.rl.vec_env.NativeVecEnv`)."""
    from .vec_env import NativeVecEnv
    return NativeVecEnv(make_native_env(env_id, n_envs, env_kwargs),
                        bootstrap_truncated=bootstrap_truncated, info_keys=info_keys)
