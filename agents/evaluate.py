#!/usr/bin/env python
"""Evaluate the shipped PPO agents against the strongest baselines on held-out machines, and
measure the feedback gap.

A thin command line over :mod:`abb_gym.rl.comparison` (the runs: each agent on its own
held-out machines with its own reward, its open-loop replay, the baselines tuned on its
training preset, the per-machine oracle and the goal's room),
:mod:`abb_gym.evaluation.feedback_gap` (the goal check and the tables) and
:mod:`abb_gym.evaluation.results_pages` (where the tables go); their docstrings say what is
compared and why.

It writes the report of ``abb-gym evaluate`` to ``<out>/<agent>/`` (summary.md, episodes.csv,
evaluation.json, timeseries.png, pareto.png), ``<out>/<agent>/comparison.json`` and
``<out>/comparison.md``, and one documentation page per agent plus an index to ``--pages``
(default ``docs/results/`` of the repository).  Run without agent names, it evaluates every
shipped agent and also writes the training page (every agent's training cost and learning
curves).  The READMEs' marked sections are regenerated only when asked: ``--readme`` alone
regenerates agents/README.md (``<!-- comparison:begin/end -->``: every table;
``<!-- training:begin/end -->``) and README.md (``<!-- feedback-gap:begin/end -->``: the
feedback-gap tables); ``--readme FILE`` the comparison section of FILE, ``--gap-readme FILE``
the feedback-gap section of FILE.

    python agents/evaluate.py                                # every agent: pages, no READMEs
    python agents/evaluate.py --readme                       # ... and the READMEs' sections
    python agents/evaluate.py runup_speed_yoshida_odd --episodes 200 --seed 0
    python agents/evaluate.py runs/x/s0-... --baselines knots retry --pages out/pages \\
        --readme notes.md
"""
import argparse
import os
import sys
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

REPO = Path(__file__).resolve().parents[1]
#: ``--readme`` without a file: the repository's READMEs (an object, which argparse does not
#: convert as it converts a text)
REPOSITORY_READMES = object()


def build_parser() -> argparse.ArgumentParser:
    from abb_gym.evaluation.feedback_gap import DEFAULT_BASELINES
    from abb_gym.execution.cli import add_executor_arguments
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "),
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("agents", nargs="*",
                   help="shipped agent names (agents/trained/<name>) or run folders; default: "
                        "every shipped agent, and the training page is written too")
    p.add_argument("--episodes", type=int, default=100, help="test episodes per policy")
    p.add_argument("--seed", type=int, default=0, help="seed of the test set")
    p.add_argument("--preset", default=None,
                   help="environment preset of the test set (default: the agent's held-out "
                        "preset, test or the one its config names)")
    p.add_argument("--baselines", nargs="*", default=list(DEFAULT_BASELINES),
                   help="baseline families to compare with")
    p.add_argument("--oracle-budget", type=int, default=60,
                   help="CMA-ES candidates per machine of the oracle (0: no oracle)")
    p.add_argument("--machine-oracle-budget", type=int, default=24,
                   help="CMA-ES candidates per machine of the oracle that knows the machine but "
                        "not where its balls start (0: none)")
    p.add_argument("--machine-oracle-draws", type=int, default=3,
                   help="ball starts each candidate of that oracle is scored on (0: none)")
    p.add_argument("--elsewhere-draws", type=int, default=4,
                   help="ball-angle draws per machine on which the oracle's profiles and knots "
                        "run again with the balls started elsewhere (0: not measured)")
    p.add_argument("--room-factors", type=float, nargs="*", default=[3.0],
                   help="the oracle again at these multiples of the agent's residual weight "
                        "(from the tuned knots), for the goal's room: the least residual a "
                        "planner that knows each machine reaches at knots' run-up time (no "
                        "value: not measured)")
    p.add_argument("--room-budget", type=int, default=None,
                   help="CMA-ES candidates per machine of the oracle at those weights "
                        "(default: --oracle-budget)")
    p.add_argument("--out", default="agents/results", help="report folder")
    p.add_argument("--pages", default=str(REPO / "docs" / "results"),
                   help="folder of the documentation pages: one per agent and an index")
    from abb_gym.cli.evaluate import add_trust_argument
    add_trust_argument(p)
    add_executor_arguments(p, resume=False)
    p.add_argument("--readme", nargs="?", type=Path, const=REPOSITORY_READMES, default=None,
                   metavar="FILE",
                   help="regenerate the comparison section (and the training section, if it "
                        "has one) of FILE; without FILE: of agents/README.md, and the "
                        "feedback-gap section of README.md (default: no README is rewritten)")
    p.add_argument("--gap-readme", type=Path, default=None, metavar="FILE",
                   help="regenerate the feedback-gap section of FILE")
    return p


def check_args(args: argparse.Namespace) -> None:
    """Refuse inconsistent options, naming the option, before anything runs."""
    for flag in ("out", "pages"):
        if not str(getattr(args, flag)).strip():
            raise ValueError(f"--{flag} must be a folder path (got {getattr(args, flag)!r})")
    if args.episodes < 2:
        raise ValueError(f"--episodes must be >= 2 for confidence intervals "
                         f"(got {args.episodes})")
    if args.room_budget is not None and args.room_budget < 1:
        raise ValueError(f"--room-budget must be >= 1 (got {args.room_budget})")
    for flag in ("oracle_budget", "machine_oracle_budget", "machine_oracle_draws",
                 "elsewhere_draws"):
        if getattr(args, flag) < 0:
            raise ValueError(f"--{flag.replace('_', '-')} must be >= 0 "
                             f"(got {getattr(args, flag)})")
    for factor in args.room_factors:
        if not factor > 0 or factor == 1 or factor > 1e4:
            raise ValueError(f"--room-factors must lie in (0, 10000] and differ from 1 "
                             f"(the agent's own weight is the oracle's; got {factor})")
    if args.readme is REPOSITORY_READMES:
        args.readme = REPO / "agents" / "README.md"
        args.gap_readme = args.gap_readme or REPO / "README.md"
    for flag, path, hint in (("--readme", args.readme, " (agent names go before --readme)"),
                             ("--gap-readme", args.gap_readme, "")):
        if path is not None and not path.is_file():
            raise ValueError(f"{flag} {path} is not a file{hint}")


def own_study(folder: Path) -> bool:
    """An agent of SpinRedistribute: its comparison (rules, oracle, floor, two scenes) is
    agents/spin_study.py's, not the run-up study's (a per-machine knots oracle)."""
    import yaml

    from abb_gym.envs.tasks import SPIN_REDISTRIBUTE
    run = yaml.safe_load((folder / "config.yml").read_text()).get("_run", {})
    return run.get("env_id") == SPIN_REDISTRIBUTE.env_id


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    if args.trust_pickle:  # as abb-gym's --trust-pickle: the worker processes trust them too
        from abb_gym.resources import TRUST_PICKLE_ENV
        os.environ[TRUST_PICKLE_ENV] = "1"
    from abb_gym.evaluation.feedback_gap import GapStudy
    from abb_gym.evaluation.results_pages import (COMPARISON_MARKERS, GAP_MARKERS,
                                                  TRAINING_MARKERS, replace_between_markers,
                                                  write_agent_page, write_index,
                                                  write_training_page)
    from abb_gym.execution.cli import executor_from_args
    from abb_gym.rl.agent import trained_dir
    from abb_gym.rl.comparison import compare_agent, training_section
    everything = not args.agents
    agents = args.agents or [d.name for d in sorted(trained_dir().iterdir())
                             if (d / "agent.yml").exists() and not own_study(d)]
    try:
        check_args(args)
        # the oracle's searches and its replays with the balls elsewhere run there; the
        # results do not depend on it (inconsistent --workers / --ray options fail here)
        executor = executor_from_args(args)
        study = GapStudy(episodes=args.episodes, seed=args.seed, preset=args.preset,
                         baselines=tuple(args.baselines), oracle_budget=args.oracle_budget,
                         machine_oracle_budget=args.machine_oracle_budget,
                         machine_oracle_draws=args.machine_oracle_draws,
                         elsewhere_draws=args.elsewhere_draws,
                         room_factors=tuple(args.room_factors), room_budget=args.room_budget,
                         out=Path(args.out))
        parts = [compare_agent(a, study, executor) for a in agents]
    except ValueError as exc:
        print(f"evaluate: error: {exc}", file=sys.stderr)
        return 2
    out, pages = Path(args.out), Path(args.pages)
    body = "\n".join(text for text, _, _ in parts)
    out.mkdir(parents=True, exist_ok=True)
    pages.mkdir(parents=True, exist_ok=True)
    (out / "comparison.md").write_text(body)
    written = [str(out / "comparison.md")]
    for text, _, report in parts:
        name = report["agent"]
        written.append(str(write_agent_page(pages, name, text, out / name / "pareto.png")))
    if everything:
        written.append(str(write_training_page(
            pages, training_section(agents, pages / "training_curves.png",
                                    pages / "training.md"))))
    written.append(str(write_index(pages)))
    if args.readme is not None:
        replace_between_markers(args.readme, body, COMPARISON_MARKERS)
        if TRAINING_MARKERS[0] in args.readme.read_text():
            replace_between_markers(args.readme, training_section(
                agents, out / "training_curves.png", args.readme), TRAINING_MARKERS)
        written.append(str(args.readme))
    gaps = "\n".join(gap for _, gap, _ in parts if gap)
    if args.gap_readme is not None and gaps:
        replace_between_markers(args.gap_readme, gaps, GAP_MARKERS)
        written.append(str(args.gap_readme))
    print("wrote " + ", ".join(written))
    return 0


if __name__ == "__main__":
    sys.exit(main())
