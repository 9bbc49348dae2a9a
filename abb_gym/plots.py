"""Figures for people who would rather look than read (matplotlib, written as PNG)."""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .physics.trajectory import Trajectory  # noqa: E402

__all__ = ["plot_runup", "plot_runup_comparison", "short_label"]


def _draw_runup(axes, tr: Trajectory, label: str | None, colour, critical: bool) -> None:
    ax_speed, ax_balls = axes
    ax_whirl = ax_speed._abb_twin  # created once per figure
    ax_speed.plot(tr.t, tr.rotor_speed, color=colour, ls="--", lw=1.0)
    ax_whirl.plot(tr.t, tr.whirl_ratio, color=colour, lw=1.2, label=label)
    for i in range(tr.n_balls):
        ax_balls.plot(tr.t, np.degrees(tr.ball_angles[:, i]), color=colour, lw=1.2,
                      ls=("-", ":", "-.", (0, (5, 1)), (0, (3, 1, 1, 1)))[i % 5],
                      label=f"{label + ': ' if label else ''}ball {i + 1}")
    if critical:
        for ax in (ax_speed, ax_balls):
            crossing = np.nonzero(tr.rotor_speed >= tr.scene.critical_speed)[0]
            if crossing.size:
                ax.axvline(tr.t[crossing[0]], color="0.6", lw=0.8, ls=":")


def _figure(title: str, wide: bool = False):
    fig, (ax_speed, ax_balls) = plt.subplots(2, 1, figsize=(11 if wide else 8, 7), sharex=True,
                                             constrained_layout=True)
    ax_speed._abb_twin = ax_speed.twinx()
    ax_speed.set_ylabel("rotor speed dpsi/dt [rad/s] (dashed)")
    ax_speed._abb_twin.set_ylabel("normalised whirl W_r / e [-] (solid)")
    ax_speed.set_title("(a) rotation speed and whirl radius")
    ax_balls.set_title("(b) ball angles relative to the rotor, from the imbalance")
    ax_balls.set_ylabel("ball angle theta_b [deg]")
    ax_balls.set_xlabel("time t [s]")
    ax_balls.axhline(-180.0, color="k", lw=0.6)
    ax_balls.axhline(-540.0, color="k", lw=0.3)
    fig.suptitle(title)
    return fig, (ax_speed, ax_balls)


def plot_runup(tr: Trajectory, path: str | Path, title: str | None = None) -> Path:
    """Thesis-style time histories of one run (Yoshida Figs. 4.x (a) and (c)) to a PNG."""
    return plot_runup_comparison({"": tr}, path, title)


def short_label(name: str, limit: int = 24) -> str:
    """A legend label of at most ``limit`` characters (the full name goes in the caption)."""
    return name if len(name) <= limit else name[:limit - 3] + "..."


def plot_runup_comparison(runs: Mapping[str, Trajectory], path: str | Path,
                          title: str | None = None) -> Path:
    """Several runs of one scene on the same axes (e.g. policy versus baseline) to a PNG.

    With several runs the legends sit beside the axes (never over the traces); labels longer
    than 24 characters are shortened there, numbered, and given whole in a caption."""
    runs = dict(runs)
    first = next(iter(runs.values()))
    several = len(runs) > 1 or any(runs)
    fig, axes = _figure(title or f"{first.scene.name}: run-up", wide=several)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    caption = []
    for k, (label, tr) in enumerate(runs.items()):
        short = short_label(label) if label else label
        if short != label:
            short = f"[{k + 1}] {short}"
            caption.append(f"[{k + 1}] {label}")
        _draw_runup(axes, tr, short or None, colours[k % len(colours)], critical=(k == 0))
    if several:
        axes[0]._abb_twin.legend(loc="upper left", bbox_to_anchor=(1.08, 1.0), fontsize=8,
                                 borderaxespad=0.0)
        axes[1].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7,
                       borderaxespad=0.0)
    else:
        axes[1].legend(loc="lower left", fontsize=7, ncol=2)
    if caption:  # supxlabel: constrained layout keeps room for it below the axes
        fig.supxlabel("; ".join(caption), fontsize=7)
    lo = min(np.degrees(tr.ball_angles).min() for tr in runs.values())
    hi = max(np.degrees(tr.ball_angles).max() for tr in runs.values())
    axes[1].set_ylim(min(-200.0, lo - 20), max(30.0, hi + 20))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


TRAINING_CURVE_METRICS = (("return", "held-out return (own reward) [-]"),
                          ("residual_vibration", "residual vibration W_r/e [-]"))


def plot_training_curves(curves: Mapping[str, Mapping[str, np.ndarray]], path: str | Path
                         ) -> Path:
    """Learning curves of trained agents to a PNG: one row per agent, one column per metric
    of :data:`TRAINING_CURVE_METRICS`, mean and 95 % band of the held-out evaluations during
    training against environment steps (the columns of a run's ``evaluations.csv``:
    ``timesteps``, ``<metric>``, ``<metric>_ci_low``, ``<metric>_ci_high``).  Each agent
    keeps its own axes: their rewards weigh the terms differently."""
    if not curves:
        raise ValueError("no training curves to plot")
    need = ["timesteps"] + [f"{m}{s}" for m, _ in TRAINING_CURVE_METRICS
                            for s in ("", "_ci_low", "_ci_high")]
    for name, c in curves.items():
        missing = [k for k in need if k not in c]
        if missing:
            raise ValueError(f"training curve {name!r} lacks the column(s) {missing}")
    fig, axes = plt.subplots(len(curves), len(TRAINING_CURVE_METRICS), squeeze=False,
                             figsize=(10, 2.2 * len(curves) + 0.8), constrained_layout=True)
    for row, (name, c) in enumerate(curves.items()):
        steps = np.asarray(c["timesteps"], float) / 1e6
        for col, (metric, label) in enumerate(TRAINING_CURVE_METRICS):
            ax = axes[row, col]
            ax.plot(steps, c[metric], "o-", ms=3, color=f"C{col}")
            ax.fill_between(steps, c[f"{metric}_ci_low"], c[f"{metric}_ci_high"], alpha=0.25,
                            color=f"C{col}")
            ax.set_title(f"{name}: {metric}", fontsize=8)
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=7)
            if row == len(curves) - 1:
                ax.set_xlabel("environment steps [millions]", fontsize=8)
            if row == 0:
                ax.annotate(label, (0.5, 1.25), xycoords="axes fraction", ha="center",
                            fontsize=9)
    fig.suptitle("Training: held-out evaluations during training (mean, 95 % band)",
                 fontsize=10)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
