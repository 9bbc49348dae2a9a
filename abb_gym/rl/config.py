"""PPO training configurations (rl-baselines3-zoo format) and the environments they build.

A file in ``configs/ppo/`` holds, under the environment id, hyperparameters that
rl-baselines3-zoo reads unchanged (``python -m rl_zoo3.train --algo ppo --env
abb_gym/RunUpSpeed-v0 --gym-packages abb_gym -conf FILE``), and under ``_abb_gym`` the
settings only ``abb-gym train`` uses (rl_zoo3 ignores keys that are not environment ids)::

    abb_gym/RunUpSpeed-v0:
      n_envs: 16                    # sub-environments of the native vector environment
      n_timesteps: 800000           # environment steps (all sub-environments together)
      policy: abb_gym.rl.networks.BoundedMlpPolicy     # or MlpPolicy
      normalize: "dict(norm_obs=True, norm_reward=True)"   # true/false or VecNormalize kwargs
      policy_kwargs: "dict(net_arch=[64, 64], activation_fn=nn.Tanh)"
      learning_rate: lin_3.0e-4     # a number or lin_<start> (linear decay to 0)
      n_steps: 256                  # ... any other PPO keyword
      env_kwargs:                   # gym.make keywords: scene, preset, observe_balls,
        scene: yoshida_odd          # and any preset field (see abb_gym.envs.config)
        preset: train
        control_interval: 0.05
    _abb_gym:
      eval_env_kwargs: {reward: {residual: 3.0}}  # the held-out evaluation (see below)
      eval_freq: 50000              # env steps between evaluations (0: none)
      eval_episodes: 64             # episodes per evaluation (a fixed, seeded test set)
      eval_seed: 1000               # seed of the test set
      checkpoint_freq: 200000       # env steps between checkpoints (0: none)
      bootstrap_truncated: true     # report truncations to SB3 as TimeLimit.truncated

The keys, declared once on :class:`TrainConfig`:

{table}

Any other key under the id must be a PPO keyword argument (``tensorboard_log: DIR``
included: TensorBoard event files, as ``abb-gym train --tensorboard-log DIR``).  The
``_abb_gym`` keys are also accepted under the id (files of the first wave).
``policy_kwargs`` and ``normalize`` may be mappings or the zoo's Python strings, which are
read without evaluating code (:func:`abb_gym.configuration.parse_python_literal`: literals,
``dict(...)`` and ``nn.X``); ``activation_fn`` may name a ``torch.nn`` activation (``Tanh``).
A file may hold several ids; ``load_config(path, env_id)`` picks one.  Top-level keys
starting with ``_`` other than ``_abb_gym`` are ignored (a run's ``config.yml`` keeps its
metadata under ``_run``, so it can be trained again as it is).

The evaluation environment is ``{scene, preset: "test"}`` plus the *policy-relevant* fields of
``env_kwargs`` (:data:`POLICY_FIELDS`: what changes the observation or the meaning of an
action), then ``eval_env_kwargs``; reward weights and randomisation ranges of the training
environment are not carried over, so shaping the reward never changes the test.
"""
from __future__ import annotations

import copy
import inspect
import os
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Mapping

import gymnasium as gym

from .. import resources
from ..configuration import (ConfigError, check, declare, fields_table, locate,
                             parse_python_literal, read_yaml, specs)

__all__ = ["TrainConfig", "load_config", "config_path", "configs_dir", "POLICY_FIELDS",
           "make_native_env", "make_sb3_env", "eval_env_kwargs", "policy_env_fields",
           "linear_schedule", "resolve_policy_kwargs", "ABB_GYM_SECTION"]

#: preset fields that change the observation or the meaning of an action; a policy needs the
#: same values in evaluation (``control_interval``: the same or an integer fraction of it)
POLICY_FIELDS = ("control_interval", "episode_length", "operating_speed",
                 "vibration_filter_time", "dwell")
ENV_KEYWORDS = ("scene", "preset", "observe_balls")
ABB_GYM_SECTION = "_abb_gym"
POLICY_NAMES = {"MlpPolicy": "MlpPolicy",
                "BoundedMlpPolicy": "abb_gym.rl.networks.BoundedMlpPolicy",
                "abb_gym.rl.networks.BoundedMlpPolicy": "abb_gym.rl.networks.BoundedMlpPolicy"}


class TrainConfigError(ConfigError):
    """A PPO configuration is invalid (the message names the key and the file)."""


def configs_dir() -> Path:
    """Folder of the shipped PPO configs (``configs/ppo``)."""
    return resources.shipped_folder("ppo")


def config_path(name_or_path: str | os.PathLike) -> Path:
    """A config file from a path or a name on the search path (``ppo/<name>.yml``)."""
    return locate("ppo", name_or_path, "PPO config", TrainConfigError)


def _ppo_keywords() -> set[str]:
    from stable_baselines3 import PPO
    params = set(inspect.signature(PPO.__init__).parameters)
    return params - {"self", "policy", "env", "policy_kwargs", "seed", "device",
                     "_init_setup_model", "verbose"}


def linear_schedule(start: float):
    """SB3 schedule decaying linearly from ``start`` to 0 over training."""
    def schedule(progress_remaining: float) -> float:
        return progress_remaining * start
    schedule.start = start  # type: ignore[attr-defined]
    return schedule


def _schedule(key: str, value: Any):
    if isinstance(value, str) and value.startswith("lin_"):
        start = check("", key, value[4:], declare(gt=0.0).metadata["spec"], TrainConfigError)
        return linear_schedule(start)
    return check("", key, value, declare(gt=0.0).metadata["spec"], TrainConfigError)


def _torch_nn():
    from torch import nn
    return nn


def resolve_policy_kwargs(value: Any) -> dict[str, Any]:
    """``policy_kwargs`` (a mapping or a zoo string) with ``activation_fn`` as a
    ``torch.nn`` class."""
    nn = _torch_nn()
    if value is None:
        return {}
    if isinstance(value, str):
        value = parse_python_literal(value, {"nn": nn}, "policy_kwargs", TrainConfigError)
    if not isinstance(value, Mapping):
        raise TrainConfigError(f"policy_kwargs must be a mapping (got {value!r})")
    out = dict(value)
    act = out.get("activation_fn")
    if isinstance(act, str):
        name = act.split(".")[-1]
        if not hasattr(nn, name):
            raise TrainConfigError(f"policy_kwargs.activation_fn must name a torch.nn "
                                   f"activation such as Tanh or ReLU (got {act!r})")
        out["activation_fn"] = getattr(nn, name)
    return out


def zoo_policy_kwargs(value: Any) -> str | None:
    """``policy_kwargs`` as the zoo's string (``"dict(..., activation_fn=nn.Tanh)"``)."""
    if value is None:
        return None
    resolved = resolve_policy_kwargs(value)
    parts = []
    for key, v in resolved.items():
        if isinstance(v, type):
            parts.append(f"{key}=nn.{v.__name__}")
        else:
            parts.append(f"{key}={v!r}")
    return f"dict({', '.join(parts)})"


def _normalize(value: Any) -> dict[str, Any] | None:
    if isinstance(value, str):
        value = parse_python_literal(value, {}, "normalize", TrainConfigError)
    if value is True:
        return {"norm_obs": True, "norm_reward": True}
    if value is False or value is None:
        return None
    if not isinstance(value, Mapping):
        raise TrainConfigError(f"field 'normalize' must be true, false or a mapping of "
                               f"VecNormalize keywords (got {value!r})")
    return dict(value)


@dataclass
class TrainConfig:
    """One validated training configuration (see the module docstring for every key)."""

    env_id: str = declare(kind="text", doc="registered environment id")
    n_envs: int = declare(16, kind="integer", ge=1, le=65536,
                          doc="sub-environments of the native vector environment")
    n_timesteps: int = declare(500_000, kind="integer", ge=1, le=10**11,
                               doc="environment steps, all sub-environments together")
    policy: str = declare("MlpPolicy", kind="choice", choices=tuple(POLICY_NAMES),
                          doc="MlpPolicy or abb_gym.rl.networks.BoundedMlpPolicy")
    normalize: dict[str, Any] | None = declare(kind="any",
                                               factory=lambda: {"norm_obs": True,
                                                                "norm_reward": True},
                                               doc="VecNormalize: true, false or its kwargs")
    policy_kwargs: Any = declare(None, kind="any", doc="policy keywords (mapping or zoo "
                                                       "string)")
    hyperparams: dict[str, Any] = declare(kind="any", factory=dict,
                                          doc="the other PPO keyword arguments")
    env_kwargs: dict[str, Any] = declare(kind="any", factory=dict,
                                         doc="gym.make keywords of the training environment")
    eval_env_kwargs: dict[str, Any] = declare(kind="any", factory=dict,
                                              doc="_abb_gym: keywords added to the evaluation "
                                                  "environment")
    eval_freq: int = declare(50_000, kind="integer", ge=0, le=10**11,
                             doc="_abb_gym: env steps between evaluations (0: none)")
    eval_episodes: int = declare(64, kind="integer", ge=1, le=10**6,
                                 doc="_abb_gym: episodes per evaluation")
    eval_seed: int = declare(1000, kind="integer", ge=0, le=2**31,
                             doc="_abb_gym: seed of the evaluation test set")
    checkpoint_freq: int = declare(0, kind="integer", ge=0, le=10**11,
                                   doc="_abb_gym: env steps between checkpoints (0: none)")
    bootstrap_truncated: bool = declare(True, kind="flag",
                                        doc="_abb_gym: report truncations as "
                                            "TimeLimit.truncated")
    source: str = declare("", kind="text", doc="file the config came from")

    @classmethod
    def from_mapping(cls, env_id: str, raw: Mapping[str, Any], source: str = "",
                     extra: Mapping[str, Any] | None = None) -> "TrainConfig":
        """A config from the entry of ``env_id`` (zoo keys and PPO keywords) and the
        ``_abb_gym`` settings ``extra``."""
        where = f"{source or 'PPO config'} [{env_id}]"
        if env_id not in gym.registry:
            import abb_gym  # noqa: F401  (registers the ids)
        if env_id not in gym.registry:
            raise TrainConfigError(f"unknown environment id {env_id!r}; registered abb_gym "
                                   f"ids: {sorted(k for k in gym.registry if k.startswith('abb_gym/'))}")
        if not isinstance(raw, Mapping):
            raise TrainConfigError(f"{where}: the entry must be a mapping of hyperparameters "
                                   f"(got {raw!r})")
        if extra is not None and not isinstance(extra, Mapping):
            raise TrainConfigError(f"{where}: {ABB_GYM_SECTION} must be a mapping (got "
                                   f"{extra!r})")
        raw = {**copy.deepcopy(dict(raw)), **copy.deepcopy(dict(extra or {}))}
        table = specs(cls)
        own = set(table) - {"env_id", "hyperparams", "source"}
        ppo_keys = _ppo_keywords()
        unknown = sorted(set(raw) - own - ppo_keys)
        if unknown:
            raise TrainConfigError(f"{where}: unknown key(s) {unknown}; allowed: "
                                   f"{sorted(own)} and the PPO keywords {sorted(ppo_keys)}")
        values: dict[str, Any] = {}
        for key in own & set(raw):
            v = raw.pop(key)
            if key == "normalize":
                v = _normalize(v)
            elif key == "policy_kwargs":
                resolve_policy_kwargs(v)  # validate now
            elif key in ("env_kwargs", "eval_env_kwargs"):
                v = v or {}
                if not isinstance(v, Mapping):
                    raise TrainConfigError(f"{where}: field {key!r} must be a mapping (got "
                                           f"{v!r})")
                v = dict(v)
            else:
                v = check(where, key, v, table[key], TrainConfigError)
            values[key] = v
        if "policy" in values:
            values["policy"] = POLICY_NAMES[values["policy"]]
        tb = raw.get("tensorboard_log")
        if tb is not None and (not isinstance(tb, str) or not tb):
            # SB3 would only fail when training starts, after the environments are built
            raise TrainConfigError(f"{where}: field 'tensorboard_log' must be a folder path "
                                   f"or null (got {tb!r})")
        for key in ("learning_rate", "clip_range"):
            if key in raw:
                _schedule(key, raw[key])
        return cls(env_id=env_id, hyperparams=raw, source=str(source), **values)

    def with_overrides(self, **changes: Any) -> "TrainConfig":
        """A copy with top-level keys or PPO hyperparameters replaced (validated again)."""
        raw = self.to_mapping()
        raw.update(self.abb_gym_settings())
        for key, value in changes.items():
            if key in ("env_kwargs", "eval_env_kwargs") and isinstance(value, Mapping):
                raw[key] = {**raw.get(key, {}), **value}
            else:
                raw[key] = value
        return TrainConfig.from_mapping(self.env_id, raw, self.source)

    def to_mapping(self) -> dict[str, Any]:
        """The zoo-compatible entry of this config (what ``config.yml`` stores under the id)."""
        out: dict[str, Any] = {"n_envs": self.n_envs, "n_timesteps": self.n_timesteps,
                               "policy": self.policy}
        out["normalize"] = (f"dict({', '.join(f'{k}={v!r}' for k, v in self.normalize.items())})"
                            if self.normalize is not None else False)
        if self.policy_kwargs is not None:
            out["policy_kwargs"] = zoo_policy_kwargs(self.policy_kwargs)
        out.update(copy.deepcopy(self.hyperparams))
        out["env_kwargs"] = copy.deepcopy(self.env_kwargs)
        return out

    def abb_gym_settings(self) -> dict[str, Any]:
        """The ``_abb_gym`` section: settings of ``abb-gym train`` that rl_zoo3 does not know."""
        return {"eval_env_kwargs": copy.deepcopy(self.eval_env_kwargs),
                "eval_freq": self.eval_freq, "eval_episodes": self.eval_episodes,
                "eval_seed": self.eval_seed, "checkpoint_freq": self.checkpoint_freq,
                "bootstrap_truncated": self.bootstrap_truncated}

    def to_file_data(self) -> dict[str, Any]:
        """The whole file: the zoo entry under the id and the ``_abb_gym`` section."""
        return {self.env_id: self.to_mapping(), ABB_GYM_SECTION: self.abb_gym_settings()}

    def ppo_kwargs(self) -> dict[str, Any]:
        """Keyword arguments for ``PPO(...)`` (schedules and activation functions resolved)."""
        kw = dict(self.hyperparams)
        for key in ("learning_rate", "clip_range"):
            if key in kw:
                kw[key] = _schedule(key, kw[key])
        kw["policy_kwargs"] = resolve_policy_kwargs(self.policy_kwargs)
        return kw


__doc__ = __doc__.replace("{table}", fields_table(
    TrainConfig, [n for n in specs(TrainConfig) if n not in ("env_id", "hyperparams",
                                                              "source")], title="key"))


def load_config(name_or_path: str | os.PathLike, env_id: str | None = None) -> TrainConfig:
    """Read ``env_id``'s entry of a config file (by path or name on the search path)."""
    path = config_path(name_or_path)
    data = read_yaml(path, "PPO config", TrainConfigError)
    extra = data.get(ABB_GYM_SECTION)
    data = {k: v for k, v in data.items() if not str(k).startswith("_")}  # _run: metadata
    if not data:
        raise TrainConfigError(f"PPO config {str(path)!r} must map environment ids to "
                               f"hyperparameters")
    if env_id is None:
        if len(data) != 1:
            raise TrainConfigError(f"PPO config {str(path)!r} holds several ids "
                                   f"{sorted(data)}; choose one with --env")
        env_id = next(iter(data))
    if env_id not in data:
        raise TrainConfigError(f"PPO config {str(path)!r} has no entry for {env_id!r}; it has "
                               f"{sorted(data)}")
    return TrainConfig.from_mapping(env_id, data[env_id], str(path), extra)


def eval_env_kwargs(cfg: TrainConfig) -> dict[str, Any]:
    """Keywords of the held-out evaluation environment (see the module docstring)."""
    env = cfg.env_kwargs
    out: dict[str, Any] = {"scene": env.get("scene", "yoshida_odd"), "preset": "test"}
    if "observe_balls" in env:
        out["observe_balls"] = env["observe_balls"]
    for key in POLICY_FIELDS:
        if key in env:
            out[key] = copy.deepcopy(env[key])
    out.update(copy.deepcopy(cfg.eval_env_kwargs))
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
