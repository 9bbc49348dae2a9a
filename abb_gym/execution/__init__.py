"""One executor layer for every sweep-like job: local processes by default, Ray when asked.

Stability maps, baseline tuning grids, ``abb-gym evaluate`` over many seeded scenarios, the
parameter studies and multi-seed training are all lists of independent tasks.  This package
runs such a list on this machine's cores or on a Ray cluster, with the same results either way,
retries for tasks that fail, results kept on disk so that an interrupted sweep resumes, and a
progress bar in every mode.

Running tasks
-------------
::

    from abb_gym.execution import Executor, run_tasks

    def simulate_case(case: Case, seed) -> Metrics:     # module level, so it pickles
        rng = numpy.random.default_rng(seed)            # the task's own seed (see below)
        ...

    results = run_tasks(simulate_case, cases, seed=0, desc="evaluate")            # all cores
    results = run_tasks(simulate_case, cases, seed=0, ray=True)                   # local Ray
    results = run_tasks(simulate_case, cases, seed=0, ray_address="auto",         # a cluster
                        store="out/eval/resume")                                   # resumable

``run_tasks(fn, tasks, *, workers=None, ray=False, ray_address=None, store=None, retries=2,
progress=True, desc="tasks", seed=None, chunksize=None, task_ids=None, ray_options=None,
runtime_env=None) -> list`` returns ``[fn(t) for t in tasks]`` in task order, or
``[fn(t, task_seed(seed, i)) for i, t in enumerate(tasks)]`` when ``seed`` is given.
Library functions should accept an :class:`Executor` (a frozen, picklable dataclass with the
same fields) and call ``executor.map(fn, tasks, desc=..., seed=...)``; command-line tools build
it with :func:`~abb_gym.execution.cli.executor_from_args`.

=======================  ===================================================================
choice                   what runs where
=======================  ===================================================================
``workers=N`` (default)  N local worker processes (default: the usable cores).  ``workers=1``
                         runs in this process (no pickling; easiest to debug; a task that
                         kills the process ends the sweep).
``ray=True``             a new local Ray instance with ``workers`` CPUs (default: all), or
                         the Ray session this process is already connected to, or the one
                         the ``RAY_ADDRESS`` environment variable names.
``ray_address=ADDR``     an existing cluster: ``"auto"`` (started on this machine with
                         ``ray start --head``), ``"HOST:6379"`` from a cluster node, or
                         ``"ray://HOST:10001"`` (Ray Client) from outside.  ``workers`` then
                         caps the tasks in flight.
=======================  ===================================================================

Ray is optional (``pip install 'abb-gym[cluster]'``) and imported only when a Ray mode runs;
without it those modes raise :class:`MissingExtraError` naming the extra.  Cluster nodes need
abb-gym installed (same version), or pass ``runtime_env={"pip": [...]}`` /
``{"working_dir": "."}``.  ``ray_options`` go to every Ray task (``{"num_cpus": 4}``,
``{"num_gpus": 1}``, ``{"memory": 2e9}``).

Contract for task functions
---------------------------
* ``fn`` is a module-level function (or an instance of a module-level class); tasks and results
  are picklable.  Ray ships ``fn`` once per sweep; local workers get it at start.  Local
  workers start with ``forkserver`` (safe when the driver runs threads: torch, Ray, tqdm), so a
  script that runs processes must guard its top-level code with
  ``if __name__ == "__main__":``; ``Executor(start_method="fork")`` avoids that.
* ``fn`` depends only on its task (and seed): no global state, no reliance on which worker or
  in which order it runs.  Tasks may run twice (after a crash), so side effects should be
  idempotent; results are collected once per task.
* Task specs should be small records: dataclasses (e.g. :class:`~abb_gym.physics.scene.Scene`,
  :class:`~abb_gym.physics.drives.SpeedProfile`), tuples, dicts, numbers, strings, arrays.
  Their content, with the function's qualified name and the seed, gives the stable task id
  (:func:`task_id`) under which the result is stored.  Pass ``task_ids=`` to choose ids.
* Prefer several milliseconds or more per task; for tinier ones raise ``chunksize``.

Seeds
-----
With ``seed=root`` task ``i`` receives ``task_seed(root, i)`` =
``numpy.random.SeedSequence(root).spawn(n)[i]``: a function of (root, i) only, never of the
worker, so every executor gives identical results.  Build generators with
``numpy.random.default_rng(seed)`` and integer seeds with :func:`seed_int`.  When a task's
seed should not move if the list is reordered (e.g. scenario ``k`` of a test set), put
``task_seed(root, k)`` or an integer into the task spec yourself and leave ``seed=None``.

Failures, retries and resume
----------------------------
* A task that raises, or whose worker process dies (killed, out of memory, lost node), runs
  again up to ``retries`` times (default 2); then :class:`TaskFailed` is raised with the index,
  id and last traceback.  Locally the failure is charged to exactly the task that was running
  (the rest of its chunk is requeued untouched); on Ray, exceptions are retried per task inside
  the Ray task and worker deaths by Ray resubmitting the chunk.
* Bad input is never retried: a task that raises ``ValueError`` or ``TypeError`` (this includes
  the project's ``SceneError`` and ``PresetError``, e.g. an unknown scene name) stops the sweep
  at once, and that exception, with its own type and message, reaches the caller, so
  ``abb-gym`` prints it as one line (exit status 2).  A note names the task; from a worker
  process, the worker's traceback is its ``__cause__``.  An exception that cannot travel
  between processes arrives as a plain ValueError / TypeError with the same message.
* Ctrl-C raises :class:`~.errors.SweepInterrupted`, a KeyboardInterrupt whose one-line message
  says how many tasks finished and how to resume (``done``, ``total``, ``store``).  ``abb-gym``
  prints instead the tally of the whole command, whose sweeps may be many
  (:class:`~.core.TaskTally`: ``interrupted: N of M tasks stored; rerun the same command to
  resume``), and exits 130.
* However a sweep stops (a failed task, bad input, Ctrl-C), the tasks in flight have ended
  before the exception reaches the caller: nothing computes on behind its back, and a sweep
  started next (e.g. the resumed one, in the same Ray session) starts clean.  Local workers are
  terminated at once.  On Ray, the running chunks get ``ray_backend.CANCEL_GRACE`` seconds
  (10) to finish, and their results are stored; then they are cancelled without killing their
  workers, and only those that ignore that for as long again (stuck in compiled code) have
  their workers killed.  A second Ctrl-C kills at once.
* ``store=DIR`` (``--resume-dir``) keeps one small file per finished task (:class:`ResultStore`,
  written atomically by the driver before the task counts as done).  A rerun with the same
  ``DIR`` loads finished tasks instead of running them; the progress bar starts at that count.
  A sweep interrupted at any instant (Ctrl-C, killed driver, failed task) loses at most the
  tasks that were running.  Delete the directory after changing a task function's code.
  A damaged result file is recomputed with a warning naming it; a directory in the place of a
  result file is a ValueError naming it; leftover temporary files are never read (see
  :mod:`.store`).
* Each task's result enters the output exactly once, whatever retries happened.
* ``ray_address=`` with no cluster answering there raises :class:`~.errors.RayConnectionError`
  (a ValueError: one line in ``abb-gym``) within seconds, saying how to start one.
* Under Ray Tune (:mod:`.tune`), retries follow Tune's ``FailureConfig`` for every exception.

Hyperparameter search and multi-seed training
---------------------------------------------
:func:`abb_gym.execution.tune.run_trials` runs a trainable ``config -> metrics`` over a search
space (``grid``, ``choice``, ``uniform``, ``loguniform``, ``randint``) with Ray Tune when the
executor is a Ray one and with :meth:`Executor.map` otherwise; the configs are drawn from a
seed before anything runs, so both modes run the same trials.

Command line
------------
:func:`~abb_gym.execution.cli.add_executor_arguments` adds ``--workers``, ``--ray``,
``--ray-address``, ``--resume-dir`` and ``--retries`` to a subcommand;
:func:`~abb_gym.execution.cli.executor_from_args` turns them into an :class:`Executor`.

Modules: :mod:`.core` (Executor, run_tasks), :mod:`.local` (serial and process pool),
:mod:`.ray_backend`, :mod:`.store`, :mod:`.ids` (task ids, seeds), :mod:`.tune`, :mod:`.cli`,
:mod:`.testing` (a toy task with fault injection, to check an executor or a cluster).
"""
from .core import Executor, default_workers, run_tasks
from .errors import MissingExtraError, RayConnectionError, SweepInterrupted, TaskFailed
from .ids import seed_int, task_id, task_seed, task_seeds
from .store import ResultStore

__all__ = ["Executor", "run_tasks", "default_workers", "TaskFailed", "MissingExtraError",
           "RayConnectionError", "SweepInterrupted", "ResultStore", "task_id", "task_seed",
           "task_seeds", "seed_int"]
