"""Errors of the executor layer and the one place a task function is called."""
from __future__ import annotations

from typing import Any, Callable

__all__ = ["TaskFailed", "MissingExtraError", "call_task"]


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


def call_task(fn: Callable, task: Any, seed: Any) -> Any:
    """``fn(task)``, or ``fn(task, seed)`` in a seeded sweep (``seed`` not None)."""
    return fn(task) if seed is None else fn(task, seed)
