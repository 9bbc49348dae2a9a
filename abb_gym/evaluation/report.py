"""Evaluation outputs: Markdown tables, CSV and JSON files, and charts.

* ``summary.md`` - one row per policy: mean [95 % CI] of the headline metrics (the share of
  episodes that completed the run-up first: a residual is measured only on those); then, for
  every policy evaluated together with its ``replay:`` (:mod:`abb_gym.evaluation.replay`),
  its **feedback value**: the paired difference replay minus policy, with 95 % intervals.
* ``episodes.csv`` - one row per policy and episode; ``evaluation.json`` - all of it (every
  metric of :data:`abb_gym.evaluation.evaluate.METRICS` for every policy, its parameters, the
  feedback values and the sweep).
* ``timeseries.png`` - thesis-style time histories of every policy on the same machine
  (episode 0 of the test set); the legend sits beside the axes, long policy names are
  shortened there and given whole in the caption.
* ``pareto.png`` - the speed-versus-accuracy chart of control: settled run-up time against
  residual vibration (``balance.png``: the same for balancing, time to balance against the
  residual after a hold at speed, :mod:`abb_gym.evaluation.metrics`); a family keeps one colour whether swept (small points) or evaluated
  (large markers with 95 % intervals); policies that did not complete every run-up are drawn
  hollow with their success share, and swept points that failed are left out of the Pareto
  front; points that carry a ``label`` of their own (``agents/evaluate.py``'s oracle at other
  residual weights and the goal's room) are drawn as stars under that label; the legend sits
  outside the data.
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from .._files import replacing_together, savefig
from ..tables import markdown_table
from .evaluate import METRICS, UNITS, EvaluationResult
from .replay import feedback_value, paired_by_episode

HEADLINE = ("at_speed", "run_up_time", "residual_vibration", "time_to_balance",
            "residual_after_hold", "peak_whirl", "first_at_speed", "peak_speed",
            "time_above_band", "balanced", "return")


def unit(key: str, results: Sequence[EvaluationResult]) -> str:
    """The unit of metric ``key`` in ``results``: the task's length unit for lengths."""
    u = UNITS[key]
    return results[0].length_unit if u == "W_r/e" and results else u


def cell(stat: dict, digits: int = 4, ci_digits: int = 3) -> str:
    """``mean [low, high]`` of a :func:`~abb_gym.evaluation.statistics.mean_interval` dict
    (``n/a`` without a finite mean; the mean alone without an interval)."""
    if not np.isfinite(stat["mean"]):
        return "n/a"
    if stat.get("ci_low") is None or not np.isfinite(stat["ci_low"]):
        return f"{stat['mean']:.{digits}g}"
    return (f"{stat['mean']:.{digits}g} [{stat['ci_low']:.{ci_digits}g}, "
            f"{stat['ci_high']:.{ci_digits}g}]")


def summary_table(results: Sequence[EvaluationResult], keys: Sequence[str] = HEADLINE) -> str:
    rows = []
    mixed = len({r.env_id for r in results}) > 1
    for r in results:
        s = r.summary()
        row = {"policy": r.policy, "episodes": s["episodes"]}
        if mixed:  # DwellProfile next to baselines it cannot express (evaluate.policy_env_id)
            row["env"] = r.env_id.split("/")[-1]
        row.update({f"{k} [{unit(k, results)}]": cell(s[k]) for k in keys})
        rows.append(row)
    return markdown_table(rows)


def reward_line(result: EvaluationResult) -> str:
    """The reward weights the returns of ``result`` were computed with, in one line."""
    weights = ", ".join(f"{k} {v:g}" + (" m" if k == "length_scale" else "")
                        for k, v in result.reward_weights.items() if v is not None)
    source = f" ({result.reward_source})" if result.reward_source else ""
    return f"Reward weights{source}: {weights}."


def base_name(policy: str) -> str:
    """A policy's name without the tuned/default tag."""
    return policy.split(" (")[0]


def feedback_values(results: Sequence[EvaluationResult]) -> dict[str, dict]:
    """Feedback value of every policy whose ``replay:`` was evaluated with it."""
    by_name = {base_name(r.policy): r for r in results}
    out = {}
    for r in results:
        name = base_name(r.policy)
        replay = by_name.get(f"replay:{name}")
        if replay is not None and not name.startswith("replay:"):
            out[name] = feedback_value(r.episodes, replay.episodes)
    return out


def feedback_table(values: dict[str, dict], length_unit: str = "W_r/e") -> str:
    rows = [{"policy": name,
             f"residual: replay - policy [{length_unit}]": cell(v["residual_vibration"]),
             "run-up time: replay - policy [s]": cell(v["run_up_time"]),
             "return: replay - policy": cell(v["return"])} for name, v in values.items()]
    return markdown_table(rows)


GAP_METRICS = ("at_speed", "run_up_time", "residual_vibration", "return")


def paired_gap(a: EvaluationResult, b: EvaluationResult, key: str) -> dict:
    """Paired difference ``a - b`` of metric ``key`` over the episodes both ran (matched by
    episode index: the same machines), with its 95 % interval."""
    if not {e["episode"] for e in a.episodes} & {e["episode"] for e in b.episodes}:
        raise ValueError(f"{a.policy!r} and {b.policy!r} share no episode")
    return paired_by_episode(a.episodes, b.episodes, key)


def family_table(columns: dict[str, EvaluationResult], keys: Sequence[str] = GAP_METRICS
                 ) -> str:
    """The feedback-gap table: one column per family (e.g. best open loop, closed-loop hand
    design, PPO, oracle), one row per metric, mean [95 % CI]; the first row names the policy
    of each column."""
    rows = [{"": "policy", **{label: base_name(r.policy) for label, r in columns.items()}}]
    for key in keys:
        row = {"": f"{key} [{unit(key, list(columns.values()))}]"}
        row.update({label: cell(r.summary()[key]) for label, r in columns.items()})
        rows.append(row)
    return markdown_table(rows)


def residual_floor(result: EvaluationResult) -> dict | None:
    """The task's open-loop floor on ``result``'s episodes (:attr:`abb_gym.envs.tasks.Task.
    residual_floor`), mean and 95 % interval in the task's unit, with its definition; None
    when the task has none."""
    from ..envs import tasks
    from .statistics import mean_interval

    path = tasks.get(result.env_id).residual_floor
    if path is None or not result.episodes:
        return None
    fn = tasks.load_named(path)
    values = fn(result.env_id, result.scene, result.preset,
                [e["seed"] for e in result.episodes])
    return {**mean_interval(values, nonnegative=True),
            "definition": getattr(fn, "definition", ""),
            "per_episode": [float(v) for v in values]}


def write_report(results: Sequence[EvaluationResult], out: str | Path,
                 sweep: list[dict] | None = None) -> dict[str, Path]:
    """Write the files of the module docstring; returns their paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"summary": out / "summary.md", "episodes": out / "episodes.csv",
             "json": out / "evaluation.json"}
    first = results[0]
    head = (f"Evaluation on {first.env_id}, scene {first.scene}, preset {first.preset}, "
            f"seed {first.seed}: {len(first.episodes)} episodes per policy, mean [95 % CI].  "
            f"at_speed: share of episodes that completed the run-up (an unbroken settling "
            f"window in the operating band); residual_vibration over those.\n\n")
    if first.reward_weights:
        head += reward_line(first) + "\n\n"
    if first.env_kwargs:
        head += ("Environment keywords: " + ", ".join(f"{k}={v}" for k, v in
                                                   sorted(first.env_kwargs.items())) + ".\n\n")
    if len({r.env_id for r in results}) > 1:
        head += ("Column env: the baselines that DwellProfile's one action cannot express "
                 "ran on RunUpSpeed, on the same machines (same preset and seeds).\n\n")
    text = head + summary_table(results) + "\n"
    floor = residual_floor(first)
    if floor is not None:
        text += (f"\nOpen-loop floor: {cell(floor)} {first.length_unit} (mean [95 % CI] over "
                 f"these episodes; the least residual a drive that never reacts can leave: "
                 f"{floor['definition']}).\n")
    feedback = feedback_values(results)
    if feedback:
        text += ("\nFeedback value (paired over the same episodes; positive residual and "
                 "run-up time differences, and negative return differences, mean the policy "
                 "beats its own open-loop replay):\n\n" + feedback_table(feedback, first.length_unit) + "\n")
    rows = [e for r in results for e in r.episodes]
    payload = {"env_id": first.env_id, "scene": first.scene, "preset": first.preset,
               "seed": first.seed, "reward_weights": first.reward_weights,
               "reward_source": first.reward_source, "env_kwargs": first.env_kwargs,
               "metrics": {k: unit(k, results) for k in METRICS},
               "policies": [{"policy": r.policy, "env_id": r.env_id, "params": r.params, "summary": r.summary(),
                             "episodes": r.episodes} for r in results],
               "feedback_value": feedback, "open_loop_floor": floor, "sweep": sweep or []}
    recorded = [(r.policy, r.rollouts[min(r.rollouts)]) for r in results if r.rollouts]
    # every file beside its target first, then all renamed: a failure half-way leaves the
    # previous report as it was
    with replacing_together() as files:
        files.path(paths["summary"]).write_text(text)
        with open(files.path(paths["episodes"]), "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        files.path(paths["json"]).write_text(json.dumps(payload, indent=1,
                                                        default=_json_default))
        if recorded:
            from ..plots import plot_runup_comparison
            paths["timeseries"] = out / "timeseries.png"
            plot_runup_comparison(
                dict(recorded), files.path(paths["timeseries"]),
                f"{first.scene}: policies on test episode {min(results[0].rollouts)}")
        paths["pareto"] = out / "pareto.png"
        plot_pareto(results, sweep or [], files.path(paths["pareto"]))
        paths["balance"] = out / "balance.png"
        plot_pareto(results, [], files.path(paths["balance"]), BALANCE_AXES)
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


def family_of(policy: str) -> str:
    """The colour key of a policy: its baseline family, or its own name (``replay:X`` is X's
    family, drawn apart by its marker)."""
    name = base_name(policy)
    if name.startswith("replay:"):
        name = name[len("replay:"):]
    return name.split(":", 1)[1] if name.startswith("baseline:") else name


#: the axes of the speed-versus-accuracy charts: (x metric, its label, y metric, its label
#: with ``{unit}``, the title)
RUN_UP_AXES = ("run_up_time", "settled run-up time: entry into the operating band for good [s]",
               "residual_vibration", "residual vibration over the settling window [{unit}]",
               "Run-up time against residual vibration")
BALANCE_AXES = ("time_to_balance", "time to balance: the vibration within the balance "
                "tolerance for good, through a 15 s hold at speed [s]",
                "residual_after_hold", "residual vibration after a 15 s hold at speed [{unit}]",
                "Time to balance against residual after a hold")


def plot_pareto(results: Sequence[EvaluationResult], sweep: list[dict], path,
                axes: tuple = RUN_UP_AXES) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    xkey, xlabel, ykey, ylabel, name = axes
    fig, ax = plt.subplots(figsize=(10, 5.5), constrained_layout=True)
    cmap = plt.get_cmap("tab10")
    keys = list(dict.fromkeys([s["family"] for s in sweep] +
                              [family_of(r.policy) for r in results]))
    colour = {k: cmap(i % 10) for i, k in enumerate(keys)}
    pts = []
    for fam in dict.fromkeys(s["family"] for s in sweep):
        fs = [s for s in sweep if s["family"] == fam]
        ok = [s for s in fs if s.get("at_speed", 1.0) >= 1.0]
        bad = [s for s in fs if s.get("at_speed", 1.0) < 1.0]
        named = "label" in fs[0]  # points of their own (the goal's room), not a sweep
        ax.scatter([s[xkey] for s in ok], [s[ykey] for s in ok],
                   s=90 if named else 16, marker="*" if named else "o",
                   alpha=1.0 if named else 0.5, color=colour[fam],
                   edgecolors="k" if named else "none",
                   label=fs[0]["label"] if named else f"{fam}: swept")
        if bad:
            ax.scatter([s[xkey] for s in bad], [s[ykey] for s in bad],
                       s=16, alpha=0.5, facecolors="none", edgecolors=colour[fam])
        pts += [(s[xkey], s[ykey]) for s in ok]
    failed_any = False
    never = []
    for r in results:
        s = r.summary()
        x, y, share = s[xkey], s[ykey], s["at_speed"]["mean"]
        fam = family_of(r.policy)
        replay = base_name(r.policy).startswith("replay:")
        complete = share >= 1.0
        failed_any |= not complete
        label = _short(base_name(r.policy)) + ("" if complete else f" (at speed {share:.0%})")
        if not np.isfinite(y["mean"]):  # no run-up completed: drawn in the failure strip
            never.append((x["mean"], colour[fam], label))
            continue
        ax.errorbar(x["mean"], y["mean"],
                    xerr=[[x["mean"] - x["ci_low"]], [x["ci_high"] - x["mean"]]]
                    if np.isfinite(x["ci_low"]) else None,
                    yerr=[[y["mean"] - y["ci_low"]], [y["ci_high"] - y["mean"]]]
                    if np.isfinite(y["ci_low"]) else None,
                    fmt="s" if replay else "D", ms=8, color=colour[fam], mec="k",
                    mfc=colour[fam] if complete else "none", label=label)
        if complete:
            pts.append((x["mean"], y["mean"]))
    if pts:
        arr = np.array(pts, float)
        front = pareto_front(arr)
        if front.size:
            ax.plot(arr[front, 0], arr[front, 1], "k--", lw=1, label="Pareto front (complete)")
    if never:
        lo, hi = ax.get_ylim()
        strip = hi + 0.08 * (hi - lo)
        ax.axhline(strip, color="0.5", lw=0.6, ls=":")
        ax.text(ax.get_xlim()[0], strip, "  no run-up completed", fontsize=7, va="bottom",
                color="0.3")
        for x, c, label in never:
            ax.plot(x, strip, "X", ms=9, color=c, mec="k", label=label)
        ax.set_ylim(lo, strip + 0.06 * (hi - lo))
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel.format(unit=unit(ykey, results)))
    title = f"{name} ({results[0].scene})" if results else name
    if failed_any or any(s.get("at_speed", 1.0) < 1.0 for s in sweep):
        title += "\nhollow: some run-ups never completed (residual over the completed ones)"
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    path = savefig(fig, path, dpi=110)
    plt.close(fig)
    return path


def _short(name: str, limit: int = 40) -> str:
    return name if len(name) <= limit else name[:limit - 3] + "..."
