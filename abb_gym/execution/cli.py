"""Shared command-line options, so every sweep command offers the same execution choices.

Usage in a subcommand module (see :mod:`abb_gym.cli.stability`)::

    from ..execution.cli import add_executor_arguments, executor_from_args

    def register(subparsers):
        p = subparsers.add_parser("my-sweep", ...)
        ...
        add_executor_arguments(p)

    def run(args):
        ex = executor_from_args(args, progress=not args.no_progress)
        results = ex.map(my_task, tasks, desc="my sweep")

Options added (one argument group, "execution"):

======================  =========================================================================
option                  meaning
======================  =========================================================================
``--workers N``         local worker processes (default: all cores); with Ray, at most N tasks
                        at once (and the CPUs of a local instance)
``--ray``               run on a new local Ray instance (or the one ``RAY_ADDRESS`` names)
``--ray-address ADDR``  run on an existing Ray cluster (``auto``, ``HOST:6379``,
                        ``ray://HOST:10001``); implies ``--ray``
``--resume-dir DIR``    keep finished results in DIR; rerunning with the same DIR resumes
``--retries N``         reruns of a failed task before the command fails (default 2); a task
                        raising ValueError or TypeError (bad input) is never rerun
======================  =========================================================================
"""
from __future__ import annotations

import argparse
from typing import Any

from .core import Executor

__all__ = ["add_executor_arguments", "executor_from_args"]


def _int_at_least(minimum: int):
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer >= {minimum} "
                                             f"(got {text!r})") from None
        if v < minimum:
            raise argparse.ArgumentTypeError(f"must be an integer >= {minimum} (got {v})")
        return v
    return parse


def add_executor_arguments(parser: argparse.ArgumentParser, *, resume: bool = True,
                           default_retries: int = 2) -> argparse._ArgumentGroup:
    """Add ``--workers``, ``--ray``, ``--ray-address``, ``--retries`` and (with ``resume``)
    ``--resume-dir`` to ``parser``; returns the argument group."""
    g = parser.add_argument_group(
        "execution", "where the tasks run (the results do not depend on it)")
    g.add_argument("--workers", type=_int_at_least(1), default=None, metavar="N",
                   help="local worker processes (default: all cores; 1 = this process); "
                        "with Ray: at most N tasks at once")
    g.add_argument("--ray", action="store_true",
                   help="run on a local Ray instance (needs abb-gym[cluster])")
    g.add_argument("--ray-address", default=None, metavar="ADDRESS",
                   help="run on an existing Ray cluster: auto, HOST:6379 or ray://HOST:10001 "
                        "(implies --ray)")
    if resume:
        g.add_argument("--resume-dir", default=None, metavar="DIR",
                       help="keep each finished task's result in DIR; rerunning with the same "
                            "DIR skips finished tasks")
    g.add_argument("--retries", type=_int_at_least(0), default=default_retries, metavar="N",
                   help=f"reruns of a task whose worker died or raised (default "
                        f"{default_retries}); bad input (ValueError) is never rerun")
    return g


def executor_from_args(args: argparse.Namespace, **overrides: Any) -> Executor:
    """The :class:`Executor` the options of :func:`add_executor_arguments` describe.

    ``overrides`` (e.g. ``progress=False``, ``chunksize=8``, ``store=...``) take precedence.
    Raises ValueError (reported as one line by ``abb-gym``) for inconsistent options.
    """
    resume = getattr(args, "resume_dir", None)
    if resume is not None:  # named as the option, before any task (the store checks again)
        from pathlib import Path
        if not str(resume).strip() or "\x00" in str(resume):
            raise ValueError(f"--resume-dir must be a folder path (got {resume!r:.200})")
        try:
            blocked = Path(resume).exists() and not Path(resume).is_dir()
        except (OSError, ValueError) as exc:
            raise ValueError(f"--resume-dir {str(resume)[:200]!r}: not a usable path "
                             f"({getattr(exc, 'strerror', None) or exc})") from None
        if blocked:
            raise ValueError(f"--resume-dir {str(resume)!r} is a file, not a folder")
    kw: dict[str, Any] = dict(workers=getattr(args, "workers", None),
                              ray=bool(getattr(args, "ray", False)),
                              ray_address=getattr(args, "ray_address", None),
                              store=getattr(args, "resume_dir", None),
                              retries=getattr(args, "retries", 2))
    kw.update(overrides)
    ex = Executor(**kw)
    if ex.ray:
        # fail now with the install hint, not after the sweep has been set up
        from .ray_backend import import_ray
        import_ray()
    return ex
