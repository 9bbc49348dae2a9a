"""Yoshida-style parameter studies, as data and as charts.

* :func:`settling_study` - Yoshida Fig. 4.23: the settling period (from the dwell start until
  a ball first reaches -180 deg) against the dwell length, for constant-speed and
  constant-acceleration (alpha_c = 20 rad/s^2) dwells that start at the critical speed.
* :func:`ball_position_study` - Yoshida Figs. 5.5 and 5.11: the ball position 2.5 s after the
  critical speed against the race drag c_b, one curve per ball mass, without (5.5) and with
  (5.11) the 0.5 s constant-speed dwell.

Both start every ball at 0 deg (Yoshida's Figs. 4.1/4.7 case: 0/0) and run one ``simulate`` per
point; the sweeps are small (tens of runs of a few ms) and show a progress bar.

The ``plot_*`` functions write the chart and, next to it, its data as CSV (same name,
``.csv``; :func:`write_csv`): one row per point, the units in the column names.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from .._files import replacing, savefig
from ..physics import SpeedProfile, load_scene, simulate
from ..progress import ProgressBar

ACCEL = 40.0  # rad/s^2, Yoshida's run-up rate
ACCEL_DWELL = 20.0  # rad/s^2, his constant-acceleration dwell (Fig. 4.15)
Y_FLOOR = -1080.0  # deg, three revolutions: lower positions are drawn on the floor, labelled


def _settling_drive(scene, dwell_time: float, dwell_accel: float) -> SpeedProfile:
    """Ramp at ACCEL [rad/s^2] to the critical speed, then a ``dwell_time`` [s] dwell at
    ``dwell_accel`` [rad/s^2] (raises ValueError for an impossible profile)."""
    return SpeedProfile.dwell(ACCEL, scene.critical_speed, dwell_time, dwell_accel)


def settling_period(scene, dwell_time: float, dwell_accel: float,
                    ball_angles0=None, horizon: float = 3.0) -> float:
    """Time [s] from the dwell start (at the critical speed) until a ball first reaches
    -180 deg; NaN if none does within ``horizon`` s after the dwell.  ``ball_angles0`` [rad]:
    default every ball at 0 (Yoshida's 0/0 case)."""
    t_s = scene.critical_speed / ACCEL
    drive = _settling_drive(scene, dwell_time, dwell_accel)
    if ball_angles0 is None:
        ball_angles0 = np.zeros(scene.ball_count)
    tr = simulate(scene, drive, t_s + dwell_time + horizon, ball_angles0=ball_angles0,
                  output_dt=1e-3)
    hit = np.nonzero(np.min(tr.ball_angles, axis=1) <= -math.pi)[0]
    return float(tr.t[hit[0]] - t_s) if hit.size else math.nan


def _settling_task(task) -> dict:
    scene_name, kind, acc, tc = task
    return {"dwell": kind, "dwell_accel": acc, "dwell_time_s": tc,
            "settling_period_s": settling_period(load_scene(scene_name), tc, acc)}


def _map(fn, tasks, desc, progress, executor):
    if executor is None:
        return [fn(t) for t in ProgressBar(tasks, desc=desc, disable=not progress)]
    return executor.map(fn, tasks, desc=desc)


def settling_study(scene_name: str = "yoshida_odd",
                   dwell_times=(0.3, 0.4, 0.5, 0.6, 0.7, 0.8),
                   progress: bool = True, executor=None) -> list[dict]:
    """Rows of (dwell kind, dwell length [s], settling period [s]); ``executor`` as in
    :mod:`abb_gym.execution` (None: this process).  Every input is checked before any run
    starts (a bad scene or dwell length is one ValueError, not one per task)."""
    todo = [(scene_name, kind, acc, tc) for kind, acc in (("constant speed", 0.0),
                                                          ("constant acceleration", ACCEL_DWELL))
            for tc in dwell_times]
    scene = load_scene(scene_name)
    for _, _, acc, tc in todo:
        _settling_drive(scene, tc, acc)
    return _map(_settling_task, todo, "settling study", progress, executor)


def ball_position_after_critical(scene, with_dwell: bool, after: float = 2.5) -> float:
    """The lowest ball angle [deg] ``after`` s after the critical speed (balls from 0)."""
    t_c = scene.critical_speed / ACCEL
    drive = (SpeedProfile.dwell(ACCEL, scene.critical_speed, 0.5) if with_dwell
             else SpeedProfile.ramp(ACCEL))
    tr = simulate(scene, drive, t_c + after, ball_angles0=np.zeros(scene.ball_count),
                  output_dt=0.01)
    return float(np.degrees(tr.ball_angles[-1].min()))


def _position_task(task) -> dict:
    scene_name, with_dwell, m, c = task
    scene = load_scene(scene_name, ball_mass=m, ball_drag=c)
    return {"profile": "dwell 0.5 s" if with_dwell else "no profile",
            "ball_mass_g": m * 1e3, "ball_drag_Ns_m": c,
            "ball_angle_deg": ball_position_after_critical(scene, with_dwell)}


def ball_position_study(scene_name: str = "yoshida_odd", masses=(0.5e-3, 1e-3, 1.5e-3, 2e-3),
                        drags=(0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0),
                        progress: bool = True, executor=None) -> list[dict]:
    """Rows of (profile, ball mass [g], race drag [N s/m], ball angle [deg] 2.5 s after the
    critical speed).  Every input is checked before any run starts."""
    todo = [(scene_name, dw, m, c) for dw in (False, True) for m in masses for c in drags]
    load_scene(scene_name)  # the scene's own message for a bad name, before the fields'
    for m in masses:
        for c in drags:
            load_scene(scene_name, ball_mass=m, ball_drag=c)
    return _map(_position_task, todo, "ball position study", progress, executor)


def write_csv(rows: list[dict], path) -> Path:
    """Write ``rows`` (dicts with the same keys) as CSV to ``path``; NaN stays ``nan``, which
    pandas and numpy read back as NaN.  Returns the path."""
    if not rows:
        raise ValueError("a study without rows has nothing to write")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with replacing(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return path


def _save(fig, rows: list[dict], path) -> Path:
    """Save the chart to ``path`` and its rows next to it (``.csv``); returns the chart."""
    import matplotlib.pyplot as plt
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path = savefig(fig, path, dpi=110)
    plt.close(fig)
    write_csv(rows, path.with_suffix(".csv"))
    return path


def plot_settling_study(rows: list[dict], path) -> Path:
    """Chart of :func:`settling_study` at ``path``, its data next to it (``.csv``)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.5, 4.5), constrained_layout=True)
    for kind, marker in (("constant speed", "o"), ("constant acceleration", "s")):
        pts = [r for r in rows if r["dwell"] == kind]
        ax.plot([r["dwell_time_s"] for r in pts], [r["settling_period_s"] for r in pts],
                marker=marker, label=kind)
    ax.set_xlabel("dwell (variable-speed period) length t_c [s]")
    ax.set_ylabel("settling period: dwell start to a ball at -180 deg [s]")
    ax.set_title("Settling period against dwell length (cf. Yoshida Fig. 4.23)")
    ax.grid(alpha=0.3)
    ax.legend()
    return _save(fig, rows, path)


def plot_ball_position_study(rows: list[dict], path) -> Path:
    """Chart of :func:`ball_position_study` at ``path``, its data next to it (``.csv``)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    profiles = list(dict.fromkeys(r["profile"] for r in rows))
    fig, axes = plt.subplots(1, len(profiles), figsize=(12, 4.5), sharey=True,
                             constrained_layout=True)
    for ax, prof in zip(np.atleast_1d(axes), profiles):
        for m in sorted({r["ball_mass_g"] for r in rows}):
            pts = [r for r in rows if r["profile"] == prof and r["ball_mass_g"] == m]
            x = np.array([r["ball_drag_Ns_m"] for r in pts])
            y = np.array([r["ball_angle_deg"] for r in pts])
            line, = ax.plot(x, np.maximum(y, Y_FLOOR), marker="o", label=f"m = {m:g} g")
            for xi, yi in zip(x[y < Y_FLOOR], y[y < Y_FLOOR]):  # circulating balls: off scale
                ax.annotate(f"{yi:.0f}", (xi, Y_FLOOR), textcoords="offset points",
                            xytext=(4, 4), fontsize=7, color=line.get_color())
        ax.set_ylim(Y_FLOOR - 40, 30)
        for k in (1, 3, 5):
            ax.axhline(-180.0 * k, color="k", lw=0.5, ls=":")
        ax.set_xlabel("race drag c_b [N s/m]")
        ax.set_title(f"{prof} (cf. Yoshida Fig. {'5.11' if 'dwell' in prof else '5.5'})")
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("ball angle 2.5 s after the critical speed [deg]")
    np.atleast_1d(axes)[0].legend()
    return _save(fig, rows, path)
