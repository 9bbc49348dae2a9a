#!/usr/bin/env python
"""SpinRedistribute: the shipped PPO agents against the open loop, the hand rules, the oracle
and their own replays, on the training scene (washer_reduced) and on the full washer.

For each scene it runs ``abb-gym evaluate``'s evaluation (the same seeded ``laundry_test``
episodes for every policy, the agent's reward weights) and writes its report to
``<out>/<scene>/``; then the goal check of :mod:`abb_gym.evaluation.spin_goal` for each agent
and one documentation page with both scenes side by side (``--page``).  ``--agents`` takes
several (shipped names or run folders), each with its replay and its goal check.

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
AGENTS = ("spin_redistribute_washer",)
PAGE = "spin_redistribute_washer"
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
    p.add_argument("--agents", nargs="+", default=list(AGENTS),
                   help="shipped agent names or run folders")
    p.add_argument("--episodes", type=int, default=100, help="test episodes per policy")
    p.add_argument("--seed", type=int, default=5000, help="seed of the test set")
    p.add_argument("--scenes", nargs="+", default=["washer_reduced", "washer"])
    p.add_argument("--out", default="out/spin-study", help="folder of the reports")
    p.add_argument("--page", default=str(REPO / "docs" / "results" / f"{PAGE}.md"),
                   help="documentation page to write ('' for none)")
    p.add_argument("--beyond-capacity", type=int, default=32, metavar="N",
                   help="also N constructed episodes with every load beyond capacity (0: none)")
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
    source = Path(run.get("config_source", f"configs/ppo/{agent}.yml")).name
    text = ", ".join(parts) + f" (`configs/ppo/{source}`)"
    parent = (run.get("init_from") or {}).get("folder")
    if parent:
        name = Path(parent).name
        try:  # a shipped agent (or a folder still there): how it was trained in turn
            text += f", fine-tuned from `{name}`, {_training(name)}"
        except (FileNotFoundError, ValueError):
            text += f", fine-tuned from `{name}`"
    return text


def beyond_capacity(policies, scene: str, episodes: int, env_kwargs: dict, seed: int = 7):
    """Each policy on ``episodes`` constructed episodes whose every load, the first and each
    of the four redistributions, lies beyond the balls' capacity (1.2-1.6 C, phases uniform,
    from generator ``seed``, the same for every policy): a drive that redistributes them all
    has spent its budget and must then spin with what it has.  The held-out preset makes such
    episodes rare (the last draw beyond capacity after four: a few in a hundred), yet one
    drive that keeps dipping until the time limit costs a mean return as much as all its
    other episodes.  Returns the results, as the test set's."""
    import numpy as np

    from abb_gym.evaluation import evaluate as ev
    from abb_gym.physics.scene import load_scene

    cap = load_scene(scene).balancing_capacity
    rng = np.random.default_rng(seed)
    loads = tuple(float(x) for x in rng.uniform(1.2, 1.6, episodes))
    draws = tuple((float(r * cap), float(ph)) for r, ph in
                  zip(rng.uniform(1.2, 1.6, 4), rng.uniform(-np.pi, np.pi, 4)))
    out = []
    for spec in policies:
        chunk = ev.Chunk(ENV, scene, "laundry_test", spec, 0, tuple(range(episodes)),
                         env_kwargs=tuple(sorted(env_kwargs.items())),
                         reset_options=(("imbalance_ratio", loads), ("redistributions", draws)))
        rows = ev.run_chunk(chunk)[0]
        out.append(ev.EvaluationResult(rows[0]["policy"], ENV, scene, "laundry_test", 0,
                                       episodes=rows))
    return out


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from abb_gym.cli.evaluate import agent_reward_weights
    from abb_gym.evaluation.evaluate import check_inputs, evaluate
    from abb_gym.evaluation.report import cell, reward_line, summary_table, write_report
    from abb_gym.evaluation.spin_goal import goal_check, goal_lines
    from abb_gym.execution.cli import executor_from_args

    agents = [f"ppo:{a}" for a in args.agents]
    policies = [p for ppo in agents for p in (ppo, f"replay:{ppo}")] + list(BASELINES)
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
        named = {r.policy: r for r in results}  # an agent's result names it as it was loaded
        checks = [goal_check(named, results[policies.index(ppo)].policy) for ppo in agents]
        floor = json.loads(Path(paths["json"]).read_text())["open_loop_floor"]  # the report's
        unit = results[0].length_unit
        text = (f"## {scene}\n\n{reward_line(results[0])}\n\n"
                f"{summary_table(results, HEADLINE)}\n\n"
                f"Open-loop floor: {cell(floor)} {unit} ({floor['definition']}).\n\n"
                + "".join(f"Goal check of `{c['policy']}` (paired over the {args.episodes} "
                          f"episodes):\n\n{goal_lines(c)}\n\n" for c in checks))
        if args.beyond_capacity:
            print(f"{scene}: every load beyond capacity", flush=True)
            hard = beyond_capacity([p for p in policies if not p.startswith("replay:")], scene,
                                   args.beyond_capacity, env_kwargs)
            text += (f"Every load beyond the capacity ({args.beyond_capacity} constructed "
                     f"episodes: the first load and all four redistributions drawn at "
                     f"1.2-1.6 C, `beyond_capacity` in `agents/spin_study.py`): a drive that "
                     f"redistributes them all has spent its budget and must spin with the "
                     f"last.\n\n{summary_table(hard, HEADLINE)}\n\n")
        sections.append((scene, text, paths, checks))
        print(text, flush=True)
    if args.page:
        page = Path(args.page)
        page.parent.mkdir(parents=True, exist_ok=True)
        command = "python agents/spin_study.py " + " ".join(shlex.quote(a) for a in
                                                            (argv or sys.argv[1:]))
        body = [f"# SpinRedistribute-v0 on washer_reduced and washer: the shipped agents\n",
                f"Generated by `{command.strip()}` ({time.time() - started:.0f} s): rerun it "
                f"rather than editing this page.\n",
                "The PPO agents " + "; ".join(f"`{a}` ({_training(a)})" for a in args.agents)
                + ", their "
                f"open-loop replays, the best single open-loop profile (`knots`), the two hand "
                f"rules tuned on the laundry preset and the laundry oracle (which knows the "
                f"load) on the held-out preset `laundry_test` (loads up to 1.8 of the "
                f"capacity), seeds {args.seed} + k; mean [95 % CI].  Goal: close at least half "
                f"of the return gap between knots and the oracle, a return above both rules, "
                f"a positive feedback value ({'`abb_gym.evaluation.spin_goal`'}).\n"]
        for scene, text, paths, _ in sections:
            body.append(text)
            chart = paths.get("balance") or paths.get("pareto")
            if chart is not None and Path(chart).is_file():
                name = f"{PAGE}_{scene}_{Path(chart).name}"
                shutil.copyfile(chart, page.parent / name)
                body.append(f"![{scene}: time to balance against the residual]({name})\n")
        page.write_text("\n".join(body))
        print(f"wrote {page}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
