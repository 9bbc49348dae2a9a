#!/usr/bin/env python
"""SpinRedistribute: the shipped PPO agent against the open loop, the hand rules, the oracle
and its own replay, on the training scene (washer_reduced) and on the full washer.

For each scene it runs ``abb-gym evaluate``'s evaluation (the same seeded ``laundry_test``
episodes for every policy, the agent's reward weights) and writes its report to
``<out>/<scene>/``; then the goal check of :mod:`abb_gym.evaluation.spin_goal` and one
documentation page with both scenes side by side (``--page``).

    python agents/spin_study.py                                  # 100 episodes, both scenes
    python agents/spin_study.py --episodes 20 --scenes washer_reduced --page out/spin.md

The test seeds (5000 + k) differ from those the training's evaluations chose the agent on
(1000 + k).  The full washer (12 balls, contact) runs about 3x slower than washer_reduced.
"""
import argparse
import json
import os
import shlex
import shutil
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

REPO = Path(__file__).resolve().parents[1]
ENV = "abb_gym/SpinRedistribute-v0"
AGENT = "spin_redistribute_washer"
BASELINES = ("baseline:knots", "baseline:retry_at_spin", "baseline:redistribute_low",
             "baseline:laundry_oracle")
#: the table's columns: ``at_speed`` below 1 shows episodes that never completed their spin
#: (a time limit or a cabinet hit), ``redistributions`` the retries spent
HEADLINE = ("return", "residual_vibration", "residual_after_hold", "run_up_time",
            "time_to_balance", "at_speed", "redistributions", "peak_whirl")


def build_parser() -> argparse.ArgumentParser:
    from abb_gym.execution.cli import add_executor_arguments
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "),
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--agent", default=AGENT, help="shipped agent name or run folder")
    p.add_argument("--episodes", type=int, default=100, help="test episodes per policy")
    p.add_argument("--seed", type=int, default=5000, help="seed of the test set")
    p.add_argument("--scenes", nargs="+", default=["washer_reduced", "washer"])
    p.add_argument("--out", default="out/spin-study", help="folder of the reports")
    p.add_argument("--page", default=str(REPO / "docs" / "results" / f"{AGENT}.md"),
                   help="documentation page to write ('' for none)")
    add_executor_arguments(p)
    return p


def _training(agent: str) -> str:
    """How the agent was trained, as its config.yml records it: the scene, the rule it was
    cloned from, the agent it was fine-tuned from."""
    import yaml

    from abb_gym.rl.agent import resolve_agent_path
    run = yaml.safe_load((resolve_agent_path(agent) / "config.yml").read_text()).get("_run", {})
    parts = [f"trained on {run.get('policy_env', {}).get('scene', '?')}"]
    teacher = (run.get("imitate") or {}).get("policy")
    if teacher:
        parts.append(f"cloned from the tuned `{teacher}` rule, then PPO")
    source = Path(run.get("config_source", f"configs/ppo/{AGENT}.yml")).name
    text = ", ".join(parts) + f" (`configs/ppo/{source}`)"
    parent = (run.get("init_from") or {}).get("folder")
    if parent:
        name = Path(parent).name
        try:  # a shipped agent (or a folder still there): how it was trained in turn
            text += f", fine-tuned from `{name}`, {_training(name)}"
        except (FileNotFoundError, ValueError):
            text += f", fine-tuned from `{name}`"
    return text


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from abb_gym.cli.evaluate import agent_reward_weights
    from abb_gym.evaluation.evaluate import check_inputs, evaluate
    from abb_gym.evaluation.report import cell, reward_line, summary_table, write_report
    from abb_gym.evaluation.spin_goal import goal_check, goal_lines
    from abb_gym.execution.cli import executor_from_args

    ppo = f"ppo:{args.agent}"
    policies = [ppo, f"replay:{ppo}", *BASELINES]
    executor = executor_from_args(args)
    sections, started = [], time.time()
    for scene in args.scenes:
        env_kwargs = {"integrator": "etdrk4"}
        inner = [check_inputs(ENV, scene, "laundry_test", args.seed, p, **env_kwargs)
                 for p in policies]
        env_kwargs, source = agent_reward_weights(policies, inner, env_kwargs)
        results = []
        for spec in policies:
            print(f"{scene}: {spec}", flush=True)
            r = evaluate(ENV, scene, spec, args.episodes, args.seed, "laundry_test",
                         executor=executor, **env_kwargs)
            r.reward_source = f"recorded with {source}" if source else "preset laundry_test"
            results.append(r)
        out = Path(args.out) / scene
        paths = write_report(results, out)
        check = goal_check({r.policy: r for r in results}, ppo)
        floor = json.loads(Path(paths["json"]).read_text())["open_loop_floor"]  # the report's
        unit = results[0].length_unit
        text = (f"## {scene}\n\n{reward_line(results[0])}\n\n"
                f"{summary_table(results, HEADLINE)}\n\n"
                f"Open-loop floor: {cell(floor)} {unit} ({floor['definition']}).\n\n"
                f"Goal check (paired over the {args.episodes} episodes):\n\n"
                f"{goal_lines(check)}\n")
        sections.append((scene, text, paths, check))
        print(text, flush=True)
    if args.page:
        page = Path(args.page)
        page.parent.mkdir(parents=True, exist_ok=True)
        command = "python agents/spin_study.py " + " ".join(shlex.quote(a) for a in
                                                            (argv or sys.argv[1:]))
        body = [f"# {AGENT}: SpinRedistribute-v0 on washer_reduced and washer\n",
                f"Generated by `{command.strip()}` ({time.time() - started:.0f} s): rerun it "
                f"rather than editing this page.\n",
                f"The PPO agent `{args.agent}` ({_training(args.agent)}), its "
                f"open-loop replay, the best single open-loop profile (`knots`), the two hand "
                f"rules tuned on the laundry preset and the laundry oracle (which knows the "
                f"load) on the held-out preset `laundry_test` (loads up to 1.8 of the "
                f"capacity), seeds {args.seed} + k; mean [95 % CI].  Goal: close at least half "
                f"of the return gap between knots and the oracle, a return above both rules, "
                f"a positive feedback value ({'`abb_gym.evaluation.spin_goal`'}).\n"]
        for scene, text, paths, _ in sections:
            body.append(text)
            chart = paths.get("balance") or paths.get("pareto")
            if chart is not None and Path(chart).is_file():
                name = f"{AGENT}_{scene}_{Path(chart).name}"
                shutil.copyfile(chart, page.parent / name)
                body.append(f"![{scene}: time to balance against the residual]({name})\n")
        page.write_text("\n".join(body))
        print(f"wrote {page}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
