"""On-disk results of finished tasks, so an interrupted sweep resumes where it stopped.

Layout: ``<directory>/<task id>.pkl``, one small pickle per finished task, holding
``{"format": 1, "task_id": ..., "result": ...}``.  Only the driver (the process that called
:func:`~abb_gym.execution.run_tasks`) writes, so there is one writer per directory and run.

Each file is written to a temporary name in the same directory and then renamed with
:func:`os.replace`, which is atomic on POSIX and Windows: a reader (or a resumed run after a
crash at any instant) sees either no file or the complete file, never half of one.  A file that
cannot be read back (e.g. truncated by a power loss before the data reached the disk) counts as
missing, so that task is simply recomputed.

Ids come from :func:`~abb_gym.execution.ids.task_id`, which names the task function and the
spec, so several sweeps may share one directory.  The store does not know when the code of a
task function changes: start a new directory (or :meth:`ResultStore.clear`) after such a change.
"""
from __future__ import annotations

import os
import pickle
import re
import tempfile
from pathlib import Path
from typing import Any, Iterator

__all__ = ["ResultStore"]

_ID = re.compile(r"^[0-9a-f]{8,64}$")
_FORMAT = 1


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

    def __repr__(self) -> str:
        return f"ResultStore({str(self.directory)!r})"

    def _path(self, tid: str) -> Path:
        if not _ID.match(tid):
            raise ValueError(f"task id must be 8-64 lowercase hex digits (got {tid!r})")
        return self.directory / f"{tid}.pkl"

    def __contains__(self, tid: str) -> bool:
        return self._path(tid).is_file()

    def load(self, tid: str) -> tuple[bool, Any]:
        """``(True, result)`` if task ``tid`` is stored and readable, else ``(False, None)``."""
        path = self._path(tid)
        try:
            with open(path, "rb") as fh:
                rec = pickle.load(fh)
        except FileNotFoundError:
            return False, None
        except Exception:  # unreadable (truncated, foreign): recompute instead of failing
            return False, None
        if not isinstance(rec, dict) or rec.get("format") != _FORMAT or rec.get("task_id") != tid:
            return False, None
        return True, rec["result"]

    def save(self, tid: str, result: Any) -> Path:
        """Write ``result`` for task ``tid`` atomically (temporary file + rename)."""
        path = self._path(tid)
        self.directory.mkdir(parents=True, exist_ok=True)
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

    def ids(self) -> Iterator[str]:
        """Ids of the stored tasks (finished files only; temporary files are skipped)."""
        if not self.directory.is_dir():
            return iter(())
        return (p.stem for p in sorted(self.directory.glob("*.pkl")) if _ID.match(p.stem))

    def __len__(self) -> int:
        return sum(1 for _ in self.ids())

    def clear(self) -> None:
        """Delete every stored result and leftover temporary file (the directory stays)."""
        if not self.directory.is_dir():
            return
        for p in list(self.directory.glob("*.pkl")) + list(self.directory.glob(".*.tmp")):
            p.unlink(missing_ok=True)
