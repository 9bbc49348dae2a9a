"""The ``abb-gym`` command line.

Each subcommand lives in its own module of this package and defines ``register(subparsers)``,
which adds its parser and sets ``func`` to the function that runs it.  To add a subcommand,
write the module and list it in ``SUBCOMMANDS``.
"""
from __future__ import annotations

import argparse
import importlib
import sys

SUBCOMMANDS = [
    "abb_gym.cli.simulate",
    "abb_gym.cli.demo",
    "abb_gym.cli.stability",
    "abb_gym.cli.bench",
    "abb_gym.cli.evaluate",
    "abb_gym.cli.tune",
    "abb_gym.cli.study",
    "abb_gym.cli.train",
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="abb-gym", description="Automatic ball balancer simulator and Gymnasium suite")
    parser.add_argument("--configs", action="append", default=[], metavar="DIR",
                        help="a folder of your own scenes/, envs/, baselines/, ppo/ and "
                             "agents/, searched before the shipped ones (repeatable; also "
                             "$ABB_GYM_CONFIGS)")
    sub = parser.add_subparsers(dest="command", required=True)
    for name in SUBCOMMANDS:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        from .. import resources
        for folder in args.configs:
            resources.add_user_folder(folder)
        return int(args.func(args) or 0)
    except ValueError as exc:  # bad input: one clear line, no traceback
        print(f"abb-gym {args.command}: error: {exc}", file=sys.stderr)
        return 2
