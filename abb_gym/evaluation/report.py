"""Evaluation outputs: a Markdown table, CSV and JSON files, and charts.

* ``summary.md`` - one row per policy: mean [95 % CI] of each metric.
* ``episodes.csv`` - one row per policy and episode; ``evaluation.json`` - both.
* ``timeseries.png`` - thesis-style time histories of every policy on the same scenario
  (episode 0 of the test set).
* ``pareto.png`` - the speed-versus-accuracy chart of control: run-up time against residual
  vibration, one point cloud per policy family (baselines swept over their parameters,
  evaluated policies as their means with confidence bars), with the Pareto front marked.
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from ..tables import markdown_table
from .evaluate import METRICS, UNITS, EvaluationResult


def _cell(stat: dict) -> str:
    if not np.isfinite(stat["mean"]):
        return "n/a"
    if not np.isfinite(stat["ci_low"]):
        return f"{stat['mean']:.4g}"
    return f"{stat['mean']:.4g} [{stat['ci_low']:.3g}, {stat['ci_high']:.3g}]"


def summary_table(results: Sequence[EvaluationResult]) -> str:
    rows = []
    for r in results:
        s = r.summary()
        row = {"policy": r.policy, "episodes": s["episodes"]}
        row.update({f"{k} [{UNITS[k]}]": _cell(s[k]) for k in METRICS})
        rows.append(row)
    return markdown_table(rows)


def write_report(results: Sequence[EvaluationResult], out: str | Path,
                 sweep: list[dict] | None = None) -> dict[str, Path]:
    """Write the files of the module docstring; returns their paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"summary": out / "summary.md", "episodes": out / "episodes.csv",
             "json": out / "evaluation.json"}
    first = results[0]
    head = (f"Evaluation on {first.env_id}, scene {first.scene}, preset {first.preset}, "
            f"seed {first.seed}: {len(first.episodes)} episodes per policy, mean [95 % CI].\n\n")
    paths["summary"].write_text(head + summary_table(results) + "\n")
    rows = [e for r in results for e in r.episodes]
    with open(paths["episodes"], "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    payload = {"env_id": first.env_id, "scene": first.scene, "preset": first.preset,
               "seed": first.seed,
               "policies": [{"policy": r.policy, "params": r.params, "summary": r.summary(),
                             "episodes": r.episodes} for r in results],
               "sweep": sweep or []}
    paths["json"].write_text(json.dumps(payload, indent=1, default=_json_default))
    recorded = [(r.policy, r.rollouts[min(r.rollouts)]) for r in results if r.rollouts]
    if recorded:
        from ..plots import plot_runup_comparison
        paths["timeseries"] = plot_runup_comparison(
            dict(recorded), out / "timeseries.png",
            f"{first.scene}: policies on test episode {min(results[0].rollouts)}")
    paths["pareto"] = plot_pareto(results, sweep or [], out / "pareto.png")
    return paths


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.bool_):
        return bool(o)
    raise TypeError(type(o))


def pareto_front(points: np.ndarray) -> np.ndarray:
    """Indices of the points not dominated in (x, y), both to be minimised, sorted by x."""
    finite = np.nonzero(np.all(np.isfinite(points), axis=1))[0]
    order = finite[np.lexsort((points[finite, 1], points[finite, 0]))]
    front, best = [], math.inf
    for i in order:
        if points[i, 1] < best:
            front.append(i)
            best = points[i, 1]
    return np.array(front, dtype=int)


def plot_pareto(results: Sequence[EvaluationResult], sweep: list[dict], path) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 5.5), constrained_layout=True)
    pts, labels = [], []
    families = sorted({s["family"] for s in sweep})
    cmap = plt.get_cmap("tab10")
    for k, fam in enumerate(families):
        fs = [s for s in sweep if s["family"] == fam]
        x = [s["time_to_speed"] for s in fs]
        y = [s["residual_vibration"] for s in fs]
        ax.scatter(x, y, s=18, alpha=0.55, color=cmap(k % 10), label=f"{fam} (swept)")
        pts += list(zip(x, y))
        labels += [fam] * len(fs)
    for j, r in enumerate(results):
        s = r.summary()
        x, y = s["time_to_speed"], s["residual_vibration"]
        ax.errorbar(x["mean"], y["mean"],
                    xerr=[[x["mean"] - x["ci_low"]], [x["ci_high"] - x["mean"]]]
                    if np.isfinite(x["ci_low"]) else None,
                    yerr=[[y["mean"] - y["ci_low"]], [y["ci_high"] - y["mean"]]]
                    if np.isfinite(y["ci_low"]) else None,
                    fmt="D", ms=8, color=cmap((len(families) + j) % 10), mec="k",
                    label=f"{r.policy} (mean, 95 % CI)")
        pts.append((x["mean"], y["mean"]))
        labels.append(r.policy)
    if pts:
        arr = np.array(pts, float)
        front = pareto_front(arr)
        if front.size:
            ax.plot(arr[front, 0], arr[front, 1], "k--", lw=1, label="Pareto front")
    ax.set_xlabel("time to operating speed [s]")
    ax.set_ylabel("residual vibration at operating speed, mean W_r / e [-]")
    title = f"Run-up time against residual vibration ({results[0].scene})" if results \
        else "Run-up time against residual vibration"
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
