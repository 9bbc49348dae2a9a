"""Whether rl_zoo3 can train a config file unchanged: :func:`zoo_problems`, the rl-zoo linter.

A file in ``configs/ppo/`` is both an ``abb-gym train`` config and an rl-baselines3-zoo
hyperparameter file; :mod:`abb_gym.rl.config` describes the format and what rl_zoo3 does with
a file.  :func:`zoo_problems` checks a file against those rules without rl_zoo3 (the shipped
configs are checked by the tests; ``tests/test_rl_zoo.py`` also trains each one with rl_zoo3
when it is installed).
"""
from __future__ import annotations

import os
from typing import Any, Mapping

from ..configuration import parse_python_literal, read_yaml
from .algorithms import (ALGORITHMS, POLICY_NAMES, SB3_POLICY_ALIASES, algorithm_keywords,
                         algorithm_of)
from .config import (ABB_GYM_KEYS, ABB_GYM_SECTION, SCHEDULE_KEYS, TrainConfigError,
                     config_path, section_algorithm)

__all__ = ["zoo_problems", "ZOO_KEYS", "ZOO_OWN_KEYWORDS"]

#: keys rl_zoo3 consumes itself under the id (``ExperimentManager._preprocess_hyperparams``);
#: every other key goes to ``PPO(...)``
ZOO_KEYS = ("n_envs", "n_timesteps", "normalize", "env_kwargs", "policy", "policy_kwargs",
            "frame_stack", "monitor_kwargs", "env_wrapper", "vec_env_wrapper", "callback")
#: PPO keywords rl_zoo3 sets from its command line: under the id PPO would get them twice
ZOO_OWN_KEYWORDS = ("env", "tensorboard_log", "seed", "verbose", "device")


def zoo_problems(config: str | os.PathLike | Mapping[str, Any],
                 env_id: str | None = None) -> list[str]:
    """What keeps rl_zoo3 (``python -m rl_zoo3.train --algo ppo -conf FILE``, ``--algo
    ppo_lstm`` for a recurrent policy) from training a
    config file unchanged: one line per problem, naming the id and the key; empty if none.

    ``config`` is a file (path or name on the search path) or its parsed content; ``env_id``
    None checks every environment id in it.  The rules are those of rl_zoo3's
    ``ExperimentManager`` (see :mod:`abb_gym.rl.config`); the file must also be a valid
    ``abb-gym train`` config (:func:`~abb_gym.rl.config.load_config`), which this does not
    check."""
    if isinstance(config, Mapping):
        data = config
    else:
        data = read_yaml(config_path(config), "PPO config", TrainConfigError)
    ids = [k for k in data if not str(k).startswith("_")]
    if env_id is not None:
        if env_id not in data:
            return [f"{env_id}: no entry for this environment id (rl_zoo3 reads only the "
                    f"entry of --env)"]
        ids = [env_id]
    if not ids:
        return ["the file has no environment id entry (rl_zoo3 reads only the entry of "
                "--env)"]
    algo = section_algorithm(data)
    out: list[str] = []
    for key in ids:
        out += [f"{key}: {p}" for p in _zoo_entry_problems(data[key], algo)]
    return out


def _zoo_entry_problems(entry: Any, algo: str | None = None) -> list[str]:
    if not isinstance(entry, Mapping):
        return [f"the entry must be a mapping of hyperparameters (got {entry!r})"]
    problems = []
    for key in ("n_timesteps", "policy"):
        if key not in entry:
            problems.append(f"{key!r} is missing (rl_zoo3 needs it; abb-gym train has a "
                            f"default)")
    policy = entry.get("policy", "MlpPolicy")
    if not isinstance(policy, str):
        problems.append(f"'policy' must be a policy name or an import path (got {policy!r})")
    elif "." in policy:
        import importlib
        module, _, name = policy.rpartition(".")
        try:
            found = getattr(importlib.import_module(module), name, None)
        except ImportError as exc:
            found, why = None, f" ({exc})"
        else:
            why = ""
        if not isinstance(found, type):
            problems.append(f"'policy': rl_zoo3 cannot import the class {policy!r}{why}")
    elif policy not in SB3_POLICY_ALIASES:
        hint = (f"; rl_zoo3 imports a custom policy by its import path: "
                f"{POLICY_NAMES[policy]}" if policy in POLICY_NAMES else "")
        problems.append(f"'policy': {policy!r} is not an SB3 policy name "
                        f"{list(SB3_POLICY_ALIASES)}{hint}")
    kwargs = entry.get("policy_kwargs")
    if isinstance(kwargs, str):
        from torch import nn
        try:
            parse_python_literal(kwargs, {"nn": nn}, "policy_kwargs", TrainConfigError)
        except TrainConfigError as exc:
            problems.append(str(exc))
    elif isinstance(kwargs, Mapping):
        for k, v in kwargs.items():
            if isinstance(v, str) and str(k).endswith(("_fn", "_class")):
                problems.append(f"'policy_kwargs.{k}' is the string {v!r} in a mapping, which "
                                f"rl_zoo3 passes to the policy as it is; write policy_kwargs "
                                f"as the zoo's string, e.g. \"dict(..., {k}=nn.{v})\"")
    elif kwargs is not None:
        problems.append(f"'policy_kwargs' must be a zoo string \"dict(...)\" or a mapping "
                        f"(got {kwargs!r})")
    norm = entry.get("normalize", False)
    if isinstance(norm, str):
        try:
            parse_python_literal(norm, {}, "normalize", TrainConfigError)
        except TrainConfigError as exc:
            problems.append(str(exc))
    elif not isinstance(norm, (bool, Mapping)):
        problems.append(f"'normalize' must be true, false, a mapping or a zoo string (got "
                        f"{norm!r})")
    for key in SCHEDULE_KEYS:
        v = entry.get(key)
        if isinstance(v, str) and not (v.startswith("lin_") and v.count("_") == 1):
            problems.append(f"{key!r}: rl_zoo3 reads a string only as lin_<start> (got {v!r})")
    env_kwargs = entry.get("env_kwargs")
    if env_kwargs is not None and not isinstance(env_kwargs, Mapping):
        problems.append(f"'env_kwargs' must be a mapping (got {env_kwargs!r})")
    algo = algorithm_of(policy, algo) if isinstance(policy, str) else "ppo"
    algo_keys = algorithm_keywords(algo)
    for key in entry:
        if key in ABB_GYM_KEYS:
            why = ("rl_zoo3 passes its own tensorboard_log to PPO" if key == "tensorboard_log"
                   else "rl_zoo3 passes it to PPO, which does not know it")
            problems.append(f"{key!r} under the environment id: {why}; move it to the "
                            f"{ABB_GYM_SECTION} section")
        elif key in ZOO_OWN_KEYWORDS:
            problems.append(f"{key!r} under the environment id: rl_zoo3 sets it from its "
                            f"command line")
        elif key not in ZOO_KEYS and key not in algo_keys:
            problems.append(f"{key!r} is neither an rl_zoo3 key nor a {ALGORITHMS[algo][1]} "
                            f"keyword")
    return problems
