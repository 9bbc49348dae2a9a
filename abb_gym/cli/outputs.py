"""Output paths of the subcommands, checked (and their folders created) before any computation.

A command that computes for minutes and then cannot write its result wastes the minutes: every
subcommand passes its output options through :func:`output_file` or :func:`output_folder`
first.  Both create the missing folders (as ``--plot`` always did) and raise ``ValueError``
(one line from ``abb-gym``) naming the option when the path cannot be written: a regular
file where a folder must be, a folder where a file must be, an empty name (which ``Path``
reads as the current folder), or no write permission.

A folder of reports (``--out`` of ``evaluate``, ``train``, ``study``, ``bench``, ``demo``) is
locked for the command's run (:func:`output_folder`): a second command writing the same
folder at the same time is refused in one line, instead of both finishing and the last one
silently replacing the first one's reports.  The lock is ``flock`` on the folder itself, so no
lock file is left in it and a killed command cannot leave a stale lock behind (the system
drops it with the process); ``abb-gym`` releases it when the command ends
(:func:`release_locks`).  Where ``flock`` does not exist (Windows) folders are not locked.
The files themselves are written whole or not at all (:mod:`abb_gym._files`).
"""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["check_path", "output_file", "output_folder", "output_image", "lock_folder",
           "release_locks"]

#: locked output folders of the running command: real path -> the open descriptor holding it
_LOCKS: dict[str, int] = {}


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


def _path(path: str | os.PathLike, option: str) -> Path:
    """``path`` as a Path; an empty or blank name (which ``Path`` reads as ".", the current
    folder) and names the system refuses (a NUL byte, too long) raise ValueError naming
    ``option``."""
    text = os.fspath(path) if isinstance(path, os.PathLike) else path
    if not isinstance(text, str) or not text.strip():
        raise ValueError(f"{option} must be a path (got {text!r:.80})")
    if "\x00" in text:  # Path.exists() says False for it; open() would raise later
        raise ValueError(f"{option} {text[:200]!r}: not a usable path (a NUL character)")
    p = Path(text)
    try:
        p.exists()
    except (OSError, ValueError) as exc:  # a name too long
        raise ValueError(f"{option} {text[:200]!r}: not a usable path "
                         f"({getattr(exc, 'strerror', None) or exc})") from None
    return p


def check_path(path: str | os.PathLike, option: str) -> Path:
    """``path`` as a Path, refused as :func:`output_folder` refuses it for its text (empty,
    blank, a NUL character, a name the system cannot take), without making anything: for
    commands that must refuse a bad path before they build an environment (and compile)."""
    return _checked(lambda p, _: p, path, option)


def _checked(make, path, option: str) -> Path:
    try:
        return make(_path(path, option), option)
    except OSError as exc:  # a name the system refuses further up (too long, a loop)
        raise ValueError(f"{option} {str(path)[:200]!r}: not a usable path "
                         f"({exc.strerror or exc})") from None


def _file(p: Path, option: str) -> Path:
    if p.is_dir():
        raise ValueError(f"{option} {str(p)!r} is a folder; give a file name")
    if p.exists() and not os.access(p, os.W_OK):
        raise ValueError(f"{option} {str(p)!r} exists and is not writable")
    _make_folder(p.parent, option, p)
    return p


def _folder(p: Path, option: str) -> Path:
    if p.exists() and not p.is_dir():
        raise ValueError(f"{option} {str(p)!r} is a file, not a folder")
    _make_folder(p, option, p)
    return p


def output_file(path: str | os.PathLike, option: str) -> Path:
    """``path`` as a file to be written later: its folder exists (created) and is writable,
    and ``path`` is not a folder nor empty.  ``option`` names the option in the message
    (``--json``)."""
    return _checked(_file, path, option)


def output_folder(path: str | os.PathLike, option: str, lock: bool = True) -> Path:
    """``path`` as a folder that files will be written into: created if missing; a regular
    file there or above it, and an empty name (not the current folder), are refused.  With
    ``lock`` (a folder of this command's reports) it is locked until the command ends
    (:func:`lock_folder`)."""
    folder = _checked(_folder, path, option)
    if lock:
        lock_folder(folder, option)
    return folder


def lock_folder(folder: str | os.PathLike, option: str) -> None:
    """Hold an exclusive lock on ``folder`` until :func:`release_locks`; a ValueError naming
    ``option`` if another process (or another command of this one) holds it."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no flock (see the module docstring)
        return
    key = os.path.realpath(folder)
    if key in _LOCKS:
        return
    fd = os.open(key, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise ValueError(f"{option} {str(folder)!r} is being written by another abb-gym "
                         f"command; wait until it has finished, or write elsewhere") from None
    _LOCKS[key] = fd


def release_locks() -> None:
    """Release every folder lock this process holds (the end of a command)."""
    while _LOCKS:
        _, fd = _LOCKS.popitem()
        try:
            os.close(fd)  # closing the descriptor drops its flock
        except OSError:
            pass


def output_image(path: str | os.PathLike, option: str) -> Path:
    """:func:`output_file` for a figure: the suffix must be a format matplotlib writes (none
    means PNG), checked before the run rather than when the figure is saved after it."""
    p = output_file(path, option)
    suffix = p.suffix[1:].lower()
    if suffix:
        from matplotlib.backend_bases import FigureCanvasBase
        formats = FigureCanvasBase.get_supported_filetypes()
        if suffix not in formats:
            raise ValueError(f"{option} {str(p)!r}: matplotlib cannot write {suffix!r} files; "
                             f"use one of {', '.join(sorted(formats))}")
    return p
