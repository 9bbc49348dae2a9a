"""Cost of the equations of motion per environment: one right-hand side
(:func:`abb_gym.physics.model.accelerations_block`) per lane, at several block widths, as the
kernels compile it (``noalias``: :mod:`abb_gym._numba`) and without the no-alias promise,
side by side in one process.

    python -m abb_gym.benchmarks.rhs_cost [SCENE]

Each variant is compiled here for the scene's ball count and effects (not cached: a few
seconds each) and called in a compiled loop, so no Python or dispatch cost is counted.  The
variant without the promise is compiled as the kernels were before it, with the large
run-time overlap-check budget without which that loop would not vectorise at all
(:func:`abb_gym._numba.allow_overlap_checks`, process wide: set by this benchmark, not by the
package).  A third column times the no-alias variant on float32 arrays (the
``precision="float32"`` option: :mod:`abb_gym.physics.batch`).  The
environments run 4 right-hand sides per RK4 substep, 8 substeps per 10 ms control interval on
``yoshida_odd``.
"""
from __future__ import annotations

import sys
import time

import numpy as np

from .._numba import NOALIAS, allow_overlap_checks, njit
from ..physics import drive_law as dl
from ..physics import load_scene
from ..physics import model as mdl
from ..physics.specialise import Specialised

__all__ = ["rhs_cost", "LANES"]

LANES = (1, 16, 32, 64, 128, 256, 1024)


def _inputs(scene, n_lanes: int, spec: int) -> list:
    """Arguments of the right-hand side for ``n_lanes`` lanes of ``scene`` (seeded ball
    angles, the rotor off its axis by 10 um, half the critical speed, 40 rad/s^2)."""
    p1, b1 = mdl.pack_parameters(scene)
    nb = scene.ball_count
    d1 = _drive_row(scene)
    s = np.zeros((2 * (3 + nb), n_lanes))
    s[3:3 + nb] = np.random.default_rng(0).uniform(-3.0, 3.0, (nb, n_lanes))
    s[0] = 1e-5  # m: the rotor off its axis
    return [np.zeros(n_lanes), s, np.repeat(p1[:, None], n_lanes, 1),
            np.repeat(b1[:, :, None], n_lanes, 2), np.repeat(d1[:, None], n_lanes, 1),
            np.zeros_like(s), mdl.make_work(nb, n_lanes), nb, spec]


def _drive_row(scene) -> np.ndarray:
    d = np.zeros(dl.N_DRIVE)
    dl.write_prescribed_row(d, 0.0, 0.0, 0.5 * scene.critical_speed, 40.0)
    return d


def _looped(noalias: bool) -> Specialised:
    rhs = njit(error_model="numpy", noalias=noalias)(mdl.accelerations_block.py_func)

    @njit(noalias=noalias)
    def many(t, s, p, b, d, ds, work, nb, spec, n):
        acc = 0.0
        for _ in range(n):
            rhs(t, s, p, b, d, ds, work, nb, spec)
            acc += ds[ds.shape[0] - 1, 0]
            t[0] += 1e-9  # a new time each call: nothing to hoist out of the loop
        return acc

    return Specialised(many, literal=(7, 8), names=("balls", mdl.EFFECTS))


def rhs_cost(scene: str = "yoshida_odd", lanes=LANES, calls: int = 2_000_000,
             repeats: int = 5) -> list[dict]:
    """Nanoseconds per right-hand side and lane (best of ``repeats``), with and without the
    no-alias promise, and with it in float32, for each block width in ``lanes``; ``calls``
    lane-evaluations per timing.  The two float64 variants give the same derivatives bit for
    bit (checked here)."""
    sc = load_scene(scene)
    spec = mdl.spec_of(mdl.pack_parameters(sc)[0], _drive_row(sc))
    allow_overlap_checks()
    variants = {"noalias": _looped(True), "plain": _looped(False)}
    variants["float32"] = variants["noalias"]
    rows = []
    for n_lanes in lanes:
        row = {"scene": scene, "lanes": n_lanes}
        results = []
        for name, fn in variants.items():
            args = _inputs(sc, n_lanes, spec)
            if name == "float32":
                args = [a.astype(np.float32) if isinstance(a, np.ndarray) else a for a in args]
            fn(*args, 1)
            results.append(args[5].copy())
            n = max(2000, calls // n_lanes)
            best = np.inf
            for _ in range(repeats):
                start = time.perf_counter()
                fn(*args, n)
                best = min(best, time.perf_counter() - start)
            row[f"{name}_ns"] = best / n / n_lanes * 1e9
        row["same_result"] = bool(np.array_equal(results[0], results[1]))
        row["speedup"] = row["plain_ns"] / row["noalias_ns"]
        rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    scene = argv[0] if argv else "yoshida_odd"
    if not NOALIAS:
        print("this numba does not take the noalias flag: both variants are the same")
    print(f"{'lanes':>6} {'noalias [ns]':>13} {'plain [ns]':>11} {'speed-up':>9}  same result"
          f"  {'float32 [ns]':>12}")
    for r in rhs_cost(scene):
        print(f"{r['lanes']:6d} {r['noalias_ns']:13.1f} {r['plain_ns']:11.1f} "
              f"{r['speedup']:8.2f}x  {str(r['same_result']):>11}  {r['float32_ns']:12.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
