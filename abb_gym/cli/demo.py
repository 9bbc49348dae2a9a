"""``abb-gym demo``: the reference optical-drive run-up (Yoshida 2014, ch. 4) with and without
a constant-speed dwell at the critical speed, for two initial ball configurations.

It first compiles (or loads) the kernels it needs, with a progress bar.  It then prints its
conclusion in one line, computed from the runs: with the dwell both balls get to the side
opposite the imbalance (within :data:`OPPOSITE_TOLERANCE` of -180 deg) soon after the
critical speed from both starts, without it later or never, and the price is a higher whirl
peak while they cross (Yoshida's Figs. 4.1, 4.7 and 4.9).  A metrics table follows (with the
error of the compiled RK4 against a DOP853 reference), and thesis-style PNG figures whose
legends name every line style and reference line (the critical-speed crossing, -180 deg, the
balanced position)."""
from __future__ import annotations

import math

import numpy as np

from ..tables import markdown_table

T_END = 6.0  # s, the thesis's time axis
#: [deg] a ball this close to -180 deg (mod 360) is on the side opposite the imbalance
OPPOSITE_TOLERANCE = 45.0


def register(sub) -> None:
    p = sub.add_parser("demo", help="Yoshida run-up with and without a dwell: table + figures",
                       description=__doc__)
    p.add_argument("--out", default="out/demo", help="folder for the PNG figures")
    p.set_defaults(func=run)


def run(args) -> int:
    from .outputs import output_folder
    demonstrate(output_folder(args.out, "--out"))
    return 0


def _offset_from_opposite(angles) -> np.ndarray:
    """|angle - (-180 deg)| folded into [0, 180] deg, for angles [rad]."""
    deg = np.degrees(np.asarray(angles, float))
    return np.abs((deg + 360.0) % 360.0 - 180.0)


def opposite_from(tr) -> float:
    """The time [s] from which every ball stays within :data:`OPPOSITE_TOLERANCE` of
    -180 deg to the end of the run (NaN: not at the end)."""
    inside = np.all(_offset_from_opposite(tr.ball_angles) <= OPPOSITE_TOLERANCE, axis=1)
    if not inside[-1]:
        return math.nan
    outside = np.flatnonzero(~inside)
    return float(tr.t[outside[-1] + 1]) if outside.size else float(tr.t[0])


def conclusion(rows: list[dict], runs: dict) -> str:
    """The demo's one-line conclusion from its runs (``runs[(start, profile)]``)."""
    def when(key) -> str:
        t = opposite_from(runs[key])
        if math.isfinite(t):
            return f"{t:.2f} s"
        stray = np.degrees(runs[key].ball_angles[-1])
        worst = stray[np.argmax(_offset_from_opposite(np.radians(stray)))]
        return f"never (a ball ends at {worst:.0f} deg)"

    starts = list(dict.fromkeys(start for start, _ in runs))
    dwell, plain = "dwell 2.5-3.0 s", "no dwell"
    peaks = {(r["start"], r["profile"]): r["peak W_r/e"] for r in rows}
    return (f"conclusion: with the dwell both balls are opposite the imbalance (within "
            f"{OPPOSITE_TOLERANCE:g} deg of -180 deg) from "
            + " and ".join(when((s, dwell)) for s in starts)
            + f" ({' and '.join(starts)}), without it from "
            + " and ".join(when((s, plain)) for s in starts)
            + "; the price is a higher whirl peak while they cross ("
            + " and ".join(f"{peaks[(s, dwell)]:.1f}" for s in starts) + " against "
            + " and ".join(f"{peaks[(s, plain)]:.1f}" for s in starts)
            + " W_r/e), as in Yoshida's Figs. 4.1, 4.7 and 4.9")


def warm_up(scene, profile) -> None:
    """Compile (or load) the demo's kernels with a progress bar: the compiled RK4 and the
    right-hand side of the DOP853 reference."""
    from ..kernels import build
    from ..physics import simulate
    build(steps=[("simulate (compiled RK4)", lambda: simulate(scene, profile, 0.01)),
                 ("simulate (DOP853 reference)",
                  lambda: simulate(scene, profile, 0.01, method="DOP853"))],
          desc="demo kernels")


def balanced_angles(scene) -> np.ndarray:
    """The balls' balanced position [rad] at the operating speed, each folded to within
    180 deg of -180 deg (for the figures' reference lines)."""
    from ..analysis.rotating_frame import balanced_family
    omega = scene.drive_operating_speed / scene.critical_speed
    members = balanced_family(scene, omega)
    if not len(members):
        return np.zeros(0)
    return np.sort(np.remainder(members[0], 2 * math.pi) - 2 * math.pi)


def demonstrate(out) -> None:
    """The demonstration's runs: figures written into the folder ``out``, the conclusion and
    the table printed."""
    from ..physics import SpeedProfile, load_scene, simulate
    from ..plots import plot_runup_comparison
    scene = load_scene("yoshida_odd")
    accel = 40.0
    profiles = {
        "no dwell": SpeedProfile.ramp(accel),
        "dwell 2.5-3.0 s": SpeedProfile.dwell(accel, dwell_speed=scene.critical_speed,
                                              dwell_time=0.5),
    }
    starts = {"balls 0/0 deg": [0.0, 0.0], "balls 45/-45 deg": [45.0, -45.0]}
    warm_up(scene, profiles["no dwell"])  # before timing
    balanced = balanced_angles(scene)
    rows, every = [], {}
    for start_label, start in starts.items():
        runs = {}
        for label, profile in profiles.items():
            angles = np.radians(start)
            tr = simulate(scene, profile, T_END, ball_angles0=angles)
            ref = simulate(scene, profile, T_END, ball_angles0=angles, method="DOP853")
            runs[label] = every[(start_label, label)] = tr
            s = tr.summary()
            t_opposite = opposite_from(tr)
            rows.append({
                "start": start_label, "profile": label,
                "peak W_r/e": s["peak_whirl_ratio"], "t_peak [s]": s["peak_time_s"],
                "balls opposite the imbalance from [s]":
                    f"{t_opposite:.3f}" if math.isfinite(t_opposite) else "never",
                "W_r/e at 6 s": float(tr.whirl_ratio[-1]),
                "ball angles at 6 s [deg]": s["final_ball_angles_deg"],
                "RK4 time [ms]": 1e3 * tr.wall_time,
                "RK4 peak error vs DOP853": abs(s["peak_whirl_ratio"] / ref.whirl_ratio.max() - 1),
                "RK4 angle error [deg]": float(np.degrees(np.abs(tr.ball_angles - ref.ball_angles).max())),
            })
        tag = start_label.replace(" ", "_").replace("/", "_")
        path = plot_runup_comparison(runs, out / f"runup_{tag}.png",
                                     f"yoshida_odd, {start_label}: run-up at {accel:g} rad/s^2",
                                     balanced=balanced)
        print(f"wrote {path}")
    print()
    print(f"scene yoshida_odd: critical speed {scene.critical_speed:.1f} rad/s, "
          f"RK4 step {tr.step * 1e3:.2f} ms")
    print(conclusion(rows, {(s, p): every[(s, p)] for s in starts for p in profiles}))
    print(markdown_table(rows))
