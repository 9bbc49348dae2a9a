"""``abb-gym bench``: ``accuracy`` draws the work-precision chart of every integrator (PNG +
Markdown table + CSV) and the energy drift of long undamped runs; ``speed`` measures
throughput."""
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
