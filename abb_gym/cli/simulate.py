"""``abb-gym simulate``: one run of a scene under a speed profile or a motor, as a table,
JSON and a thesis-style PNG.

The drive defaults to the scene's: a ramp at half ``drive.max_acceleration`` held at
``drive.operating_speed``, for as long as it takes to reach that speed plus the 1 s settling
window.  A drive beyond the scene's drive limits (a speed above ``drive.operating_speed``,
an acceleration above ``drive.max_acceleration``, a torque above ``drive.torque_limit``) is
refused before the run, naming the limit, unless ``--allow-beyond-drive-limits``
(:mod:`abb_gym.physics.drive_limits`)."""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from ..physics.methods import METHODS
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
    # the drive options default to None, so that one given for another drive is refused
    # (build_drive) instead of silently ignored; the defaults below are filled in there
    p.add_argument("--profile", choices=["ramp", "dwell", "constant"], default=None,
                   help="prescribed speed profile (default ramp; not with --motor-torque or "
                        "--limited-power)")
    p.add_argument("--accel", type=float, default=None,
                   help="run-up acceleration of ramp and dwell [rad/s^2] (default: half the "
                        "scene's drive.max_acceleration)")
    p.add_argument("--dwell-speed", type=float, default=None,
                   help="dwell start speed [rad/s] (default: the scene's critical speed)")
    p.add_argument("--dwell-time", type=float, default=None,
                   help=f"dwell length [s] (default {DEFAULTS['dwell_time']:g})")
    p.add_argument("--dwell-accel", type=float, default=None,
                   help="acceleration during the dwell [rad/s^2] (default 0: constant speed)")
    p.add_argument("--operating-speed", type=float, default=None,
                   help="hold speed of ramp and dwell [rad/s] (default: the scene's "
                        "drive.operating_speed)")
    p.add_argument("--speed", type=float, default=None,
                   help="speed of --profile constant, target of --limited-power [rad/s] "
                        "(default: the scene's operating speed)")
    p.add_argument("--motor-torque", type=float, default=None,
                   help="drive the rotor with a constant motor torque [N m] instead")
    p.add_argument("--limited-power", type=float, default=None, metavar="GAIN",
                   help="limited-power drive M0 = GAIN (target - w) [N m s]; target: --speed")
    p.add_argument("--t-end", type=float, default=None,
                   help="simulated time [s] (default: until the profile holds its speed, "
                        "plus 1 s; a motor drive needs it)")
    p.add_argument("--allow-beyond-drive-limits", action="store_true",
                   help="run a drive beyond the scene's drive limits (operating speed, "
                        "largest acceleration, torque limit) instead of refusing it")
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


DEFAULTS = {"dwell_time": 0.5, "dwell_accel": 0.0}
# the options each drive reads (any other drive option given with it is refused)
DRIVE_OPTIONS = {
    "motor": ("motor_torque",),
    "limited-power": ("limited_power", "speed"),
    "constant": ("profile", "speed"),
    "ramp": ("profile", "accel", "operating_speed"),
    "dwell": ("profile", "accel", "dwell_speed", "dwell_time", "dwell_accel",
              "operating_speed"),
}


def _drive_kind(args) -> str:
    if args.motor_torque is not None:
        return "motor"
    if args.limited_power is not None:
        return "limited-power"
    return args.profile or "ramp"


def check_drive_options(args) -> str:
    """The drive the options select; an option the drive would ignore (``--speed`` with a
    ramp, ``--profile`` with ``--motor-torque``, both motors) is a ValueError naming it."""
    kind = _drive_kind(args)
    used = DRIVE_OPTIONS[kind]
    for name in ("motor_torque", "limited_power", "profile", "accel", "dwell_speed",
                 "dwell_time", "dwell_accel", "operating_speed", "speed"):
        if getattr(args, name) is not None and name not in used:
            option = "--" + name.replace("_", "-")
            drive = {"motor": "--motor-torque", "limited-power": "--limited-power"}.get(
                kind, f"--profile {kind}")
            raise ValueError(f"{option} does not apply to {drive} (it would be ignored); "
                             f"that drive takes "
                             f"{', '.join('--' + u.replace('_', '-') for u in used)}")
    for name, value in DEFAULTS.items():
        if getattr(args, name) is None:
            setattr(args, name, value)
    return kind


def build_drive(args, scene):
    """The drive the options describe; a rejected value names the options it came from (the
    API's message names its own argument: ``torque`` for ``--motor-torque``)."""
    from ..physics import MotorDrive, SpeedProfile
    check_drive_options(args)
    if args.motor_torque is not None:
        options, make = "--motor-torque", lambda: MotorDrive.constant_torque(args.motor_torque)
    elif args.limited_power is not None:
        target = args.speed if args.speed is not None else scene.drive_operating_speed
        options = "--limited-power/--speed"
        make = lambda: MotorDrive.limited_power(args.limited_power, target)  # noqa: E731
    elif _drive_kind(args) == "constant":
        options = "--speed"
        make = lambda: SpeedProfile.constant(  # noqa: E731
            args.speed if args.speed is not None else scene.drive_operating_speed)
    elif _drive_kind(args) == "dwell":
        dwell_speed = scene.critical_speed if args.dwell_speed is None else args.dwell_speed
        accel, hold = _run_up(args, scene)
        options = "--accel/--dwell-speed/--dwell-time/--dwell-accel/--operating-speed"
        make = lambda: SpeedProfile.dwell(accel, dwell_speed, args.dwell_time,  # noqa
                                          args.dwell_accel, hold)
    else:
        accel, hold = _run_up(args, scene)
        options = "--accel/--operating-speed"
        make = lambda: SpeedProfile.ramp(accel, hold)  # noqa: E731
    try:
        return make()
    except ValueError as exc:
        raise ValueError(f"{options}: {exc}") from None


def _run_up(args, scene) -> tuple[float, float]:
    """(acceleration [rad/s^2], hold speed [rad/s]) of a ramp or dwell: the options, else the
    scene's nominal run-up (:func:`abb_gym.physics.drive_limits.nominal_drive`)."""
    from ..physics.drive_limits import nominal_acceleration
    accel = nominal_acceleration(scene) if args.accel is None else args.accel
    hold = scene.drive_operating_speed if args.operating_speed is None else args.operating_speed
    return accel, hold


def check_drive_limits(args, scene, drive, t_end: float) -> None:
    """Refuse a drive beyond the scene's drive limits (ValueError naming them and the
    options), unless ``--allow-beyond-drive-limits``."""
    from ..physics.drive_limits import drive_excess
    excess = drive_excess(scene, drive, t_end)
    if excess and not args.allow_beyond_drive_limits:
        raise ValueError(f"scene {scene.name!r}: {'; '.join(excess)}; change the drive "
                         f"options or the scene's drive.* fields, or run it anyway with "
                         f"--allow-beyond-drive-limits")


def ball_angles(args, scene):
    """``--ball-angles-deg`` in radians, checked in the option's own unit and words."""
    from ..physics.scene import ANGLE_LIMIT
    if args.ball_angles_deg is None:
        return None
    deg = np.asarray(args.ball_angles_deg, float)
    limit = np.degrees(ANGLE_LIMIT)
    if deg.shape != (scene.ball_count,) or not np.all(np.abs(deg) <= limit):
        raise ValueError(f"--ball-angles-deg must be {scene.ball_count} finite angles (one per "
                         f"ball of {scene.name!r}) in [-{limit:.6g}, {limit:.6g}] deg (got "
                         f"{' '.join(f'{v:g}' for v in args.ball_angles_deg[:8])})")
    return np.radians(deg)


def run(args) -> int:
    from ..physics import load_scene, simulate
    from .outputs import output_file, output_image
    from ..physics.drive_limits import default_t_end
    scene = load_scene(args.scene, **parse_overrides(args.set))
    drive = build_drive(args, scene)
    try:
        t_end = default_t_end(drive) if args.t_end is None else args.t_end
    except ValueError as exc:
        raise ValueError(f"--t-end: {exc}") from None
    check_drive_limits(args, scene, drive, t_end)
    angles = ball_angles(args, scene)
    # after the inputs (no folders for a rejected command), before the run; an empty path is
    # refused, not read as "no --plot"
    if args.plot is not None:
        output_image(args.plot, "--plot")
    if args.json is not None and args.json != "-":
        output_file(args.json, "--json")
    tr = simulate(scene, drive, t_end, ball_angles0=angles, method=args.method, dt=args.dt,
                  output_dt=args.output_dt,
                  drive_limits="ignore" if args.allow_beyond_drive_limits else "raise")
    if args.plot is not None:
        from ..plots import plot_runup
        plot_runup(tr, args.plot)
    if args.json == "-":
        json.dump(tr.to_dict(), sys.stdout)
        print()
        return 0
    if args.json is not None:
        from .._files import write_text
        write_text(args.json, tr.to_json())
    print(markdown_table([tr.summary()]))
    return 0
