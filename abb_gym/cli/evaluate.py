"""``abb-gym evaluate``: policies against baselines on a fixed, seeded test set.

    abb-gym evaluate --env abb_gym/RunUpSpeed-v0 --scene yoshida_odd \\
        --policy baseline:speed_dwell --policy baseline:speed_reduction --policy ppo:agents/trained/X \\
        --episodes 200 --seed 0 --sweep 12 --out out/eval

Writes summary.md (mean [95 % CI] per metric), episodes.csv, evaluation.json, timeseries.png
(every policy on test episode 0) and pareto.png (run-up time against residual vibration,
with the baseline families swept over their parameters when --sweep N > 0).
"""
from __future__ import annotations

from ..execution.cli import add_executor_arguments, executor_from_args


def register(sub) -> None:
    p = sub.add_parser("evaluate", help="evaluate policies and baselines on a seeded test set",
                       description=__doc__)
    p.add_argument("--env", default="abb_gym/RunUpSpeed-v0", help="environment id")
    p.add_argument("--scene", default="yoshida_odd", help="scene name")
    p.add_argument("--policy", action="append", required=True,
                   help="baseline:NAME or ppo:PATH (repeatable)")
    p.add_argument("--episodes", type=int, default=100, help="test episodes per policy")
    p.add_argument("--seed", type=int, default=0, help="seed of the test set (episode k: seed + k)")
    p.add_argument("--preset", default="test", help="environment preset of the test set")
    p.add_argument("--sweep", type=int, default=0, metavar="N",
                   help="also sweep every baseline family over N parameter sets for the "
                        "Pareto chart (RunUpSpeed)")
    p.add_argument("--sweep-episodes", type=int, default=12, help="episodes per swept point")
    p.add_argument("--out", default="out/evaluate", help="output folder")
    add_executor_arguments(p)
    p.set_defaults(func=run)


def _executor(args):
    chosen = (args.workers is not None or args.ray or args.ray_address
              or getattr(args, "resume_dir", None))
    return executor_from_args(args) if chosen else None  # default: this process, both cores


def run(args) -> int:
    from ..evaluation.evaluate import evaluate
    from ..evaluation.report import summary_table, write_report
    if args.episodes < 1:
        raise ValueError(f"--episodes must be >= 1 (got {args.episodes})")
    ex = _executor(args)
    results = [evaluate(args.env, args.scene, spec, args.episodes, args.seed, args.preset,
                        executor=ex) for spec in args.policy]
    sweep_rows = []
    if args.sweep > 0:
        from ..baselines.tuner import sweep
        sweep_rows = sweep(args.scene, n=args.sweep, episodes=args.sweep_episodes,
                           seed=args.seed, preset=args.preset, executor=ex)
    paths = write_report(results, args.out, sweep_rows)
    print(summary_table(results))
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0
