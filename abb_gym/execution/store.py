"""On-disk results of finished tasks, so an interrupted sweep resumes where it stopped.

Layout: ``<directory>/<task id>.npz``, one small NumPy archive per finished task, holding
the record as JSON text (``record``: ``{"format": 2, "task_id": ..., "function": ...,
"result": ...}``) and the result's arrays (``a0``, ``a1``, ...).  Only the driver (the
process that called :func:`~abb_gym.execution.run_tasks`) writes, so there is one writer per
directory and run.

No pickle: a record is data, never a program.  It is read with ``numpy.load(...,
allow_pickle=False)`` and ``json``; a file that needs anything else (an object array, an
unknown tag) is refused before any of it is used.  A result may hold None, bools, numbers
(Python and NumPy scalars, exactly: floats through ``repr``), text, lists, tuples, dicts (any
of these as keys), NumPy arrays of a plain dtype, paths, and dataclasses and named tuples
defined in ``abb_gym`` (rebuilt from their fields by their own class, which is looked up in
``abb_gym``'s modules only); saving anything else raises ``TypeError`` naming its type.
Results of an older abb-gym (``<task id>.pkl``, pickles) are never opened: their tasks are
recomputed, with one warning.

A record is checked against its task before use: the task id and the task function's name
(``module:qualname``) it was stored under must be the ones the sweep asks for.

Each file is written to a temporary name (``.<task id>.<random>.tmp``) in the same directory
and then renamed with :func:`os.replace`, which is atomic on POSIX and Windows: a reader (or a
resumed run after a crash at any instant) sees either no file or the complete file, never half
of one.  Temporary files are never read as results; those a killed sweep left behind are
deleted by the next run's first write once they are older than :data:`STALE_TMP_AGE` seconds
(an actual write takes milliseconds; the margin protects another run writing there now).

Damage is reported, never silently skipped:

* a result file that cannot be read back (truncated by a power loss, overwritten, not written
  by this store, or the record of another task) counts as missing: a :class:`RuntimeWarning`
  names the file, the task is recomputed and its new result replaces the file;
* a *directory* named like a result file raises a ValueError naming it, before anything runs
  (the result could never be saved there); remove it or use another directory.

Ids come from :func:`~abb_gym.execution.ids.task_id`, which names the task function and the
spec, so several sweeps may share one directory.  The store does not know when the code of a
task function changes: start a new directory (or :meth:`ResultStore.clear`) after such a change.
"""
from __future__ import annotations

import dataclasses
import importlib
import io
import json
import os
import re
import tempfile
import time
import warnings
from pathlib import Path, PurePath
from typing import Any, Iterator

import numpy as np

__all__ = ["ResultStore", "STALE_TMP_AGE", "encode_result", "decode_result"]

_ID = re.compile(r"^[0-9a-f]{8,64}$")
_FORMAT = 2
_SUFFIX = ".npz"
_LEGACY_SUFFIX = ".pkl"
#: Seconds after which a leftover temporary file is taken as stale and deleted.
STALE_TMP_AGE = 600.0
_MAX_DEPTH = 200


class RecordError(ValueError):
    """A stored record that cannot be taken as a result (the message says why)."""


# ------------------------------------------------------------------------ the record codec
def encode_result(value: Any) -> tuple[Any, list[np.ndarray]]:
    """``value`` as JSON-ready data and the arrays it refers to (see the module docstring);
    ``TypeError`` naming the type of a value the store cannot keep."""
    arrays: list[np.ndarray] = []
    return _encode(value, arrays, 0), arrays


def _class_name(cls: type) -> str:
    return f"{cls.__module__}:{cls.__qualname__}"


def _encode(obj: Any, arrays: list[np.ndarray], depth: int) -> Any:
    if depth > _MAX_DEPTH:
        raise TypeError(f"a result nesting deeper than {_MAX_DEPTH} levels cannot be stored")
    d = depth + 1
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, (int, float)) and type(obj) in (int, float):
        return obj
    if isinstance(obj, (np.generic, np.ndarray)):
        arr = np.asarray(obj)
        if arr.dtype.hasobject:
            raise TypeError("a NumPy array of Python objects cannot be stored (it would need "
                            "pickle)")
        arrays.append(arr)
        return {"$s" if isinstance(obj, np.generic) else "$a": len(arrays) - 1}
    if isinstance(obj, complex) and type(obj) is complex:
        return {"$j": [obj.real, obj.imag]}
    if isinstance(obj, PurePath):
        return {"$p": str(obj)}
    if isinstance(obj, list) and type(obj) is list:
        return [_encode(v, arrays, d) for v in obj]
    if isinstance(obj, tuple):
        items = [_encode(v, arrays, d) for v in obj]
        if type(obj) is tuple:
            return {"$t": items}
        _check_ours(type(obj))
        return {"$n": _class_name(type(obj)), "v": items}
    if isinstance(obj, dict) and type(obj) is dict:
        return {"$d": [[_encode(k, arrays, d), _encode(v, arrays, d)] for k, v in obj.items()]}
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        cls = type(obj)
        _check_ours(cls)
        fields = dataclasses.fields(obj)
        if any(not f.init for f in fields):
            raise TypeError(f"a {cls.__qualname__} cannot be stored: it has fields its "
                            f"constructor does not take")
        return {"$c": _class_name(cls),
                "f": {f.name: _encode(getattr(obj, f.name), arrays, d) for f in fields}}
    raise TypeError(f"a result of type {type(obj).__qualname__} cannot be stored (a store "
                    f"keeps numbers, text, lists, tuples, dicts, NumPy arrays and abb_gym "
                    f"dataclasses)")


def _check_ours(cls: type) -> None:
    if not (cls.__module__ == "abb_gym" or cls.__module__.startswith("abb_gym.")) \
            or "<locals>" in cls.__qualname__:
        raise TypeError(f"a {cls.__qualname__} of module {cls.__module__} cannot be stored: "
                        f"only dataclasses and named tuples of abb_gym are rebuilt on loading")


def _our_class(name: Any, kind: str) -> type:
    """The abb_gym class ``module:qualname`` (never another package's: nothing but abb-gym's
    own modules is imported on loading)."""
    if not isinstance(name, str) or ":" not in name:
        raise RecordError(f"bad class name {name!r}")
    module, _, qualname = name.partition(":")
    if not (module == "abb_gym" or module.startswith("abb_gym.")) or not qualname \
            or not all(part.isidentifier() for part in qualname.split(".") + module.split(".")):
        raise RecordError(f"class {name!r} is not one of abb_gym's")
    try:
        cls: Any = importlib.import_module(module)
        for part in qualname.split("."):
            cls = getattr(cls, part)
    except (ImportError, AttributeError) as exc:
        raise RecordError(f"no class {name!r} ({exc})") from None
    ok = (dataclasses.is_dataclass(cls) if kind == "dataclass"
          else issubclass(cls, tuple) and hasattr(cls, "_fields")) if isinstance(cls, type) \
        else False
    if not ok:
        raise RecordError(f"{name!r} is not a {kind}")
    return cls


def decode_result(data: Any, arrays: list[np.ndarray]) -> Any:
    """The value :func:`encode_result` encoded; :class:`RecordError` if ``data`` is not such
    an encoding."""
    return _decode(data, arrays, 0)


def _decode(obj: Any, arrays: list[np.ndarray], depth: int) -> Any:
    if depth > _MAX_DEPTH:
        raise RecordError("the record nests too deeply")
    d = depth + 1
    if obj is None or isinstance(obj, (bool, str, int, float)):
        return obj
    if isinstance(obj, list):
        return [_decode(v, arrays, d) for v in obj]
    if not isinstance(obj, dict) or len(obj) not in (1, 2):
        raise RecordError(f"unexpected item {str(obj)[:60]!r}")
    tag = next(iter(obj))
    body = obj[tag]
    if tag in ("$a", "$s"):
        if isinstance(body, bool) or not isinstance(body, int) or not 0 <= body < len(arrays):
            raise RecordError(f"bad array reference {body!r}")
        arr = arrays[body]
        return arr[()] if tag == "$s" else arr
    if tag == "$t" and isinstance(body, list):
        return tuple(_decode(v, arrays, d) for v in body)
    if tag == "$d" and isinstance(body, list):
        out = {}
        for pair in body:
            if not isinstance(pair, list) or len(pair) != 2:
                raise RecordError("bad dict item")
            key = _decode(pair[0], arrays, d)
            try:
                out[key] = _decode(pair[1], arrays, d)
            except TypeError:  # an unhashable key
                raise RecordError("bad dict key") from None
        return out
    if tag == "$j" and isinstance(body, list) and len(body) == 2 \
            and all(isinstance(v, (int, float)) for v in body):
        return complex(*body)
    if tag == "$p" and isinstance(body, str):
        return Path(body)
    if tag == "$n" and isinstance(obj.get("v"), list):
        cls = _our_class(body, "named tuple")
        return cls(*(_decode(v, arrays, d) for v in obj["v"]))
    if tag == "$c" and isinstance(obj.get("f"), dict):
        cls = _our_class(body, "dataclass")
        names = {f.name for f in dataclasses.fields(cls) if f.init}
        fields = obj["f"]
        if set(fields) != names:
            raise RecordError(f"the fields of {body!r} are not the stored ones")
        try:
            return cls(**{k: _decode(v, arrays, d) for k, v in fields.items()})
        except (TypeError, ValueError) as exc:
            raise RecordError(f"{body!r} refuses the stored fields ({exc})") from None
    raise RecordError(f"unknown tag {tag!r}")


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
        self._legacy_noted = False

    def __repr__(self) -> str:
        return f"ResultStore({str(self.directory)!r})"

    def _path(self, tid: str) -> Path:
        if not _ID.match(tid):
            raise ValueError(f"task id must be 8-64 lowercase hex digits (got {tid!r})")
        return self.directory / f"{tid}{_SUFFIX}"

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

    def load(self, tid: str, function: str | None = None) -> tuple[bool, Any]:
        """``(True, result)`` if task ``tid`` is stored and readable (and, with ``function``,
        was stored by that task function), else ``(False, None)`` (with a
        :class:`RuntimeWarning` naming the file when it exists but is unreadable or another
        task's)."""
        path = self._file(tid)
        self._note_legacy()
        try:
            with np.load(path, allow_pickle=False) as archive:
                names = set(archive.files)
                if "record" not in names:
                    raise RecordError("no record in the file")
                rec = json.loads(archive["record"].tobytes().decode("utf-8"))
                if not isinstance(rec, dict):
                    raise RecordError("the record is not a mapping")
                n = rec.get("arrays")
                if isinstance(n, bool) or not isinstance(n, int) \
                        or names != {"record"} | {f"a{i}" for i in range(n)}:
                    raise RecordError("the arrays are not the ones the record lists")
                arrays = [archive[f"a{i}"] for i in range(n)]
        except FileNotFoundError:
            return False, None
        except Exception as exc:  # noqa: BLE001 - numpy, zip and json raise many kinds
            return self._unreadable(path, f"{type(exc).__name__}: {exc}")
        if rec.get("format") != _FORMAT or rec.get("task_id") != tid or "result" not in rec:
            return self._unreadable(path, "not a result record of this task")
        if function is not None and rec.get("function") != function:
            return self._unreadable(path, f"stored by {rec.get('function')!r}, not by "
                                          f"{function!r}")
        try:
            return True, decode_result(rec["result"], arrays)
        except (RecordError, RecursionError) as exc:
            return self._unreadable(path, str(exc))

    @staticmethod
    def _unreadable(path: Path, why: str) -> tuple[bool, None]:
        # recompute rather than fail: the sweep heals the store by writing the file anew
        warnings.warn(f"ignoring unreadable result file {str(path)!r} ({why}); the task is "
                      f"recomputed", RuntimeWarning, stacklevel=3)
        return False, None

    def _note_legacy(self) -> None:
        """Warn once if the directory holds results of an older abb-gym (pickles)."""
        if self._legacy_noted:
            return
        self._legacy_noted = True
        if not self.directory.is_dir():
            return
        old = sum(1 for p in self.directory.glob(f"*{_LEGACY_SUFFIX}") if _ID.match(p.stem))
        if old:
            warnings.warn(f"store {str(self.directory)!r} holds {old} result file(s) of an "
                          f"older abb-gym (*{_LEGACY_SUFFIX}: pickles, which are never opened "
                          f"because loading them could run code); their tasks are recomputed",
                          RuntimeWarning, stacklevel=3)

    def save(self, tid: str, result: Any, function: str | None = None) -> Path:
        """Write ``result`` for task ``tid`` (of the task function ``function``,
        ``module:qualname``) atomically (temporary file + rename)."""
        path = self._file(tid)
        encoded, arrays = encode_result(result)
        record = {"format": _FORMAT, "task_id": tid, "function": function,
                  "arrays": len(arrays), "result": encoded}
        text = json.dumps(record, separators=(",", ":"))
        buffer = io.BytesIO()
        np.savez(buffer, record=np.frombuffer(text.encode("utf-8"), dtype=np.uint8),
                 **{f"a{i}": a for i, a in enumerate(arrays)})
        self.directory.mkdir(parents=True, exist_ok=True)
        if not self._tidied:
            self.remove_stale_temp_files()
        fd, tmp = tempfile.mkstemp(prefix=f".{tid}.", suffix=".tmp", dir=self.directory)
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(buffer.getvalue())
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
        return (p.stem for p in sorted(self.directory.glob(f"*{_SUFFIX}"))
                if _ID.match(p.stem) and p.is_file())

    def __len__(self) -> int:
        return sum(1 for _ in self.ids())

    def clear(self) -> None:
        """Delete every stored result (an older abb-gym's included) and leftover temporary
        file (the directory stays)."""
        if not self.directory.is_dir():
            return
        for pattern in (f"*{_SUFFIX}", f"*{_LEGACY_SUFFIX}", ".*.tmp"):
            for p in list(self.directory.glob(pattern)):
                if p.is_file():
                    p.unlink(missing_ok=True)
