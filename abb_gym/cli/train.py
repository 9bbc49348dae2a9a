"""``abb-gym train``: train Stable-Baselines3 PPO from a zoo-style config in ``configs/ppo/``.

    abb-gym train --config runup_speed_yoshida_odd --seed 0
    abb-gym train --config runup_speed_yoshida_odd --seeds 0 1 2 --n-timesteps 1e6
    abb-gym train --config runs/x/config.yml --hyperparams learning_rate=1e-4 \\
        --env-kwargs 'reward={residual: 5}' --out runs/x_lr1e-4

Each run writes a folder (default ``runs/<config>/s<seed>-<time>``) with
``policy.safetensors``, ``vecnormalize.json``, ``config.yml``, ``agent.yml``, the test-set
evaluations and checkpoints (data only: no pickle, :mod:`abb_gym.rl.agent_files`), and prints its
wall time and env-steps/s (see :mod:`abb_gym.rl.train`).  Needs the training extra
(``pip install -c constraints.txt 'abb-gym[train]'``); the options are defined here so that
``abb-gym --help`` works without it.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any, Sequence

from ..execution.cli import add_executor_arguments, executor_from_args


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
    p.add_argument("--init-from", default=None, metavar="FOLDER",
                   help="start from the best model (and statistics) of this agent folder, "
                        "e.g. an earlier run (the config's _abb_gym init_from; see "
                        "abb_gym.rl.warm_start)")
    p.add_argument("--trust-pickle", action="store_true",
                   help="let --init-from read an agent folder of pickles (model.zip, "
                        "vecnormalize.pkl), which run any code they contain: only one you "
                        "trust (also $ABB_GYM_TRUST_PICKLE=1); abb-gym convert-agent converts "
                        "it once for good")
    p.add_argument("--tensorboard-log", "-tb", default=None, metavar="DIR",
                   help="write TensorBoard event files to DIR (SB3's tensorboard_log)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--verbose", "-v", type=int, default=0, choices=[0, 1, 2],
                   help="SB3 verbosity (1 prints the training table and each evaluation)")
    # with --seeds: --ray / --ray-address run the seeds as Ray Tune trials
    # (abb_gym.execution.tune; needs abb-gym[cluster]); --workers caps the trials at once
    add_executor_arguments(p, resume=False)


def register(sub) -> None:
    p = sub.add_parser("train", help="train PPO from a config in configs/ppo",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_train_arguments(p)
    p.set_defaults(func=run)


def config_from_args(args: argparse.Namespace):
    """The TrainConfig the options describe: the file, then the overrides."""
    from ..configuration import parse_assignments
    from ..rl.config import load_config
    from . import check_env_kwargs
    cfg = load_config(args.config, args.env)
    # the config file's environment keywords as well (a TypeError in make_vec otherwise)
    for key in ("env_kwargs", "eval_env_kwargs"):
        check_env_kwargs(dict(getattr(cfg, key)), f"--config {args.config}: {key}",
                         allowed=("scene", "preset", "record_history"))
    changes: dict[str, Any] = parse_assignments(args.hyperparams, "--hyperparams")
    for key in ("n_envs", "eval_freq", "eval_episodes", "checkpoint_freq"):
        if getattr(args, key) is not None:
            changes[key] = getattr(args, key)
    if args.n_timesteps is not None:
        changes["n_timesteps"] = args.n_timesteps
    if args.init_from is not None:
        changes["init_from"] = {"folder": args.init_from, "model": "best"}
    # the environment's own keywords (scene, preset, ...) are welcome; make_vec's are not
    env_kw = check_env_kwargs(parse_assignments(args.env_kwargs, "--env-kwargs"),
                              "--env-kwargs", allowed=("scene", "preset", "record_history"))
    if env_kw:
        changes["env_kwargs"] = env_kw
    return cfg.with_overrides(**changes) if changes else cfg


def _report(res) -> None:
    print(f"run folder: {res.run_dir}")
    rate = res.training_steps_per_s
    speed = (f"{rate:.0f} env-steps/s (training only: without the first step, which compiles "
             f"the kernel when it is not cached, and without the evaluations)"
             if math.isfinite(rate) else "too few steps to measure a speed")
    print(f"wall time {res.wall_time_s:.1f} s, {res.env_steps} env steps, {speed}")
    s = res.evaluation
    if s:
        def fmt(key: str, digits: int = 3) -> str:
            m = s[key]
            if not all(math.isfinite(m[k]) for k in ("mean", "ci_low", "ci_high")):
                return "n/a (no episode settled)"  # a mean over no episodes, not "nan"
            return (f"{m['mean']:.{digits}f} [{m['ci_low']:.{digits}f}, "
                    f"{m['ci_high']:.{digits}f}]")
        print(f"test set ({s['episodes']} episodes, 95 % CI): return {fmt('return')}, "
              f"at speed {fmt('at_speed', 2)}, residual vibration "
              f"{fmt('residual_vibration')} {s.get('length_unit', 'W_r/e')}, run-up time "
              f"{fmt('run_up_time', 2)} s, "
              f"balanced {fmt('balanced', 2)}")


def run_from_args(args: argparse.Namespace) -> int:
    from ..rl.train import default_run_dir, seeded_trial, train
    from .outputs import output_folder
    cfg = config_from_args(args)
    if args.out is not None:  # "" is refused, not read as "no --out" (nor as ".")
        output_folder(args.out, "--out")
    if args.tensorboard_log is not None:
        output_folder(args.tensorboard_log, "--tensorboard-log", lock=False)
    if args.seeds is None:
        res = train(cfg, seed=args.seed, run_dir=args.out, progress=not args.no_progress,
                    verbose=args.verbose, tensorboard_log=args.tensorboard_log)
        _report(res)
        return 0
    seeds = list(dict.fromkeys(args.seeds))
    root = Path(args.out) if args.out is not None else \
        default_run_dir(cfg, 0).parent / time.strftime("seeds-%Y%m%d-%H%M%S")
    if args.ray or args.ray_address:
        from ..execution.tune import grid, run_trials
        space = {"env_id": cfg.env_id, "hyperparams": cfg.to_mapping(),
                 "settings": cfg.abb_gym_settings(), "source": cfg.source,
                 "seed": grid(seeds), "run_dir": str(root),
                 "tensorboard_log": args.tensorboard_log}
        trials = run_trials(seeded_trial, space,
                            executor=executor_from_args(args, ray=True, progress=False),
                            metric="return", mode="max", resources_per_trial={"cpu": 2},
                            name="abb_gym_ppo")
        for t in trials:
            print(f"seed {t.config['seed']}: {t.metrics}")
        return 0
    if args.workers not in (None, 1):
        raise ValueError("--workers applies to --ray runs; local seeds train one after the "
                         "other (each run already uses the machine's cores)")
    for s in seeds:
        res = train(cfg, seed=s, run_dir=root / f"s{s}", progress=not args.no_progress,
                    verbose=args.verbose, tensorboard_log=args.tensorboard_log)
        _report(res)
    return 0




def run(args: argparse.Namespace) -> int:
    try:
        import abb_gym.rl.train  # noqa: F401  (fails early without the training extra)
    except ImportError as exc:
        raise ValueError(f"training needs the training extra: pip install -c constraints.txt "
                         f"'abb-gym[train]' ({exc})") from None
    return run_from_args(args)


def main(argv: Sequence[str] | None = None) -> int:
    """``agents/train.py``: the options of ``abb-gym train`` as a script."""
    from . import ArgumentParser
    p = ArgumentParser(prog="train", description=__doc__.split("\n")[0])
    add_train_arguments(p)
    args = p.parse_args(argv)
    args.command = "train"
    from . import _command_settings
    try:
        with _command_settings(args):
            return run(args)
    except ValueError as exc:
        print(f"train: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("train: interrupted", file=sys.stderr)
        return 130
