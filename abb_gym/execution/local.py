"""Local back ends: in this process (``workers=1``) and a pool of worker processes.

Why not :class:`concurrent.futures.ProcessPoolExecutor`: when one of its workers dies, the whole
pool is marked broken and every pending future fails with ``BrokenProcessPool``, without saying
which task killed the worker.  Retrying all of them would charge innocent tasks with attempts
(and a task that always crashes the worker would exhaust everyone's retries).  This pool gives
each worker its own pipe and knows which task it is running: a worker that dies costs that task
one attempt, the rest of its chunk goes back to the queue untouched, and a fresh worker takes
its place.

Workers start with the ``forkserver`` method where the platform has it (Linux, macOS): a clean,
single-threaded server process that has imported ``abb_gym`` once forks each worker.  Plain
``fork`` from the driver would copy whatever threads it runs (tqdm's monitor, a Ray or gRPC
client, torch's thread pools) in an unknown state, which can deadlock the child.  The task
function travels as a cloudpickle (when installed: it ships with gymnasium), so functions
defined in a script's ``__main__`` work too, as they do on Ray.

Protocol (parent -> worker): a list of jobs ``(index, task, seed)`` or ``None`` to stop.
Worker -> parent, per job in order: ``("ok", index, result)``, ``("err", index, text)`` or,
for an input error (:data:`~.errors.INPUT_ERRORS`, never retried), ``("bad", index, text,
exception)``.  Results are sent one by one, so a worker that dies in the middle of a chunk
loses nothing it had finished; a worker is idle again once every job of its chunk is answered.

However the sweep stops (a failed task, Ctrl-C, an error in the driver), every worker is
stopped and joined before the exception leaves :func:`run_processes`: busy workers are
terminated, so nothing keeps computing after the call returns.
"""
from __future__ import annotations

import collections
import multiprocessing
import pickle
import signal
import traceback
from multiprocessing.connection import wait
from typing import Any, Callable, Iterable

from .._threads import available_cpus, share_cores
from .errors import INPUT_ERRORS, RemoteTraceback, call_task, portable_error

__all__ = ["run_serial", "run_processes"]

Job = tuple  # (index, task, seed or None)


class _Attempts:
    """Failures per task; raises through ``on_fail`` once a task may not run again."""

    def __init__(self, retries: int, on_fail: Callable[..., None]) -> None:
        self.retries, self.on_fail = retries, on_fail
        self.count: dict[int, int] = collections.defaultdict(int)

    def failed(self, index: int, detail: str, error: BaseException | None = None) -> None:
        """Record one failure; raises (through ``on_fail``) when the retries are used up or
        ``error`` is an input error, which a rerun would only repeat."""
        self.count[index] += 1
        if error is not None or self.count[index] > self.retries:
            self.on_fail(index, self.count[index], detail, error)


def run_serial(fn: Callable, jobs: Iterable[Job], *, retries: int,
               on_result: Callable[[int, Any], None],
               on_fail: Callable[..., None]) -> None:
    """Run every job in this process, retrying exceptions (a hard crash ends the process)
    except input errors, which ``on_fail`` raises at once."""
    attempts = _Attempts(retries, on_fail)
    for index, task, seed in jobs:
        while True:
            try:
                result = call_task(fn, task, seed)
            except INPUT_ERRORS as exc:
                attempts.failed(index, traceback.format_exc(), exc)
            except Exception:
                attempts.failed(index, traceback.format_exc())
                continue
            on_result(index, result)
            break


def _dump_fn(fn: Callable) -> bytes:
    try:
        import cloudpickle
        return cloudpickle.dumps(fn)
    except ImportError:
        pass
    try:
        return pickle.dumps(fn)
    except Exception as exc:
        raise ValueError(f"the task function must be picklable (define it at module level); "
                         f"{fn!r} is not: {exc}") from exc


class WorkerStartError(RuntimeError):
    """A worker process could not load the task function (not a task failure: no retry)."""


def _worker_main(conn, fn_bytes: bytes, threads: int) -> None:
    # The parent handles Ctrl-C and stops the workers; a worker that also raised
    # KeyboardInterrupt would only print a second traceback.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    share_cores(threads)  # the workers share the cores (abb_gym._threads.share_cores)
    try:
        fn = pickle.loads(fn_bytes)
    except Exception:
        conn.send(("fatal", -1, traceback.format_exc()))
        return
    conn.send(("ready",))
    while True:
        try:
            chunk = conn.recv()
        except (EOFError, OSError):  # parent gone: nothing left to do
            return
        if chunk is None:
            return
        for index, task, seed in chunk:
            try:
                msg = ("ok", index, call_task(fn, task, seed))
            except INPUT_ERRORS as exc:
                msg = ("bad", index, traceback.format_exc(), portable_error(exc))
            except Exception:
                msg = ("err", index, traceback.format_exc())
            try:
                conn.send(msg)
            except (EOFError, OSError, BrokenPipeError):
                return
            except Exception:  # the result does not pickle: a task error, not a dead worker
                conn.send(("err", index, traceback.format_exc()))


class _Worker:
    def __init__(self, ctx, fn_bytes: bytes, threads: int) -> None:
        self.conn, child = ctx.Pipe(duplex=True)
        self.proc = ctx.Process(target=_worker_main, args=(child, fn_bytes, threads),
                                daemon=True, name="abb-gym-worker")
        self.proc.start()
        child.close()  # so that recv() in the parent sees EOF when the worker dies
        self.running: list[Job] = []  # jobs sent and not yet answered, in order
        self.ready = False  # set by the worker's first message, once it has loaded the function

    def stop(self, timeout: float = 2.0) -> None:
        try:
            self.conn.send(None)
        except (OSError, ValueError):
            pass
        self.proc.join(timeout)
        self.kill()

    def kill(self) -> None:
        if self.proc.is_alive():
            self.proc.terminate()
            self.proc.join(2.0)
            if self.proc.is_alive():
                self.proc.kill()
                self.proc.join()
        self.conn.close()


def run_processes(fn: Callable, jobs: Iterable[Job], *, workers: int, retries: int,
                  chunksize: int, on_result: Callable[[int, Any], None],
                  on_fail: Callable[..., None],
                  context: str | None = None) -> None:
    """Run jobs on ``workers`` local processes, ``chunksize`` jobs per dispatch.

    ``context`` is the multiprocessing start method (default: ``forkserver`` where available,
    see the module docstring).

    ``on_result(index, result)`` is called in this process once per job (in completion order);
    ``on_fail(index, attempts, detail, error)`` must raise (``error``: the exception of an
    input error, else None).  A job whose worker died or raised is requeued at the front until
    it has failed ``retries + 1`` times; an input error stops the sweep at once.

    Each worker runs its compiled parallel loops on its share of the CPUs, ``CPUs // workers``
    threads (at least one; :func:`abb_gym._threads.share_cores`).
    """
    if context is None and "forkserver" in multiprocessing.get_all_start_methods():
        context = "forkserver"
    ctx = multiprocessing.get_context(context)
    if context == "forkserver":
        # workers fork from a server that has abb_gym (numpy, numba kernels) imported already
        ctx.set_forkserver_preload(["abb_gym"])
    fn_bytes = _dump_fn(fn)
    threads = max(1, available_cpus() // workers)
    queue: collections.deque[Job] = collections.deque(jobs)
    attempts = _Attempts(retries, on_fail)
    pool: list[_Worker] = []
    try:
        while queue or any(w.running for w in pool):
            # start workers lazily: never more than there are chunks to run
            idle = [w for w in pool if not w.running]
            while queue and not idle and len(pool) < workers:
                pool.append(_Worker(ctx, fn_bytes, threads))
                idle = [pool[-1]]
            for w in idle:
                if not queue:
                    break
                w.running = [queue.popleft() for _ in range(min(chunksize, len(queue)))]
                w.conn.send(w.running)
            busy = [w for w in pool if w.running]
            ready = set(wait([w.conn for w in busy] + [w.proc.sentinel for w in busy]))
            for w in busy:
                dead = False
                if w.conn in ready or w.proc.sentinel in ready:
                    # drain everything the worker sent before looking at whether it died
                    try:
                        while w.conn.poll():
                            msg = w.conn.recv()
                            if msg[0] == "fatal":
                                raise WorkerStartError(
                                    f"a worker process could not load the task function:\n"
                                    f"{msg[2]}")
                            if msg[0] == "ready":
                                w.ready = True
                                continue
                            job = w.running.pop(0)
                            if msg[0] == "ok":
                                on_result(job[0], msg[2])
                            elif msg[0] == "bad":
                                error = msg[3]
                                error.__cause__ = RemoteTraceback(msg[2])
                                attempts.failed(job[0], msg[2], error)
                            else:
                                attempts.failed(job[0], msg[2])
                                queue.appendleft(job)
                    except (EOFError, OSError):
                        dead = True
                    dead = dead or not w.proc.is_alive()
                if dead:
                    w.proc.join(2.0)  # the exit code arrives a moment after the pipe closes
                    code = w.proc.exitcode
                    if not w.ready:
                        # died before running anything: not the task's fault, and retrying
                        # would only fail the same way
                        raise WorkerStartError(
                            f"a worker process exited (code {code}) before it could start. "
                            f"Local workers start with the {ctx.get_start_method()!r} method, "
                            f"which imports the main script again: guard a script's top-level "
                            f"code with `if __name__ == \"__main__\":` (or use workers=1)")
                    w.kill()
                    pool.remove(w)
                    if w.running:
                        # the first unanswered job was running; the rest never started
                        crashed, rest = w.running[0], w.running[1:]
                        queue.extendleft(reversed(rest))
                        how = (f"killed by signal {-code}" if code is not None and code < 0
                               else f"exited with code {code}")
                        attempts.failed(crashed[0], f"worker process {how}")
                        queue.appendleft(crashed)
    finally:
        for w in pool:
            if w.running:
                w.kill()
            else:
                w.stop()
