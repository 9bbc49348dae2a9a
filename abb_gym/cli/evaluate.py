"""``abb-gym evaluate``: policies against baselines on a fixed, seeded test set.

    abb-gym evaluate --env abb_gym/RunUpSpeed-v0 --scene yoshida_odd \\
        --policy ppo:runup_speed_yoshida_odd --policy replay:ppo:runup_speed_yoshida_odd \\
        --policy baseline:knots --policy baseline:retry \\
        --episodes 200 --seed 0 --sweep 12 --out out/eval

Policies: ``baseline:NAME`` (a family, tuned parameters when a baselines/<scene>.yaml is on the
search path), ``ppo:NAME|PATH`` (a trained agent), ``replay:SPEC`` (SPEC recorded on the
nominal machine and replayed open-loop: with SPEC itself, the report gives SPEC's feedback
value).  Writes, into --out: summary.md (mean [95 % CI] per metric, feedback values),
episodes.csv, evaluation.json, timeseries.png (every policy on test episode 0) and pareto.png
(settled run-up time against residual vibration, the baseline families swept over their
parameters when --sweep N > 0).
"""
from __future__ import annotations

import argparse

from ..execution.cli import add_executor_arguments, executor_from_args
from ..envs import tasks


def register(sub) -> None:
    p = sub.add_parser("evaluate", help="evaluate policies and baselines on a seeded test set",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", default=tasks.DEFAULT_ENV_ID,
                   help=f"environment id (one of {', '.join(tasks.TASKS)})")
    p.add_argument("--scene", default="yoshida_odd", help="scene name")
    p.add_argument("--policy", action="append", required=True,
                   help="baseline:NAME, ppo:NAME|PATH or replay:SPEC (repeatable)")
    p.add_argument("--episodes", type=int, default=100, help="test episodes per policy")
    p.add_argument("--seed", type=int, default=0, help="seed of the test set (episode k: seed + k)")
    p.add_argument("--preset", default="test", help="environment preset of the test set")
    p.add_argument("--sweep", type=int, default=0, metavar="N",
                   help="also sweep every baseline family over N parameter sets for the "
                        "Pareto chart (RunUpSpeed)")
    p.add_argument("--sweep-episodes", type=int, default=12, help="episodes per swept point")
    p.add_argument("--out", default="out/evaluate",
                   help="output folder for summary.md, episodes.csv, evaluation.json and the "
                        "charts (created)")
    add_executor_arguments(p)
    p.set_defaults(func=run)


def _executor(args):
    chosen = (args.workers is not None or args.ray or args.ray_address
              or getattr(args, "resume_dir", None))
    return executor_from_args(args) if chosen else None  # default: this process, both cores


def run(args) -> int:
    from ..evaluation.evaluate import MAX_EPISODES, check_inputs, evaluate
    from ..evaluation.report import summary_table, write_report
    from .outputs import output_folder
    # every input before any folder or task: one line, exit 2
    for label, n, least in (("--episodes", args.episodes, 1), ("--sweep", args.sweep, 0),
                            ("--sweep-episodes", args.sweep_episodes, 1)):
        if not least <= n <= MAX_EPISODES:
            raise ValueError(f"{label} must be in [{least}, {MAX_EPISODES}] (got {n})")
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0 (got {args.seed})")
    for spec in args.policy:  # a bad agent folder is one line before any episode
        check_inputs(args.env, args.scene, args.preset, args.seed, spec)
    output_folder(args.out, "--out")
    ex = _executor(args)
    results = [evaluate(args.env, args.scene, spec, args.episodes, args.seed, args.preset,
                        executor=ex) for spec in args.policy]
    sweep_rows = []
    if args.sweep > 0:
        from ..baselines.tuner import sweep
        sweep_rows = sweep(args.scene, n=args.sweep, episodes=args.sweep_episodes,
                           seed=args.seed, preset=args.preset, executor=ex,
                           env_id=tasks.get(args.env).baselines_on or args.env)
    paths = write_report(results, args.out, sweep_rows)
    print(summary_table(results))
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0
