"""Stable task ids and per-task seeds.

A task id is the SHA-256 (first 32 hex digits) of a canonical encoding of

* the task function's qualified name (``module:qualname``),
* the task spec, and
* the task's seed (root entropy and spawn key) when the sweep is seeded.

It does not depend on the process, the executor, ``PYTHONHASHSEED``, the task's position in
the list (unless the seed is derived from the position) or the order of dict keys, so the same
spec maps to the same file of a :class:`~abb_gym.execution.store.ResultStore` in every run.

Encoded exactly (type-tagged, so ``1``, ``1.0`` and ``True`` differ; numpy scalars encode like
the Python number they hold): None, bool, int, float (bit-exact via ``float.hex``), complex,
str, bytes, tuple/list, dict (keys sorted by their encoding), set/frozenset, numpy arrays
(dtype, shape, bytes), dataclasses (class name + every field), enums, paths, functions and
classes (by qualified name), :class:`numpy.random.SeedSequence`, and any object with a
``__task_key__()`` method (its return value is encoded instead).  Anything else falls back to
its pickle: faithful, so two different specs never share an id, but possibly different between
library versions, in which case a resumed sweep recomputes rather than reuses.
"""
from __future__ import annotations

import dataclasses
import enum
import hashlib
import os
import pickle
import struct
from typing import Any, Callable

import numpy as np

__all__ = ["task_id", "task_seed", "task_seeds", "seed_int", "function_name"]


def function_name(fn: Callable) -> str:
    """``module:qualname`` of a task function (the part of the id that names the work)."""
    mod = getattr(fn, "__module__", None) or type(fn).__module__
    name = getattr(fn, "__qualname__", None) or type(fn).__qualname__
    return f"{mod}:{name}"


def _encode(obj: Any, out: list[bytes], depth: int = 0) -> None:
    if depth > 200:
        raise ValueError("task spec nests deeper than 200 levels (recursive structure?)")
    d = depth + 1
    if obj is None:
        out.append(b"N")
    elif isinstance(obj, (bool, np.bool_)):
        out.append(b"T" if obj else b"F")
    elif isinstance(obj, enum.Enum):
        out.append(b"E" + function_name(type(obj)).encode() + b"." + obj.name.encode() + b";")
    elif isinstance(obj, (int, np.integer)):
        out.append(b"i" + str(int(obj)).encode() + b";")
    elif isinstance(obj, (float, np.floating)):
        out.append(b"f" + float(obj).hex().encode() + b";")
    elif isinstance(obj, (complex, np.complexfloating)):
        c = complex(obj)
        out.append(b"c" + c.real.hex().encode() + b"," + c.imag.hex().encode() + b";")
    elif isinstance(obj, str):
        b = obj.encode("utf-8", "surrogatepass")
        out.append(b"s" + struct.pack("<Q", len(b)) + b)
    elif isinstance(obj, (bytes, bytearray, memoryview)):
        b = bytes(obj)
        out.append(b"b" + struct.pack("<Q", len(b)) + b)
    elif isinstance(obj, os.PathLike):
        out.append(b"p")
        _encode(os.fspath(obj), out, d)
    elif isinstance(obj, np.ndarray):
        if obj.dtype.hasobject:
            out.append(b"A" + str(obj.shape).encode())
            for item in obj.ravel(order="C"):
                _encode(item, out, d)
        else:
            b = np.ascontiguousarray(obj).tobytes()
            out.append(b"a" + obj.dtype.str.encode() + str(obj.shape).encode()
                       + struct.pack("<Q", len(b)) + b)
    elif isinstance(obj, np.random.SeedSequence):
        out.append(b"q")
        _encode((obj.entropy, tuple(obj.spawn_key), obj.pool_size), out, d)
    elif hasattr(obj, "__task_key__") and not isinstance(obj, type):
        out.append(b"k" + function_name(type(obj)).encode() + b";")
        _encode(obj.__task_key__(), out, d)
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        out.append(b"D" + function_name(type(obj)).encode() + b";")
        for f in dataclasses.fields(obj):
            _encode(f.name, out, d)
            _encode(getattr(obj, f.name), out, d)
        out.append(b")")
    elif isinstance(obj, (tuple, list)):
        # named tuples keep their class name: two record types with equal values differ
        tag = b"t" if type(obj) in (tuple, list) else b"n" + function_name(type(obj)).encode()
        out.append(tag + (b"L" if isinstance(obj, list) else b"") + struct.pack("<Q", len(obj)))
        for item in obj:
            _encode(item, out, d)
    elif isinstance(obj, dict):
        items = []
        for k, v in obj.items():
            kb: list[bytes] = []
            _encode(k, kb, d)
            vb: list[bytes] = []
            _encode(v, vb, d)
            items.append((b"".join(kb), b"".join(vb)))
        items.sort()
        out.append(b"d" + struct.pack("<Q", len(items)))
        for kb_, vb_ in items:
            out.append(kb_)
            out.append(vb_)
    elif isinstance(obj, (set, frozenset)):
        parts = []
        for item in obj:
            ib: list[bytes] = []
            _encode(item, ib, d)
            parts.append(b"".join(ib))
        parts.sort()
        out.append(b"S" + struct.pack("<Q", len(parts)) + b"".join(parts))
    elif callable(obj) and hasattr(obj, "__qualname__") and "<locals>" not in obj.__qualname__ \
            and obj.__qualname__ != "<lambda>":
        out.append(b"r" + function_name(obj).encode() + b";")
    else:
        b = pickle.dumps(obj, protocol=4)
        out.append(b"P" + struct.pack("<Q", len(b)) + b)


def task_id(fn: Callable, task: Any, seed: np.random.SeedSequence | None = None) -> str:
    """Stable id (32 hex digits) of running ``fn`` on ``task`` with ``seed`` (see module doc)."""
    out: list[bytes] = [b"abb-gym-task-v1;", function_name(fn).encode(), b";"]
    _encode(task, out)
    if seed is not None:
        _encode(seed, out)
    return hashlib.sha256(b"".join(out)).hexdigest()[:32]


def _check_root(root: Any) -> int:
    if isinstance(root, bool) or not isinstance(root, (int, np.integer)) or root < 0:
        raise ValueError(f"seed must be an integer >= 0 (got {root!r})")
    return int(root)


def task_seed(root: int, index: int) -> np.random.SeedSequence:
    """The seed of task ``index`` in a sweep seeded with ``root``.

    Equal to ``numpy.random.SeedSequence(root).spawn(n)[index]`` for any ``n > index``, but
    computed directly, so it depends only on (root, index): never on the worker, the executor
    or how many tasks ran before.  Use ``numpy.random.default_rng(seed)`` for a Generator, or
    :func:`seed_int` for an integer seed (e.g. ``env.reset(seed=...)``).
    """
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or index < 0:
        raise ValueError(f"index must be an integer >= 0 (got {index!r})")
    return np.random.SeedSequence(_check_root(root), spawn_key=(int(index),))


def task_seeds(root: int, n: int) -> list[np.random.SeedSequence]:
    """``[task_seed(root, i) for i in range(n)]``."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
        raise ValueError(f"n must be an integer >= 0 (got {n!r})")
    return [task_seed(root, i) for i in range(int(n))]


def seed_int(seed: np.random.SeedSequence) -> int:
    """A 32-bit integer drawn from ``seed`` (for APIs that take an int, e.g. Gymnasium's
    ``reset(seed=...)`` or ``torch.manual_seed``)."""
    return int(seed.generate_state(1, np.uint32)[0])
