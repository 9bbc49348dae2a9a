"""``abb-gym simulate``: one run of a scene under a speed profile or a motor, as a table,
JSON and a thesis-style PNG."""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from ..physics import MotorDrive, SpeedProfile, load_scene, simulate
from ..physics.simulate import METHODS
from ..tables import markdown_table


def parse_overrides(items: list[str] | None) -> dict:
    """``FIELD=VALUE`` strings -> dict (values parsed as YAML: numbers, lists)."""
    from ..configuration import parse_assignments
    return parse_assignments(items, "--set")


def add_scene_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scene", default="yoshida_odd", help="scene name or YAML path")
    p.add_argument("--set", action="append", metavar="FIELD=VALUE",
                   help="override a scene field, e.g. --set ball_mass=2e-3 (repeatable)")


def register(sub) -> None:
    p = sub.add_parser("simulate", help="simulate one run and print/plot it",
                       description=__doc__)
    add_scene_arguments(p)
    p.add_argument("--profile", choices=["ramp", "dwell", "constant"], default="ramp",
                   help="prescribed speed profile (ignored with --motor-torque/--limited-power)")
    p.add_argument("--accel", type=float, default=40.0, help="run-up acceleration [rad/s^2]")
    p.add_argument("--dwell-speed", type=float, default=None,
                   help="dwell start speed [rad/s] (default: the scene's critical speed)")
    p.add_argument("--dwell-time", type=float, default=0.5, help="dwell length [s]")
    p.add_argument("--dwell-accel", type=float, default=0.0,
                   help="acceleration during the dwell [rad/s^2] (0: constant speed)")
    p.add_argument("--operating-speed", type=float, default=None,
                   help="hold speed [rad/s] (default: keep accelerating)")
    p.add_argument("--speed", type=float, default=None, help="speed of --profile constant [rad/s]")
    p.add_argument("--motor-torque", type=float, default=None,
                   help="drive the rotor with a constant motor torque [N m] instead")
    p.add_argument("--limited-power", type=float, default=None, metavar="GAIN",
                   help="limited-power drive M0 = GAIN (target - w) [N m s]; target: --speed")
    p.add_argument("--t-end", type=float, default=6.0, help="simulated time [s]")
    p.add_argument("--ball-angles-deg", type=float, nargs="+", default=None,
                   help="initial ball angles [deg] (default: the scene's)")
    p.add_argument("--method", default="rk4", choices=METHODS,
                   help="compiled rk4, etdrk4 (stiff drag), ros2 (any stiffness), dopri5 "
                        "(adaptive), or a solve_ivp method")
    p.add_argument("--dt", type=float, default=None,
                   help="fixed step [s] (default: the method's stability and accuracy limit)")
    p.add_argument("--output-dt", type=float, default=None, help="output interval [s]")
    p.add_argument("--plot", default=None, help="write a PNG of the run to this path")
    p.add_argument("--json", nargs="?", const="-", default=None, metavar="PATH",
                   help="write the trajectory as JSON to PATH (or stdout without PATH)")
    p.set_defaults(func=run)


def build_drive(args, scene):
    if args.motor_torque is not None:
        return MotorDrive.constant_torque(args.motor_torque)
    if args.limited_power is not None:
        target = args.speed if args.speed is not None else scene.drive_operating_speed
        return MotorDrive.limited_power(args.limited_power, target)
    if args.profile == "constant":
        return SpeedProfile.constant(args.speed if args.speed is not None
                                     else scene.drive_operating_speed)
    if args.profile == "dwell":
        dwell_speed = scene.critical_speed if args.dwell_speed is None else args.dwell_speed
        return SpeedProfile.dwell(args.accel, dwell_speed, args.dwell_time, args.dwell_accel,
                                  args.operating_speed)
    return SpeedProfile.ramp(args.accel, args.operating_speed)


def run(args) -> int:
    from .outputs import output_file
    scene = load_scene(args.scene, **parse_overrides(args.set))
    drive = build_drive(args, scene)
    # after the inputs (no folders for a rejected command), before the run
    if args.plot:
        output_file(args.plot, "--plot")
    if args.json and args.json != "-":
        output_file(args.json, "--json")
    angles = None if args.ball_angles_deg is None else np.radians(args.ball_angles_deg)
    tr = simulate(scene, drive, args.t_end, ball_angles0=angles, method=args.method, dt=args.dt,
                  output_dt=args.output_dt)
    if args.plot:
        from ..plots import plot_runup
        plot_runup(tr, args.plot)
    if args.json == "-":
        json.dump(tr.to_dict(), sys.stdout)
        print()
        return 0
    if args.json:
        tr.to_json(args.json)
    print(markdown_table([tr.summary()]))
    return 0
