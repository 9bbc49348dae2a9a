"""Errors of the executor layer and the one place a task function is called."""
from __future__ import annotations

import os
import pickle
from typing import Any, Callable

__all__ = ["TaskFailed", "MissingExtraError", "RayConnectionError", "SweepInterrupted",
           "RemoteTraceback", "INPUT_ERRORS", "call_task", "portable_error"]

#: Exceptions a task raises when its input is wrong (this includes the project's ``SceneError``
#: and ``PresetError``): running it again would fail the same way, so the sweep stops at once
#: and the exception itself reaches the caller (``abb-gym`` prints it as one line).
INPUT_ERRORS: tuple[type[BaseException], ...] = (ValueError, TypeError)


class TaskFailed(RuntimeError):
    """A task still failed after ``retries`` retries (exception or worker death).

    Results of the tasks that finished are already in the store (when one was given), so a
    rerun with the same store resumes after the failing task is fixed.

    Attributes: ``index`` (position in the task list), ``task_id``, ``attempts`` and ``detail``
    (the last error's traceback text, or how the worker died).
    """

    def __init__(self, index: int, task_id: str, attempts: int, detail: str) -> None:
        self.index, self.task_id, self.attempts, self.detail = index, task_id, attempts, detail
        super().__init__(f"task {index} (id {task_id}) failed after {attempts} attempt(s):\n"
                         f"{detail}")

    def __reduce__(self):  # picklable across processes and Ray
        return (TaskFailed, (self.index, self.task_id, self.attempts, self.detail))


class MissingExtraError(ImportError, ValueError):
    """An optional dependency is missing; the message names the extra to install.

    Also a ValueError so that the ``abb-gym`` command line reports it as one clear line.
    """


class RayConnectionError(ConnectionError, ValueError):
    """No Ray cluster answers at the address given (``--ray-address``).

    A ValueError (reported by ``abb-gym`` as one line, exit status 2) and a ConnectionError.
    Attributes: ``address`` and ``reason``.
    """

    def __init__(self, address: str, reason: str) -> None:
        self.address, self.reason = address, reason
        super().__init__(
            f"no Ray cluster found at {address!r} ({reason}); start one with `ray start "
            f"--head` on the head node (then use --ray-address auto there), or use --ray to "
            f"run on a new local Ray instance")

    def __reduce__(self):
        return (RayConnectionError, (self.address, self.reason))


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C stopped a sweep; the tasks in flight were cancelled before this was raised.

    A KeyboardInterrupt, so code that handles Ctrl-C keeps working.  ``str()`` is one line for
    a command line to print, e.g. ``interrupted; 12 of 40 tasks finished; rerun the same
    command with --resume-dir out/resume to continue``.  Attributes: ``done`` (finished tasks,
    those loaded from the store included), ``total`` and ``store`` (the result directory, or
    None when nothing was kept).
    """

    def __init__(self, done: int, total: int, store: str | os.PathLike | None) -> None:
        self.done, self.total, self.store = done, total, store
        head = f"interrupted; {done} of {total} tasks finished"
        if store is not None:
            super().__init__(f"{head}; rerun the same command with --resume-dir {store} "
                             f"to continue")
        else:
            super().__init__(f"{head}; nothing was kept (rerun with --resume-dir DIR to keep "
                             f"finished tasks across interruptions)")

    def __reduce__(self):
        return (SweepInterrupted, (self.done, self.total, self.store))


class RemoteTraceback(Exception):
    """The traceback of an exception raised in a worker process, attached as ``__cause__``
    of the exception re-raised in the driver (as :mod:`concurrent.futures` does)."""

    def __str__(self) -> str:
        return "\n" + str(self.args[0] if self.args else "")


def call_task(fn: Callable, task: Any, seed: Any) -> Any:
    """``fn(task)``, or ``fn(task, seed)`` in a seeded sweep (``seed`` not None)."""
    return fn(task) if seed is None else fn(task, seed)


def portable_error(exc: BaseException) -> BaseException:
    """``exc`` if it survives pickling (to travel from a worker to the driver), else the
    nearest :data:`INPUT_ERRORS` type with the same message.

    Checked in the worker: an exception class whose ``__init__`` does not accept its own
    ``args`` pickles fine but fails to unpickle, which would break the driver instead.
    """
    try:
        pickle.loads(pickle.dumps(exc))
        return exc
    except Exception:
        base = next((t for t in INPUT_ERRORS if isinstance(exc, t)), RuntimeError)
        return base(f"{type(exc).__qualname__}: {exc}")
