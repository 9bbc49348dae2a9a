"""Time to train: the wall time a training run takes to reach a target held-out return.

A run folder of ``abb-gym train`` (or a shipped agent's folder) holds ``evaluations.csv``: one
row per held-out evaluation during training, with the environment steps, the wall time since
``learn()`` started and the mean return on the fixed, seeded test set with its 95 % interval.
Runs written since the column exists also hold ``eval_time_s``, the seconds those evaluations
took so far; the *training time* of a row is ``wall_time_s - eval_time_s``, so that how often a
run was measured does not count as training.  For older files the training time is the wall
time (evaluations included), which overstates it, and the table says so.

The target is a return on the same test set (by default the reference agent's final return,
its ``evaluation.json``).  A run *reaches* it at its first evaluation whose mean return is at
least ``target - tolerance * |target|``.  The default tolerance, 2 %, is the spread of a
converged run's evaluations on that set: the last nine evaluations of the shipped
``runup_speed_yoshida_odd`` run, whose return no longer rises, lie within 1.7 % of each other.
A smaller tolerance would time the noise of one evaluation rather than the learning.

Wall times are only comparable between runs that shared the machine's load: train the runs
you compare side by side (one core each on a 2-core machine) or one after the other on a quiet
machine, and say which.
"""
from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["DEFAULT_TOLERANCE", "TrainingCurve", "TargetGroup", "read_curve", "final_return",
           "check_rule", "first_reaching", "time_to_target_rows", "config_rows", "section",
           "plot_time_to_target"]

#: relative tolerance of "reached the target" (see the module docstring for why 2 %)
DEFAULT_TOLERANCE = 0.02

_NEEDED = ("timesteps", "wall_time_s", "return", "return_ci_low", "return_ci_high")


@dataclass(frozen=True)
class TrainingCurve:
    """The held-out evaluations of one training run, in the order they were made.

    ``wall_s`` [s] counts from the start of ``learn()``, evaluations included; ``eval_s`` [s]
    is the time spent in evaluations so far (None if the file predates the column)."""
    label: str
    folder: Path
    timesteps: np.ndarray
    wall_s: np.ndarray
    eval_s: np.ndarray | None
    ret: np.ndarray
    ret_low: np.ndarray
    ret_high: np.ndarray

    @property
    def train_s(self) -> np.ndarray:
        """Training time [s] at each evaluation: wall time less the evaluations' time."""
        return self.wall_s if self.eval_s is None else self.wall_s - self.eval_s


def read_curve(folder: str | Path, label: str | None = None) -> TrainingCurve:
    """The curve in ``folder/evaluations.csv``; ValueError naming the file and what it lacks
    (no file, a missing column, no rows, a value that is not a finite number)."""
    folder = Path(folder)
    path = folder / "evaluations.csv"
    if not path.is_file():
        raise ValueError(f"{path}: no such file (a run folder of abb-gym train or a trained "
                         "agent's folder holds one)")
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise ValueError(f"{path}: no evaluations (the run ended before its first)")
    missing = [k for k in _NEEDED if k not in rows[0]]
    if missing:
        raise ValueError(f"{path}: lacks the column(s) {missing}")
    cols = list(_NEEDED) + (["eval_time_s"] if "eval_time_s" in rows[0] else [])
    data = {}
    for k in cols:
        try:
            data[k] = np.array([float(r[k]) for r in rows])
        except (TypeError, ValueError):
            raise ValueError(f"{path}: column {k!r} holds a value that is not a number") from None
    for k in ("timesteps", "wall_time_s", "return") + (("eval_time_s",) if "eval_time_s" in data
                                                         else ()):
        if not np.all(np.isfinite(data[k])):
            raise ValueError(f"{path}: column {k!r} holds a value that is not finite")
    return TrainingCurve(label or folder.name, folder, data["timesteps"], data["wall_time_s"],
                         data.get("eval_time_s"), data["return"], data["return_ci_low"],
                         data["return_ci_high"])


def final_return(folder: str | Path) -> float:
    """The final held-out mean return of a run or agent folder: its ``evaluation.json``
    (the final model on the test set), else the last row of its ``evaluations.csv``."""
    folder = Path(folder)
    path = folder / "evaluation.json"
    if path.is_file():
        value = float(json.loads(path.read_text())["summary"]["return"]["mean"])
    else:
        value = float(read_curve(folder).ret[-1])
    if not math.isfinite(value):
        raise ValueError(f"{folder}: its final return is not finite ({value})")
    return value


def check_rule(target: float | None, tolerance: float, target_name: str = "target",
               tolerance_name: str = "tolerance") -> None:
    """ValueError, naming the field, unless ``target`` is a finite return (None: not known
    yet, not checked) and ``tolerance`` a fraction in [0, 1); callers that read the values
    from options pass the options' names."""
    if target is not None and not math.isfinite(target):
        raise ValueError(f"{target_name} must be a finite return (got {target})")
    if not (0.0 <= tolerance < 1.0):
        raise ValueError(f"{tolerance_name} must be in [0, 1) (a fraction of |target|; got "
                         f"{tolerance})")


def first_reaching(curve: TrainingCurve, target: float,
                   tolerance: float = DEFAULT_TOLERANCE) -> int | None:
    """Index of the first evaluation whose mean return is at least
    ``target - tolerance * |target|``; None if none is."""
    check_rule(target, tolerance)
    hits = np.flatnonzero(curve.ret >= target - tolerance * abs(target))
    return int(hits[0]) if hits.size else None


def time_to_target_rows(curves: list[TrainingCurve], target: float,
                        tolerance: float = DEFAULT_TOLERANCE) -> list[dict]:
    """One table row per run: when it reached the target (environment steps, training time
    and wall time), its final return and its whole training time."""
    rows = []
    for c in curves:
        k = first_reaching(c, target, tolerance)
        rows.append({
            "run": f"{c.label} ({c.folder.name})",
            "env steps to target": "not reached" if k is None else f"{c.timesteps[k]:,.0f}",
            "training time to target [s]": "" if k is None else f"{c.train_s[k]:.0f}",
            "wall time to target, evaluations included [s]":
                "" if k is None else f"{c.wall_s[k]:.0f}",
            "final return [95 % CI]": f"{c.ret[-1]:.3f} [{c.ret_low[-1]:.3f}, "
                                      f"{c.ret_high[-1]:.3f}]",
            "whole run: training time [s]": f"{c.train_s[-1]:.0f}" + (
                "" if c.eval_s is not None else " (with evaluations)"),
        })
    return rows


def config_rows(curves: list[TrainingCurve], target: float,
                tolerance: float = DEFAULT_TOLERANCE) -> list[dict]:
    """One row per label (the runs of one config, one per seed): how many reached the target,
    the median and range of their training times to it [s], and the median as a share of the
    first label's (the reference).  A run that never reached it
    counts as its whole training time in the median (it took at least that long), and the row
    says how many did not."""
    by_label: dict[str, list[TrainingCurve]] = {}
    for c in curves:
        by_label.setdefault(c.label, []).append(c)
    rows, first_median = [], None
    for label, runs in by_label.items():
        times, reached = [], 0
        for c in runs:
            k = first_reaching(c, target, tolerance)
            reached += k is not None
            times.append(float(c.train_s[k] if k is not None else c.train_s[-1]))
        censored = len(runs) - reached
        median = float(np.median(times))
        first_median = median if first_median is None else first_median
        rows.append({
            "config": label, "runs": len(runs), "reached": f"{reached} of {len(runs)}",
            "median training time to target [s]": f"{median:.0f}"
                                                  + (" (at least)" if censored * 2 >= len(runs)
                                                     else ""),
            "range [s]": f"{min(times):.0f}-{max(times):.0f}",
            "share of the first config's median": f"{median / first_median:.2f}"
                                                  if first_median > 0 else "",
            "median final return": f"{np.median([c.ret[-1] for c in runs]):.3f}",
        })
    return rows


def section(title: str, curves: list[TrainingCurve], target: float, target_source: str,
            tolerance: float, chart: str, command: str = "") -> str:
    """The Markdown of one comparison: the command that made it (if given), the target and
    rule, the per-config summary, every run's row, and the chart (``chart``: its link)."""
    from ..tables import markdown_table
    made = f"Generated by `{command}`.\n\n" if command else ""
    return (f"### {title}\n\n{made}Target: held-out return {target:.3f} ({target_source}); a run "
            f"reaches it at its first evaluation at or above {target - tolerance * abs(target):.3f}"
            f" ({100 * tolerance:g} % below).  Training time leaves out the evaluations; a run that"
            " never reached the target counts in its config's median and range with its whole"
            " training time, a lower bound.\n\n"
            + markdown_table(config_rows(curves, target, tolerance)) + "\n\n"
            + markdown_table(time_to_target_rows(curves, target, tolerance))
            + f"\n\n![held-out return against training time, {title}]({chart})\n")


@dataclass(frozen=True)
class TargetGroup:
    """Runs compared against one target: a panel of the chart and a table of the page."""
    title: str
    curves: list[TrainingCurve]
    target: float
    tolerance: float = DEFAULT_TOLERANCE


def plot_time_to_target(groups: list[TargetGroup], path: str | Path) -> Path:
    """One panel per group: each run's held-out return (mean, 95 % band) against its training
    time [min], the target as a line with the tolerance band below it, and a dot where each run
    first reaches it; written as PNG."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .._files import savefig
    if not groups:
        raise ValueError("no runs to plot")
    fig, axes = plt.subplots(1, len(groups), squeeze=False, figsize=(4.6 * len(groups), 3.4),
                             constrained_layout=True)
    for ax, g in zip(axes[0], groups):
        floor = g.target - g.tolerance * abs(g.target)
        ax.axhspan(floor, g.target, color="0.85", lw=0)
        ax.axhline(g.target, color="0.3", lw=0.9, ls="--",
                   label=f"target {g.target:.2f} (tolerance {100 * g.tolerance:g} %)")
        colour: dict[str, str] = {}
        for c in g.curves:  # the runs of one config (its seeds) share a colour and a label
            first = c.label not in colour
            colour.setdefault(c.label, f"C{len(colour)}")
            minutes = c.train_s / 60.0
            ax.plot(minutes, c.ret, "o-", ms=3, lw=1.0, color=colour[c.label],
                    label=c.label if first else None)
            ax.fill_between(minutes, c.ret_low, c.ret_high, color=colour[c.label], alpha=0.12,
                            lw=0)
            k = first_reaching(c, g.target, g.tolerance)
            if k is not None:
                ax.plot(minutes[k], c.ret[k], "o", ms=9, mfc="none", mec=colour[c.label],
                        mew=1.6)
        ax.set_title(g.title, fontsize=9)
        ax.set_xlabel("training time [min] (evaluations excluded)", fontsize=8)
        ax.set_ylabel("held-out return (own reward) [-]", fontsize=8)
        ax.set_xlim(left=0)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=7, loc="lower right")
    fig.suptitle("Time to target: held-out return against training time\n"
                 "(circle: a run's first evaluation at the target)", fontsize=9)
    path = savefig(fig, Path(path), dpi=100)
    plt.close(fig)
    return path
