"""Figures for people who would rather look than read (matplotlib, written as PNG)."""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from ._files import savefig  # noqa: E402
from .physics.trajectory import Trajectory  # noqa: E402

__all__ = ["plot_runup", "plot_runup_comparison", "short_label"]


def _draw_runup(axes, tr: Trajectory, label: str | None, colour) -> None:
    ax_speed, ax_balls = axes
    ax_whirl = ax_speed._abb_twin  # created once per figure
    ax_speed.plot(tr.t, tr.rotor_speed, color=colour, ls="--", lw=1.0)
    ax_whirl.plot(tr.t, tr.whirl_ratio, color=colour, lw=1.2, label=label)
    for i in range(tr.n_balls):
        ax_balls.plot(tr.t, np.degrees(tr.ball_angles[:, i]), color=colour, lw=1.2,
                      ls=BALL_STYLES[i % len(BALL_STYLES)],
                      label=f"{label + ': ' if label else ''}ball {i + 1}")


#: line styles of balls 1, 2, ... in panel (b)
BALL_STYLES = ("-", ":", "-.", (0, (5, 1)), (0, (3, 1, 1, 1)))
REFERENCE = {"color": "0.45", "lw": 0.8}  # the reference lines: grey, thin


def _critical_crossing(axes, tr: Trajectory) -> Line2D | None:
    """A dotted vertical line where the first run's speed reaches the critical speed, in both
    panels; its legend entry (None if the run never reaches it)."""
    crossing = np.nonzero(tr.rotor_speed >= tr.scene.critical_speed)[0]
    if not crossing.size:
        return None
    for ax in axes:
        ax.axvline(tr.t[crossing[0]], ls=":", **REFERENCE)
    return Line2D([], [], ls=":", **REFERENCE,
                  label=f"critical speed {tr.scene.critical_speed:.4g} rad/s reached")


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
    fig.suptitle(title)
    return fig, (ax_speed, ax_balls)


def _ball_references(ax, balanced, low: float) -> list:
    """The reference lines of panel (b) and their legend entries: -180 deg (opposite the
    imbalance), -540 deg when the angles go that low, and the balanced position(s)."""
    handles = [Line2D([], [], color="k", lw=0.6, label="-180 deg: opposite the imbalance")]
    ax.axhline(-180.0, color="k", lw=0.6)
    if low < -400.0:
        ax.axhline(-540.0, color="k", lw=0.3)
        handles.append(Line2D([], [], color="k", lw=0.3,
                              label="-540 deg: the same, one revolution behind"))
    if balanced is not None and len(balanced):
        degrees = np.degrees(np.asarray(balanced, float))
        for angle in degrees:
            ax.axhline(angle, ls="--", **REFERENCE)
        handles.append(Line2D([], [], ls="--", **REFERENCE,
                              label="balanced position (no residual imbalance): "
                                    + ", ".join(f"{a:.0f}" for a in degrees) + " deg"))
    return handles


def plot_runup(tr: Trajectory, path: str | Path, title: str | None = None,
               balanced=None) -> Path:
    """Thesis-style time histories of one run (Yoshida Figs. 4.x (a) and (c)) to a PNG."""
    return plot_runup_comparison({"": tr}, path, title, balanced=balanced)


def short_label(name: str, limit: int = 24) -> str:
    """A legend label of at most ``limit`` characters (the full name goes in the caption)."""
    return name if len(name) <= limit else name[:limit - 3] + "..."


def plot_runup_comparison(runs: Mapping[str, Trajectory], path: str | Path,
                          title: str | None = None, balanced=None) -> Path:
    """Several runs of one scene on the same axes (e.g. policy versus baseline) to a PNG.

    Every line style and reference line is in a legend: dashed speed and solid whirl, the
    critical-speed crossing of the first run (dotted), -180 deg (opposite the imbalance) and,
    given ``balanced`` (ball angles [rad]), the balanced position (dashed).  With several
    runs the legends sit beside the axes (never over the traces); labels longer than 24
    characters are shortened there, numbered, and given whole in a caption."""
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
        _draw_runup(axes, tr, short or None, colours[k % len(colours)])
    styles = [Line2D([], [], color="0.3", ls="--", lw=1.0, label="rotor speed (left axis)"),
              Line2D([], [], color="0.3", lw=1.2, label="whirl W_r / e (right axis)")]
    crossing = _critical_crossing(axes, first)
    if crossing is not None:
        styles.append(crossing)
    lo = min(np.degrees(tr.ball_angles).min() for tr in runs.values())
    hi = max(np.degrees(tr.ball_angles).max() for tr in runs.values())
    references = _ball_references(axes[1], balanced, lo)
    runs_a, names_a = axes[0]._abb_twin.get_legend_handles_labels()
    runs_b, names_b = axes[1].get_legend_handles_labels()
    handles_a, handles_b = runs_a + styles, runs_b + references
    if several:
        axes[0]._abb_twin.legend(handles=handles_a, loc="upper left", fontsize=8,
                                 bbox_to_anchor=(1.08, 1.0), borderaxespad=0.0)
        axes[1].legend(handles=handles_b, loc="upper left", bbox_to_anchor=(1.01, 1.0),
                       fontsize=7, borderaxespad=0.0)
    else:
        axes[0]._abb_twin.legend(handles=handles_a, loc="upper left", fontsize=7)
        axes[1].legend(handles=handles_b, loc="lower left", fontsize=7, ncol=2)
    if caption:  # supxlabel: constrained layout keeps room for it below the axes
        fig.supxlabel("; ".join(caption), fontsize=7)
    if balanced is not None and len(balanced):  # the balanced position stays in view
        lo = min(lo, float(np.degrees(np.min(balanced))))
        hi = max(hi, float(np.degrees(np.max(balanced))))
    axes[1].set_ylim(min(-200.0, lo - 20), max(30.0, hi + 20))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path = savefig(fig, path, dpi=110)
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
    path = savefig(fig, path, dpi=100)
    plt.close(fig)
    return path
