"""Multi-seed training and hyperparameter search: Ray Tune on Ray, the local executor otherwise.

A *trainable* is a module-level function ``trainable(config: dict) -> dict`` that trains (or
evaluates) one configuration and returns its final metrics, e.g. ``{"return": 812.0,
"settle_time": 1.9}``.  It may call :func:`report` with intermediate metrics (one call per
training iteration): under Ray Tune these feed Tune's schedulers (e.g. ASHA) and loggers
(TensorBoard, CSV); locally they are ignored except that a trainable returning None takes the
last reported metrics as final.

The search space is a dict (nested dicts allowed) whose leaves are fixed values or the samplers
of this module::

    space = {"lr": loguniform(1e-4, 1e-2), "gamma": grid([0.98, 0.995]),
             "seed": grid(range(5)), "env_kwargs": {"scene": "lu_hung_odd3"}}
    trials = run_trials(train_ppo, space, num_samples=4, seed=0,
                        executor=Executor(ray=True), metric="return", mode="max",
                        resources_per_trial={"cpu": 2})
    best = trials.best()            # a Trial: .config, .metrics, .index, .task_id

Semantics follow Ray Tune's: every ``grid`` is crossed with every other, the whole grid is
repeated ``num_samples`` times, and the random samplers draw anew for each trial.  The
configurations are drawn *here*, from ``numpy.random.SeedSequence(seed)`` (one child per trial,
by (sample, grid point)), before anything runs, so the same trials run whatever the executor;
Ray Tune is used to schedule, retry and log them (``tune.grid_search`` over the drawn list),
not to draw them.  For multi-seed training put the training seed in the space
(``"seed": grid(range(n))``) so it is part of each trial's config.

Resume: with ``executor.store`` set, each finished trial's final metrics are saved under a
task id of (trainable, config), locally by the executor and on Ray by a Tune callback in the
driver, so a rerun (in either mode) skips finished trials.  A trial that fails is retried
``executor.retries`` times (locally like any task; on Ray through Tune's ``FailureConfig``),
restarting from scratch: checkpointing inside a trial is the trainable's business.  A trial
that a Tune scheduler (``tune_config={"scheduler": ASHAScheduler()}``) stops early counts as
finished, with its last reported metrics.

Under Ray Tune the trainable runs in the driver's working directory (this module sets
``RAY_CHDIR_TO_TRIAL_DIR=0`` unless already set), so relative paths mean the same in both modes;
on a multi-node cluster, give it absolute paths on shared storage.
"""
from __future__ import annotations

import itertools
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from .core import Executor
from .errors import TaskFailed
from .ids import task_id, task_seed
from .store import ResultStore

__all__ = ["grid", "choice", "uniform", "loguniform", "randint", "expand_space", "report",
           "run_trials", "Trial", "TrialResults"]


# ---------------------------------------------------------------------- search space
@dataclass(frozen=True)
class Grid:
    """Every value, crossed with the other grids (Ray Tune's ``grid_search``)."""
    values: tuple


@dataclass(frozen=True)
class Choice:
    """One of ``values`` at random, uniformly."""
    values: tuple


@dataclass(frozen=True)
class Uniform:
    """A float uniform in [low, high)."""
    low: float
    high: float


@dataclass(frozen=True)
class LogUniform:
    """A float whose logarithm is uniform in [log low, log high); 0 < low < high."""
    low: float
    high: float


@dataclass(frozen=True)
class RandInt:
    """An integer uniform in [low, high) (high excluded, like ``numpy`` and Ray Tune)."""
    low: int
    high: int


def _values(name: str, values: Sequence[Any]) -> tuple:
    vals = tuple(values)
    if not vals:
        raise ValueError(f"{name}() needs at least one value")
    return vals


def grid(values: Sequence[Any]) -> Grid:
    """Try every value (crossed with the other grids)."""
    return Grid(_values("grid", values))


def choice(values: Sequence[Any]) -> Choice:
    """Draw one of ``values`` per trial."""
    return Choice(_values("choice", values))


def _bounds(name: str, low: float, high: float, positive: bool = False) -> tuple[float, float]:
    lo, hi = float(low), float(high)
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise ValueError(f"{name}: need finite low < high (got {low!r}, {high!r})")
    if positive and lo <= 0:
        raise ValueError(f"{name}: need low > 0 (got {low!r})")
    return lo, hi


def uniform(low: float, high: float) -> Uniform:
    """Draw a float uniformly in [low, high)."""
    return Uniform(*_bounds("uniform", low, high))


def loguniform(low: float, high: float) -> LogUniform:
    """Draw a float log-uniformly in [low, high), 0 < low < high (learning rates)."""
    return LogUniform(*_bounds("loguniform", low, high, positive=True))


def randint(low: int, high: int) -> RandInt:
    """Draw an integer uniformly in [low, high)."""
    if int(low) != low or int(high) != high or not int(low) < int(high):
        raise ValueError(f"randint: need integers low < high (got {low!r}, {high!r})")
    return RandInt(int(low), int(high))


_SAMPLERS = (Choice, Uniform, LogUniform, RandInt)


def _leaves(space: dict, prefix: tuple = ()) -> list[tuple[tuple, Any]]:
    out = []
    for k, v in space.items():
        if isinstance(v, dict):
            out.extend(_leaves(v, prefix + (k,)))
        else:
            out.append((prefix + (k,), v))
    return out


def _set(config: dict, path: tuple, value: Any) -> None:
    for k in path[:-1]:
        config = config[k]
    config[path[-1]] = value


def _copy(space: dict) -> dict:
    return {k: _copy(v) if isinstance(v, dict) else v for k, v in space.items()}


def _draw(s: Any, rng: np.random.Generator) -> Any:
    if isinstance(s, Choice):
        return s.values[int(rng.integers(len(s.values)))]
    if isinstance(s, Uniform):
        return float(rng.uniform(s.low, s.high))
    if isinstance(s, LogUniform):
        return float(math.exp(rng.uniform(math.log(s.low), math.log(s.high))))
    return int(rng.integers(s.low, s.high))


def expand_space(space: dict, num_samples: int = 1, seed: int = 0) -> list[dict]:
    """The concrete configs of ``space``: grids crossed (first key varies slowest), the grid
    repeated ``num_samples`` times, samplers drawn per trial from
    ``SeedSequence(seed, spawn_key=(sample, grid_point))``."""
    if not isinstance(space, dict):
        raise ValueError(f"space must be a dict (got {type(space).__name__})")
    if isinstance(num_samples, bool) or not isinstance(num_samples, (int, np.integer)) \
            or num_samples < 1:
        raise ValueError(f"num_samples must be an integer >= 1 (got {num_samples!r})")
    task_seed(seed, 0)  # validates seed
    leaves = _leaves(space)
    grids = [(p, v.values) for p, v in leaves if isinstance(v, Grid)]
    samplers = [(p, v) for p, v in leaves if isinstance(v, _SAMPLERS)]
    configs = []
    for k in range(int(num_samples)):
        for g, combo in enumerate(itertools.product(*(vals for _, vals in grids))):
            cfg = _copy(space)
            for (p, _), v in zip(grids, combo):
                _set(cfg, p, v)
            if samplers:
                rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(k, g)))
                for p, s in samplers:
                    _set(cfg, p, _draw(s, rng))
            configs.append(cfg)
    return configs


# ---------------------------------------------------------------------- reporting
def _ignore(metrics: dict) -> None:
    pass


_reporter: Callable[[dict], None] = _ignore
_last_reported: dict | None = None


def report(metrics: dict) -> None:
    """Report intermediate metrics of the running trial (one call per training iteration):
    forwarded to Ray Tune under Tune, remembered as the fallback final metrics locally."""
    global _last_reported
    if not isinstance(metrics, dict):
        raise ValueError(f"report() takes a dict of metrics (got {type(metrics).__name__})")
    _last_reported = dict(metrics)
    _reporter(dict(metrics))


def _final(trainable: Callable, config: dict) -> dict:
    global _last_reported
    _last_reported = None
    out = trainable(_copy(config))
    if out is None:
        out = _last_reported
    if not isinstance(out, dict):
        raise ValueError(f"trainable {getattr(trainable, '__name__', trainable)!r} must return "
                         f"a dict of final metrics or call report() (got {type(out).__name__})")
    return out


def _run_local_trial(job: tuple[Callable, dict]) -> dict:
    """Task function of the local mode: one trial."""
    trainable, config = job
    return _final(trainable, config)


_NAMES = "abb_metric_names"  # carries the final metrics' names through Tune's result dict


def _tune_entry(tune_config: dict, abb_trainable: Callable, abb_configs: list) -> None:
    """Ray Tune function trainable: runs trial ``tune_config["abb_index"]`` of the configs."""
    global _reporter
    from ray import tune

    def forward(metrics: dict) -> None:
        # every report carries its metric names, so a trial that a scheduler stops early
        # still yields its last metrics (without Tune's own fields) as the final ones
        tune.report({**metrics, _NAMES: json.dumps(list(metrics))})

    _reporter = forward
    forward(_final(abb_trainable, abb_configs[tune_config["abb_index"]]))


# ---------------------------------------------------------------------- results
@dataclass
class Trial:
    """One finished trial: ``index`` in :func:`expand_space` order, its ``config``, the final
    ``metrics`` the trainable returned and the ``task_id`` it is stored under."""
    index: int
    config: dict
    metrics: dict
    task_id: str


class TrialResults(list):
    """The trials in :func:`expand_space` order, with :meth:`best`."""

    def __init__(self, trials: Sequence[Trial], metric: str | None, mode: str) -> None:
        super().__init__(trials)
        self.metric, self.mode = metric, mode

    def best(self, metric: str | None = None, mode: str | None = None) -> Trial:
        """The trial with the highest (``mode="max"``) or lowest (``"min"``) ``metric``;
        trials without it or with NaN are skipped.  Defaults: those given to run_trials."""
        metric = metric or self.metric
        mode = mode or self.mode
        if metric is None:
            raise ValueError("best() needs a metric (none was given to run_trials)")
        if mode not in ("max", "min"):
            raise ValueError(f"mode must be 'max' or 'min' (got {mode!r})")
        ok = [t for t in self if metric in t.metrics
              and not (isinstance(t.metrics[metric], float) and math.isnan(t.metrics[metric]))]
        if not ok:
            raise ValueError(f"no trial reported metric {metric!r}")
        key = (lambda t: t.metrics[metric])
        return max(ok, key=key) if mode == "max" else min(ok, key=key)


# ---------------------------------------------------------------------- running
def run_trials(trainable: Callable[[dict], dict | None], space: dict, *, num_samples: int = 1,
               seed: int = 0, executor: Executor | None = None, metric: str | None = None,
               mode: str = "max", resources_per_trial: dict | None = None,
               name: str = "abb_gym_tune", storage_path: str | os.PathLike | None = None,
               tune_config: dict | None = None, desc: str = "trials") -> TrialResults:
    """Run ``trainable`` on every config of ``space`` (see the module docstring).

    Parameters
    ----------
    trainable : module-level function ``config -> final metrics dict`` (or None after
        :func:`report`)
    space, num_samples, seed : the search space, see :func:`expand_space`
    executor : where to run (default ``Executor()``: local processes).  ``ray=True`` or
        ``ray_address`` runs the trials with Ray Tune, ``workers`` caps concurrent trials,
        ``store`` keeps finished trials, ``retries`` reruns failed ones.
    metric, mode : default of :meth:`TrialResults.best`; also given to Ray Tune (for schedulers)
    resources_per_trial : Ray Tune resources of one trial, e.g. ``{"cpu": 2, "gpu": 0}``
        (default one CPU); ignored locally, where each trial is one process
    name, storage_path : Ray Tune experiment name and folder for its logs (default
        ``<store>/ray_tune`` with a store, else Ray's default ``~/ray_results``)
    tune_config : extra keyword arguments of ``ray.tune.TuneConfig`` (e.g. ``scheduler``)
    """
    if mode not in ("max", "min"):
        raise ValueError(f"mode must be 'max' or 'min' (got {mode!r})")
    if not callable(trainable):
        raise ValueError(f"trainable must be callable (got {type(trainable).__name__})")
    executor = executor or Executor()
    configs = expand_space(space, num_samples, seed)
    ids = [task_id(trainable, cfg) for cfg in configs]
    if not executor.ray:
        jobs = [(trainable, cfg) for cfg in configs]
        metrics = executor.map(_run_local_trial, jobs, desc=desc, task_ids=ids)
    else:
        metrics = _run_tune(trainable, configs, ids, executor, metric, mode,
                            resources_per_trial, name, storage_path, tune_config, desc)
    return TrialResults([Trial(i, cfg, m, tid) for i, (cfg, m, tid)
                         in enumerate(zip(configs, metrics, ids))], metric, mode)


def _run_tune(trainable, configs, ids, executor: Executor, metric, mode, resources_per_trial,
              name, storage_path, tune_config, desc) -> list[dict]:
    from ..progress import ProgressBar

    from .ray_backend import ensure_ray

    store = ResultStore(executor.store) if executor.store is not None else None
    results: list[Any] = [None] * len(configs)
    same: dict[str, list[int]] = {}  # task id -> indices (a config listed twice runs once)
    for i, tid in enumerate(ids):
        same.setdefault(tid, []).append(i)
    todo: list[int] = []
    for tid, idxs in same.items():
        ok, value = store.load(tid) if store is not None else (False, None)
        if ok:
            for j in idxs:
                results[j] = value
        else:
            todo.append(idxs[0])
    bar = ProgressBar(total=len(configs), initial=sum(r is not None for r in results), desc=desc,
                      unit="trial", disable=not executor.progress, dynamic_ncols=True)
    try:
        if todo:
            ensure_ray(executor.ray_address, executor.workers, executor.runtime_env)
            _fit(trainable, configs, ids, same, todo, results, store, bar, executor, metric,
                 mode, resources_per_trial, name, storage_path, tune_config)
    finally:
        bar.close()
    return results


def _fit(trainable, configs, ids, same, todo, results, store, bar, executor, metric, mode,
         resources_per_trial, name, storage_path, tune_config) -> None:
    from ray import tune

    class _Collect(tune.Callback):
        """Runs in the driver: stores each finished trial at once (so an interrupted
        search resumes from it) and advances the progress bar."""

        def on_trial_complete(self, iteration, trials, trial, **info):
            last = trial.last_result or {}
            if _NAMES not in last:
                return
            i = todo[trial.config["abb_index"]]
            final = {k: last[k] for k in json.loads(last[_NAMES])}
            if results[i] is None:  # first delivery only: nothing is counted twice
                if store is not None:
                    store.save(ids[i], final)
                for j in same[ids[i]]:
                    results[j] = final
                bar.update(len(same[ids[i]]))

    # trials see the driver's working directory, as local trials do (Tune would chdir)
    os.environ.setdefault("RAY_CHDIR_TO_TRIAL_DIR", "0")
    fn = tune.with_parameters(_tune_entry, abb_trainable=trainable,
                              abb_configs=[configs[i] for i in todo])
    if resources_per_trial:
        fn = tune.with_resources(fn, resources_per_trial)
    if storage_path is None and store is not None:
        storage_path = store.directory / "ray_tune"
    if storage_path is not None:
        storage_path = str(Path(storage_path).resolve())
    tc = dict(max_concurrent_trials=executor.workers)
    if metric is not None:
        tc.update(metric=metric, mode=mode)
    tc.update(tune_config or {})
    tuner = tune.Tuner(
        fn, param_space={"abb_index": tune.grid_search(list(range(len(todo))))},
        tune_config=tune.TuneConfig(**tc),
        run_config=tune.RunConfig(
            name=name, storage_path=storage_path, verbose=0, callbacks=[_Collect()],
            failure_config=tune.FailureConfig(max_failures=executor.retries)))
    grid_results = tuner.fit()
    for r in grid_results:
        if r.error is not None:
            k = todo[r.config["abb_index"]]
            raise TaskFailed(k, ids[k], executor.retries + 1, f"{type(r.error).__name__}: "
                                                              f"{r.error}")
    missing = [i for i in todo if results[i] is None]
    if missing:
        raise TaskFailed(missing[0], ids[missing[0]], executor.retries + 1,
                         "Ray Tune finished without a result for this trial")
