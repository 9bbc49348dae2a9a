"""The ``abb-gym`` command line.

Each subcommand lives in its own module of this package and defines ``register(subparsers)``,
which adds its parser and sets ``func`` to the function that runs it.  To add a subcommand,
write the module and list it in ``SUBCOMMANDS``; it checks its output paths before computing
(:mod:`abb_gym.cli.outputs`).

Failures are one line on stderr, never a traceback: bad input (``ValueError``) exits 2, a
simulation that cannot continue (:class:`abb_gym.SimulationError`) or a file that cannot be
written (``OSError``) exits 1.  A reader that closes stdout early (``abb-gym simulate --json |
head``) ends the command quietly with 141, the status of a process killed by SIGPIPE.  Ctrl-C
prints ``interrupted: N of M tasks stored; rerun the same command to resume`` (N and M over
the whole command: :class:`abb_gym.execution.core.TaskTally`) and exits 130, the status of a
process ended by SIGINT.  The output folders a command locked are released when it ends
(:mod:`abb_gym.cli.outputs`).
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import re
import sys

NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$|^-(inf|infinity|nan)$",
                             re.IGNORECASE)

SUBCOMMANDS = [
    "abb_gym.cli.simulate",
    "abb_gym.cli.demo",
    "abb_gym.cli.stability",
    "abb_gym.cli.bench",
    "abb_gym.cli.evaluate",
    "abb_gym.cli.tune",
    "abb_gym.cli.study",
    "abb_gym.cli.train",
    "abb_gym.cli.kernels",
    "abb_gym.cli.render",
    "abb_gym.cli.convert",
    "abb_gym.cli.listing",
    "abb_gym.cli.new_scene",
]


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser whose usage errors are one line on stderr and exit 2, like every
    other error of ``abb-gym`` (argparse prints the whole usage first, a dozen lines for
    ``simulate``); the line says where the usage is.  Subcommand parsers inherit it.

    Negative numbers in any float notation are values, not options: argparse (before Python
    3.13) reads ``--ball-angles-deg 0 -1e-3`` or ``--dwell-accel -inf`` as an unknown option
    ``-1e-3`` (no option of abb-gym looks like a number)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBER

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {_one_line(message)} (usage: {self.prog} --help)\n")


class HelpFormatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Descriptions as written (their examples keep their lines) but without the docstrings'
    reST markup; options with their defaults, where there is one worth showing."""

    def _format_text(self, text):
        return super()._format_text(text.replace("``", "").replace("::\n", ":\n"))

    def _get_help_string(self, action):
        text = action.help or ""
        if action.default in (None, False, [], argparse.SUPPRESS) or "default" in text:
            return text
        return super()._get_help_string(action)


def _with_defaults(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = HelpFormatter
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                _with_defaults(sub)


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__
    parser = ArgumentParser(
        prog="abb-gym", description="Automatic ball balancer simulator and Gymnasium suite")
    parser.add_argument("--version", action="version", version=f"abb-gym {__version__}")
    parser.add_argument("--configs", action="append", default=[], metavar="DIR",
                        help="a folder of your own scenes/, envs/, baselines/, ppo/ and "
                             "agents/, searched before the shipped ones (repeatable; also "
                             "$ABB_GYM_CONFIGS)")
    sub = parser.add_subparsers(dest="command", required=True)
    for name in SUBCOMMANDS:
        importlib.import_module(name).register(sub)
    _with_defaults(parser)
    return parser


#: keywords of ``gym.make_vec`` itself and those the sweep commands set: never
#: ``--env-kwargs`` entries (a duplicate keyword would be a TypeError deep in a task)
RESERVED_ENV_KWARGS = {"id": None, "num_envs": None, "vectorization_mode": None,
                       "vector_kwargs": None, "wrappers": None, "record_history": None,
                       "scene": "--scene", "preset": "--preset"}


def check_env_kwargs(env_kwargs: dict, option: str, allowed: tuple = ()) -> dict:
    """``env_kwargs`` (from ``option``) without the keywords the command sets itself
    (:data:`RESERVED_ENV_KWARGS`, less ``allowed``): those raise ValueError naming them."""
    for key in env_kwargs:
        if key in RESERVED_ENV_KWARGS and key not in allowed:
            use = RESERVED_ENV_KWARGS[key]
            raise ValueError(f"{option} {key}: set by the command itself"
                             + (f"; use {use}" if use else "") + " (an environment keyword "
                             "such as control_interval=0.02 or 'reward={residual: 4}' goes "
                             "here)")
    return env_kwargs


EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE, what a shell reports for a writer killed by it
EXIT_INTERRUPTED = 130  # 128 + SIGINT, what a shell reports for a command ended by Ctrl-C


def _one_line(text: object) -> str:
    return " ".join(str(text).split())


def _silence_stdout() -> None:
    """Point the process's stdout at /dev/null, so that the interpreter's final flush of the
    unwritable buffer does not raise BrokenPipeError again (Python's documented remedy).
    Only the real stdout: a replaced sys.stdout (tests, embedding) is left alone."""
    if sys.stdout is not sys.__stdout__ or sys.stdout is None:
        return
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):
        pass


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from ..execution.core import task_tally
    from .outputs import release_locks
    task_tally().reset()
    try:
        with _command_settings(args):
            return _run(args)
    except KeyboardInterrupt:  # Ctrl-C, also while the line below is printed
        try:
            print(f"abb-gym {args.command}: {task_tally().interrupted_message()}",
                  file=sys.stderr)
        except KeyboardInterrupt:
            pass
        return EXIT_INTERRUPTED
    finally:
        release_locks()


@contextlib.contextmanager
def _command_settings(args: argparse.Namespace):
    """For the command's run: warnings as one line each (``abb-gym CMD: warning: ...``), and
    ``--trust-pickle`` as the environment variable the agent loaders read, so that the
    worker processes the command starts trust the same files."""
    import warnings
    from ..resources import TRUST_PICKLE_ENV as TRUST_ENV
    saved_format, saved_trust = warnings.formatwarning, os.environ.get(TRUST_ENV)

    def one_line(message, category, filename, lineno, line=None):
        return f"abb-gym {args.command}: warning: {_one_line(message)}\n"

    warnings.formatwarning = one_line
    if getattr(args, "trust_pickle", False):
        os.environ[TRUST_ENV] = "1"
    try:
        yield
    finally:
        warnings.formatwarning = saved_format
        if saved_trust is None:
            os.environ.pop(TRUST_ENV, None)
        else:
            os.environ[TRUST_ENV] = saved_trust


def _run(args: argparse.Namespace) -> int:
    from ..physics import SimulationError
    try:
        from .. import resources
        for folder in args.configs:
            try:
                resources.add_user_folder(folder)
            except ValueError as exc:
                raise ValueError(f"--configs: {exc}") from None
        code = int(args.func(args) or 0)
        # flush here, inside the try: a closed pipe then surfaces now, not at exit
        sys.stdout.flush()
        return code
    except BrokenPipeError:
        _silence_stdout()
        return EXIT_BROKEN_PIPE
    except ValueError as exc:  # bad input: one clear line, no traceback
        print(f"abb-gym {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except SimulationError as exc:  # valid input the integrator cannot follow
        print(f"abb-gym {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return 1
    except OSError as exc:  # a disk that fills or a permission lost after the checks
        where = f" {str(exc.filename)!r}" if exc.filename else ""
        print(f"abb-gym {args.command}: error: cannot access{where}: "
              f"{_one_line(exc.strerror or exc)}", file=sys.stderr)
        return 1
