"""Reinforcement learning on the balancer environments: Stable-Baselines3 PPO.

Needs the training extra (``pip install -c constraints.txt 'abb-gym[train]'``).

===================================  ===========================================================
:class:`NativeVecEnv`                SB3 ``VecEnv`` over the native gymnasium vector
                                     environment (same-step resets through ``reset_mask``,
                                     ``terminal_observation``, ``TimeLimit.truncated``)
:func:`load_config`, TrainConfig     zoo-style YAML configs in ``configs/ppo/``
:func:`zoo_problems`                 what keeps rl_zoo3 from training a config file unchanged
:func:`make_sb3_env`                 the adapter over ``gym.make_vec(..., "vector_entry_point")``
:func:`train`                        one PPO run -> run folder (``abb-gym train``)
:func:`load_policy`, PPOPolicy       a run folder or shipped agent as an evaluation ``Policy``
                                     with frozen VecNormalize statistics
:func:`run_episodes`, summarise      a policy *object* on the seeded test set of
                                     :mod:`abb_gym.evaluation.evaluate` (same metrics)
===================================  ===========================================================

``--policy ppo:PATH`` resolves through the ``abb_gym.policies`` entry point
:func:`abb_gym.rl.agent.load_ppo` (PATH: a run folder or an agent's name on the search path
of :mod:`abb_gym.resources`).
"""
from __future__ import annotations

# numba's and torch's OpenMP threads are kept from spinning against each other by
# `import abb_gym` (abb_gym._threads), which runs before this module, whichever of torch and
# abb_gym the user imported first

try:
    import stable_baselines3  # noqa: F401
    import torch  # noqa: F401
except ImportError as exc:  # pragma: no cover - depends on the installed extras
    raise ImportError(f"abb_gym.rl needs the training extra: pip install -c constraints.txt "
                      f"'abb-gym[train]' ({exc})") from exc

from .config import TrainConfig, load_config
from .env_factory import POLICY_FIELDS, eval_env_kwargs, make_native_env, make_sb3_env
from .agent import PPOPolicy, load_policy, load_ppo, trained_dir
from ..evaluation.evaluate import summarise
from .rollout import run_episodes
from .train import RunResult, train
from .vec_env import NativeVecEnv, split_info
from .zoo import zoo_problems

__all__ = ["NativeVecEnv", "split_info", "TrainConfig", "load_config", "make_sb3_env",
           "make_native_env", "eval_env_kwargs", "POLICY_FIELDS", "train", "RunResult",
           "PPOPolicy", "load_policy", "load_ppo", "trained_dir", "run_episodes", "summarise",
           "zoo_problems"]

