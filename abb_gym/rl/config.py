"""PPO training configurations (rl-baselines3-zoo style) and the environments they build.

A file in ``configs/ppo/`` maps environment ids to their hyperparameters::

    abb_gym/RunUpSpeed-v0:
      n_envs: 16                    # sub-environments of the native vector environment
      n_timesteps: 800000           # environment steps (all sub-environments together)
      policy: BoundedMlpPolicy      # or MlpPolicy (see abb_gym.rl.policies)
      normalize: {norm_obs: true, norm_reward: true}   # VecNormalize kwargs, or true/false
      policy_kwargs: {net_arch: [64, 64], activation_fn: Tanh}
      learning_rate: lin_3.0e-4     # a number or lin_<start> (linear decay to 0)
      n_steps: 256                  # ... any other PPO keyword
      env_kwargs:                   # gym.make_vec keywords: scene, preset, observe_balls,
        scene: yoshida_odd          # and any preset field (see abb_gym.envs.config)
        preset: train
        control_interval: 0.05
        reward: {residual: 3.0}
      eval_env_kwargs: {preset: test}     # the held-out evaluation environment (see below)
      eval_freq: 50000              # env steps between evaluations (0: none)
      eval_episodes: 64             # episodes per evaluation (a fixed, seeded test set)
      eval_seed: 1000               # seed of the test set
      checkpoint_freq: 200000       # env steps between checkpoints (0: none)
      bootstrap_truncated: true     # report truncations to SB3 as TimeLimit.truncated

Keys other than the ones above and PPO's keyword arguments raise ``ValueError`` naming the key.
A file may hold several ids; ``load_config(path, env_id)`` picks one (a file with one id needs
no ``env_id``).  Top-level keys starting with ``_`` are ignored (a run's ``config.yml`` keeps
its metadata under ``_run``, so it can be trained again as it is).  ``activation_fn`` may be a name of ``torch.nn`` (``Tanh``, ``ReLU``);
``policy_kwargs`` may also be a zoo string such as ``"dict(net_arch=[64, 64])"``, evaluated with
only ``dict`` and ``nn`` in scope.

The evaluation environment is ``{scene, preset: "test"}`` plus the *policy-relevant* fields of
``env_kwargs`` (:data:`POLICY_FIELDS`: what changes the observation or the meaning of an
action), then ``eval_env_kwargs``; reward weights and randomisation ranges of the training
environment are not carried over, so shaping the reward never changes the test.
"""
from __future__ import annotations

import copy
import inspect
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Mapping

import gymnasium as gym
import yaml

__all__ = ["TrainConfig", "load_config", "config_path", "configs_dir", "POLICY_FIELDS",
           "make_native_env", "make_sb3_env", "eval_env_kwargs", "policy_env_fields",
           "linear_schedule", "resolve_policy_kwargs"]

#: preset fields that change the observation or the meaning of an action; a policy needs the
#: same values in evaluation (``control_interval``: the same or an integer fraction of it)
POLICY_FIELDS = ("control_interval", "episode_length", "operating_speed",
                 "vibration_filter_time", "dwell")
ENV_KEYWORDS = ("scene", "preset", "observe_balls")

_EXTRA_KEYS = {
    "n_envs": "integer >= 1",
    "n_timesteps": "integer >= 1",
    "policy": "'MlpPolicy' or 'BoundedMlpPolicy'",
    "normalize": "true, false or a mapping of VecNormalize keywords",
    "policy_kwargs": "mapping (or zoo string)",
    "env_kwargs": "mapping",
    "eval_env_kwargs": "mapping",
    "eval_freq": "integer >= 0",
    "eval_episodes": "integer >= 1",
    "eval_seed": "integer >= 0",
    "checkpoint_freq": "integer >= 0",
    "bootstrap_truncated": "true or false",
}


def configs_dir() -> Path:
    """``$ABB_GYM_CONFIGS/ppo`` or the repository's ``configs/ppo``."""
    root = os.environ.get("ABB_GYM_CONFIGS")
    base = Path(root) if root else Path(__file__).resolve().parents[2] / "configs"
    return base / "ppo"


def config_path(name_or_path: str | os.PathLike) -> Path:
    """A config file from a path or a name in :func:`configs_dir` (``.yml``/``.yaml``)."""
    p = Path(name_or_path)
    if p.exists():
        return p
    for ext in (".yml", ".yaml", ""):
        q = configs_dir() / f"{name_or_path}{ext}"
        if q.exists():
            return q
    names = sorted(x.stem for x in configs_dir().glob("*.y*ml"))
    raise ValueError(f"unknown PPO config {str(name_or_path)!r}; available in "
                     f"{configs_dir()}: {', '.join(names) or 'none'} (or give a path)")


def _ppo_keywords() -> set[str]:
    from stable_baselines3 import PPO
    params = set(inspect.signature(PPO.__init__).parameters)
    return params - {"self", "policy", "env", "policy_kwargs", "seed", "device",
                     "_init_setup_model", "tensorboard_log", "verbose"}


def linear_schedule(start: float):
    """SB3 schedule decaying linearly from ``start`` to 0 over training."""
    def schedule(progress_remaining: float) -> float:
        return progress_remaining * start
    schedule.start = start  # type: ignore[attr-defined]
    return schedule


def _schedule(key: str, value: Any):
    if isinstance(value, str) and value.startswith("lin_"):
        try:
            start = float(value[4:])
        except ValueError:
            raise ValueError(f"{key} must be a number > 0 or 'lin_<number>' (got "
                             f"{value!r})") from None
        if start <= 0:
            raise ValueError(f"{key} must be > 0 (got {value!r})")
        return linear_schedule(start)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value <= 0:
        raise ValueError(f"{key} must be a number > 0 or 'lin_<number>' (got {value!r})")
    return float(value)


def resolve_policy_kwargs(value: Any) -> dict[str, Any]:
    """``policy_kwargs`` with ``activation_fn`` names turned into ``torch.nn`` classes."""
    from torch import nn
    if value is None:
        return {}
    if isinstance(value, str):
        try:
            value = eval(value, {"__builtins__": {}}, {"dict": dict, "nn": nn})  # noqa: S307
        except Exception as exc:
            raise ValueError(f"policy_kwargs string {value!r} could not be read: {exc}"
                             ) from None
    if not isinstance(value, Mapping):
        raise ValueError(f"policy_kwargs must be a mapping (got {value!r})")
    out = dict(value)
    act = out.get("activation_fn")
    if isinstance(act, str):
        name = act.split(".")[-1]
        if not hasattr(nn, name):
            raise ValueError(f"policy_kwargs.activation_fn must name a torch.nn activation "
                             f"such as Tanh or ReLU (got {act!r})")
        out["activation_fn"] = getattr(nn, name)
    return out


def _int(key: str, value: Any, lo: int) -> int:
    if isinstance(value, bool):
        raise ValueError(f"{key} must be an integer >= {lo} (got {value!r})")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{key} must be an integer >= {lo} (got {value!r})") from None
    if v != int(v) or v < lo:
        raise ValueError(f"{key} must be an integer >= {lo} (got {value!r})")
    return int(v)


@dataclass
class TrainConfig:
    """One validated training configuration (see the module docstring for every key)."""

    env_id: str
    n_envs: int = 16
    n_timesteps: int = 500_000
    policy: str = "MlpPolicy"
    normalize: dict[str, Any] | None = field(default_factory=lambda: {"norm_obs": True,
                                                                      "norm_reward": True})
    policy_kwargs: Any = None
    hyperparams: dict[str, Any] = field(default_factory=dict)
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    eval_env_kwargs: dict[str, Any] = field(default_factory=dict)
    eval_freq: int = 50_000
    eval_episodes: int = 64
    eval_seed: int = 1000
    checkpoint_freq: int = 0
    bootstrap_truncated: bool = True
    source: str = ""

    @classmethod
    def from_mapping(cls, env_id: str, raw: Mapping[str, Any], source: str = ""
                     ) -> "TrainConfig":
        if env_id not in gym.registry:
            import abb_gym  # noqa: F401  (registers the ids)
        if env_id not in gym.registry:
            raise ValueError(f"unknown environment id {env_id!r}; registered abb_gym ids: "
                             f"{sorted(k for k in gym.registry if k.startswith('abb_gym/'))}")
        if not isinstance(raw, Mapping):
            raise ValueError(f"{source or 'config'}: the entry of {env_id!r} must be a mapping "
                             f"of hyperparameters (got {raw!r})")
        raw = copy.deepcopy(dict(raw))
        ppo_keys = _ppo_keywords()
        unknown = sorted(set(raw) - set(_EXTRA_KEYS) - ppo_keys)
        if unknown:
            raise ValueError(f"{source or 'config'} [{env_id}]: unknown key(s) {unknown}; "
                             f"allowed: {sorted(_EXTRA_KEYS)} and the PPO keywords "
                             f"{sorted(ppo_keys)}")
        cfg = cls(env_id=env_id, source=str(source))
        if "n_envs" in raw:
            cfg.n_envs = _int("n_envs", raw.pop("n_envs"), 1)
        if "n_timesteps" in raw:
            cfg.n_timesteps = _int("n_timesteps", raw.pop("n_timesteps"), 1)
        if "policy" in raw:
            cfg.policy = str(raw.pop("policy"))
            if cfg.policy not in ("MlpPolicy", "BoundedMlpPolicy"):
                raise ValueError(f"policy must be 'MlpPolicy' or 'BoundedMlpPolicy' (flat Box "
                                 f"observations; see abb_gym.rl.policies; got {cfg.policy!r})")
        if "normalize" in raw:
            norm = raw.pop("normalize")
            if isinstance(norm, str):
                try:
                    norm = eval(norm, {"__builtins__": {}}, {"dict": dict,  # noqa: S307
                                                             "True": True, "False": False})
                except Exception:
                    raise ValueError(f"normalize must be true, false or a mapping (got "
                                     f"{norm!r})") from None
            if norm is True:
                norm = {"norm_obs": True, "norm_reward": True}
            elif norm is False or norm is None:
                norm = None
            elif not isinstance(norm, Mapping):
                raise ValueError(f"normalize must be true, false or a mapping of VecNormalize "
                                 f"keywords (got {norm!r})")
            cfg.normalize = None if norm is None else dict(norm)
        if "policy_kwargs" in raw:
            cfg.policy_kwargs = raw.pop("policy_kwargs")
            resolve_policy_kwargs(cfg.policy_kwargs)  # validate now
        for key in ("env_kwargs", "eval_env_kwargs"):
            if key in raw:
                v = raw.pop(key) or {}
                if not isinstance(v, Mapping):
                    raise ValueError(f"{key} must be a mapping (got {v!r})")
                setattr(cfg, key, dict(v))
        if "eval_freq" in raw:
            cfg.eval_freq = _int("eval_freq", raw.pop("eval_freq"), 0)
        if "eval_episodes" in raw:
            cfg.eval_episodes = _int("eval_episodes", raw.pop("eval_episodes"), 1)
        if "eval_seed" in raw:
            cfg.eval_seed = _int("eval_seed", raw.pop("eval_seed"), 0)
        if "checkpoint_freq" in raw:
            cfg.checkpoint_freq = _int("checkpoint_freq", raw.pop("checkpoint_freq"), 0)
        if "bootstrap_truncated" in raw:
            v = raw.pop("bootstrap_truncated")
            if not isinstance(v, bool):
                raise ValueError(f"bootstrap_truncated must be true or false (got {v!r})")
            cfg.bootstrap_truncated = v
        for key in ("learning_rate", "clip_range"):
            if key in raw:
                _schedule(key, raw[key])
        cfg.hyperparams = raw
        return cfg

    def with_overrides(self, **changes: Any) -> "TrainConfig":
        """A copy with top-level keys or PPO hyperparameters replaced (validated again)."""
        raw = self.to_mapping()
        for key, value in changes.items():
            if key in ("env_kwargs", "eval_env_kwargs") and isinstance(value, Mapping):
                raw[key] = {**raw.get(key, {}), **value}
            else:
                raw[key] = value
        return TrainConfig.from_mapping(self.env_id, raw, self.source)

    def to_mapping(self) -> dict[str, Any]:
        """The zoo-style mapping of this config (what ``config.yml`` stores under the id)."""
        d = asdict(self)
        out: dict[str, Any] = {k: d[k] for k in ("n_envs", "n_timesteps", "policy")}
        out["normalize"] = d["normalize"] if d["normalize"] is not None else False
        if d["policy_kwargs"] is not None:
            out["policy_kwargs"] = d["policy_kwargs"]
        out.update(d["hyperparams"])
        for k in ("env_kwargs", "eval_env_kwargs", "eval_freq", "eval_episodes", "eval_seed",
                  "checkpoint_freq", "bootstrap_truncated"):
            out[k] = d[k]
        return out

    def ppo_kwargs(self) -> dict[str, Any]:
        """Keyword arguments for ``PPO(...)`` (schedules and activation functions resolved)."""
        kw = dict(self.hyperparams)
        for key in ("learning_rate", "clip_range"):
            if key in kw:
                kw[key] = _schedule(key, kw[key])
        kw["policy_kwargs"] = resolve_policy_kwargs(self.policy_kwargs)
        return kw


def load_config(name_or_path: str | os.PathLike, env_id: str | None = None) -> TrainConfig:
    """Read ``env_id``'s entry of a zoo-style YAML file (by path or name in ``configs/ppo``)."""
    path = config_path(name_or_path)
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as exc:
        raise ValueError(f"PPO config {str(path)!r} is not valid YAML: {exc}") from None
    if not isinstance(data, Mapping):
        raise ValueError(f"PPO config {str(path)!r} must map environment ids to "
                         f"hyperparameters")
    data = {k: v for k, v in data.items() if not str(k).startswith("_")}  # _run: metadata
    if not data:
        raise ValueError(f"PPO config {str(path)!r} must map environment ids to "
                         f"hyperparameters")
    if env_id is None:
        if len(data) != 1:
            raise ValueError(f"PPO config {str(path)!r} holds several ids {sorted(data)}; "
                             f"choose one with --env")
        env_id = next(iter(data))
    if env_id not in data:
        raise ValueError(f"PPO config {str(path)!r} has no entry for {env_id!r}; it has "
                         f"{sorted(data)}")
    return TrainConfig.from_mapping(env_id, data[env_id], str(path))


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
