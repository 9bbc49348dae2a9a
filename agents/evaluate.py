#!/usr/bin/env python
"""Evaluate the shipped PPO agents against the strongest baselines on the seeded test set.

A thin script over :mod:`abb_gym.evaluation` (the same episodes, metrics and report as
``abb-gym evaluate``).  For each agent it evaluates, on the agent's environment and scene, the
same test machines (episode k: seed + k on the ``test`` preset) under

* ``ppo:<agent>`` and ``replay:ppo:<agent>`` (its own actions on the nominal machine, replayed
  open-loop: the difference is the agent's **feedback value**);
* ``baseline:knots``, the strongest open-loop profile (CMA-ES-tuned speed knots);
* the closed-loop hand-designed baselines ``retry`` and ``resonance_dwell``;
* the dwell families, ``speed_reduction`` and ``ramp`` (tuned parameters from
  ``configs/baselines/<scene>.yaml``).

On DwellProfile, the baselines its one action cannot express (every one above after tuning,
since they carry their own run-up acceleration) run on RunUpSpeed, on the same machines
(:func:`abb_gym.evaluation.evaluate.policy_env_id`); the tables mark the environment.

It writes the report of ``abb-gym evaluate`` to ``<out>/<agent>/`` (summary.md, episodes.csv,
evaluation.json, timeseries.png, pareto.png), ``<out>/<agent>/comparison.json`` and
``<out>/comparison.md`` (every agent's table and the goal check), and with ``--readme FILE``
replaces the part of FILE between ``<!-- comparison:begin -->`` and ``<!-- comparison:end -->``
by the same text.

The goal check (the project's "Tasks where feedback pays" goal), per agent, against
``baseline:knots`` on the same machines:

* residual vibration (mean W_r/e over the settling window, at the operating speed) at least
  20 % lower, with the paired difference knots - PPO and its 95 % interval;
* settled run-up time (start of the final stay in the operating band) no longer;
* feedback value: the open-loop replay's residual at least 10 % worse, and its paired
  difference positive at 95 % confidence.

    python agents/evaluate.py                                       # every shipped agent
    python agents/evaluate.py --readme agents/README.md            # and regenerate its tables
    python agents/evaluate.py runup_speed_yoshida_odd --episodes 200 --seed 0
    python agents/evaluate.py runs/x/s0-... --baselines knots retry
"""
import argparse
import json
import os
import sys
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

STRONGEST_OPEN_LOOP = "knots"
CLOSED_LOOP = ("retry", "resonance_dwell")
DEFAULT_BASELINES = (STRONGEST_OPEN_LOOP, *CLOSED_LOOP, "speed_dwell", "accel_dwell",
                     "decel_dwell", "speed_reduction", "ramp")
RESIDUAL_GOAL = 0.20   # at least 20 % lower residual than knots
FEEDBACK_GOAL = 0.10   # the replay at least 10 % worse than the agent
BEGIN, END = "<!-- comparison:begin -->", "<!-- comparison:end -->"


def goal_check(ppo, replay, knots) -> dict:
    """The goal of the module docstring from three :class:`EvaluationResult` on the same
    machines."""
    from abb_gym.evaluation.replay import feedback_value
    from abb_gym.evaluation.statistics import paired_interval

    def paired(a, b, key):
        return paired_interval([e[key] for e in a.episodes], [e[key] for e in b.episodes])

    s_ppo, s_knots = ppo.summary(), knots.summary()
    r_ppo = s_ppo["residual_vibration"]["mean"]
    r_knots = s_knots["residual_vibration"]["mean"]
    t_ppo = s_ppo["run_up_time"]["mean"]
    t_knots = s_knots["run_up_time"]["mean"]
    feedback = feedback_value(ppo.episodes, replay.episodes)["residual_vibration"]
    reduction = 1.0 - r_ppo / r_knots
    return {
        "residual": {"ppo": r_ppo, "knots": r_knots, "reduction": reduction,
                     "knots_minus_ppo": paired(knots, ppo, "residual_vibration")},
        "run_up_time": {"ppo": t_ppo, "knots": t_knots,
                        "ppo_minus_knots": paired(ppo, knots, "run_up_time")},
        "at_speed": {"ppo": s_ppo["at_speed"]["mean"], "knots": s_knots["at_speed"]["mean"]},
        "feedback_value": feedback,
        "goal_residual": bool(reduction >= RESIDUAL_GOAL),
        "goal_run_up_time": bool(t_ppo <= t_knots and s_ppo["at_speed"]["mean"]
                                 >= s_knots["at_speed"]["mean"]),
        "goal_feedback": bool(feedback["ci_low"] > 0
                              and feedback["mean"] >= FEEDBACK_GOAL * r_ppo),
    }


def _cell(stat: dict, digits: int = 3) -> str:
    import math
    mean, low, high = stat["mean"], stat.get("ci_low"), stat.get("ci_high")
    if not math.isfinite(mean):
        return "n/a"
    if low is None or not math.isfinite(low):
        return f"{mean:.{digits}g}"
    return f"{mean:.{digits}g} [{low:.{digits}g}, {high:.{digits}g}]"


def agent_table(results) -> str:
    """One row per policy: environment, at-speed share, settled run-up time, residual."""
    from abb_gym.tables import markdown_table
    rows = []
    for r in results:
        s = r.summary()
        rows.append({"policy": r.policy, "env": r.env_id.split("/")[-1].removesuffix("-v0"),
                     "at speed": _cell(s["at_speed"], 2),
                     "settled run-up [s]": _cell(s["run_up_time"]),
                     "residual [W_r/e]": _cell(s["residual_vibration"]),
                     "peak speed [w_op]": _cell(s["peak_speed"]),
                     "return": _cell(s["return"])})
    return markdown_table(rows)


def goal_line(check: dict) -> str:
    import math
    res, run, fb = check["residual"], check["run_up_time"], check["feedback_value"]
    yes = {True: "met", False: "NOT met"}
    if not math.isfinite(res["ppo"]):  # no episode settled: no residual to compare
        return (f"NOT met: PPO never held the operating speed (at speed "
                f"{check['at_speed']['ppo']:.2f} against {check['at_speed']['knots']:.2f}; "
                f"settled run-up {run['ppo']:.2f} s, the episode limit, against "
                f"{run['knots']:.2f} s)")
    return (f"residual {res['ppo']:.3f} vs knots {res['knots']:.3f} W_r/e "
            f"({100 * res['reduction']:+.0f} %, knots - PPO {_cell(res['knots_minus_ppo'])}; "
            f">= 20 %: {yes[check['goal_residual']]}); settled run-up {run['ppo']:.2f} vs "
            f"{run['knots']:.2f} s (no longer, as often at speed: "
            f"{yes[check['goal_run_up_time']]}); feedback value (replay - PPO residual) "
            f"{_cell(fb)} W_r/e (>= 10 % and > 0 at 95 %: {yes[check['goal_feedback']]})")


def evaluate_agent(agent: str, args) -> tuple[str, dict]:
    from abb_gym.evaluation.evaluate import evaluate
    from abb_gym.evaluation.report import write_report
    from abb_gym.rl.agent import resolve_agent_path
    from abb_gym.rl.agent_files import check_folder

    folder = resolve_agent_path(agent)
    files = check_folder(folder)
    env_id, scene = files.env_id, files.manifest["scene"]
    ppo_spec = f"ppo:{agent}"
    specs = [ppo_spec, f"replay:{ppo_spec}"] + [f"baseline:{b}" for b in args.baselines]
    results = [evaluate(env_id, scene, spec, args.episodes, args.seed, args.preset)
               for spec in specs]
    out = Path(args.out) / folder.name
    write_report(results, out)
    by_spec = dict(zip(specs, results))
    check = {}
    if STRONGEST_OPEN_LOOP in args.baselines:
        check = goal_check(results[0], results[1], by_spec[f"baseline:{STRONGEST_OPEN_LOOP}"])
    text = (f"### {folder.name}: {env_id.split('/')[-1]} on {scene}\n\n"
            f"{args.episodes} test episodes (preset {args.preset}, seed {args.seed}), mean "
            f"[95 % CI]; the same machines for every row.\n\n" + agent_table(results) + "\n")
    if check:
        text += f"\nGoal against knots: {goal_line(check)}.\n"
    report = {"agent": folder.name, "env_id": env_id, "scene": scene,
              "episodes": args.episodes, "seed": args.seed, "preset": args.preset,
              "summaries": {r.policy: dict(r.summary(), env_id=r.env_id) for r in results},
              "goal": check}
    (out / "comparison.json").write_text(json.dumps(report, indent=1, default=float))
    print("\n" + text, flush=True)
    return text, report


def replace_between_markers(path: Path, text: str) -> None:
    """Replace what lies between the comparison markers of ``path`` by ``text``."""
    old = path.read_text()
    if BEGIN not in old or END not in old:
        raise ValueError(f"{path} has no {BEGIN} ... {END} section to regenerate")
    head, rest = old.split(BEGIN, 1)
    tail = rest.split(END, 1)[1]
    path.write_text(f"{head}{BEGIN}\n{text}\n{END}{tail}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("agents", nargs="*",
                   help="shipped agent names (agents/trained/<name>) or run folders; default: "
                        "every shipped agent")
    p.add_argument("--episodes", type=int, default=100, help="test episodes per policy")
    p.add_argument("--seed", type=int, default=0, help="seed of the test set")
    p.add_argument("--preset", default="test", help="environment preset of the test set")
    p.add_argument("--baselines", nargs="*", default=list(DEFAULT_BASELINES),
                   help="baseline families to compare with")
    p.add_argument("--out", default="agents/results", help="report folder")
    p.add_argument("--readme", type=Path, default=None,
                   help="also regenerate the comparison section of this Markdown file")
    args = p.parse_args(argv)
    from abb_gym.rl.agent import trained_dir
    agents = args.agents or sorted(d.name for d in trained_dir().iterdir()
                                   if (d / "model.zip").exists())
    try:
        if args.episodes < 2:
            raise ValueError(f"--episodes must be >= 2 for confidence intervals "
                             f"(got {args.episodes})")
        if args.readme is not None and not args.readme.is_file():
            raise ValueError(f"--readme {args.readme} is not a file")
        texts = [evaluate_agent(a, args)[0] for a in agents]
    except ValueError as exc:
        print(f"evaluate: error: {exc}", file=sys.stderr)
        return 2
    body = "\n".join(texts)
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "comparison.md").write_text(body)
    if args.readme is not None:
        replace_between_markers(args.readme, body)
    print(f"wrote {Path(args.out) / 'comparison.md'}"
          + (f" and {args.readme}" if args.readme else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
