#!/usr/bin/env python
"""The upper bound of the feedback gap: ``knots`` tuned on each test machine alone.

For each of the ``--episodes`` machines of the seeded test set (episode k: the reset with seed
``seed + k``, the machines ``abb-gym evaluate`` uses), CMA-ES tunes the ``knots`` profile on that
machine alone (:func:`abb_gym.baselines.tuner.tune_per_machine`), refining the ``knots``
tuned on the training distribution (one of its candidates, so the oracle is never below it
on any machine).  The oracle knows everything
about the machine, the initial ball angles included, and plans with the simulator; the best
open-loop profile tuned on the training distribution (``baseline:knots``) is the lower bound;
the gap between the two is the room a controller that watches the machine has.

    ABB_GYM_CONFIGS=configs/varied python agents/oracle_knots.py --scene yoshida_odd \\
        --preset varied_test \\
        --env-kwargs 'reward={residual: 6}' --out out/oracle_yoshida_varied
"""
import argparse
import json
import sys
from pathlib import Path


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--scene", default="yoshida_odd")
    p.add_argument("--preset", default="varied_test", help="preset of the test machines")
    p.add_argument("--episodes", type=int, default=100, help="test machines")
    p.add_argument("--seed", type=int, default=0, help="seed of the test set")
    p.add_argument("--budget", type=int, default=120, help="CMA-ES candidates per machine")
    p.add_argument("--env-kwargs", nargs="*", default=[], metavar="KEY=VALUE",
                   help="environment keywords, e.g. the agents' reward weights")
    p.add_argument("--start", choices=("tuned", "centre"), default="tuned",
                   help="each machine's search refines the tuned knots (baselines/<scene>.yaml "
                        "on the search path, e.g. abb-gym's --configs), which is also one of "
                        "its candidates, or starts at the centre of the box")
    p.add_argument("--out", default="out/oracle", help="folder for oracle.json")
    args = p.parse_args(argv)
    from abb_gym.baselines.baseline_policy import tuned_parameters
    from abb_gym.baselines.tuner import tune_per_machine
    from abb_gym.configuration import parse_assignments
    from abb_gym.evaluation.statistics import mean_interval
    try:
        env_kwargs = parse_assignments(args.env_kwargs, "--env-kwargs")
        start = tuned_parameters(args.scene, "knots") if args.start == "tuned" else None
        rows = tune_per_machine(args.scene, "knots", args.episodes, args.seed, args.preset,
                                args.budget, env_kwargs=env_kwargs, start=start)
    except ValueError as exc:
        print(f"oracle_knots: error: {exc}", file=sys.stderr)
        return 2
    summary = {key: mean_interval([r[key] for r in rows], nonnegative=key != "return")
               for key in ("at_speed", "run_up_time", "residual_vibration", "return")}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "oracle.json").write_text(json.dumps(
        {"scene": args.scene, "preset": args.preset, "seed": args.seed,
         "budget": args.budget, "env_kwargs": env_kwargs, "summary": summary,
         "machines": rows}, indent=1, default=float))
    for key in ("at_speed", "run_up_time", "residual_vibration", "return"):
        s = summary[key]
        print(f"{key}: {s['mean']:.4g} [{s['ci_low']:.4g}, {s['ci_high']:.4g}]")
    print(f"wrote {out / 'oracle.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
