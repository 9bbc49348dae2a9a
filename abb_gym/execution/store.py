"""On-disk results of finished tasks, so an interrupted sweep resumes where it stopped.

Layout: ``<directory>/<task id>.pkl``, one small pickle per finished task, holding
``{"format": 1, "task_id": ..., "result": ...}``.  Only the driver (the process that called
:func:`~abb_gym.execution.run_tasks`) writes, so there is one writer per directory and run.

Each file is written to a temporary name (``.<task id>.<random>.tmp``) in the same directory
and then renamed with :func:`os.replace`, which is atomic on POSIX and Windows: a reader (or a
resumed run after a crash at any instant) sees either no file or the complete file, never half
of one.  Temporary files are never read as results; those a killed sweep left behind are
deleted by the next run's first write once they are older than :data:`STALE_TMP_AGE` seconds
(an actual write takes milliseconds; the margin protects another run writing there now).

Damage is reported, never silently skipped:

* a result file that cannot be read back (truncated by a power loss, overwritten, or not
  written by this store) counts as missing: a :class:`RuntimeWarning` names the file, the task
  is recomputed and its new result replaces the file;
* a *directory* named like a result file raises a ValueError naming it, before anything runs
  (the result could never be saved there); remove it or use another directory.

Files are unpickled: open only stores you (or your own runs) wrote.

Ids come from :func:`~abb_gym.execution.ids.task_id`, which names the task function and the
spec, so several sweeps may share one directory.  The store does not know when the code of a
task function changes: start a new directory (or :meth:`ResultStore.clear`) after such a change.
"""
from __future__ import annotations

import os
import pickle
import re
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any, Iterator

__all__ = ["ResultStore", "STALE_TMP_AGE"]

_ID = re.compile(r"^[0-9a-f]{8,64}$")
_FORMAT = 1
#: Seconds after which a leftover temporary file is taken as stale and deleted.
STALE_TMP_AGE = 600.0


class ResultStore:
    """A directory of finished task results keyed by task id (created on first use)."""

    def __init__(self, directory: str | os.PathLike) -> None:
        if isinstance(directory, ResultStore):
            directory = directory.directory
        if directory is None or str(directory) == "":
            raise ValueError("store directory must be a non-empty path")
        self.directory = Path(directory)
        if self.directory.exists() and not self.directory.is_dir():
            raise ValueError(f"store {str(self.directory)!r} exists and is not a directory")
        self._tidied = False  # stale temporary files removed (done by the first save)

    def __repr__(self) -> str:
        return f"ResultStore({str(self.directory)!r})"

    def _path(self, tid: str) -> Path:
        if not _ID.match(tid):
            raise ValueError(f"task id must be 8-64 lowercase hex digits (got {tid!r})")
        return self.directory / f"{tid}.pkl"

    def _file(self, tid: str) -> Path:
        """The result file of ``tid``; a ValueError naming it if a directory is in its way."""
        path = self._path(tid)
        if path.is_dir():
            raise ValueError(f"store {str(self.directory)!r}: {str(path)!r} is a directory, "
                             f"where the result of task {tid} belongs; remove it or use "
                             f"another directory")
        return path

    def __contains__(self, tid: str) -> bool:
        return self._path(tid).is_file()

    def load(self, tid: str) -> tuple[bool, Any]:
        """``(True, result)`` if task ``tid`` is stored and readable, else ``(False, None)``
        (with a :class:`RuntimeWarning` naming the file when it exists but is unreadable)."""
        path = self._file(tid)
        try:
            with open(path, "rb") as fh:
                rec = pickle.load(fh)
        except FileNotFoundError:
            return False, None
        except Exception as exc:
            return self._unreadable(path, f"{type(exc).__name__}: {exc}")
        if not isinstance(rec, dict) or rec.get("format") != _FORMAT or rec.get("task_id") != tid \
                or "result" not in rec:
            return self._unreadable(path, "not a result record of this store")
        return True, rec["result"]

    @staticmethod
    def _unreadable(path: Path, why: str) -> tuple[bool, None]:
        # recompute rather than fail: the sweep heals the store by writing the file anew
        warnings.warn(f"ignoring unreadable result file {str(path)!r} ({why}); the task is "
                      f"recomputed", RuntimeWarning, stacklevel=3)
        return False, None

    def save(self, tid: str, result: Any) -> Path:
        """Write ``result`` for task ``tid`` atomically (temporary file + rename)."""
        path = self._file(tid)
        self.directory.mkdir(parents=True, exist_ok=True)
        if not self._tidied:
            self.remove_stale_temp_files()
        data = pickle.dumps({"format": _FORMAT, "task_id": tid, "result": result},
                            protocol=pickle.HIGHEST_PROTOCOL)
        fd, tmp = tempfile.mkstemp(prefix=f".{tid}.", suffix=".tmp", dir=self.directory)
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
            os.replace(tmp, path)
        except BaseException:
            try:
                os.unlink(tmp)
            except OSError:
                pass
            raise
        return path

    def remove_stale_temp_files(self, max_age: float = STALE_TMP_AGE) -> int:
        """Delete temporary files older than ``max_age`` seconds (left by a killed run);
        returns how many were deleted."""
        self._tidied = True
        if not self.directory.is_dir():
            return 0
        now, n = time.time(), 0
        for p in self.directory.glob(".*.tmp"):
            try:
                if now - p.stat().st_mtime > max_age:
                    p.unlink()
                    n += 1
            except OSError:  # gone meanwhile, or not ours to delete: harmless either way
                pass
        return n

    def ids(self) -> Iterator[str]:
        """Ids of the stored tasks (finished files only; temporary files are skipped)."""
        if not self.directory.is_dir():
            return iter(())
        return (p.stem for p in sorted(self.directory.glob("*.pkl"))
                if _ID.match(p.stem) and p.is_file())

    def __len__(self) -> int:
        return sum(1 for _ in self.ids())

    def clear(self) -> None:
        """Delete every stored result and leftover temporary file (the directory stays)."""
        if not self.directory.is_dir():
            return
        for p in list(self.directory.glob("*.pkl")) + list(self.directory.glob(".*.tmp")):
            if p.is_file():
                p.unlink(missing_ok=True)
