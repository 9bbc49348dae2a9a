"""``abb-gym stability-map``: balanced-state stability over two parameters (PNG + CSV).

Example (Lu & Hung's zeta-Omega plane for the lu_hung_odd3 scene, 2- and 3-ball overlays)::

    abb-gym stability-map --scene lu_hung_odd3 --x zeta --x-range 0.02 0.3 --nx 30 \\
        --y Omega --y-range 1 2.5 --ny 60 --out out/stability/lu_hung

Without ``--scene`` the base is the dimensionless groups (defaults of
:class:`abb_gym.analysis.Groups`, changed with ``--set name=value``).  Axis names: ``Omega``,
any group (eta, eta_total, mu, delta, zeta, zeta_b, spin, race_eccentricity, ...) or, with a
scene, any scene field by its YAML path or its flat name (``balls.drag`` or ``ball_drag``; the
same names as ``--set``).  ``Omega`` is the rotor speed over the undamped natural frequency
w_n = sqrt(K/M).  Writes ``<out>.csv`` and ``<out>.png`` (axes labelled with their
definitions and units, ``Omega`` explained under the plot).

Execution options are those of every sweep command (:mod:`abb_gym.execution.cli`): local
processes (``--workers N``, default all cores), a local Ray instance (``--ray``) or an existing
Ray cluster (``--ray-address ADDRESS``); ``--resume-dir DIR`` keeps finished points so that an
interrupted map resumes.
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from ..execution.cli import add_executor_arguments, executor_from_args

__all__ = ["register", "run"]


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "stability-map", help="stability map of the balanced state over two parameters",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", default=None,
                   help="scene name or YAML path (default: dimensionless groups)")
    p.add_argument("--length-scale", type=float, default=None,
                   help="Lu & Hung's e [m] for a scene (default: its rotor_eccentricity)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="fix a group or scene field (repeatable), e.g. --set eta=0.4")
    p.add_argument("--x", default="zeta", help="x-axis parameter (default zeta)")
    p.add_argument("--x-range", type=float, nargs=2, default=(0.02, 0.3), metavar=("LO", "HI"))
    p.add_argument("--nx", type=int, default=30, help="x points (default 30)")
    p.add_argument("--y", default="Omega", help="y-axis parameter (default Omega)")
    p.add_argument("--y-range", type=float, nargs=2, default=(1.0, 2.5), metavar=("LO", "HI"))
    p.add_argument("--ny", type=int, default=60, help="y points (default 60)")
    p.add_argument("--omega", type=float, default=2.0,
                   help="speed ratio when neither axis is Omega (default 2)")
    p.add_argument("--balls", type=int, nargs="+", default=None,
                   help="ball counts at equal total ball mass (default: the base's, 3 and 2)")
    p.add_argument("--members", type=int, default=13,
                   help="balanced-family members per point (default 13)")
    p.add_argument("--out", default="out/stability/map", help="output path without suffix")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    add_executor_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..analysis import Groups, stability_map
    from ..analysis.groups import GROUP_FIELDS, MAX_BALLS
    from ..analysis.rotating_frame import OMEGA_RANGE
    from ..physics.scene import load_scene
    from .outputs import output_file

    # every input before any worker starts or any task is dispatched (stability_map checks
    # the grid again): a bad one is one line, exit 2, never a task that fails and is retried
    for label, n in (("--nx", args.nx), ("--ny", args.ny), ("--members", args.members)):
        if n < 1:
            raise ValueError(f"{label} must be >= 1 (got {n})")
    for label, values in (("--x-range", args.x_range), ("--y-range", args.y_range),
                          ("--omega", [args.omega])):
        if not all(np.isfinite(values)):
            raise ValueError(f"{label} must be finite (got {' '.join(map(str, values))})")
    lo, hi = OMEGA_RANGE
    if not lo <= args.omega <= hi:
        raise ValueError(f"--omega must be in [{lo:g}, {hi:g}] (got {args.omega})")
    name = Path(args.out).name
    if not args.out.strip() or args.out.endswith(("/", os.sep)) or name in ("", ".", ".."):
        raise ValueError(f"--out must be a file path without suffix (<out>.csv and <out>.png "
                         f"are written; got {args.out!r})")
    if args.balls is not None and any(not 1 <= n <= MAX_BALLS for n in args.balls):
        raise ValueError(f"--balls must be ball counts in [1, {MAX_BALLS}] (got {args.balls})")
    if args.length_scale is not None and not (np.isfinite(args.length_scale)
                                              and args.length_scale > 0):
        raise ValueError(f"--length-scale must be a finite length > 0 [m] "
                         f"(got {args.length_scale})")
    if args.x == args.y:
        raise ValueError(f"--x and --y must be different parameters (both {args.x!r})")
    executor = executor_from_args(args, progress=not args.no_progress)
    from ..configuration import parse_assignments
    settings = parse_assignments(args.set, "--set")
    group_keys = set(GROUP_FIELDS) | {"eta_total"}
    # ball counts written 3.0 are 3; 2.5, 1e400 or [1] go to the validators, which name them
    # (int() would truncate 2.5 to 2 silently, or raise OverflowError or TypeError)
    for key in ("ball_count", "n_balls"):
        if isinstance(settings.get(key), float) and settings[key].is_integer():
            settings[key] = int(settings[key])
    if args.scene is not None:
        scene_set = {k: v for k, v in settings.items() if k not in group_keys}
        base = load_scene(args.scene, **scene_set)
        group_set = {k: v for k, v in settings.items() if k in group_keys}
        if group_set:
            g = Groups.from_scene(base, args.length_scale)
            base = g.replace(**group_set)
    else:
        unknown = sorted(set(settings) - group_keys)
        if unknown:
            raise ValueError(f"--set {unknown}: not a group; allowed {sorted(group_keys)} "
                             f"(scene fields need --scene)")
        base = Groups().replace(**settings) if settings else Groups()
    # the axis names and the grid's corners, as stability_map resolves every point
    from ..analysis.maps import check_map_size, resolve_groups
    from ..analysis.rotating_frame import _check_omega
    corner_balls = []
    for xv in args.x_range:
        for yv in args.y_range:
            g, om = resolve_groups(base, {args.x: xv, args.y: yv}, args.length_scale)
            if om is not None:
                _check_omega(om)
            corner_balls.append(g.n_balls)  # an n_balls axis has its largest at a corner
    # the size of the work, before any grid is built (a 1e9-point axis would take minutes
    # and gigabytes before the first task)
    g0, _ = resolve_groups(base, {}, args.length_scale)
    balls = args.balls or list(dict.fromkeys([g0.n_balls, 3, 2]))
    check_map_size(1, 1, corner_balls, args.members,
                   names=("--nx", "--ny", "--balls", "--members"))
    check_map_size(args.nx, args.ny, balls, args.members,
                   names=("--nx", "--ny", "--balls", "--members"))
    # after the inputs (no folders for a rejected command), before any point is computed
    for suffix in (".csv", ".png"):
        output_file(f"{args.out}{suffix}", "--out")
    m = stability_map(base, (args.x, np.linspace(*args.x_range, args.nx)),
                      (args.y, np.linspace(*args.y_range, args.ny)), n_balls=args.balls,
                      omega=args.omega, n_members=args.members, executor=executor,
                      length_scale=args.length_scale)
    csv_path = m.to_csv(f"{args.out}.csv")
    png_path = m.plot(f"{args.out}.png")
    for n in m.n_balls:
        frac = float(np.mean(m.field(n, "union_stable")))
        print(f"{n} balls: union-stable on {100 * frac:.1f} % of the map")
    print(f"wrote {csv_path} and {png_path}")
    return 0
