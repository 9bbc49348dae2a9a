"""``abb-gym bench``: ``accuracy`` draws the work-precision chart of every integrator (PNG +
Markdown table + CSV) and the energy drift of long undamped runs; ``speed`` measures
throughput; ``time-to-target`` times training runs to a target held-out return.

    abb-gym bench time-to-target --target runup_speed_yoshida_odd \\
        --run "shipped config=runs/a/s0" --run "shipped config=runs/a/s1" \\
        --run "tuned=runs/b/s0" --run "tuned=runs/b/s1" --out out/ttt
"""
from __future__ import annotations

import csv
import sys
from pathlib import Path

from .._files import replacing, write_text
from ..tables import markdown_lines, markdown_table
from .outputs import output_folder


def register(sub) -> None:
    p = sub.add_parser("bench", help="benchmarks: work-precision chart and throughput",
                       description=__doc__)
    bsub = p.add_subparsers(dest="bench", required=True)
    acc = bsub.add_parser("accuracy", help="work-precision chart of every integrator")
    acc.add_argument("--out", default="out/bench", help="folder for PNG, CSV and Markdown")
    acc.add_argument("--repeats", type=int, default=3, help="timing repeats (best of)")
    acc.set_defaults(func=run_accuracy)
    spd = bsub.add_parser("speed", help="throughput of simulate, gym.make and the vector env")
    spd.add_argument("--out", default="out/bench", help="folder for the Markdown table")
    spd.add_argument("--quick", action="store_true", help="shorter measurements (smoke test)")
    spd.add_argument("--costs-only", action="store_true",
                     help="only the side-by-side CPU-time tables (benchmarks.env_cost)")
    spd.add_argument("--docs", default=None, metavar="PATH",
                     help="also write the generated section of this page (docs/performance.md: "
                          "between its bench-costs markers; the rest stays as written)")
    spd.set_defaults(func=run_speed)
    ttt = bsub.add_parser("time-to-target",
                          help="training time of runs to a target held-out return (table, chart)",
                          description="Training time of runs to a target held-out return: per "
                                      "run and per config (the median of its seeds), with a "
                                      "chart of return against training time.  See "
                                      "abb_gym.benchmarks.time_to_target for the rule.")
    ttt.add_argument("--run", action="append", default=[], metavar="LABEL=FOLDER",
                     help="a run folder of abb-gym train (or an agent's folder) and its config's "
                          "label; repeat a label for the seeds of one config (the first label "
                          "is the reference)")
    ttt.add_argument("--target", default=None, metavar="AGENT",
                     help="the target is this agent's final held-out return (a shipped agent's "
                          "name or a folder: its evaluation.json)")
    ttt.add_argument("--target-return", type=float, default=None, metavar="R",
                     help="the target as a number instead of --target")
    ttt.add_argument("--tolerance", type=float, default=None,
                     help="reached at a return of at least target - tolerance * |target| "
                          "(default 0.02: abb_gym.benchmarks.time_to_target)")
    ttt.add_argument("--title", default=None, help="heading (default: the target's name)")
    ttt.add_argument("--out", default="out/bench", help="folder for time_to_target.md and .png")
    ttt.add_argument("--docs", default=None, metavar="PAGE",
                     help="also write the section between this page's "
                          "'<!-- time-to-target:TITLE:begin -->' and ':end -->' markers, with "
                          "the chart beside the page")
    ttt.set_defaults(func=run_time_to_target)


def _write_csv(rows, path: Path) -> None:
    with replacing(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def run_accuracy(args) -> int:
    from ..benchmarks.accuracy import (energy_drift, plot_work_precision, precision_table,
                                       run_accuracy as bench)
    if args.repeats < 1:  # "best of 0" has no best
        raise ValueError(f"--repeats must be >= 1 (got {args.repeats})")
    out = output_folder(args.out, "--out")
    rows = bench(repeats=args.repeats)
    png = plot_work_precision(rows, out / "work_precision.png")
    _write_csv(rows, out / "work_precision.csv")
    drift = energy_drift()
    _write_csv(drift, out / "energy_drift.csv")
    f32 = precision_table()
    _write_csv(f32, out / "float32.csv")
    text = ("## Work-precision\n\n" + markdown_table(rows) + "\n\n## Energy drift, undamped "
            "free rotor\n\n" + markdown_table(drift) + "\n\n## float32 against float64, "
            "every scene (a run-up through the critical speed; bounds 1 % peak whirl, 1 deg)"
            "\n\n" + markdown_table(f32) + "\n")
    write_text(out / "accuracy.md", text)
    print(text)
    print(f"wrote {png}, {out / 'work_precision.csv'}, {out / 'accuracy.md'}")
    return 0


def run_speed(args) -> int:
    """Each row printed as soon as it is measured (above the progress bars); speed.md gets
    the aligned table at the end."""
    from ..progress import ProgressBar

    from ..benchmarks.speed import COLUMNS, iter_speed
    out = output_folder(args.out, "--out")
    rows: list[dict] = []

    def measured():
        for row in iter_speed(quick=args.quick, costs_only=args.costs_only):
            rows.append(row)
            yield row

    for line in markdown_lines(measured(), COLUMNS):
        ProgressBar.write(line, file=sys.stdout)
        sys.stdout.flush()
    write_text(out / "speed.md", markdown_table(rows, COLUMNS) + "\n")
    print(f"wrote {out / 'speed.md'}")
    from ..benchmarks.env_cost import performance_page, write_docs_section
    page = performance_page(rows, COLUMNS)
    (out / "performance.md").write_text(page)
    print(f"wrote {out / 'performance.md'}")
    if args.docs:
        write_docs_section(args.docs, rows, COLUMNS)
        print(f"wrote the generated section of {args.docs}")
    return 0


def _run_option(text: str) -> tuple[str, Path]:
    label, sep, folder = text.partition("=")
    if not sep or not label.strip() or not folder.strip():
        raise ValueError(f"--run {text!r}: expected LABEL=FOLDER (e.g. 'tuned=runs/b/s0')")
    return label.strip(), Path(folder.strip())


def _command(args) -> str:
    """The command line that makes this section again (its options as given)."""
    import shlex
    parts = ["abb-gym", "bench", "time-to-target"]
    if args.target is not None:
        parts += ["--target", args.target]
    else:
        parts += ["--target-return", repr(args.target_return)]
    for option in ("tolerance", "title"):
        if getattr(args, option) is not None:
            parts += [f"--{option}", str(getattr(args, option))]
    for run in args.run:
        parts += ["--run", run]
    return shlex.join(parts)


def run_time_to_target(args) -> int:
    import re

    from ..benchmarks.time_to_target import (DEFAULT_TOLERANCE, TargetGroup, check_rule,
                                             final_return, plot_time_to_target, read_curve,
                                             section)
    from .outputs import check_path
    check_path(args.out, "--out")  # before any file is read
    if not args.run:
        raise ValueError("--run: give at least one LABEL=FOLDER")
    runs = [_run_option(text) for text in args.run]
    if (args.target is None) == (args.target_return is None):
        raise ValueError("give one of --target AGENT and --target-return R")
    tolerance = DEFAULT_TOLERANCE if args.tolerance is None else args.tolerance
    check_rule(args.target_return, tolerance, "--target-return", "--tolerance")  # before reading
    docs = Path(args.docs) if args.docs else None
    if docs is not None and not docs.is_file():
        raise ValueError(f"--docs {docs}: no such page")
    curves = [read_curve(folder, label) for label, folder in runs]
    if args.target is not None:
        from ..rl.agent import resolve_agent_path
        folder = resolve_agent_path(args.target)
        target, source = final_return(folder), f"the final evaluation of `{folder.name}`"
        title = args.title or folder.name
    else:
        target, source = float(args.target_return), "given"
        title = args.title or "time to target"
    out = output_folder(args.out, "--out")
    slug = re.sub(r"[^A-Za-z0-9_.-]+", "_", title)
    png = plot_time_to_target([TargetGroup(title, curves, target, tolerance)],
                              out / f"time_to_target_{slug}.png")
    text = section(title, curves, target, source, tolerance, png.name, _command(args))
    write_text(out / f"time_to_target_{slug}.md", text)
    print(text)
    print(f"wrote {out / f'time_to_target_{slug}.md'} and {png}")
    if docs is not None:
        import shutil

        from ..evaluation.results_pages import replace_between_markers
        shutil.copyfile(png, docs.parent / png.name)
        replace_between_markers(docs, text.strip(), (f"<!-- time-to-target:{title}:begin -->",
                                                     f"<!-- time-to-target:{title}:end -->"))
        print(f"wrote the {title} section of {docs} and {docs.parent / png.name}")
    return 0
