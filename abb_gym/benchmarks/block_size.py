"""The vector environment's speed against its block size (lanes per block), in one process.

    python -m abb_gym.benchmarks.block_size [--envs N] [--precision P] [--preset NAME]
                                            [--lanes 64 128 ...] [--rounds R]

One vector environment per block size (:data:`abb_gym.physics.batch.MAX_LANES` set while
each is built; the block size each got is reported, since few sub-environments cap it) of
the ``bench speed`` kind
(``RunUpSpeed-v0`` on ``yoshida_odd``, 100-step episodes, so resets are included), all in
one process and stepped in alternating bursts of :data:`BURST` steps.  The machine's speed
drifts by 10-25 % within minutes; bursts a fraction of a second apart see the same machine,
so the ratio of two sizes' burst times is steadier than any whole-process comparison.
Printed per size: the median and best env-steps per second; per size after the first: the
median and quartiles of the burst-time ratio (first size / this size: above 1, this size is
faster).  This is how :data:`~abb_gym.physics.batch.MAX_LANES` was chosen (its comment says
why).
"""
from __future__ import annotations

import argparse
import sys
import time
from contextlib import contextmanager
from typing import Iterator, Sequence

import numpy as np

from ..physics import batch
from ..physics.methods import PRECISIONS
from ..progress import ProgressBar
from .env_speed import make_vector

__all__ = ["block_size_rates", "BURST"]

BURST = 50  # steps per timed burst: a tenth of a second at 1024 sub-environments


@contextmanager
def _max_lanes(lanes: int) -> Iterator[None]:
    saved = batch.MAX_LANES
    batch.MAX_LANES = lanes
    try:
        yield
    finally:
        batch.MAX_LANES = saved


def block_size_rates(num_envs: int = 1024, lanes: Sequence[int] = (64, 128),
                     precision: str = "float64", preset: str = "train", rounds: int = 100,
                     progress: bool = False) -> list[dict]:
    """Env-steps per second of the vector environment with at most ``lanes[i]`` lanes per
    block (module docstring): one dict per size with ``lanes`` (the block size the
    environment got), ``median`` and ``best`` [env-steps/s] over ``rounds`` bursts, and, for
    every size after the first, ``ratio`` = (median, lower quartile, upper quartile) of the
    first size's burst time over this size's in the same round."""
    if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 2:
        raise ValueError(f"num_envs must be an integer >= 2 (got {num_envs!r})")
    sizes = list(lanes)
    if len(sizes) < 2 or any(isinstance(v, bool) or not isinstance(v, int) or v < 1
                             or v & (v - 1) for v in sizes):
        raise ValueError(f"lanes must be two or more powers of two >= 1 (got {lanes!r})")
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS} (got {precision!r})")
    if isinstance(rounds, bool) or not isinstance(rounds, int) or rounds < 2:
        raise ValueError(f"rounds must be an integer >= 2 (got {rounds!r})")
    envs = []
    try:
        for size in sizes:
            with _max_lanes(size):
                envs.append(make_vector(num_envs, "specialised", precision=precision,
                                        preset=preset))
            envs[-1].reset(seed=0)
        return _race(envs, sizes, num_envs, rounds, progress)
    finally:
        for env in envs:
            env.close()


def _race(envs: list, sizes: list[int], num_envs: int, rounds: int, progress: bool
          ) -> list[dict]:
    """The timed bursts of :func:`block_size_rates` and its rows."""
    actions = np.random.default_rng(0).uniform(
        0.2, 1.0, size=(BURST, num_envs, 1)).astype(np.float32)
    for env in envs:  # compile (or load) and warm up
        for a in actions:
            env.step(a)
    times = np.zeros((rounds, len(envs)))
    for r in ProgressBar(range(rounds), desc="bursts", disable=not progress, file=sys.stderr):
        # alternate which size goes first, so neither always follows the other
        for i in (range(len(envs)) if r % 2 == 0 else reversed(range(len(envs)))):
            start = time.perf_counter()
            for a in actions:
                envs[i].step(a)
            times[r, i] = time.perf_counter() - start
    rows = []
    for i, env in enumerate(envs):
        rate = num_envs * BURST / times[:, i]
        row = {"lanes": int(env.unwrapped._bufs.blocks.lanes), "requested": sizes[i],
               "median": float(np.median(rate)), "best": float(rate.max())}
        if i:
            ratio = times[:, 0] / times[:, i]
            row["ratio"] = tuple(float(v) for v in np.percentile(ratio, [50, 25, 75]))
        rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m abb_gym.benchmarks.block_size",
        description="Vector-environment speed against lanes per block, in one process.")
    parser.add_argument("--envs", type=int, default=1024, help="sub-environments (default 1024)")
    parser.add_argument("--lanes", type=int, nargs="+", default=[64, 128],
                        help="block sizes to compare, powers of two (default 64 128)")
    parser.add_argument("--precision", default="float64", help="float64 (default) or float32")
    parser.add_argument("--preset", default="train", help="environment preset (default train)")
    parser.add_argument("--rounds", type=int, default=100,
                        help=f"bursts of {BURST} steps per size (default 100)")
    args = parser.parse_args(argv)
    try:
        rows = block_size_rates(args.envs, args.lanes, args.precision, args.preset,
                                args.rounds, progress=True)
    except ValueError as err:
        parser.error(str(err))
    print(f"{args.envs} sub-environments, {args.precision}, preset {args.preset}, "
          f"{args.rounds} bursts of {BURST} steps per size")
    print(f"{'lanes':>6} {'median [env-steps/s]':>21} {'best':>10}  "
          f"burst-time ratio to {rows[0]['lanes']} lanes (median [quartiles])")
    for row in rows:
        ratio = row.get("ratio")
        text = (f"{ratio[0]:.3f} [{ratio[1]:.3f}, {ratio[2]:.3f}]" if ratio else "-")
        note = "" if row["lanes"] == row["requested"] else f" (asked {row['requested']})"
        print(f"{row['lanes']:6d} {row['median']:21,.0f} {row['best']:10,.0f}  {text}{note}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
