"""Files written whole or not at all: a temporary file in the target's folder, renamed into
place (:func:`os.replace`, atomic on POSIX and Windows).

Why: a report, a result record or an agent file that a crash, a full disk or Ctrl-C
interrupts half-way must not replace a good one with half of a new one, and a reader (a
second command, a resumed sweep) must see either the old file or the new one.  A failed
write leaves the old file as it was and removes its temporary file.

A set of files that belong together (the files of one report) is written with
:func:`replacing_together`: every file to its temporary name first, then all renamed at the
end, so that a failure half-way leaves the previous set as it was, not half of each.

Temporary files are named ``.<name>.<random>.part<suffix>`` (the suffix kept so that
matplotlib and imageio pick the format from it); they get the permissions an ordinary
``open(path, "w")`` would give (``0o666`` less the umask), not ``mkstemp``'s ``0o600``.
"""
from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import IO, Iterator

__all__ = ["replacing_path", "replacing", "replacing_together", "write_text", "write_bytes",
           "savefig"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_MODE = 0o666 & ~_umask()


@contextlib.contextmanager
def replacing_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; when the block ends without an exception the
    temporary file becomes ``path`` in one rename, otherwise it is removed."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".part{path.suffix}",
                               dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, _MODE)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


class _Together:
    """The temporary paths of :func:`replacing_together` and their targets."""

    def __init__(self) -> None:
        self.pending: list[tuple[Path, Path]] = []

    def path(self, target: str | os.PathLike) -> Path:
        """A temporary path to write ``target``'s content to (renamed at the end)."""
        target = Path(target)
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=f".part{target.suffix}",
                                   dir=target.parent)
        os.close(fd)
        self.pending.append((Path(tmp), target))
        return Path(tmp)


@contextlib.contextmanager
def replacing_together() -> Iterator[_Together]:
    """Yield an object whose ``path(target)`` gives a temporary path for each file of a set;
    when the block ends without an exception every file is renamed into place, otherwise
    every temporary file is removed and the targets stay as they were."""
    batch = _Together()
    try:
        yield batch
        for tmp, _ in batch.pending:
            os.chmod(tmp, _MODE)
        for tmp, target in batch.pending:
            os.replace(tmp, target)
    except BaseException:
        for tmp, _ in batch.pending:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        raise


@contextlib.contextmanager
def replacing(path: str | os.PathLike, mode: str = "w", **open_kwargs) -> Iterator[IO]:
    """``open(path, mode)`` through :func:`replacing_path`: the file appears when the block
    ends, whole."""
    with replacing_path(path) as tmp:
        with open(tmp, mode, **open_kwargs) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())


def write_text(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` whole or not at all; returns ``path``."""
    with replacing(path, "w", encoding=encoding) as fh:
        fh.write(text)
    return Path(path)


def write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` whole or not at all; returns ``path``."""
    with replacing(path, "wb") as fh:
        fh.write(data)
    return Path(path)


def savefig(fig, path: str | os.PathLike, **kwargs) -> Path:
    """``fig.savefig(path, **kwargs)`` whole or not at all; returns the path written.  The
    format comes from ``path``'s suffix; without one it is PNG and ``.png`` is appended, as
    matplotlib does."""
    path = Path(path)
    if not path.suffix:
        path = path.with_suffix(".png")
    kwargs.setdefault("format", path.suffix[1:].lower())
    with replacing_path(path) as tmp:
        fig.savefig(tmp, **kwargs)
    return path
