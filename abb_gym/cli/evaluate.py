"""``abb-gym evaluate``: policies against baselines on a fixed, seeded test set.

    abb-gym evaluate --env abb_gym/RunUpSpeed-v0 --scene yoshida_odd \\
        --policy ppo:runup_speed_yoshida_odd --policy replay:ppo:runup_speed_yoshida_odd \\
        --policy baseline:knots --policy baseline:retry \\
        --episodes 200 --seed 0 --sweep 12 --out out/eval

Policies: ``baseline:NAME`` (a family, tuned parameters when a baselines/<scene>.yaml is on the
search path), ``ppo:NAME|PATH`` (a trained agent: an agent folder, or with --trust-pickle a
model.zip or an rl_zoo3 run folder), ``replay:SPEC`` (SPEC recorded on the nominal machine and
replayed open-loop: with SPEC itself, the report gives SPEC's feedback value).  Writes, into
--out: summary.md (mean [95 % CI] per metric, feedback values), episodes.csv,
evaluation.json, timeseries.png (every policy on test episode 0) and pareto.png (settled
run-up time against residual vibration, the baseline families swept over their parameters
when --sweep N > 0).

Reward weights: every policy of one evaluation is scored with the same weights, so that the
returns compare: --env-kwargs 'reward={...}' if given, else the weights the agents were
evaluated with when they were trained (their agent.yml; agents that disagree need
--env-kwargs), else the preset's.  The summary states them.
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
    add_test_set_arguments(p, "environment preset of the test set")
    p.add_argument("--policy", action="append", required=True,
                   help="baseline:NAME, ppo:NAME|PATH or replay:SPEC (repeatable)")
    p.add_argument("--episodes", type=int, default=100, help="test episodes per policy")
    p.add_argument("--seed", type=int, default=0, help="seed of the test set (episode k: seed + k)")
    p.add_argument("--sweep", type=int, default=0, metavar="N",
                   help="also sweep every baseline family over N parameter sets for the "
                        "Pareto chart (RunUpSpeed)")
    p.add_argument("--sweep-episodes", type=int, default=12, help="episodes per swept point")
    p.add_argument("--env-kwargs", nargs="+", default=None, metavar="KEY=VALUE",
                   help="environment keywords of the test set, e.g. 'reward={residual: 6}' or "
                        "control_interval=0.05 (values are YAML)")
    p.add_argument("--out", default="out/evaluate",
                   help="output folder for summary.md, episodes.csv, evaluation.json and the "
                        "charts (created; one evaluation writes it at a time)")
    add_trust_argument(p)
    add_executor_arguments(p)
    p.set_defaults(func=run)


def add_test_set_arguments(parser, preset_help: str) -> None:
    """``--scene`` and ``--preset``, by default the environment's
    (:func:`apply_test_set_defaults`)."""
    parser.add_argument("--scene", default=None,
                        help="scene name (default: the environment's, yoshida_odd; washer for "
                             "SpinRedistribute)")
    parser.add_argument("--preset", default=None,
                        help=f"{preset_help} (default: the environment's held-out preset, "
                             f"test; laundry_test for SpinRedistribute)")


def apply_test_set_defaults(args) -> None:
    """Fill ``args.scene`` and ``args.preset`` left out with the task's default scene and
    held-out preset (``args.env`` names the task)."""
    task = tasks.get(args.env)
    args.scene = args.scene or task.default_scene
    args.preset = args.preset or task.test_preset


def add_trust_argument(parser) -> None:
    """``--trust-pickle``: load pickled agent files (abb_gym.rl.agent_files.require_trust)."""
    parser.add_argument("--trust-pickle", action="store_true",
                        help="load pickled agents (model.zip, vecnormalize.pkl, rl_zoo3 runs), "
                             "which run any code they contain: only files you trust (also "
                             "$ABB_GYM_TRUST_PICKLE=1); abb-gym convert-agent converts them "
                             "once for good")


def agent_reward_weights(specs, policies, env_kwargs: dict) -> tuple[dict, str | None]:
    """``env_kwargs`` with the reward weights the agents among ``policies`` recorded (all of
    them must agree), unless ``env_kwargs`` sets a reward; and which agent they came from."""
    if "reward" in env_kwargs:
        return env_kwargs, None
    recorded = {spec: dict(w) for spec, p in zip(specs, policies)
                if (w := getattr(p, "reward_weights", None))}
    if not recorded:
        return env_kwargs, None
    distinct = {tuple(sorted(w.items())) for w in recorded.values()}
    if len(distinct) > 1:
        listed = "; ".join(f"{spec}: {w}" for spec, w in recorded.items())
        raise ValueError(f"the agents were evaluated with different reward weights ({listed}), "
                         f"and the returns of one evaluation must compare: choose the weights "
                         f"with --env-kwargs 'reward={{...}}'")
    spec, weights = next(iter(recorded.items()))
    return {**env_kwargs, "reward": weights}, spec


def _executor(args):
    # "is not None": an empty --resume-dir is refused by the executor, not read as "none"
    chosen = (args.workers is not None or args.ray or args.ray_address
              or getattr(args, "resume_dir", None) is not None)
    return executor_from_args(args) if chosen else None  # default: this process, both cores


def run(args) -> int:
    apply_test_set_defaults(args)
    from ..evaluation.evaluate import MAX_EPISODES, check_inputs, evaluate
    from ..evaluation.report import reward_line, summary_table, write_report
    from .outputs import check_path, output_folder
    # every input before any folder or task: one line, exit 2
    check_path(args.out, "--out")
    if getattr(args, "resume_dir", None) is not None:
        check_path(args.resume_dir, "--resume-dir")
    for label, n, least in (("--episodes", args.episodes, 1), ("--sweep", args.sweep, 0),
                            ("--sweep-episodes", args.sweep_episodes, 1)):
        if not least <= n <= MAX_EPISODES:
            raise ValueError(f"{label} must be in [{least}, {MAX_EPISODES}] (got {n})")
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0 (got {args.seed})")
    from ..configuration import parse_assignments
    from . import check_env_kwargs
    env_kwargs = check_env_kwargs(parse_assignments(args.env_kwargs, "--env-kwargs"),
                                  "--env-kwargs")
    # a bad agent folder is one line before any episode
    policies = [check_inputs(args.env, args.scene, args.preset, args.seed, spec, **env_kwargs)
                for spec in args.policy]
    env_kwargs, weights_from = agent_reward_weights(args.policy, policies, env_kwargs)
    ex = _executor(args)
    output_folder(args.out, "--out")
    results = [evaluate(args.env, args.scene, spec, args.episodes, args.seed, args.preset,
                        executor=ex, **env_kwargs) for spec in args.policy]
    for r in results:
        r.reward_source = (f"recorded with {weights_from}" if weights_from is not None
                           else "--env-kwargs" if "reward" in env_kwargs
                           else f"preset {args.preset}")
    sweep_rows = []
    if args.sweep > 0:
        from ..baselines.tuner import sweep
        sweep_rows = sweep(args.scene, n=args.sweep, episodes=args.sweep_episodes,
                           seed=args.seed, preset=args.preset, executor=ex,
                           env_id=tasks.get(args.env).baselines_on or args.env)
    paths = write_report(results, args.out, sweep_rows)
    print(reward_line(results[0]))
    print(summary_table(results))
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0
