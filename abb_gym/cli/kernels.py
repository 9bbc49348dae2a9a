"""``abb-gym build-kernels``: compile the kernels ahead of time (:mod:`abb_gym.kernels`).

The first use of each compiled kernel otherwise compiles it (20-50 s each, announced on
stderr).  This command compiles the general kernels of ``simulate``, the environments and
batch simulation, and the vectorised kernels of the default scene, into numba's on-disk cache
(a few minutes once; a second run only loads them).  A wheel built afterwards ships them.
"""
from __future__ import annotations

import argparse

__all__ = ["register", "run"]


def register(subparsers) -> None:
    p = subparsers.add_parser("build-kernels", help="compile the kernels ahead of time",
                              description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..kernels import build
    for label, seconds in build(progress=not args.quiet):
        print(f"{seconds:7.1f} s  {label}")
    return 0
