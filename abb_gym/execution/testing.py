"""A toy task with fault injection, for testing executors and checking a cluster.

:func:`toy_task` is seeded, cheap and deterministic; through marker files in
``ToyTask.marker_dir`` it can kill its own worker process or raise once, and it leaves one
``started-<key>-*`` file per run, locked (``flock``) while the run lasts, and one
``computed-<key>-*`` file per computation, so a test can count how often each task ran
(:func:`count_started`, :func:`count_computed`) and which tasks are running right now
(:func:`running_keys`): none should be once a sweep has returned or raised.  Input errors come
naturally: ``n=-1`` raises ValueError, ``n="x"`` TypeError, on every run.

Check a cluster from any node (Ray workers must be able to import ``abb_gym``)::

    from abb_gym.execution import run_tasks
    from abb_gym.execution.testing import ToyTask, toy_task
    tasks = [ToyTask(key=i, x=float(i)) for i in range(200)]
    assert run_tasks(toy_task, tasks, ray_address="auto", seed=1) == \\
        run_tasks(toy_task, tasks, workers=1, seed=1, progress=False)
"""
from __future__ import annotations

import contextlib
import importlib
import os
import signal
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

try:
    import fcntl
except ImportError:  # not POSIX: runs are counted but running_keys() sees none
    fcntl = None

__all__ = ["ToyTask", "toy_task", "toy_trainable", "count_computed", "count_started",
           "running_keys", "ctrl_c_after_saves", "parallel_threads"]


@dataclass(frozen=True)
class ToyTask:
    """One toy task.

    key : int - names the task in marker files
    x : float - offset of the result
    n : int - normal draws averaged into the result
    marker_dir : directory for marker files (None: no markers, no fault injection)
    crash_once : SIGKILL the worker process the first time this task runs
    raise_once : raise RuntimeError the first time this task runs
    sleep : seconds to wait before computing (to interrupt a sweep mid-way)
    """

    key: int
    x: float = 0.0
    n: int = 16
    marker_dir: str | None = None
    crash_once: bool = False
    raise_once: bool = False
    sleep: float = 0.0


def _first_time(marker_dir: str, name: str) -> bool:
    """True the first time (creates the marker atomically, so concurrent runs agree)."""
    try:
        fd = os.open(Path(marker_dir) / name, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        return False
    os.close(fd)
    return True


@contextlib.contextmanager
def _running(marker_dir: str | None, key: int):
    """Leaves a ``started-<key>-*`` file, locked until the run ends (or its process dies)."""
    if marker_dir is None:
        yield
        return
    path = Path(marker_dir) / f"started-{key}-{os.getpid()}-{uuid.uuid4().hex}"
    with open(path, "w") as fh:
        if fcntl is not None:
            fcntl.flock(fh, fcntl.LOCK_EX)
        yield


def toy_task(task: ToyTask, seed: np.random.SeedSequence | None = None) -> float:
    """``x + mean(n standard normals)`` drawn from ``seed`` (default: ``task.key``)."""
    with _running(task.marker_dir, task.key):
        if task.sleep > 0:
            time.sleep(task.sleep)
        if task.marker_dir is not None:
            if task.crash_once and _first_time(task.marker_dir, f"crashed-{task.key}"):
                os.kill(os.getpid(), signal.SIGKILL)  # as if the OOM killer or a node loss hit
            if task.raise_once and _first_time(task.marker_dir, f"raised-{task.key}"):
                raise RuntimeError(f"injected failure of toy task {task.key}")
        rng = np.random.default_rng(seed if seed is not None else task.key)
        value = float(task.x + rng.standard_normal(task.n).mean())
        if task.marker_dir is not None:
            (Path(task.marker_dir) / f"computed-{task.key}-{os.getpid()}-"
                                     f"{uuid.uuid4().hex}").touch()
        return value


def _count(marker_dir: str | os.PathLike, prefix: str) -> dict[int, int]:
    counts: dict[int, int] = {}
    for p in Path(marker_dir).glob(f"{prefix}-*"):
        key = int(p.name.split("-")[1])
        counts[key] = counts.get(key, 0) + 1
    return counts


def count_computed(marker_dir: str | os.PathLike) -> dict[int, int]:
    """Computations (runs that returned a result) per task key found in ``marker_dir``."""
    return _count(marker_dir, "computed")


def count_started(marker_dir: str | os.PathLike) -> dict[int, int]:
    """Runs per task key found in ``marker_dir``, whatever their outcome."""
    return _count(marker_dir, "started")


def running_keys(marker_dir: str | os.PathLike) -> set[int]:
    """Keys of the toy tasks running right now (their ``started-*`` file is still locked)."""
    running: set[int] = set()
    if fcntl is None:
        return running
    for p in Path(marker_dir).glob("started-*"):
        with open(p) as fh:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                running.add(int(p.name.split("-")[1]))
    return running


@contextlib.contextmanager
def ctrl_c_after_saves(n_saved: int):
    """Inside the block, the driver gets one KeyboardInterrupt, as from Ctrl-C, when it is
    about to store a result while ``n_saved`` are stored already: Ctrl-C at a known instant."""
    from .store import ResultStore

    save, pressed = ResultStore.save, []

    def interrupted_save(self, tid, result, *args, **kwargs):
        if not pressed and len(self) >= n_saved:
            pressed.append(True)
            raise KeyboardInterrupt
        return save(self, tid, result, *args, **kwargs)

    ResultStore.save = interrupted_save
    try:
        yield
    finally:
        ResultStore.save = save


def toy_trainable(config: dict) -> dict:
    """A trainable for :func:`abb_gym.execution.tune.run_trials`: three "iterations" of a
    seeded noisy quadratic in ``config["lr"]``, reported through
    :func:`~abb_gym.execution.tune.report`; final metrics ``{"score", "lr", "seed"}``.

    ``config["marker_dir"]`` (optional) gets one ``computed-<seed>-*`` file per run, and with
    ``config["crash_once"]`` the first run of each seed kills its process.
    """
    from .tune import report

    marker_dir = config.get("marker_dir")
    seed = int(config.get("seed", 0))
    if marker_dir and config.get("crash_once") and _first_time(marker_dir, f"crashed-{seed}"):
        os.kill(os.getpid(), signal.SIGKILL)
    rng = np.random.default_rng(seed)
    lr = float(config["lr"])
    score = 0.0
    for it in range(3):
        score = float(-(np.log10(lr) + 3.0) ** 2 + 0.01 * rng.standard_normal() + 0.1 * it)
        report({"score": score, "iteration": it})
    if marker_dir:
        (Path(marker_dir) / f"computed-{seed}-{os.getpid()}-{uuid.uuid4().hex}").touch()
    return {"score": score, "lr": lr, "seed": seed}


def parallel_threads(task: Any = None, seed: Any = None) -> int:
    """The threads numba's parallel loops use in the process that runs the task (the tests of
    the workers' share of the cores: :func:`abb_gym._threads.share_cores`)."""
    # imported by name: an import statement would put this module into the kernel-cache
    # fingerprint (abb_gym._jit_cache), and an edit of it would rebuild every kernel
    return importlib.import_module("numba").get_num_threads()
