#!/usr/bin/env python
"""Evaluate shipped PPO agents against the tuned baselines on the seeded test set.

A thin script over :mod:`abb_gym.evaluation.evaluate` (the same episodes and metrics as
``abb-gym evaluate``): for each agent it evaluates ``ppo:<agent>`` and the baseline families
(tuned parameters from ``configs/baselines/<scene>.yaml`` where they exist) on the agent's
environment and scene, writes the report of ``abb-gym evaluate`` (summary.md, episodes.csv,
evaluation.json, charts) to ``<out>/<agent>/``, and prints the check of the project goal
against the best tuned dwell baseline (the dwell family with the lowest mean residual
vibration):

* residual vibration (mean W_r/e over the settling window) at least 30 % lower,
* mean time to speed no longer,
* a higher balanced share.

``time_to_speed`` is the *first* time the speed reaches 99 % of the operating speed.  A policy
that is free to leave the operating speed again (RunUpTorque may run above it, up to the
overspeed trip) can reach it early and settle later, so the script also reports the *settled
entry time*: the start of the final settling window, ``episode end - settle_time`` for
episodes that ended before the time limit (for a profile that holds the operating speed it
equals the time to speed).

DwellProfile episodes are one step, so the histories the evaluation records hold only the
start and the end of the run (its time to speed is the episode end, its peak and residual
vibration the last sample).  For a DwellProfile agent the script therefore also *replays* the
agent's dwell on RunUpSpeed: without ball observations the agent sees the same observation at
every reset, so its decision is one fixed dwell profile, which is then evaluated on the same
test machines as the baselines (``RunUpSpeed`` is the same physics interval by interval; the
replay lands the profile's breakpoints on 10 ms control instants).  The goal check uses the
replay.

    python agents/evaluate.py                                  # every agent in agents/trained
    python agents/evaluate.py runup_speed_yoshida_odd --episodes 200 --seed 0
    python agents/evaluate.py runs/x/s0-... --baselines speed_dwell ramp
"""
import argparse
import json
import math
import os
import sys
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

DWELL_FAMILIES = ("speed_dwell", "accel_dwell", "decel_dwell")
DEFAULT_BASELINES = ("ramp", "speed_dwell", "accel_dwell", "decel_dwell", "speed_reduction")


def goal_check(ppo: dict, baselines: dict[str, dict]) -> dict:
    """Compare the agent's summary with the best tuned dwell baseline's (summaries of
    :func:`abb_gym.evaluation.evaluate.summarise`)."""
    dwell = {k: v for k, v in baselines.items() if k.split(":")[-1] in DWELL_FAMILIES}
    if not dwell:
        return {}
    best_name = min(dwell, key=lambda k: dwell[k]["residual_vibration"]["mean"])
    best = dwell[best_name]
    r_ppo = ppo["residual_vibration"]["mean"]
    r_base = best["residual_vibration"]["mean"]
    reduction = 1.0 - r_ppo / r_base if r_base > 0 else math.nan
    return {
        "best_dwell_baseline": best_name,
        "residual_vibration": (r_ppo, r_base),
        "residual_reduction": reduction,
        "time_to_speed": (ppo["time_to_speed"]["mean"], best["time_to_speed"]["mean"]),
        "balanced": (ppo["balanced"]["mean"], best["balanced"]["mean"]),
        "goal_residual": reduction >= 0.30,
        "goal_time": ppo["time_to_speed"]["mean"] <= best["time_to_speed"]["mean"],
        "goal_balanced": ppo["balanced"]["mean"] > best["balanced"]["mean"],
        "settled_entry_time": (ppo.get("settled_entry_time", {}).get("mean"),
                               best.get("settled_entry_time", {}).get("mean")),
    }


def entry_time(result, settle_time: float, dt: float, episode_length: float) -> dict:
    """Mean and 95 % CI of the settled entry time (see the module docstring) [s]."""
    import numpy as np
    from scipy import stats
    ends = np.array([e["steps"] * dt for e in result.episodes])
    v = ends[ends < episode_length - 1e-9] - settle_time
    if v.size < 2:
        return {"mean": float(v.mean()) if v.size else math.nan, "n": int(v.size)}
    half = float(stats.t.ppf(0.975, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size))
    return {"mean": float(v.mean()), "ci_low": float(v.mean() - half),
            "ci_high": float(v.mean() + half), "n": int(v.size)}


def dwell_replay_policy(folder, scene: str, preset: str):
    """The fixed dwell profile a DwellProfile agent chooses, as a RunUpSpeed baseline policy
    (see the module docstring); raises ValueError for an agent that observes the balls."""
    import numpy as np
    from abb_gym.baselines.baseline_policy import BaselinePolicy
    from abb_gym.envs.actions import dwell_profile
    from abb_gym.rl import load_policy, make_native_env

    pol = load_policy(folder)
    if pol.policy_env.get("observe_balls"):
        raise ValueError("an agent that observes the balls chooses a dwell per episode; "
                         "it has no single replay profile")
    env = make_native_env("abb_gym/DwellProfile-v0", 4, dict(scene=scene, preset=preset))
    obs, _ = env.reset(seed=0)
    acts = pol.predict(obs)
    if not np.allclose(acts, acts[0]):
        raise ValueError("the agent's dwell depends on the observation; no single replay")
    profile, params = dwell_profile(env.unwrapped.setup, acts[0])
    env.close()
    name = "ppo-dwell replayed on RunUpSpeed (" + ", ".join(
        f"{k} {v:.4g}" for k, v in params.items() if k != "runup_acceleration") + ")"
    return BaselinePolicy(name, profile, params), params


def evaluate_agent(agent: str, args) -> dict:
    from abb_gym.evaluation.evaluate import evaluate
    from abb_gym.evaluation.report import summary_table, write_report
    from abb_gym.rl.agent import resolve_agent_path
    import yaml

    folder = resolve_agent_path(agent)
    meta = (yaml.safe_load((folder / "config.yml").read_text()) or {}).get("_run", {})
    env_id = meta["env_id"]
    scene = meta["policy_env"]["scene"]
    own = list(args.baselines)
    if env_id == "abb_gym/DwellProfile-v0":  # only dwells are DwellProfile actions
        own = [b for b in own if b in DWELL_FAMILIES]
    specs = [f"ppo:{folder}"] + [f"baseline:{b}" for b in own]
    results = [evaluate(env_id, scene, spec, args.episodes, args.seed, args.preset)
               for spec in specs]
    out = Path(args.out) / folder.name
    write_report(results, out)
    print(f"\n## {folder.name}: {env_id} on {scene}, {args.episodes} test episodes, "
          f"seed {args.seed}\n")
    print(summary_table(results))
    from abb_gym.envs.setup import EnvSetup
    kind = {"abb_gym/RunUpSpeed-v0": "speed", "abb_gym/RunUpTorque-v0": "torque",
            "abb_gym/DwellProfile-v0": "dwell"}[env_id]
    setup = EnvSetup(kind, scene, args.preset)
    summaries = {}
    print("\nsettled entry time [s] (start of the final settling window):")
    for r in results:
        s = r.summary()
        if kind != "dwell":
            s["settled_entry_time"] = entry_time(r, setup.config.settle_time,
                                                 setup.control_interval, setup.episode_length)
            print(f"  {r.policy:40s} {s['settled_entry_time']['mean']:.2f}")
        summaries[r.policy] = s
    ppo = summaries[results[0].policy]
    check = goal_check(ppo, {spec: summaries[r.policy] for spec, r in zip(specs[1:], results[1:])})
    if kind == "dwell":
        replay, params = dwell_replay_policy(folder, scene, args.preset)
        from abb_gym.evaluation.evaluate import run_chunk, chunks, EvaluationResult
        speed_id = "abb_gym/RunUpSpeed-v0"
        rep = EvaluationResult(replay.name, speed_id, scene, args.preset, args.seed)
        for ch in chunks(speed_id, scene, replay.name, args.episodes, args.seed, args.preset):
            rows, rolls = run_chunk(ch, policy=replay)
            rep.episodes.extend(rows)
            rep.rollouts.update(rolls)
        base = [evaluate(speed_id, scene, f"baseline:{b}", args.episodes, args.seed,
                         args.preset) for b in args.baselines]
        write_report([rep] + base, out / "replay_on_runup_speed")
        print(f"\nreplay of the agent's dwell on RunUpSpeed ({params}):\n")
        print(summary_table([rep] + base))
        setup = EnvSetup("speed", scene, args.preset)
        for r in [rep] + base:
            s = r.summary()
            s["settled_entry_time"] = entry_time(r, setup.config.settle_time,
                                                 setup.control_interval, setup.episode_length)
            summaries["replay/" + r.policy] = s
        check = goal_check(summaries["replay/" + rep.policy],
                           {f"baseline:{b}": summaries["replay/" + r.policy]
                            for b, r in zip(args.baselines, base)})
    if check:
        rp, rb = check["residual_vibration"]
        tp, tb = check["time_to_speed"]
        bp, bb = check["balanced"]
        print(f"\ngoal vs best tuned dwell baseline ({check['best_dwell_baseline']}): residual "
              f"{rp:.3f} vs {rb:.3f} W_r/e ({100 * check['residual_reduction']:+.0f} % "
              f"reduction; goal >= 30 %: {'met' if check['goal_residual'] else 'NOT met'}), "
              f"time to speed {tp:.2f} vs {tb:.2f} s ({'ok' if check['goal_time'] else 'longer'})"
              f", balanced {bp:.2f} vs {bb:.2f} "
              f"({'higher' if check['goal_balanced'] else 'NOT higher'})")
        ep, eb = check["settled_entry_time"]
        if ep is not None:
            print(f"settled entry time {ep:.2f} vs {eb:.2f} s")
    report = {"agent": folder.name, "env_id": env_id, "scene": scene,
              "episodes": args.episodes, "seed": args.seed, "summaries": summaries,
              "goal": check}
    (out / "comparison.json").write_text(json.dumps(report, indent=1, default=str))
    return report


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("agents", nargs="*",
                   help="shipped agent names (agents/trained/<name>) or run folders; default: "
                        "every shipped agent")
    p.add_argument("--episodes", type=int, default=100, help="test episodes per policy")
    p.add_argument("--seed", type=int, default=0, help="seed of the test set")
    p.add_argument("--preset", default="test", help="environment preset of the test set")
    p.add_argument("--baselines", nargs="*", default=list(DEFAULT_BASELINES),
                   help="baseline families to compare with")
    p.add_argument("--out", default="out/agents", help="report folder")
    args = p.parse_args(argv)
    from abb_gym.rl.agent import trained_dir
    agents = args.agents or sorted(d.name for d in trained_dir().iterdir()
                                   if (d / "model.zip").exists())
    if not agents:
        print("no agents to evaluate", file=sys.stderr)
        return 2
    try:
        for a in agents:
            evaluate_agent(a, args)
    except ValueError as exc:
        print(f"evaluate: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
