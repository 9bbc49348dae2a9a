"""Ray back end: chunks of tasks as Ray tasks on a local instance or an existing cluster.

Ray is imported only here and only when a Ray executor runs, so ``abb-gym`` works without it;
:func:`import_ray` names the extra to install when it is missing.

Fault handling is split by cause:

* an exception raised by the task function is retried inside the Ray task, per task, so the
  finished tasks of the same chunk are not recomputed; an input error
  (:data:`~.errors.INPUT_ERRORS`) is not retried: it ends the chunk and stops the sweep;
* a worker that dies (killed, out of memory, node lost) makes Ray resubmit the whole chunk
  (``max_retries = retries``); tasks of that chunk that had finished before the crash run
  again, but the driver keeps one result per task, so nothing is counted twice.  Use
  ``chunksize=1`` when a task must never run twice.

Stopping: however a sweep stops (a failed task, Ctrl-C, an error in the driver), the chunks in
flight have ended before the exception leaves :func:`run_ray`, so nothing computes after the
call returns and a sweep started next in the same Ray session gets healthy workers:

1. wait up to :data:`CANCEL_GRACE` seconds for them, handing over (and storing) every result
   they finish;
2. cancel the chunks still running *without* killing their workers (Ray raises
   KeyboardInterrupt inside the task) and wait as long again;
3. kill the workers of those that ignore it (stuck in one long call into compiled code).

Cancelling only after a grace period matters: ``ray.cancel`` of a task that is completing at
that instant can abort the driver in Ray ("Tried to complete task that was not pending",
ray-project/ray#54846), and a killed worker may still be handed the next sweep's first task
in its last milliseconds, failing it with WorkerCrashedError.  Such a death shortly after a kill
of ours is therefore not charged: the chunk it hit is resubmitted without costing an attempt.
A second Ctrl-C while waiting kills at once.
"""
from __future__ import annotations

import contextlib
import os
import socket
import time
import traceback
from typing import Any, Callable, Sequence

from .._threads import share_cores
from .errors import (INPUT_ERRORS, MissingExtraError, RayConnectionError, RemoteTraceback,
                     call_task, portable_error)

__all__ = ["import_ray", "ensure_ray", "run_ray", "ray_cpus", "CANCEL_GRACE"]

_INSTALL_HINT = "pip install 'abb-gym[cluster]'"

#: Seconds a stopping sweep waits for its chunks in flight to end, before cancelling them, and
#: again before killing the workers of those that ignore the cancellation.
CANCEL_GRACE = 10.0
#: Seconds to open a TCP connection to a cluster before declaring it absent (Ray itself would
#: retry for minutes).
CONNECT_TIMEOUT = 10.0
# Times at which this process force-killed Ray workers; a WorkerCrashedError soon after may be
# one of those deaths hitting a task of the next sweep.
_KILL_WINDOW = 30.0
_our_kills: list[float] = []


def import_ray():
    """The ``ray`` module, or :class:`MissingExtraError` saying how to install it."""
    try:
        import ray
    except ImportError as exc:
        raise MissingExtraError(
            f"the Ray executor (--ray / --ray-address) needs Ray, which is not installed "
            f"({exc}); install the optional extra: {_INSTALL_HINT}") from exc
    return ray


def _check_reachable(address: str) -> None:
    """Raise :class:`RayConnectionError` at once when nothing listens at ``address``; Ray's own
    connection attempt retries for 30 s (Ray Client) to minutes (GCS) before failing."""
    target = address
    if address == "auto":
        try:  # Ray's own lookup: RAY_ADDRESS, the last `ray start`, a GCS running here
            from ray._private.services import canonicalize_bootstrap_address
            target = canonicalize_bootstrap_address("auto")
        except ConnectionError:
            raise RayConnectionError(address, "no Ray instance runs on this machine") from None
        except Exception:  # Ray's internals moved: leave the check to ray.init
            return
        if not target:
            return
    hostport = str(target).split("://", 1)[-1]
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        return  # not HOST:PORT: ray.init reports the format
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=CONNECT_TIMEOUT).close()
    except OSError as exc:
        why = exc.strerror or type(exc).__name__
        raise RayConnectionError(address, f"cannot connect to {hostport}: {why}") from None


def ensure_ray(address: str | None = None, num_cpus: int | None = None,
               runtime_env: dict | None = None):
    """Connect to Ray unless this process already is: ``address`` (an existing cluster, e.g.
    ``"auto"``, ``"HOST:6379"`` or ``"ray://HOST:10001"``) or, with ``address=None``, the
    cluster the ``RAY_ADDRESS`` environment variable names or else a new local instance with
    ``num_cpus`` CPUs (default: all).  Returns the ``ray`` module.

    A Ray session that is already initialised (e.g. by the caller or a test) is used as is.
    Raises :class:`~.errors.RayConnectionError` (a ValueError) when no cluster answers at
    ``address`` (or ``RAY_ADDRESS``), within :data:`CONNECT_TIMEOUT` seconds.
    """
    ray = import_ray()
    if ray.is_initialized():
        return ray
    kwargs: dict[str, Any] = {}
    if runtime_env:
        kwargs["runtime_env"] = runtime_env
    if address:
        _check_reachable(address)
        try:
            ray.init(address=address, **kwargs)
        except ConnectionError as exc:
            raise RayConnectionError(address, " ".join(str(exc).split())) from exc
    elif os.environ.get("RAY_ADDRESS"):
        _check_reachable(os.environ["RAY_ADDRESS"])
        ray.init(**kwargs)  # Ray connects to the cluster the environment names
    else:
        # address="local": always a new instance, never a cluster that `ray start` left
        # behind (use ray_address="auto" for that); no dashboard for a throw-away instance:
        # it costs start-up time and memory
        with _loopback_only(ray):
            ray.init(address="local", num_cpus=num_cpus, include_dashboard=False, **kwargs)
    return ray


#: Ray's switch (read when Ray is imported, and by the processes it starts) that makes a node
#: take the loopback address as its own, as Ray does by default on macOS and Windows
_LOOPBACK_SWITCH = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"


@contextlib.contextmanager
def _loopback_only(ray):
    """Start a local instance whose processes listen on 127.0.0.1 only.

    Why: on Linux, Ray's core processes (GCS, raylet, workers, agents) listen on every
    network interface, so a throw-away instance of one sweep would accept connections from
    the whole network.  A node whose own address is the loopback address binds its servers
    there; Ray does this where it does not support clusters (macOS, Windows), switched by
    :data:`_LOOPBACK_SWITCH`.  The switch is set for the processes the instance starts and,
    in this process, for the start only (the driver keeps the node's address afterwards).
    Reachable from other machines, on purpose: start the cluster yourself (``ray start
    --head``, with Ray's own address options) and pass ``--ray-address``.
    """
    import importlib
    constants = importlib.import_module("ray._private.ray_constants")
    saved_env = os.environ.get(_LOOPBACK_SWITCH)
    saved_flag = getattr(constants, "ENABLE_RAY_CLUSTER", None)
    os.environ[_LOOPBACK_SWITCH] = "0"
    constants.ENABLE_RAY_CLUSTER = False
    try:
        yield
    finally:
        if saved_env is None:
            os.environ.pop(_LOOPBACK_SWITCH, None)
        else:
            os.environ[_LOOPBACK_SWITCH] = saved_env
        if saved_flag is not None:
            constants.ENABLE_RAY_CLUSTER = saved_flag


def ray_cpus(ray) -> int:
    """CPUs the connected cluster has now (at least 1)."""
    try:
        return max(1, int(ray.cluster_resources().get("CPU", 1)))
    except Exception:  # resources unknown (e.g. a client still connecting)
        return 1


def _run_chunk(fn: Callable, chunk: Sequence[tuple], retries: int,
               threads: int = 1) -> list[tuple]:
    """Runs on a Ray worker: every job of the chunk, retrying exceptions per job; an input
    error ends the chunk (the sweep stops on it).  The compiled parallel loops run on the
    task's ``threads`` CPUs (:func:`abb_gym._threads.share_cores`; numba's default would be
    every core of the node, for each of the node's tasks)."""
    share_cores(threads)
    out: list[tuple] = []
    for index, task, seed in chunk:
        for attempt in range(1, retries + 2):
            try:
                out.append(("ok", index, call_task(fn, task, seed)))
                break
            except INPUT_ERRORS as exc:
                out.append(("err", index, attempt, traceback.format_exc(), portable_error(exc)))
                return out
            except Exception:
                if attempt == retries + 1:
                    out.append(("err", index, attempt, traceback.format_exc(), None))
    return out


def _forgiven(ray, exc: Exception) -> bool:
    """True (once per kill) if ``exc`` may be the death of a worker we force-killed."""
    now = time.monotonic()
    _our_kills[:] = [t for t in _our_kills if now - t < _KILL_WINDOW]
    if _our_kills and isinstance(exc, ray.exceptions.WorkerCrashedError):
        _our_kills.pop()
        return True
    return False


def _cancel(ray, refs: list, force: bool) -> None:
    for ref in refs:
        try:
            ray.cancel(ref, force=force)
        except Exception:  # already finished, or the cluster is gone
            pass


def _kill(ray, refs: list) -> None:
    _cancel(ray, refs, force=True)
    _our_kills.extend([time.monotonic()] * len(refs))


def _stop(ray, in_flight: dict, take: Callable) -> None:
    """Return once no chunk of ``in_flight`` runs any more (see the module docstring);
    ``take(ref)`` hands over a finished chunk's results."""
    handing_over = True
    for action in (None, "cancel", "kill"):
        if not in_flight:
            return
        if action == "cancel":
            _cancel(ray, list(in_flight), force=False)
        elif action == "kill":
            _kill(ray, list(in_flight))
        deadline = time.monotonic() + CANCEL_GRACE
        try:
            while in_flight and deadline > time.monotonic():
                ready, _ = ray.wait(list(in_flight), num_returns=1,
                                    timeout=max(0.0, deadline - time.monotonic()))
                for ref in ready:
                    if handing_over:
                        try:
                            take(ref, stopping=True)
                        except Exception:  # e.g. a full disk: the error being raised says more
                            handing_over = False
                    in_flight.pop(ref, None)
        except KeyboardInterrupt:  # Ctrl-C (again): stop now
            _kill(ray, list(in_flight))
            raise


def run_ray(fn: Callable, jobs: Sequence[tuple], *, retries: int, chunksize: int,
            max_in_flight: int | None, on_result: Callable[[int, Any], None],
            on_fail: Callable[..., None], ray_options: dict | None = None) -> None:
    """Run jobs as Ray tasks of ``chunksize`` jobs each on the connected Ray session.

    ``max_in_flight`` caps the chunks submitted at once (None: four per CPU of the cluster,
    re-read every few seconds so that a cluster that scales up gets more work).
    ``ray_options`` go to ``.options()`` of every Ray task (e.g. ``{"num_cpus": 2}``;
    default one CPU per task).  ``on_fail(index, attempts, detail, error)`` must raise; the
    chunks still in flight have ended by the time its exception (or any other) leaves.
    """
    ray = import_ray()
    opts = {"num_cpus": 1, **(ray_options or {})}
    opts.update(max_retries=retries, retry_exceptions=False)
    remote = ray.remote(_run_chunk).options(**opts)
    fn_ref = ray.put(fn)  # shipped once, not once per chunk
    chunks = [list(jobs[i:i + chunksize]) for i in range(0, len(jobs), chunksize)]
    todo = iter(chunks)
    in_flight: dict[Any, list] = {}
    cap = {"n": max_in_flight or 4 * ray_cpus(ray), "checked": time.monotonic()}

    threads = max(1, int(opts["num_cpus"]))

    def submit(chunk: list) -> None:
        in_flight[remote.remote(fn_ref, chunk, retries, threads)] = chunk

    def refill() -> None:
        if max_in_flight is None and time.monotonic() - cap["checked"] > 5.0:
            cap["n"], cap["checked"] = 4 * ray_cpus(ray), time.monotonic()
        while len(in_flight) < cap["n"]:
            chunk = next(todo, None)
            if chunk is None:
                return
            submit(chunk)

    def take(ref, stopping: bool = False) -> list[tuple]:
        """Hand over the results of a finished chunk; returns its failures."""
        chunk = in_flight.pop(ref)
        try:
            out = ray.get(ref)
        except ray.exceptions.RayError as exc:
            if stopping:
                return []
            if _forgiven(ray, exc):
                submit(chunk)
                return []
            # worker death after all retries, or a failure outside the task function
            idx = [j[0] for j in chunk]
            return [(idx[0], retries + 1, f"Ray task for task(s) {idx} failed: "
                     f"{type(exc).__name__}: {exc}", None)]
        failures = []
        for msg in out:
            if msg[0] == "ok":
                on_result(msg[1], msg[2])
            else:
                failures.append(msg[1:])
        return failures

    try:
        refill()
        while in_flight:
            ready, _ = ray.wait(list(in_flight), num_returns=1)
            # collect every other chunk that is also ready, without waiting
            more, _ = ray.wait([r for r in in_flight if r not in ready],
                               num_returns=len(in_flight) - len(ready), timeout=0)
            failures = [f for ref in list(ready) + list(more) for f in take(ref)]
            if failures:  # after every finished result above has been handed over (and stored)
                index, attempts, detail, error = failures[0]
                if error is not None:
                    error.__cause__ = RemoteTraceback(detail)
                on_fail(index, attempts, detail, error)
            refill()
    finally:
        _stop(ray, in_flight, take)
