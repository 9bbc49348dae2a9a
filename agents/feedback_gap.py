#!/usr/bin/env python
"""The feedback-gap table of one scene and preset: best open loop, closed-loop hand designs,
PPO agents, and the per-machine oracle, on the same test machines with the same reward.

Every policy runs the seeded test set of ``--preset`` (episode k: seed + k) with the reward
weights of ``--reward-residual``; the baselines use ``baselines/<scene>.yaml`` of
``--configs`` (tuned on the training preset of the same family of machines); the oracle rows
come from ``agents/oracle_knots.py``'s ``oracle.json`` (the same machines).  Prints the table,
the paired gaps against ``knots`` and each agent's feedback value, and writes ``gap.json``.

    python agents/feedback_gap.py --scene yoshida_odd --preset varied_test \\
        --configs configs/varied --oracle out/oracle_yoshida_varied/oracle.json \\
        --agent runs/runup_speed_yoshida_odd_varied/s0 \\
        --agent runs/runup_speed_yoshida_odd_varied_oracle/s0
"""
import argparse
import json
import os
import sys
from pathlib import Path

KEYS = ("at_speed", "run_up_time", "residual_vibration", "return")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--scene", default="yoshida_odd")
    p.add_argument("--preset", default="varied_test")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--configs", default="configs/varied",
                   help="folder whose baselines/<scene>.yaml the baselines use")
    p.add_argument("--oracle", default=None, help="oracle.json of agents/oracle_knots.py")
    p.add_argument("--agent", action="append", default=[], help="agent folder (repeatable)")
    p.add_argument("--baselines", nargs="*", default=["knots", "resonance_dwell", "retry"])
    p.add_argument("--reward-residual", type=float, default=6.0,
                   help="residual weight of the reward (the agents' training reward)")
    p.add_argument("--out", default="out/feedback_gap")
    args = p.parse_args(argv)
    os.environ["ABB_GYM_CONFIGS"] = args.configs
    from abb_gym.evaluation.evaluate import evaluate
    from abb_gym.evaluation.replay import feedback_value
    from abb_gym.evaluation.statistics import mean_interval, paired_interval

    env_id = "abb_gym/RunUpSpeed-v0"
    reward = {"reward": {"residual": args.reward_residual}}
    specs = [s for a in args.agent for s in (f"ppo:{a}", f"replay:ppo:{a}")]
    specs += [f"baseline:{b}" for b in args.baselines]
    try:
        episodes = {s: evaluate(env_id, args.scene, s, args.episodes, args.seed, args.preset,
                                **reward).episodes for s in specs}
    except ValueError as exc:
        print(f"feedback_gap: error: {exc}", file=sys.stderr)
        return 2
    if args.oracle:
        data = json.loads(Path(args.oracle).read_text())
        if (data["scene"], data["preset"], data["seed"]) != (args.scene, args.preset,
                                                             args.seed):
            print("feedback_gap: error: the oracle ran other machines", file=sys.stderr)
            return 2
        episodes["oracle: knots per machine"] = data["machines"][:args.episodes]

    report = {"scene": args.scene, "preset": args.preset, "seed": args.seed,
              "reward_residual": args.reward_residual, "rows": {}, "gap_vs_knots": {},
              "feedback_value": {}}
    print("| policy | " + " | ".join(KEYS) + " |\n|---" * (len(KEYS) + 1) + "|")
    for name, eps in episodes.items():
        row = {k: mean_interval([float(e[k]) for e in eps], nonnegative=k != "return")
               for k in KEYS}
        report["rows"][name] = row
        print(f"| {name} | " + " | ".join(
            f"{row[k]['mean']:.3g} [{row[k]['ci_low']:.3g}, {row[k]['ci_high']:.3g}]"
            for k in KEYS) + " |")
    knots = episodes.get("baseline:knots")
    if knots is not None:
        for name, eps in episodes.items():
            if name == "baseline:knots" or name.startswith("replay:"):
                continue
            gap = {k: paired_interval([float(e[k]) for e in eps], [float(e[k]) for e in knots])
                   for k in ("return", "residual_vibration", "run_up_time")}
            report["gap_vs_knots"][name] = gap
            print(f"{name} - knots: " + ", ".join(
                f"{k} {v['mean']:+.3g} [{v['ci_low']:+.3g}, {v['ci_high']:+.3g}]"
                for k, v in gap.items()))
    for a in args.agent:
        fv = feedback_value(episodes[f"ppo:{a}"], episodes[f"replay:ppo:{a}"])
        report["feedback_value"][a] = fv
        r = fv["residual_vibration"]
        print(f"feedback value {a}: residual {r['mean']:+.3g} [{r['ci_low']:+.3g}, "
              f"{r['ci_high']:+.3g}] W_r/e")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "gap.json").write_text(json.dumps(report, indent=1, default=float))
    print(f"wrote {out / 'gap.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
