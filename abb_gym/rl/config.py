"""PPO training configurations (rl-baselines3-zoo format): the file format and its parsing.

A file in ``configs/ppo/`` is an rl-baselines3-zoo hyperparameter file: rl_zoo3 trains it
unchanged, and ``abb-gym train`` reads the same file::

    pip install -c constraints.txt rl_zoo3
    python -m rl_zoo3.train --algo ppo --env abb_gym/RunUpSpeed-v0 --gym-packages abb_gym \\
        -conf configs/ppo/runup_speed_yoshida_odd.yml
    abb-gym train --config runup_speed_yoshida_odd

The entry under the environment id holds what both read; ``_abb_gym`` holds the settings only
``abb-gym train`` uses::

    abb_gym/RunUpSpeed-v0:
      n_envs: 16                    # sub-environments of the native vector environment
      n_timesteps: 800000           # environment steps (all sub-environments together)
      policy: abb_gym.rl.networks.BoundedMlpPolicy     # or MlpPolicy
      normalize: "dict(norm_obs=True, norm_reward=True)"   # true/false or VecNormalize kwargs
      policy_kwargs: "dict(net_arch=[64, 64], activation_fn=nn.Tanh, action_mean_init=0.5)"
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
      tensorboard_log: tb           # TensorBoard event files (as --tensorboard-log DIR)
      shaping: {observation: sync_amplitude, weight: 10.0}   # potential-based, training only
      curriculum: {fields: [critical_speed_scale], start: 0.2, full_at: 0.5}  # narrow first
      oversample: {share: 0.3, randomize: {imbalance_ratio: [1.0, 1.6]}}  # hard cases more often
      algo: sac                     # sac or tqc (policy MlpPolicy); default from the policy
      init_from: {folder: runs/x, model: best}   # start from that run's weights (fine-tune)
      imitate: {policy: "baseline:redistribute_low", episodes: 256}   # clone, then PPO

The keys, declared once on :class:`TrainConfig`:

{table}

Any other key under the id must be a PPO keyword argument.  ``policy_kwargs`` and
``normalize`` are the zoo's Python strings (or mappings), which ``abb-gym train`` reads
without evaluating code (:func:`abb_gym.configuration.parse_python_literal`: literals,
``dict(...)`` and ``nn.X``).  A file may hold several ids; ``load_config(path, env_id)`` picks
one.  Top-level keys starting with ``_`` other than ``_abb_gym`` are ignored (a run's
``config.yml`` keeps its metadata under ``_run``; it is in this format, so both ``abb-gym
train`` and rl_zoo3 train it again as it is).

Why this layout (what rl_zoo3 does with a file: ``rl_zoo3/exp_manager.py``,
``read_hyperparameters`` and ``_preprocess_hyperparams``):

* rl_zoo3 reads only the entry under ``--env``; every key there that it does not consume
  itself (``n_envs``, ``n_timesteps``, ``normalize``, ``env_kwargs``, ``policy_kwargs`` ...)
  goes to ``PPO(...)``, which rejects unknown keywords.  The evaluation, checkpoint and
  TensorBoard settings have no config-file counterpart in the zoo (it takes ``--eval-freq``,
  ``--eval-episodes``, ``--eval-env-kwargs``, ``--save-freq``, ``--tensorboard-log`` on its
  command line, and passes ``tensorboard_log`` to PPO itself, so the key under the id would
  be given twice), so they live in a separate top-level section the zoo never looks at.
  ``_abb_gym`` starts with ``_`` and therefore can never be an environment id.
* The bounded policy is named by its import path: rl_zoo3 imports a ``policy`` containing a
  dot (``get_class_by_name``), and ``abb_gym.rl.networks.BoundedMlpPolicy`` is also the
  class SB3 stores in ``model.zip``, so the zoo builds exactly the network ``abb-gym train``
  builds and the shipped agents keep loading.  The alternatives change the algorithm: SB3's
  ``squash_output`` policy keyword is allowed only with gSDE and squashes the *sample*
  (changing its log-probability), and an action ``env_wrapper`` bounds the applied action
  but not the Gaussian mean, whose run-away beyond the clip is what BoundedMlpPolicy
  prevents (see :mod:`abb_gym.rl.networks`).
* A policy with memory (``MlpLstmPolicy``, or ``abb_gym.rl.networks.BoundedMlpLstmPolicy``
  with the bounded mean) is trained by sb3-contrib's ``RecurrentPPO``, as rl_zoo3 does with
  ``--algo ppo_lstm``: the algorithm follows from the policy (:func:`~abb_gym.rl.algorithms.algorithm_of`), so the
  file needs no key of its own, and the keys under the id are RecurrentPPO's keywords.
* SAC and sb3-contrib's TQC (off-policy, their own squashed-Gaussian ``MlpPolicy``) are
  chosen by ``algo: sac`` or ``algo: tqc`` in ``_abb_gym`` (rl_zoo3 takes ``--algo`` on its
  command line); the keys under the id are then that algorithm's keywords.
* ``policy_kwargs`` is the zoo's string (``activation_fn=nn.Tanh``): the zoo evaluates a
  string with ``torch.nn`` in scope but passes a mapping on unchanged, where
  ``activation_fn: Tanh`` would reach torch as a string.

:func:`abb_gym.rl.zoo.zoo_problems` checks a file against these rules without rl_zoo3.

The first-wave format, still read (the shipped agents' ``agents/trained/*/config.yml`` use it
and are fingerprinted): the ``_abb_gym`` keys under the id, ``policy: BoundedMlpPolicy`` and
``policy_kwargs`` as a mapping with ``activation_fn: Tanh``.  rl_zoo3 cannot read such a file;
``abb-gym train`` reads it as the same :class:`TrainConfig` as the current file it came from
(tested for every shipped agent) and writes the run's ``config.yml`` in the current format.
``tensorboard_log`` is accepted only in ``_abb_gym``.

The evaluation environment built from a config, and the environment a trained agent needs:
:mod:`abb_gym.rl.env_factory`.
"""
from __future__ import annotations

import copy
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import gymnasium as gym

from .. import resources
from ..configuration import (ConfigError, build_section, check, declare, fields_table,
                             locate, parse_python_literal, read_yaml, specs)
from .algorithms import (ALGORITHMS, OFF_POLICY, POLICY_NAMES, STARTED_POLICIES,
                         algorithm_keywords, algorithm_of)

__all__ = ["TrainConfig", "WarmStartSettings", "warm_start_settings", "load_config",
           "config_path", "configs_dir", "linear_schedule", "resolve_policy_kwargs",
           "ABB_GYM_SECTION", "ABB_GYM_KEYS", "TrainConfigError", "section_algorithm"]

#: gym.make_vec keywords the trainer sets itself
RESERVED_ENV_KWARGS = frozenset({"id", "num_envs", "vectorization_mode", "vector_kwargs",
                                 "wrappers"})
ABB_GYM_SECTION = "_abb_gym"
#: the keys of the ``_abb_gym`` section: settings of ``abb-gym train`` that rl_zoo3 does not know
ABB_GYM_KEYS = ("eval_env_kwargs", "eval_freq", "eval_episodes", "eval_seed",
                "checkpoint_freq", "bootstrap_truncated", "tensorboard_log", "shaping",
                "curriculum", "oversample", "algo", "init_from", "imitate")
#: of those, the ones only the ``_abb_gym`` section may hold
SECTION_ONLY_KEYS = ("tensorboard_log", "shaping", "curriculum", "oversample", "algo", "init_from",
                     "imitate")
#: a number or ``lin_<start>`` (the keys rl_zoo3 turns into schedules for PPO)
SCHEDULE_KEYS = ("learning_rate", "clip_range", "clip_range_vf")


def _check_algorithm(where: str, policy: Any, algo: Any) -> str:
    """The algorithm of a config entry's ``policy`` and ``_abb_gym.algo`` (None: from the
    policy), or a TrainConfigError naming the field."""
    if algo is not None and (not isinstance(algo, str) or algo not in ALGORITHMS):
        raise TrainConfigError(f"{where}: field 'algo' must be one of {list(ALGORITHMS)} (got "
                               f"{algo!r})")
    policy = str(policy)
    implied = algorithm_of(policy)
    if algo in OFF_POLICY:
        allowed = ["MlpPolicy"] + [p for p, a in STARTED_POLICIES.items() if a == algo]
        if POLICY_NAMES.get(policy) not in allowed:
            raise TrainConfigError(f"{where}: field 'policy' must be one of {allowed} for algo "
                                   f"{algo!r} (its own squashed-Gaussian policy; got "
                                   f"{policy!r})")
        return algo
    if algo is not None and algo != implied:
        raise TrainConfigError(f"{where}: field 'algo' is {algo!r}, but policy {policy!r} is "
                               f"trained by {implied!r} (a recurrent policy by ppo_lstm)")
    return implied


def section_algorithm(data: Mapping[str, Any]) -> str | None:
    """``_abb_gym.algo`` of a whole config file's content, if it names an algorithm (None:
    the policy decides, :func:`algorithm_of`)."""
    section = data.get(ABB_GYM_SECTION)
    algo = section.get("algo") if isinstance(section, Mapping) else None
    return algo if algo in ALGORITHMS else None


class TrainConfigError(ConfigError):
    """A PPO configuration is invalid (the message names the key and the file)."""


def configs_dir() -> Path:
    """Folder of the shipped PPO configs (``configs/ppo``)."""
    return resources.shipped_folder("ppo")


def config_path(name_or_path: str | os.PathLike) -> Path:
    """A config file from a path or a name on the search path (``ppo/<name>.yml``)."""
    return locate("ppo", name_or_path, "PPO config", TrainConfigError)


def linear_schedule(start: float):
    """SB3 schedule decaying linearly from ``start`` to 0 over training."""
    def schedule(progress_remaining: float) -> float:
        return progress_remaining * start
    schedule.start = start  # type: ignore[attr-defined]
    return schedule


def _schedule(key: str, value: Any):
    if key == "clip_range_vf" and value is None:  # PPO's default: no value clipping
        return None
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


#: the models of an agent folder a warm start can begin with
WARM_START_MODELS = ("best", "final")


@dataclass(frozen=True)
class WarmStartSettings:
    """Settings of the warm start (the ``_abb_gym.init_from`` mapping; loaded by
    :mod:`abb_gym.rl.warm_start`)."""

    folder: str = declare(kind="text", doc="agent folder to start from (a run folder of "
                                           "abb-gym train; relative: to the working folder)")
    model: str = declare("best", kind="choice", choices=WARM_START_MODELS,
                         doc="its best_model.zip (best test-set return) or model.zip (final)")


def warm_start_settings(value: Any, where: str, error: type[ValueError]
                        ) -> dict[str, Any] | None:
    """The validated ``init_from`` mapping (None: none); a text is the folder; ``error``
    names the field."""
    if isinstance(value, str):
        value = {"folder": value}
    settings = build_section(WarmStartSettings, value, "init_from", where, error,
                             "a mapping {folder: PATH, model: best|final}, a folder path",
                             {"folder": "an agent folder, e.g. a run folder of abb-gym train"})
    if settings is None:
        return None
    if not settings.folder:
        raise error(f"{where}: field 'init_from.folder' must be a folder path (got '')")
    return {"folder": str(settings.folder), "model": str(settings.model)}


@dataclass
class TrainConfig:
    """One validated training configuration (see the module docstring for every key)."""

    env_id: str = declare(kind="text", doc="registered environment id")
    n_envs: int = declare(16, kind="integer", ge=1, le=65536,
                          doc="sub-environments of the native vector environment")
    n_timesteps: int = declare(500_000, kind="integer", ge=1, le=10**11,
                               doc="environment steps, all sub-environments together")
    policy: str = declare("MlpPolicy", kind="choice", choices=tuple(POLICY_NAMES),
                          doc="MlpPolicy or abb_gym.rl.networks.BoundedMlpPolicy "
                              "(BoundedMlpPolicy: the first-wave name), trained by PPO; "
                              "MlpLstmPolicy or abb_gym.rl.networks.BoundedMlpLstmPolicy "
                              "(memory), trained by sb3-contrib's RecurrentPPO (rl_zoo3: "
                              "--algo ppo_lstm); MlpPolicy with algo sac or tqc, or "
                              "abb_gym.rl.networks.StartedSACPolicy / StartedTQCPolicy "
                              "(their initial action mean set)")
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
    tensorboard_log: str | None = declare(None, kind="text", nullable=True,
                                          doc="_abb_gym: folder of TensorBoard event files "
                                              "(null: none)")
    shaping: dict[str, Any] | None = declare(None, kind="any",
                                             doc="_abb_gym: potential-based reward shaping "
                                                 "{observation, weight} of the training "
                                                 "environment (abb_gym.rl.shaping; null: none)")
    curriculum: dict[str, Any] | None = declare(None, kind="any",
                                                doc="_abb_gym: training ranges widened from "
                                                    "similar machines to the preset's "
                                                    "{fields, start, full_at} "
                                                    "(abb_gym.rl.curriculum; null: none)")
    oversample: dict[str, Any] | None = declare(None, kind="any",
                                                doc="_abb_gym: a share of the rollouts drawn "
                                                    "from other ranges, {share, randomize} "
                                                    "(abb_gym.rl.curriculum; null: none)")
    algo: str = declare("ppo", kind="choice", choices=tuple(ALGORITHMS),
                        doc="_abb_gym: the algorithm, rl_zoo3's --algo name (default: ppo, "
                            "ppo_lstm for a recurrent policy; sac or tqc only by this key)")
    init_from: dict[str, Any] | None = declare(None, kind="any",
                                               doc="_abb_gym: start from an agent folder's "
                                                   "weights and statistics, {folder: PATH, "
                                                   "model: best|final} "
                                                   "(abb_gym.rl.warm_start; null: none)")
    imitate: dict[str, Any] | None = declare(None, kind="any",
                                             doc="_abb_gym: clone a teacher policy before "
                                                 "PPO starts, {policy: SPEC, episodes, "
                                                 "epochs, log_std} (abb_gym.rl.imitation; "
                                                 "null: none)")
    source: str = declare("", kind="text", doc="file the config came from")

    @classmethod
    def from_mapping(cls, env_id: str, raw: Mapping[str, Any], source: str = "",
                     extra: Mapping[str, Any] | None = None) -> "TrainConfig":
        """A config from the entry of ``env_id`` (zoo keys and PPO keywords) and the
        ``_abb_gym`` settings ``extra`` (first-wave files hold them in the entry)."""
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
        raw = copy.deepcopy(dict(raw))
        extra = copy.deepcopy(dict(extra or {}))
        for key in SECTION_ONLY_KEYS:
            if key in raw:
                why = ("rl_zoo3 passes its own tensorboard_log to PPO"
                       if key == "tensorboard_log" else "rl_zoo3 would pass it to PPO")
                raise TrainConfigError(f"{where}: field {key!r} belongs in the "
                                       f"{ABB_GYM_SECTION} section, not under the environment "
                                       f"id ({why})")
        stray = sorted(set(extra) - set(ABB_GYM_KEYS), key=str)
        if stray:
            raise TrainConfigError(f"{where}: unknown key(s) {stray} in {ABB_GYM_SECTION}; "
                                   f"allowed: {list(ABB_GYM_KEYS)} (hyperparameters go under "
                                   f"the environment id)")
        twice = sorted(set(raw) & set(extra), key=str)
        if twice:
            raise TrainConfigError(f"{where}: key(s) {twice} given both under the environment "
                                   f"id and in {ABB_GYM_SECTION}; keep the {ABB_GYM_SECTION} "
                                   f"one")
        raw.update(extra)
        table = specs(cls)
        own = set(table) - {"env_id", "hyperparams", "source"}
        algo = _check_algorithm(where, raw.get("policy", "MlpPolicy"), raw.pop("algo", None))
        algo_keys = algorithm_keywords(algo)
        unknown = sorted(set(raw) - own - algo_keys, key=str)
        if unknown:
            raise TrainConfigError(f"{where}: unknown key(s) {unknown}; allowed: "
                                   f"{sorted(own)} and the {ALGORITHMS[algo][1]} keywords "
                                   f"{sorted(algo_keys)}")
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
                # what the trainer sets itself (a TypeError inside gym.make_vec otherwise)
                reserved = sorted(set(v) & RESERVED_ENV_KWARGS, key=str)
                if reserved:
                    raise TrainConfigError(f"{where}: field {key!r} must not set {reserved}: "
                                           f"the trainer sets them (n_envs is the number of "
                                           f"sub-environments)")
            elif key == "curriculum":
                from .curriculum import curriculum_settings
                v = curriculum_settings(v, where, TrainConfigError)
            elif key == "oversample":
                from .curriculum import oversample_settings
                v = oversample_settings(v, where, TrainConfigError)
            elif key == "shaping":
                from .shaping import shaping_settings
                v = shaping_settings(v, where, TrainConfigError)
            elif key == "init_from":
                v = warm_start_settings(v, where, TrainConfigError)
            elif key == "imitate":
                from .imitation import imitation_settings
                v = imitation_settings(v, where, TrainConfigError)
            elif key == "tensorboard_log":
                # SB3 would only fail when training starts, after the environments are built
                if v is not None and (not isinstance(v, str) or not v):
                    raise TrainConfigError(f"{where}: field 'tensorboard_log' must be a "
                                           f"folder path or null (got {v!r})")
            else:
                v = check(where, key, v, table[key], TrainConfigError)
            values[key] = v
        if "policy" in values:
            values["policy"] = POLICY_NAMES[values["policy"]]
        values["algo"] = algo
        for key in SCHEDULE_KEYS:
            if key in raw:
                _schedule(key, raw[key])
        return cls(env_id=env_id, hyperparams=raw, source=str(source), **values)

    def with_overrides(self, **changes: Any) -> "TrainConfig":
        """A copy with keys of the entry (PPO hyperparameters included) or of ``_abb_gym``
        replaced (validated again; ``env_kwargs`` and ``eval_env_kwargs`` are merged)."""
        entry, settings = self.to_mapping(), self.abb_gym_settings()
        for key, value in changes.items():
            target = settings if key in ABB_GYM_KEYS else entry
            if key in ("env_kwargs", "eval_env_kwargs") and isinstance(value, Mapping):
                target[key] = {**target.get(key, {}), **value}
            else:
                target[key] = value
        return TrainConfig.from_mapping(self.env_id, entry, self.source, settings)

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
        # every key of the section, so that none can be dropped from a run's config.yml or
        # by an override (the optional ones when set; algo when it is not the policy's)
        out: dict[str, Any] = {}
        for key in ABB_GYM_KEYS:
            value = getattr(self, key)
            if key == "algo":
                if value != algorithm_of(self.policy):
                    out[key] = value
            elif key not in SECTION_ONLY_KEYS or value is not None:
                out[key] = copy.deepcopy(value)
        return out

    def to_file_data(self) -> dict[str, Any]:
        """The whole file: the zoo entry under the id and the ``_abb_gym`` section."""
        return {self.env_id: self.to_mapping(), ABB_GYM_SECTION: self.abb_gym_settings()}

    def ppo_kwargs(self) -> dict[str, Any]:
        """Keyword arguments for ``PPO(...)`` (schedules and activation functions resolved)."""
        kw = dict(self.hyperparams)
        for key in SCHEDULE_KEYS:
            if key in kw:
                kw[key] = _schedule(key, kw[key])
        kw["policy_kwargs"] = resolve_policy_kwargs(self.policy_kwargs)
        if self.tensorboard_log is not None:
            kw["tensorboard_log"] = self.tensorboard_log
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
