"""The executor: :class:`Executor` (a picklable description of where to run) and
:func:`run_tasks` (map a function over task specs there).  See the package docstring of
:mod:`abb_gym.execution` for the user guide."""
from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from .._threads import available_cpus
from .errors import SweepInterrupted, TaskFailed
from .ids import function_name, task_id, task_seed
from .store import ResultStore

__all__ = ["Executor", "run_tasks", "default_workers", "TaskTally", "task_tally"]

_MAX_AUTO_CHUNK = 32


class TaskTally:
    """The tasks of one command, over all its sweeps: ``seen`` (ids of the tasks it asked
    for) and ``stored`` (those whose result is in a store, loaded or newly written).

    Why one tally for the command and not per sweep: ``evaluate`` runs one sweep per policy
    and the tuner one per CMA-ES generation, so "0 of 1 tasks finished" of the sweep that
    Ctrl-C hit said nothing about the results the command had stored before it.
    ``abb-gym`` starts a tally per command (:meth:`reset`) and reports it on Ctrl-C."""

    def __init__(self) -> None:
        self.seen: set[str] = set()
        self.stored: set[str] = set()
        self.stores: set[str] = set()  # the store directories used

    def reset(self) -> None:
        self.seen.clear()
        self.stored.clear()
        self.stores.clear()

    def interrupted_message(self) -> str:
        """The line ``abb-gym`` prints when Ctrl-C stops the command."""
        if not self.stores:
            return ("interrupted: nothing was stored (rerun with --resume-dir DIR to keep "
                    "finished tasks, so that a rerun resumes)")
        return (f"interrupted: {len(self.stored)} of {len(self.seen)} tasks stored; rerun the "
                f"same command to resume")


_TALLY = TaskTally()


def task_tally() -> TaskTally:
    """The tally of this process's command (see :class:`TaskTally`)."""
    return _TALLY


def default_workers() -> int:
    """Local worker processes when none are asked for: the CPUs this process may use."""
    return available_cpus()


def _positive_int(name: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum} (got {value!r})")
    return int(value)


@dataclass(frozen=True)
class Executor:
    """Where and how to run a list of independent tasks.

    Attributes
    ----------
    workers : int or None
        Local mode: worker processes (default: the usable cores; ``1`` runs in this process,
        which is the easiest to debug but cannot survive a task that kills the process).
        Ray mode: at most this many tasks at once, and the CPUs of a local instance started
        with ``ray=True`` (default: all cores of the machine or cluster).
    ray : bool
        Run on Ray: a new local instance, unless this process is already connected to one.
    ray_address : str or None
        Run on the existing Ray cluster at this address (implies ``ray``): ``"auto"`` for a
        cluster started on this machine with ``ray start --head``, ``"HOST:6379"`` from a node
        of the cluster, or ``"ray://HOST:10001"`` through Ray Client from outside it.
    store : path or None
        Directory of finished results (one file per task, written atomically); a rerun with
        the same directory loads them instead of recomputing.  None keeps nothing on disk.
    retries : int
        How many times a failed task (exception, or its worker process died) runs again
        before :class:`~abb_gym.execution.errors.TaskFailed` is raised; default 2.  A
        ValueError or TypeError (bad input) is never retried: it reaches the caller at once.
    progress : bool
        Show a tqdm progress bar (finished / total tasks, resumed ones included).
    chunksize : int or None
        Tasks sent to a worker at once (default: about 16 chunks per worker, at most 32
        tasks each).  Larger chunks cut overhead for tasks of a few milliseconds.
    ray_options : dict or None
        Options for every Ray task, e.g. ``{"num_cpus": 4}`` for multi-threaded tasks or
        ``{"num_gpus": 1}``; default one CPU per task.
    runtime_env : dict or None
        Ray runtime environment used when this executor connects, e.g.
        ``{"pip": ["abb-gym[cluster]==0.2.0"]}`` or ``{"working_dir": "."}`` for a cluster
        whose nodes do not have abb-gym installed.
    start_method : str or None
        How local workers start (``multiprocessing`` start method): default ``"forkserver"``
        where available (safe with threads; a script must guard its top-level code with
        ``if __name__ == "__main__":``), ``"fork"`` (fastest, no guard needed, unsafe once the
        driver runs threads such as torch's) or ``"spawn"``.
    """

    workers: int | None = None
    ray: bool = False
    ray_address: str | None = None
    store: str | os.PathLike | None = None
    retries: int = 2
    progress: bool = True
    chunksize: int | None = None
    ray_options: dict | None = dataclasses.field(default=None, compare=False)
    runtime_env: dict | None = dataclasses.field(default=None, compare=False)
    start_method: str | None = None

    def __post_init__(self) -> None:
        if self.workers is not None:
            object.__setattr__(self, "workers", _positive_int("workers", self.workers, 1))
        object.__setattr__(self, "retries", _positive_int("retries", self.retries, 0))
        if self.chunksize is not None:
            object.__setattr__(self, "chunksize", _positive_int("chunksize", self.chunksize, 1))
        if self.ray_address is not None:
            if not isinstance(self.ray_address, str) or not self.ray_address.strip():
                raise ValueError(f"ray_address must be a non-empty string such as 'auto' or "
                                 f"'HOST:6379' (got {self.ray_address!r})")
            object.__setattr__(self, "ray", True)
        if self.store is not None and str(self.store) == "":
            raise ValueError("store must be a directory path or None (got '')")
        if self.start_method is not None:
            import multiprocessing
            allowed = multiprocessing.get_all_start_methods()
            if self.start_method not in allowed:
                raise ValueError(f"start_method must be one of {allowed} or None "
                                 f"(got {self.start_method!r})")
        for name in ("ray_options", "runtime_env"):
            v = getattr(self, name)
            if v is not None and not isinstance(v, dict):
                raise ValueError(f"{name} must be a dict or None (got {type(v).__name__})")

    # ------------------------------------------------------------------ description
    @property
    def mode(self) -> str:
        """``"ray"``, ``"serial"`` (one local worker: this process) or ``"processes"``."""
        if self.ray:
            return "ray"
        return "serial" if self.n_local_workers == 1 else "processes"

    @property
    def n_local_workers(self) -> int:
        return self.workers if self.workers is not None else default_workers()

    def describe(self) -> str:
        """One line for logs, e.g. ``"2 local processes, results in out/resume"``."""
        if self.ray_address:
            where = f"Ray cluster at {self.ray_address}"
        elif self.ray:
            where = "local Ray instance" + (f" ({self.workers} CPUs)" if self.workers else "")
        elif self.mode == "serial":
            where = "this process"
        else:
            where = f"{self.n_local_workers} local processes"
        return where + (f", results in {self.store}" if self.store is not None else "")

    def replace(self, **changes: Any) -> "Executor":
        """A copy with ``changes`` applied (validated again)."""
        return dataclasses.replace(self, **changes)

    # ------------------------------------------------------------------ running
    def map(self, fn: Callable, tasks: Iterable[Any], *, desc: str = "tasks",
            seed: int | None = None, task_ids: Sequence[str] | None = None) -> list:
        """``[fn(t) for t in tasks]`` (or ``fn(t, task_seed(seed, i))`` when ``seed`` is
        given), run on this executor, returned in task order.

        ``fn`` should be a module-level function (its qualified name is part of each task's
        id; lambdas and closures run too, shipped by cloudpickle, but cannot use a store);
        tasks and results must be picklable.  Tasks whose
        id is already in the store are not run; tasks with the same id (same spec, same seed)
        run once and share the result.

        Raises :class:`~abb_gym.execution.errors.TaskFailed` when a task fails ``retries + 1``
        times; re-raises a task's ValueError or TypeError (bad input) at its first occurrence,
        unchanged, without retrying it; raises
        :class:`~abb_gym.execution.errors.SweepInterrupted` (a KeyboardInterrupt) on Ctrl-C.
        In every case the tasks in flight have been cancelled and have ended, and the finished
        results are stored, before the exception is raised.
        """
        tasks = list(tasks)
        n = len(tasks)
        if seed is not None:
            task_seed(seed, 0)  # validates the root even for an empty task list
            seeds = [task_seed(seed, i) for i in range(n)]
        else:
            seeds = [None] * n
        if task_ids is None:
            ids = [task_id(fn, t, s) for t, s in zip(tasks, seeds)]
        else:
            ids = [str(t) for t in task_ids]
            if len(ids) != n:
                raise ValueError(f"task_ids must have one id per task ({n}), got {len(ids)}")
        groups: dict[str, list[int]] = {}
        for i, tid in enumerate(ids):
            groups.setdefault(tid, []).append(i)

        store = ResultStore(self.store) if self.store is not None else None
        if store is not None and task_ids is None:
            name = function_name(fn)
            if "<lambda>" in name or "<locals>" in name:
                # every lambda has the same name: their results would share store files
                raise ValueError(f"a store needs a task function with a stable name (a "
                                 f"module-level def), got {name}; or pass task_ids")
        results: list[Any] = [None] * n
        done = [False] * n
        jobs = []
        _TALLY.seen.update(groups)
        if store is not None:
            _TALLY.stores.add(str(store.directory))
        for tid, idxs in groups.items():
            if store is not None:
                ok, value = store.load(tid, function_name(fn))
                if ok:
                    _TALLY.stored.add(tid)
                    for j in idxs:
                        results[j], done[j] = value, True
                    continue
            jobs.append((idxs[0], tasks[idxs[0]], seeds[idxs[0]]))

        if jobs and self.mode == "ray":
            # connect first: a bar drawn before "no Ray cluster found" is noise around the
            # one line the user needs
            from .ray_backend import ensure_ray
            ensure_ray(self.ray_address, self.workers, self.runtime_env)
        from ..progress import ProgressBar
        bar = ProgressBar(total=n, initial=sum(done), desc=desc, unit="task",
                          disable=not self.progress, dynamic_ncols=True)

        def on_result(index: int, value: Any) -> None:
            if done[index]:  # a duplicate delivery (e.g. a retried Ray chunk): keep the first
                return
            tid = ids[index]
            if store is not None:
                # before it counts as done: a crash now loses nothing
                store.save(tid, value, function_name(fn))
                _TALLY.stored.add(tid)
            for j in groups[tid]:
                results[j], done[j] = value, True
            bar.update(len(groups[tid]))

        def on_fail(index: int, attempts: int, detail: str,
                    error: BaseException | None = None) -> None:
            if error is None:
                raise TaskFailed(index, ids[index], attempts, detail)
            error.add_note(f"(raised by task {index}, id {ids[index]}; a {type(error).__name__} "
                           f"is taken as bad input and not retried)")
            raise error

        try:
            if jobs:
                self._dispatch(fn, jobs, on_result, on_fail)
        except KeyboardInterrupt as exc:
            raise SweepInterrupted(sum(done), n,
                                   store.directory if store is not None else None) from exc
        finally:
            bar.close()
        missing = [i for i, d in enumerate(done) if not d]
        if missing:  # a back end that returns without every result is a bug, not a resume
            raise RuntimeError(f"executor finished without results for tasks {missing[:10]}")
        return results

    def _chunksize(self, n_jobs: int, parallel: int) -> int:
        if self.chunksize is not None:
            return self.chunksize
        return max(1, min(_MAX_AUTO_CHUNK, n_jobs // (16 * parallel)))

    def _dispatch(self, fn: Callable, jobs: list, on_result, on_fail) -> None:
        if self.mode == "serial":
            from .local import run_serial
            run_serial(fn, jobs, retries=self.retries, on_result=on_result, on_fail=on_fail)
        elif self.mode == "processes":
            from .local import run_processes
            workers = min(self.n_local_workers, len(jobs))
            run_processes(fn, jobs, workers=workers, retries=self.retries,
                          chunksize=self._chunksize(len(jobs), workers),
                          on_result=on_result, on_fail=on_fail, context=self.start_method)
        else:
            from .ray_backend import ensure_ray, ray_cpus, run_ray
            ray = ensure_ray(self.ray_address, self.workers, self.runtime_env)
            parallel = self.workers or ray_cpus(ray)
            run_ray(fn, jobs, retries=self.retries, chunksize=self._chunksize(len(jobs), parallel),
                    max_in_flight=self.workers, on_result=on_result, on_fail=on_fail,
                    ray_options=self.ray_options)


def run_tasks(fn: Callable, tasks: Iterable[Any], *, workers: int | None = None,
              ray: bool = False, ray_address: str | None = None,
              store: str | os.PathLike | None = None, retries: int = 2,
              progress: bool = True, desc: str = "tasks", seed: int | None = None,
              chunksize: int | None = None, task_ids: Sequence[str] | None = None,
              ray_options: dict | None = None, runtime_env: dict | None = None,
              start_method: str | None = None) -> list:
    """``Executor(workers=..., ...).map(fn, tasks, desc=..., seed=..., task_ids=...)``.

    See :class:`Executor` for the arguments and :meth:`Executor.map` for the contract.
    """
    ex = Executor(workers=workers, ray=ray, ray_address=ray_address, store=store,
                  retries=retries, progress=progress, chunksize=chunksize,
                  ray_options=ray_options, runtime_env=runtime_env, start_method=start_method)
    return ex.map(fn, tasks, desc=desc, seed=seed, task_ids=task_ids)
