"""Stability maps of the balanced state over any two parameters (PNG + CSV).

Each map point evaluates :func:`abb_gym.analysis.rotating_frame.family_stability` - the
eigenvalues of every sampled member of the balanced family, structural zeros removed - for one
or more ball counts at the same total ball mass (``eta_total`` kept, so M is unchanged): the
two- and three-ball overlays of Lu & Hung's Figs. 7 and 9.

Axes are named by

* ``Omega`` - speed ratio w/w_n (the speed of every point when no axis is Omega: ``omega``),
* a dimensionless group (:data:`abb_gym.analysis.groups.GROUP_FIELDS`, e.g. ``zeta``,
  ``zeta_b``, ``eta``, ``mu``, ``delta``) or ``eta_total``,
* or, when the base is a :class:`~abb_gym.physics.scene.Scene`, a scene field by either of
  its names (``ball_drag`` or ``balls.drag``, ``support_damping`` or ``support.damping``:
  :data:`abb_gym.physics.scene.FIELD_NAMES`), applied to the scene before it is converted.
  ``race_eccentricity`` is the group E/e; the scene's race offset [m] is ``race.eccentricity``.

The figure labels each axis with its definition and unit (a group's formula, e.g.
``zeta = C / (2 M w_n) [-]``; a scene field's unit, e.g. ``balls.drag (ball_drag) [N s/m]``)
and explains ``Omega`` below the axes: the rotor speed over the undamped natural frequency
``w_n = sqrt(K/M)``, with its value in rad/s when the base is a scene and no axis changes it.

Work runs on the executor layer (:mod:`abb_gym.execution`): local processes by default, or a
local Ray instance or a Ray cluster; one task per (point, ball count), results in task order,
so the map does not depend on the executor or the number of workers (tested).  With a store
(``--resume-dir``) finished points are kept on disk and a rerun only computes the missing
ones.  A tqdm bar shows progress.

Classification per point and ball count: ``exists`` (the balanced family is not empty),
``union_stable`` (some member stable - Lu & Hung's stable region), ``all_stable`` (every
member stable), ``fraction_stable``, ``best`` / ``worst`` (smallest / largest member max real
part, units of w_n).
"""
from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .._files import replacing, savefig
from ..execution import Executor
from ..physics.scene import Scene, field_spec
from .groups import DEFINITIONS, GROUP_FIELDS, MAX_BALLS, Groups
from .rotating_frame import DEFAULT_TOL, _check_omega, check_family_size, family_stability

__all__ = ["StabilityMap", "stability_map", "resolve_groups", "onset_speed", "MAP_FIELDS",
           "MAX_MAP_TASKS", "check_map_size", "axis_label"]

#: Most tasks (grid points x ball counts) of one map: the task list is built before anything
#: runs (a 1e9-point grid would hang there, and its arrays take gigabytes); a default map has
#: 30 x 60 x 3 = 5400.
MAX_MAP_TASKS = 10 ** 6
MAP_FIELDS = ("exists", "union_stable", "all_stable", "fraction_stable", "best", "worst")
_GROUP_AXES = set(GROUP_FIELDS) | {"eta_total"}


def resolve_groups(base: Groups | Scene, settings: dict[str, float],
                   length_scale: float | None = None) -> tuple[Groups, float | None]:
    """(groups, Omega or None) for ``base`` with ``settings`` applied (axis name -> value).

    Scene fields are applied to the scene first, then the scene is converted and the group
    settings applied; ``Omega`` is returned separately.
    """
    settings = dict(settings)
    omega = settings.pop("Omega", None)
    group_set = {k: v for k, v in settings.items() if k in _GROUP_AXES}
    other = {k: v for k, v in settings.items() if k not in _GROUP_AXES}
    if isinstance(base, Scene):
        scene = base.replace(**other) if other else base
        g = Groups.from_scene(scene, length_scale)
    elif isinstance(base, Groups):
        if other:
            raise ValueError(f"unknown map parameter(s) {sorted(other)} for groups; allowed: "
                             f"Omega, {', '.join(sorted(_GROUP_AXES))}")
        g = base
    else:
        raise ValueError(f"base must be Groups or Scene (got {type(base).__name__})")
    if "n_balls" in group_set:
        group_set["n_balls"] = int(round(group_set["n_balls"]))
    if group_set:
        if "n_balls" in group_set and "eta" not in group_set and "eta_total" not in group_set:
            group_set["eta_total"] = g.eta_total
        g = g.replace(**group_set)
    return g, omega


def axis_label(name: str) -> str:
    """The axis label of map parameter ``name``: a group (or ``Omega``) with its formula and
    unit, a scene field with its YAML path, flat name and unit."""
    if name in DEFINITIONS:
        formula, unit, _ = DEFINITIONS[name]
        return f"{name} = {formula} [{unit}]"
    field, spec = field_spec(name)
    names = f"{spec.yaml} ({field})" if name in (field, spec.yaml) and spec.yaml else name
    return f"{names} [{spec.unit or '-'}]"


def _evaluate(task: tuple[Groups, float, int, float]) -> tuple:
    g, omega, n_members, tol = task
    fs = family_stability(g, omega, n_members, tol)
    return (fs.exists, fs.union_stable, fs.all_stable, fs.fraction_stable, fs.best, fs.worst)


@dataclass
class StabilityMap:
    """Result of :func:`stability_map`: ``data[n][field]`` arrays of shape (len(y), len(x))."""

    x_name: str
    x_values: np.ndarray
    y_name: str
    y_values: np.ndarray
    n_balls: tuple[int, ...]
    data: dict[int, dict[str, np.ndarray]]
    base_description: str = ""
    settings: dict[str, Any] = field(default_factory=dict)
    #: w_n = sqrt(K/M) [rad/s] of a scene base that no axis changes (None: groups, or an
    #: axis that changes it)
    natural_frequency: float | None = None

    def field(self, n: int, name: str) -> np.ndarray:
        if n not in self.data:
            raise ValueError(f"n_balls {n} not in this map (has {list(self.n_balls)})")
        if name not in MAP_FIELDS:
            raise ValueError(f"field must be one of {MAP_FIELDS} (got {name!r})")
        return self.data[n][name]

    def to_csv(self, path: str | os.PathLike) -> Path:
        """One row per (y, x, n_balls): the classification fields of the module docstring."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with replacing(path, "w", newline="") as fh:
            wr = csv.writer(fh)
            wr.writerow([self.x_name, self.y_name, "n_balls", *MAP_FIELDS])
            for iy, yv in enumerate(self.y_values):
                for ix, xv in enumerate(self.x_values):
                    for n in self.n_balls:
                        d = self.data[n]
                        wr.writerow([f"{xv:.10g}", f"{yv:.10g}", n,
                                     int(d["exists"][iy, ix]), int(d["union_stable"][iy, ix]),
                                     int(d["all_stable"][iy, ix]),
                                     f"{d['fraction_stable'][iy, ix]:.6g}",
                                     f"{d['best'][iy, ix]:.6g}", f"{d['worst'][iy, ix]:.6g}"])
        return path

    def plot(self, path: str | os.PathLike, title: str | None = None) -> Path:
        """PNG of :meth:`figure`."""
        import matplotlib.pyplot as plt

        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        fig = self.figure(title)
        path = savefig(fig, path)
        plt.close(fig)
        return path

    def omega_note(self) -> str:
        """What ``Omega`` is, in words, with w_n in rad/s where one value holds."""
        wn = (f"; here w_n = {self.natural_frequency:.4g} rad/s"
              if self.natural_frequency else "")
        return f"Omega = w / w_n: rotor speed over the undamped natural frequency " \
               f"w_n = sqrt(K/M){wn}"

    def figure(self, title: str | None = None):
        """The map as a matplotlib figure: shading = union-stable region of the first ball
        count (dark: no balanced state), lines = union borders of every ball count (solid 3
        balls, dashed 2, dotted others); axes labelled with definitions and units
        (:func:`axis_label`), ``Omega`` explained below them."""
        import matplotlib
        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
        from matplotlib.lines import Line2D

        fig, ax = plt.subplots(figsize=(6.4, 5.0), dpi=120, constrained_layout=True)
        n0 = self.n_balls[0]
        d0 = self.data[n0]
        shade = np.where(d0["exists"], np.where(d0["union_stable"], 2.0, 1.0), 0.0)
        ax.pcolormesh(self.x_values, self.y_values, shade, shading="nearest",
                      cmap=matplotlib.colors.ListedColormap(["#7f7f7f", "#f4cccc", "#d9ead3"]),
                      vmin=-0.5, vmax=2.5)
        handles = [matplotlib.patches.Patch(color="#d9ead3", label=f"{n0}-ball: stable (union)"),
                   matplotlib.patches.Patch(color="#f4cccc", label=f"{n0}-ball: unstable"),
                   matplotlib.patches.Patch(color="#7f7f7f", label=f"{n0}-ball: cannot balance")]
        styles = {3: "-", 2: "--"}
        if len(self.x_values) > 1 and len(self.y_values) > 1:
            for n in self.n_balls:
                u = self.data[n]["union_stable"].astype(float)
                if 0 < u.sum() < u.size:
                    ax.contour(self.x_values, self.y_values, u, levels=[0.5], colors="k",
                               linestyles=styles.get(n, ":"), linewidths=1.4)
                handles.append(Line2D([], [], color="k", linestyle=styles.get(n, ":"),
                                      label=f"{n}-ball border"))
        ax.set_xlabel(axis_label(self.x_name))
        ax.set_ylabel(axis_label(self.y_name))
        ax.set_title(title or f"Balanced-state stability ({self.base_description})", fontsize=9)
        ax.legend(handles=handles, fontsize=7, loc="best")
        omega = self.settings.get("omega")
        speed = "" if "Omega" in (self.x_name, self.y_name) or omega is None \
            else f"every point at Omega = {omega:g}. "
        fig.supxlabel(speed + self.omega_note(), fontsize=7)
        return fig


def _values(name: str, values: Sequence[float]) -> np.ndarray:
    try:
        arr = np.asarray(values, float).ravel()
    except (TypeError, ValueError):
        raise ValueError(f"axis {name!r} needs numbers (got {values!r})") from None
    if arr.size == 0 or not np.all(np.isfinite(arr)):
        bad = "no values" if arr.size == 0 else f"{int(np.sum(~np.isfinite(arr)))} of " \
            f"{arr.size} values not finite"
        raise ValueError(f"axis {name!r} needs finite values (got {bad})")
    return arr


def check_map_size(nx: int, ny: int, n_balls: Sequence[int], n_members: int,
                   names: tuple[str, str, str, str] = ("x", "y", "n_balls", "n_members")
                   ) -> None:
    """Raise ValueError, naming the argument (``names``: how the caller calls the grid sizes,
    the ball counts and the members), for a map larger than :data:`MAX_MAP_TASKS` tasks or
    a family sampling beyond :data:`~abb_gym.analysis.rotating_frame.MAX_FAMILY_CANDIDATES`
    (checked before any grid is built)."""
    tasks = float(nx) * float(ny) * max(1, len(n_balls))
    if tasks > MAX_MAP_TASKS:
        raise ValueError(f"{names[0]} x {names[1]} x {names[2]} = {nx} x {ny} x {len(n_balls)} "
                         f"= {tasks:.3g} map tasks; at most {MAX_MAP_TASKS:.0e}: use fewer "
                         f"points or ball counts")
    for n in n_balls:
        try:
            check_family_size(int(n), n_members)
        except ValueError as exc:
            raise ValueError(f"{names[3]}: {exc}") from None


def stability_map(base: Groups | Scene, x: tuple[str, Sequence[float]],
                  y: tuple[str, Sequence[float]], *, n_balls: Sequence[int] | None = None,
                  omega: float = 2.0, n_members: int = 13, tol: float = DEFAULT_TOL,
                  workers: int | None = None, progress: bool = True,
                  length_scale: float | None = None, chunksize: int | None = None,
                  executor: Executor | None = None) -> StabilityMap:
    """Balanced-state stability over the grid ``x`` x ``y``.

    Parameters
    ----------
    base : Groups or Scene
    x, y : (axis name, values) - names as in the module docstring
    n_balls : ball counts to evaluate at the same eta_total (default: the base's count and,
        for overlays, 2 and 3); the first one is the shaded one in :meth:`StabilityMap.plot`
    omega : speed ratio used when neither axis is ``Omega`` (always checked: > 0)
    n_members : family members per point (an integer >= 1) (Lu & Hung discretisation, see
        :func:`~abb_gym.analysis.rotating_frame.balanced_family`)
    workers : local processes (default: all cores; 1 runs in this process); shorthand for
        ``executor=Executor(workers=workers)``
    progress : show a tqdm bar
    chunksize : points sent to a worker at once (default: automatic)
    executor : where to run (:class:`abb_gym.execution.Executor`: processes, Ray, resume
        directory, retries); give either this or ``workers``/``chunksize``
    """
    xname, xv = x[0], _values(x[0], x[1])
    yname, yv = y[0], _values(y[0], y[1])
    if xname == yname:
        raise ValueError(f"x and y must be different parameters (both {xname!r})")
    # every input is checked here, before any task is dispatched: a bad one is one ValueError,
    # not the same error from every task (and no worker starts for nothing)
    if isinstance(n_members, bool) or not isinstance(n_members, (int, np.integer)) \
            or n_members < 1:
        raise ValueError(f"n_members must be an integer >= 1 (got {n_members!r})")
    n_members = int(n_members)
    _check_omega(omega)  # even when an axis is Omega: a nan here is a mistake
    try:
        tol = float(tol)
    except (TypeError, ValueError):
        tol = math.nan
    if not (math.isfinite(tol) and tol > 0):
        raise ValueError(f"tol must be a finite number > 0 (got {tol!r})")
    g0, _ = resolve_groups(base, {}, length_scale)
    if n_balls is None:
        n_balls = tuple(dict.fromkeys([g0.n_balls, 3, 2]))
    if isinstance(n_balls, (str, bytes)) or not all(
            isinstance(n, (int, np.integer)) and not isinstance(n, (bool, np.bool_))
            for n in n_balls):
        raise ValueError(f"n_balls must be ball counts, integers in [1, {MAX_BALLS}] (got "
                         f"{n_balls!r:.80})")
    n_balls = tuple(int(n) for n in n_balls)
    if not n_balls or any(n < 1 or n > MAX_BALLS for n in n_balls):
        raise ValueError(f"n_balls must be ball counts, integers in [1, {MAX_BALLS}] (got "
                         f"{n_balls})")
    check_map_size(len(xv), len(yv), n_balls, n_members)
    tasks = []
    for yval in yv:
        for xval in xv:
            g, om = resolve_groups(base, {xname: xval, yname: yval}, length_scale)
            om = omega if om is None else _check_omega(om)
            for n in n_balls:
                gn = g if n == g.n_balls else g.with_ball_count(n)
                tasks.append((gn, float(om), n_members, tol))
    if executor is None:
        executor = Executor(workers=workers, chunksize=chunksize, progress=progress)
    elif workers is not None or chunksize is not None:
        raise ValueError("give workers and chunksize through the executor when passing one "
                         f"(got workers={workers!r}, chunksize={chunksize!r})")
    else:
        executor = executor.replace(progress=executor.progress and progress)
    results = executor.map(_evaluate, tasks, desc="stability map")
    shape = (len(yv), len(xv))
    data = {n: {f: np.zeros(shape, dtype=bool if f in ("exists", "union_stable", "all_stable")
                            else float) for f in MAP_FIELDS} for n in n_balls}
    k = 0
    for iy in range(len(yv)):
        for ix in range(len(xv)):
            for n in n_balls:
                for f, v in zip(MAP_FIELDS, results[k]):
                    data[n][f][iy, ix] = v
                k += 1
    def fmt(v):
        return "(" + ", ".join(f"{x:.4g}" for x in v) + ")" if isinstance(v, tuple) else f"{v:.4g}"
    desc = base.name if isinstance(base, Scene) else \
        ", ".join(f"{k}={fmt(getattr(g0, k))}" for k in ("eta", "mu", "delta", "zeta", "zeta_b")
                  if k not in (xname, yname))
    wn = None
    if isinstance(base, Scene) and not ({xname, yname} - _GROUP_AXES - {"Omega"}):
        wn = math.sqrt(base.support_stiffness_x / base.total_mass)
    return StabilityMap(x_name=xname, x_values=xv, y_name=yname, y_values=yv,
                        n_balls=n_balls, data=data, base_description=desc,
                        settings={"omega": omega, "n_members": n_members, "tol": tol},
                        natural_frequency=wn)


def onset_speed(system: Groups | Scene, omega_min: float, omega_max: float,
                criterion: str = "union", n_members: int = 13, step: float = 0.01,
                tol: float = DEFAULT_TOL, refine: bool = True) -> float:
    """Lowest speed ratio in [omega_min, omega_max] above which the balanced state stays
    stable (``criterion`` "union" or "all" members), scanning in ``step`` and refining the
    last unstable-to-stable change by bisection to 1e-4.  nan if never stable at omega_max.
    """
    if criterion not in ("union", "all"):
        raise ValueError(f"criterion must be 'union' or 'all' (got {criterion!r})")
    if not (0 < omega_min < omega_max):
        raise ValueError(f"need 0 < omega_min < omega_max (got {omega_min}, {omega_max})")
    g, _ = resolve_groups(system, {})

    def ok(om: float) -> bool:
        fs = family_stability(g, om, n_members, tol)
        return fs.union_stable if criterion == "union" else fs.all_stable

    grid = np.arange(omega_min, omega_max + 0.5 * step, step)
    flags = [ok(o) for o in grid]
    if not flags[-1]:
        return math.nan
    bad = [k for k, f in enumerate(flags) if not f]
    if not bad:
        return float(grid[0])
    lo, hi = grid[bad[-1]], grid[bad[-1] + 1]
    while refine and hi - lo > 1e-4:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if ok(mid) else (mid, hi)
    return float(hi)
