"""``abb-gym demo``: the reference optical-drive run-up (Yoshida 2014, ch. 4) with and without
a constant-speed dwell at the critical speed, for two initial ball configurations.  Prints a
metrics table (with the error of the compiled RK4 against a DOP853 reference) and writes
thesis-style PNG figures."""
from __future__ import annotations

import numpy as np

from ..tables import markdown_table

T_END = 6.0  # s, the thesis's time axis


def register(sub) -> None:
    p = sub.add_parser("demo", help="Yoshida run-up with and without a dwell: table + figures",
                       description=__doc__)
    p.add_argument("--out", default="out/demo", help="folder for the PNG figures")
    p.set_defaults(func=run)


def run(args) -> int:
    from .outputs import output_folder
    demonstrate(output_folder(args.out, "--out"))
    return 0


def demonstrate(out) -> None:
    """The demonstration's runs: figures written into the folder ``out``, the table printed."""
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
    simulate(scene, profiles["no dwell"], 0.01)  # load the compiled kernel before timing
    rows = []
    for start_label, start in starts.items():
        runs = {}
        for label, profile in profiles.items():
            angles = np.radians(start)
            tr = simulate(scene, profile, T_END, ball_angles0=angles)
            ref = simulate(scene, profile, T_END, ball_angles0=angles, method="DOP853")
            runs[label] = tr
            s = tr.summary()
            rows.append({
                "start": start_label, "profile": label,
                "peak W_r/e": s["peak_whirl_ratio"], "t_peak [s]": s["peak_time_s"],
                "W_r/e at 6 s": float(tr.whirl_ratio[-1]),
                "ball angles at 6 s [deg]": s["final_ball_angles_deg"],
                "RK4 time [ms]": 1e3 * tr.wall_time,
                "RK4 peak error vs DOP853": abs(s["peak_whirl_ratio"] / ref.whirl_ratio.max() - 1),
                "RK4 angle error [deg]": float(np.degrees(np.abs(tr.ball_angles - ref.ball_angles).max())),
            })
        tag = start_label.replace(" ", "_").replace("/", "_")
        path = plot_runup_comparison(runs, out / f"runup_{tag}.png",
                                     f"yoshida_odd, {start_label}: run-up at {accel:g} rad/s^2")
        print(f"wrote {path}")
    print()
    print(f"scene yoshida_odd: critical speed {scene.critical_speed:.1f} rad/s, "
          f"RK4 step {tr.step * 1e3:.2f} ms")
    print(markdown_table(rows))
