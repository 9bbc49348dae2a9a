"""Output paths of the subcommands, checked (and their folders created) before any computation.

A command that computes for minutes and then cannot write its result wastes the minutes: every
subcommand passes its output options through :func:`output_file` or :func:`output_folder`
first.  Both create the missing folders (as ``--plot`` always did) and raise ``ValueError``
(one line from ``abb-gym``) naming the option when the path cannot be written: a regular
file where a folder must be, a folder where a file must be, or no write permission.
"""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["output_file", "output_folder"]


def _blocking_file(path: Path) -> Path | None:
    """The nearest existing ancestor of ``path`` if it is not a folder, else None."""
    for parent in path.parents:
        if parent.exists():
            return None if parent.is_dir() else parent
    return None


def _make_folder(folder: Path, option: str, target: Path) -> None:
    blocker = _blocking_file(folder / "x")
    if blocker is not None:
        raise ValueError(f"{option} {str(target)!r}: {str(blocker)!r} is a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"{option} {str(target)!r}: cannot create the folder "
                         f"{str(folder)!r} ({exc.strerror or exc})") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ValueError(f"{option} {str(target)!r}: the folder {str(folder)!r} is not "
                         f"writable")


def output_file(path: str | os.PathLike, option: str) -> Path:
    """``path`` as a file to be written later: its folder exists (created) and is writable,
    and ``path`` is not a folder.  ``option`` names the option in the message (``--json``)."""
    p = Path(path)
    if p.is_dir():
        raise ValueError(f"{option} {str(p)!r} is a folder; give a file name")
    if p.exists() and not os.access(p, os.W_OK):
        raise ValueError(f"{option} {str(p)!r} exists and is not writable")
    _make_folder(p.parent, option, p)
    return p


def output_folder(path: str | os.PathLike, option: str) -> Path:
    """``path`` as a folder that files will be written into: created if missing; a regular
    file there or above it is refused."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ValueError(f"{option} {str(p)!r} is a file, not a folder")
    _make_folder(p, option, p)
    return p
