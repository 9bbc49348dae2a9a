"""Ray back end: chunks of tasks as Ray tasks on a local instance or an existing cluster.

Ray is imported only here and only when a Ray executor runs, so ``abb-gym`` works without it;
:func:`import_ray` names the extra to install when it is missing.

Fault handling is split by cause:

* an exception raised by the task function is retried inside the Ray task, per task, so the
  finished tasks of the same chunk are not recomputed;
* a worker that dies (killed, out of memory, node lost) makes Ray resubmit the whole chunk
  (``max_retries = retries``); tasks of that chunk that had finished before the crash run
  again, but the driver keeps one result per task, so nothing is counted twice.  Use
  ``chunksize=1`` when a task must never run twice.
"""
from __future__ import annotations

import os
import time
import traceback
from typing import Any, Callable, Sequence

from .errors import MissingExtraError, call_task

__all__ = ["import_ray", "ensure_ray", "run_ray", "ray_cpus"]

_INSTALL_HINT = "pip install 'abb-gym[cluster]'"


def import_ray():
    """The ``ray`` module, or :class:`MissingExtraError` saying how to install it."""
    try:
        import ray
    except ImportError as exc:
        raise MissingExtraError(
            f"the Ray executor (--ray / --ray-address) needs Ray, which is not installed "
            f"({exc}); install the optional extra: {_INSTALL_HINT}") from exc
    return ray


def ensure_ray(address: str | None = None, num_cpus: int | None = None,
               runtime_env: dict | None = None):
    """Connect to Ray unless this process already is: ``address`` (an existing cluster, e.g.
    ``"auto"``, ``"HOST:6379"`` or ``"ray://HOST:10001"``) or, with ``address=None``, the
    cluster the ``RAY_ADDRESS`` environment variable names or else a new local instance with
    ``num_cpus`` CPUs (default: all).  Returns the ``ray`` module.

    A Ray session that is already initialised (e.g. by the caller or a test) is used as is.
    """
    ray = import_ray()
    if ray.is_initialized():
        return ray
    kwargs: dict[str, Any] = {}
    if runtime_env:
        kwargs["runtime_env"] = runtime_env
    if address:
        ray.init(address=address, **kwargs)
    elif os.environ.get("RAY_ADDRESS"):
        ray.init(**kwargs)  # Ray connects to the cluster the environment names
    else:
        # address="local": always a new instance, never a cluster that `ray start` left
        # behind (use ray_address="auto" for that); no dashboard for a throw-away instance:
        # it costs start-up time and memory
        ray.init(address="local", num_cpus=num_cpus, include_dashboard=False, **kwargs)
    return ray


def ray_cpus(ray) -> int:
    """CPUs the connected cluster has now (at least 1)."""
    try:
        return max(1, int(ray.cluster_resources().get("CPU", 1)))
    except Exception:  # resources unknown (e.g. a client still connecting)
        return 1


def _run_chunk(fn: Callable, chunk: Sequence[tuple], retries: int) -> list[tuple]:
    """Runs on a Ray worker: every job of the chunk, retrying exceptions per job."""
    out = []
    for index, task, seed in chunk:
        for attempt in range(1, retries + 2):
            try:
                out.append(("ok", index, call_task(fn, task, seed)))
                break
            except Exception:
                if attempt == retries + 1:
                    out.append(("err", index, attempt, traceback.format_exc()))
    return out


def run_ray(fn: Callable, jobs: Sequence[tuple], *, retries: int, chunksize: int,
            max_in_flight: int | None, on_result: Callable[[int, Any], None],
            on_fail: Callable[[int, int, str], None], ray_options: dict | None = None) -> None:
    """Run jobs as Ray tasks of ``chunksize`` jobs each on the connected Ray session.

    ``max_in_flight`` caps the chunks submitted at once (None: four per CPU of the cluster,
    re-read every few seconds so that a cluster that scales up gets more work).
    ``ray_options`` go to ``.options()`` of every Ray task (e.g. ``{"num_cpus": 2}``;
    default one CPU per task).
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

    def submit() -> None:
        if max_in_flight is None and time.monotonic() - cap["checked"] > 5.0:
            cap["n"], cap["checked"] = 4 * ray_cpus(ray), time.monotonic()
        while len(in_flight) < cap["n"]:
            chunk = next(todo, None)
            if chunk is None:
                return
            in_flight[remote.remote(fn_ref, chunk, retries)] = chunk

    try:
        submit()
        while in_flight:
            ready, _ = ray.wait(list(in_flight), num_returns=1)
            # collect every other chunk that is also ready, without waiting
            more, _ = ray.wait([r for r in in_flight if r not in ready],
                               num_returns=len(in_flight) - len(ready), timeout=0)
            failures = []
            for ref in list(ready) + list(more):
                chunk = in_flight.pop(ref)
                try:
                    out = ray.get(ref)
                except ray.exceptions.RayError as exc:
                    # worker death after all retries, or a failure outside the task function
                    idx = [j[0] for j in chunk]
                    failures.append((idx[0], retries + 1, f"Ray task for task(s) {idx} failed: "
                                     f"{type(exc).__name__}: {exc}"))
                    continue
                for msg in out:
                    if msg[0] == "ok":
                        on_result(msg[1], msg[2])
                    else:
                        failures.append(msg[1:])
            if failures:  # after every finished result above has been handed over (and stored)
                on_fail(*failures[0])
            submit()
    finally:
        for ref in in_flight:
            try:
                ray.cancel(ref, force=True)
            except Exception:  # already finished or the cluster is gone
                pass
