"""``abb-gym train``: train Stable-Baselines3 PPO from a zoo-style config in ``configs/ppo/``.

    abb-gym train --config runup_speed_yoshida_odd --seed 0
    abb-gym train --config runup_speed_yoshida_odd --seeds 0 1 2 --n-timesteps 1e6
    abb-gym train --config runs/x/config.yml --hyperparams learning_rate=1e-4 \\
        --env-kwargs 'reward={residual: 5}' --out runs/x_lr1e-4

Each run writes a folder (default ``runs/<config>/s<seed>-<time>``) with ``model.zip``,
``vecnormalize.pkl``, ``config.yml``, the test-set evaluations and checkpoints, and prints its
wall time and env-steps/s (see :mod:`abb_gym.rl.train`).  Needs the training extra
(``pip install -c constraints.txt 'abb-gym[train]'``); the options are defined here so that
``abb-gym --help`` works without it.
"""
from __future__ import annotations

import argparse
import os


def add_train_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``abb-gym train`` and ``agents/train.py``."""
    p.add_argument("--config", "-c", required=True,
                   help="PPO config: a name in configs/ppo (e.g. runup_speed_yoshida_odd) or a "
                        "path to a zoo-style YAML file (a run's config.yml works too)")
    p.add_argument("--env", default=None,
                   help="environment id to take from the config (needed if it holds several)")
    p.add_argument("--seed", type=int, default=0, help="training seed (default 0)")
    p.add_argument("--seeds", type=int, nargs="+", default=None, metavar="SEED",
                   help="train one run per seed (multi-seed), one after the other; see --ray")
    p.add_argument("--n-timesteps", "-n", type=float, default=None,
                   help="override n_timesteps (environment steps, all sub-environments)")
    p.add_argument("--n-envs", type=int, default=None, help="override n_envs")
    p.add_argument("--hyperparams", nargs="+", default=None, metavar="KEY=VALUE",
                   help="override config keys, e.g. learning_rate=1e-4 n_steps=512 "
                        "(values are YAML)")
    p.add_argument("--env-kwargs", nargs="+", default=None, metavar="KEY=VALUE",
                   help="override env_kwargs entries, e.g. scene=spannan_cfrp "
                        "'reward={residual: 4}'")
    p.add_argument("--eval-freq", type=int, default=None,
                   help="env steps between test-set evaluations (0: none)")
    p.add_argument("--eval-episodes", type=int, default=None,
                   help="episodes of each test-set evaluation")
    p.add_argument("--checkpoint-freq", type=int, default=None,
                   help="env steps between checkpoints (0: none)")
    p.add_argument("--out", default=None,
                   help="run folder (default runs/<config>/s<seed>-<time>); with --seeds, the "
                        "parent of one s<seed> folder per seed")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--verbose", "-v", type=int, default=0, choices=[0, 1, 2],
                   help="SB3 verbosity (1 prints the training table and each evaluation)")
    g = p.add_argument_group("multi-seed on Ray (abb_gym.execution.tune; needs "
                             "abb-gym[cluster])")
    g.add_argument("--ray", action="store_true",
                   help="with --seeds: run the seeds as Ray Tune trials")
    g.add_argument("--ray-address", default=None, metavar="ADDRESS",
                   help="with --seeds: an existing Ray cluster (auto, HOST:6379, "
                        "ray://HOST:10001); implies --ray")
    g.add_argument("--workers", type=int, default=None, metavar="N",
                   help="with --ray: trainings at once (default: as many as the cluster's "
                        "CPUs allow at 2 CPUs per trial)")


def register(sub) -> None:
    p = sub.add_parser("train", help="train PPO from a config in configs/ppo",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_train_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # before torch and the first parallel environment step load their OpenMP runtimes
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    try:
        from ..rl.train import run_from_args
    except ImportError as exc:
        raise ValueError(f"training needs the training extra: pip install -c constraints.txt "
                         f"'abb-gym[train]' ({exc})") from None
    return run_from_args(args)
