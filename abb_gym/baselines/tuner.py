"""Tune and sweep the baseline families on an environment's scenario distribution.

Every candidate parameter set of a family becomes a policy (a speed profile, or a closed-loop
controller) of one sub-environment; candidates x episodes run as the sub-environments of
native vector environments, chunked into executor tasks.

* :func:`tune` - CMA-ES (the ``cma`` package: Hansen's reference implementation) over each
  family's search box (declared with its parameters, :mod:`abb_gym.baselines.profiles` and
  :mod:`~abb_gym.baselines.closed_loop`), in coordinates scaled to [0, 1]; the objective is
  the mean return on the **training** preset (what the agents optimise) over a fixed set of
  seeded episodes (common random numbers: every candidate meets the same machines).  The
  family's default is always a candidate, so the result is never worse than the default on
  that set.  The result goes where ``out`` says (:func:`write_tuned`); a
  ``baselines/<scene>.yaml`` on the search path of :mod:`abb_gym.resources` is what
  ``baseline:NAME`` policies then use.  With a specification (``spec``,
  :mod:`abb_gym.baselines.specification`) the objective is instead the least mean residual
  vibration among the candidates that meet its requirements (peak whirl, run-up time, ...),
  ranked feasibility first.
* :func:`sweep` - the same families over their boxes on the **test** preset, as points (mean
  settled run-up time, mean residual vibration) for the speed-versus-accuracy chart.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..evaluation.evaluate import Chunk, check_inputs, run_chunk
from ..envs import tasks
from ..physics import rotor
from ..progress import ProgressBar
from . import profiles
from .baseline_policy import BaselinePolicy, ClosedLoopPolicy
from .families import FAMILY_NAMES, build_family, family_class
from .specification import Specification

ENV_ID = tasks.DEFAULT_ENV_ID
OBJECTIVE = "mean return on the preset (the environment's reward)"
# restart r of a tuning seeds its CMA-ES with seed + RUN_SEED_STRIDE * r: a prime, so that no
# restart repeats the search of a tuning run with a nearby seed
RUN_SEED_STRIDE = 7919


# the stream of the ball-angle draws a per-machine search scores on (``ball_draws``), apart
# from every episode seed and from the draws of :func:`abb_gym.baselines.oracle.balls_elsewhere`
SEARCH_BALLS_STREAM = 0x0BA12


def ball_starts(setup: Any, key: int, stream: int, count: int) -> tuple:
    """``count`` reset-option sets (``CandidateTask.reset_options``), each starting the balls at
    angles drawn as ``setup``'s preset draws them, from the generator seeded by ``(key,
    stream)``: the same sets on every call."""
    from ..envs.episodes import draw_ball_angles
    rng = np.random.default_rng((int(key), int(stream)))
    return tuple((("ball_angles", tuple(float(a) for a in draw_ball_angles(setup, rng))),)
                 for _ in range(count))


def search_scales(scene_name: str, env_id: str = ENV_ID, preset: str = "train"
                  ) -> dict[str, float]:
    """The units of the search boxes for a scene and environment preset."""
    from ..envs.setup import EnvSetup
    setup = EnvSetup(env_id, scene_name, preset)
    sc = setup.scene.replace(drive_operating_speed=setup.operating_speed)
    out = profiles.scales(sc)
    a_peak, a_op = rotor.reference_amplitudes(sc, setup.operating_speed)
    out["settle"] = setup.config.settle_time
    out["aop"] = a_op / setup.vibration_scale
    return out


def _check_counts(**counts: Any) -> None:
    """Raise ValueError naming the first count that is not an integer >= 1."""
    for name, v in counts.items():
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{name} must be an integer >= 1 (got {v!r})")


def params_from_unit(family: str, x: np.ndarray, scales: dict[str, float]) -> dict[str, Any]:
    """Family parameters from a point ``x`` of the unit cube of its search space."""
    space = profiles.search_space(family_class(family))
    out: dict[str, Any] = {}
    for (name, index, lo, hi, unit), u in zip(space, np.clip(x, 0.0, 1.0)):
        v = (lo + float(u) * (hi - lo)) * scales[unit]
        if index is None:
            out[name] = v
        else:
            out.setdefault(name, []).append(v)
    if "max_retries" in out:
        out["max_retries"] = int(round(out["max_retries"]))
    for key in ("dwell_speed", "plateau_speed", "dip_speed"):
        if key in out:
            out[key] = min(out[key], scales["wop"])
    return out


def unit_from_params(family: str, params: dict[str, Any], scales: dict[str, float]
                     ) -> np.ndarray:
    """The point of the unit cube of ``family``'s search space nearest to ``params`` (the
    inverse of :func:`params_from_unit`; a parameter not given sits at the centre)."""
    x = []
    for name, index, lo, hi, unit in profiles.search_space(family_class(family)):
        v = params.get(name)
        if v is not None and index is not None:
            v = v[index] if index < len(v) else None
        x.append(0.5 if v is None else (float(v) / scales[unit] - lo) / (hi - lo))
    return np.clip(np.array(x, dtype=float), 0.0, 1.0)


def as_candidate(params: dict[str, Any]) -> tuple:
    """Family parameters as a :class:`CandidateTask` candidate: sorted (name, value) pairs,
    lists as tuples, so that tasks stay hashable."""
    return tuple(sorted((k, tuple(v) if isinstance(v, list) else v) for k, v in params.items()))


@dataclass(frozen=True)
class CandidateTask:
    """Candidates x episodes of one family as one vector environment."""
    env_id: str
    scene: str
    preset: str
    family: str
    candidates: tuple[tuple[tuple[str, Any], ...], ...]
    episodes: tuple[int, ...]
    seed: int
    env_kwargs: tuple[tuple[str, Any], ...] = ()
    reset_options: tuple[tuple[str, Any], ...] = ()


def _policy_for(task: CandidateTask, pairs):
    def factory(env):
        setup = env.unwrapped.setup
        sc = setup.scene.replace(drive_operating_speed=setup.operating_speed)
        fams = [build_family(task.family, **dict(task.candidates[c])) for c, _ in pairs]
        name = f"baseline:{task.family}"
        if fams[0].closed_loop:
            return ClosedLoopPolicy(name, fams)
        return BaselinePolicy(name, [f.profile(sc) for f in fams])
    return factory


def _run_candidates(task: CandidateTask) -> list[dict]:
    pairs = [(c, k) for c in range(len(task.candidates)) for k in task.episodes]
    chunk = Chunk(task.env_id, task.scene, task.preset, f"sweep:{task.family}", task.seed,
                  tuple(k for _, k in pairs), env_kwargs=task.env_kwargs,
                  reset_options=task.reset_options, hold=0.0)  # a candidate's score: its return
    episodes, _ = run_chunk(chunk, _policy_for(task, pairs))
    for (c, _), row in zip(pairs, episodes):
        row["candidate"] = c
    return episodes


SUMMARY_KEYS = ("return", "run_up_time", "residual_vibration", "peak_whirl", "at_speed",
                "balanced")


def evaluate_candidates(scene_name: str, family: str, candidates: list[dict], episodes: int,
                        seed: int, preset: str, executor=None, per_task: int = 256,
                        env_id: str = ENV_ID, progress: bool = False,
                        env_kwargs: dict[str, Any] | None = None) -> list[dict]:
    """Mean metrics of each candidate over ``episodes`` seeded episodes (the residual over the
    episodes that settled; ``at_speed`` is the share that did)."""
    from ..physics.scene import load_scene
    load_scene(scene_name)  # validate early, with the scene's own error message
    _check_counts(episodes=episodes)
    check_inputs(env_id, scene_name, preset, seed, **(env_kwargs or {}))
    return _evaluate_candidates(scene_name, family, candidates, episodes, seed, preset,
                                executor, per_task, env_id, progress, env_kwargs)


def _evaluate_candidates(scene_name, family, candidates, episodes, seed, preset, executor,
                         per_task=256, env_id=ENV_ID, progress=False, env_kwargs=None, bar=None,
                         option_sets=((),)):
    """:func:`evaluate_candidates` with the scene, counts and environment already checked
    (the tuner and the sweep check them once, not once per CMA-ES generation).  ``bar``: a
    tqdm bar counting candidates, advanced as each task's candidates finish (else, with
    ``progress``, a bar of its own).  ``option_sets``: reset options (``CandidateTask``'s
    form); every candidate runs its episodes once under each, and its means are over all."""
    for c in candidates:
        build_family(family, **c)  # validate every candidate before any runs
    per = max(1, per_task // (episodes * len(option_sets)))
    cand = [as_candidate(c) for c in candidates]
    kw = tuple(sorted((env_kwargs or {}).items()))
    tasks = [CandidateTask(env_id, scene_name, preset, family, tuple(cand[a:a + per]),
                           tuple(range(episodes)), seed, kw, options)
             for a in range(0, len(cand), per) for options in option_sets]
    own = bar is None and progress
    if own:
        bar = ProgressBar(total=len(cand), desc=f"{family}: candidates", unit="candidate")
    try:
        if executor is None:  # this process; the vector environment already uses every core
            parts = []
            for i, t in enumerate(tasks):
                parts.append(_run_candidates(t))
                if bar is not None and (i + 1) % len(option_sets) == 0:
                    bar.update(len(t.candidates))
        else:  # the executor shows its tasks; the candidates count when all are back
            parts = executor.map(_run_candidates, tasks, desc=f"{family}: candidate batches")
            if bar is not None:
                bar.update(len(cand))
    finally:
        if own:
            bar.close()
    rows = []
    parts = list(parts)
    for b, a in enumerate(range(0, len(cand), per)):
        runs = [e for part in parts[b * len(option_sets):(b + 1) * len(option_sets)]
                for e in part]
        for c in range(len(tasks[b * len(option_sets)].candidates)):
            eps = [e for e in runs if e["candidate"] == c]
            mean = {}
            for k in SUMMARY_KEYS:
                vals = np.array([float(e[k]) for e in eps])
                mean[k] = float(np.nanmean(vals)) if np.isfinite(vals).any() else math.nan
            params = {k: (list(v) if isinstance(v, tuple) else v) for k, v in cand[a + c]}
            rows.append({"family": family, "params": params, **mean})
    return rows


def _shrink_bar(bar, budget: int, used: int) -> None:
    """A search that stopped early (or had nothing to search) took ``used`` of its ``budget``
    candidates: the bar still ends at its total."""
    if used < budget:
        bar.total -= budget - used
        bar.refresh()


def return_score(row: dict) -> float:
    """How a candidate's (or a machine's) mean return ranks: itself, or -inf when it is not
    finite, so that a NaN never wins a comparison and never blocks a finite one."""
    r = row["return"]
    return r if math.isfinite(r) else -math.inf


def _rank_key(spec):
    """How candidates rank, smaller first: by return (no ``spec``), or feasibility first
    under ``spec`` (:meth:`~abb_gym.baselines.specification.Specification.key`)."""
    return (lambda row: (-return_score(row),)) if spec is None else spec.key


def _fitness(spec, rows: list[dict]) -> list[float]:
    """What CMA-ES minimises for one generation's rows."""
    if spec is None:
        return [-r["return"] if math.isfinite(r["return"]) else 1e9 for r in rows]
    return spec.fitness(rows)


def _cma_search(family: str, scene_name: str, scales: dict[str, float], budget: int,
                popsize: int | None, episodes: int, seed: int, preset: str, env_id: str,
                executor, bar, env_kwargs, start: dict | None = None,
                x0: np.ndarray | None = None, run: int = 0, option_sets=((),), spec=None
                ) -> tuple[dict, dict, int]:
    """CMA-ES over the unit box from its centre; or from ``start`` (parameters, also a
    candidate, with a smaller initial step: a refinement); or from ``x0`` (a point of the unit
    box, itself the first candidate, with the full initial step: a restart).  ``run`` numbers
    the searches of one tuning and seeds each one's CMA-ES differently; ``spec``: rank by a
    specification instead of the return.  Returns the best row, the first candidate's row
    (the family's default, or the restart point) and how many candidates ran."""
    import cma

    space = profiles.search_space(family_class(family))
    if x0 is not None:
        first = [params_from_unit(family, x0, scales)]
    else:
        first = [{}] if start is None else [{}, dict(start)]
    rows = _evaluate_candidates(scene_name, family, first, episodes, seed, preset,
                                executor, env_id=env_id, env_kwargs=env_kwargs, bar=bar,
                                option_sets=option_sets)
    default = rows[0]
    rank = _rank_key(spec)
    best = min(rows, key=rank)
    evaluations = len(rows)
    sigma0 = 0.3
    if x0 is None and start is None:
        x0 = np.full(len(space), 0.5)
    elif x0 is None:
        x0, sigma0 = unit_from_params(family, start, scales), 0.1
    if space and evaluations < budget:
        # maxstd: a step beyond half the unit box means nothing, and without a cap cma 4.x
        # fails on a flat objective ("not yet initialized (dimension needed)"), as when no
        # candidate of a family ever reaches the operating speed
        opts = {"bounds": [0.0, 1.0], "verbose": -9, "maxfevals": max(budget - 1, 1),
                "seed": (seed + RUN_SEED_STRIDE * run) % (2 ** 31 - 1) + 1, "maxstd": 0.5}
        if popsize:
            opts["popsize"] = popsize
        es = cma.CMAEvolutionStrategy(x0, sigma0, opts)
        while not es.stop() and evaluations < budget:
            xs = es.ask()
            # the last generation runs only the candidates the budget has left: the family
            # never costs more than ``budget`` candidates (a cut generation is not told, the
            # search ends with it)
            xs = xs[:budget - evaluations]
            cands = [params_from_unit(family, x, scales) for x in xs]
            rows = _evaluate_candidates(scene_name, family, cands, episodes, seed, preset,
                                        executor, env_id=env_id, env_kwargs=env_kwargs,
                                        bar=bar, option_sets=option_sets)
            if len(xs) == es.popsize:
                es.tell(xs, _fitness(spec, rows))
            evaluations += len(rows)
            for r in rows:
                if rank(r) < rank(best):
                    best = r
    return best, default, evaluations


def restart_popsizes(dim: int, popsize: int | None, budget: int, restarts: int) -> list[int]:
    """Populations of the first search and its ``restarts`` restarts in a space of ``dim``
    parameters: IPOP-CMA-ES (Auger & Hansen 2005) doubles the population at each restart, so
    that later searches see more of the landscape at once; here capped at ``budget // 10`` so
    that every search of ``budget`` candidates still runs about ten generations.  The first is
    ``popsize`` or cma's default, 4 + int(3 ln dim)."""
    first = popsize or 4 + int(3 * math.log(dim))
    cap = max(first, budget // 10)
    return [first] + [min(first * 2 ** r, cap) for r in range(1, restarts + 1)]


def _restarted_search(family: str, scene_name: str, scales: dict[str, float], budget: int,
                      popsize: int | None, episodes: int, seed: int, preset: str, env_id: str,
                      executor, bar, env_kwargs, restarts: int = 0,
                      start: dict | None = None, spec=None
                      ) -> tuple[dict, dict, int, list[dict]]:
    """The first search (from the centre, or refining ``start``), then ``restarts`` searches
    from points drawn uniformly in the unit box (seeded by ``seed``), with the populations of
    :func:`restart_popsizes`; each has ``budget`` candidates.  CMA-ES is a local method: a
    restart elsewhere is what finds a better basin (the shipped spannan_cfrp ``knots`` was 0.5
    in return short of a profile tuned for another weight, on its own objective).  Returns the
    best row of all, the family default's row, the candidates run and one line per search."""
    best, default, n = _cma_search(family, scene_name, scales, budget, popsize, episodes, seed,
                                   preset, env_id, executor, bar, env_kwargs, start, spec=spec)
    _shrink_bar(bar, budget, n)
    dim = len(profiles.search_space(family_class(family)))
    sizes = restart_popsizes(dim, popsize, budget, restarts) if dim else [0]
    runs = [{"start": "centre" if start is None else "tuned", "popsize": sizes[0],
             "candidates": n, "best_return": round(best["return"], 5)}]
    points = np.random.default_rng([seed, 1]).uniform(0.0, 1.0, (len(sizes) - 1, dim))
    for r, (size, x0) in enumerate(zip(sizes[1:], points), start=1):
        found, _, m = _cma_search(family, scene_name, scales, budget, size, episodes, seed,
                                  preset, env_id, executor, bar, env_kwargs, x0=x0, run=r,
                                  spec=spec)
        _shrink_bar(bar, budget, m)
        n += m
        runs.append({"start": "random", "popsize": size, "candidates": m,
                     "best_return": round(found["return"], 5)})
        if _rank_key(spec)(found) < _rank_key(spec)(best):
            best = found
    if not dim:  # nothing to restart: the bar's share of the restarts is not coming
        _shrink_bar(bar, budget * restarts, 0)
    return best, default, n, runs


def tune(scene_name: str, families=FAMILY_NAMES, budget: int = 240, episodes: int = 24,
         seed: int = 20_000, preset: str = "train", executor=None,
         out: str | Path | None = None, force: bool = False, popsize: int | None = None,
         env_id: str = ENV_ID, progress: bool = True,
         env_kwargs: dict[str, Any] | None = None, restarts: int = 0,
         start: dict[str, dict[str, Any]] | None = None, spec=None) -> dict[str, Any]:
    """Tune each family with CMA-ES (module docstring): ``budget`` candidates per search, each
    scored on ``episodes`` seeded episodes of ``preset`` (with ``env_kwargs``, e.g. the reward
    weights an agent was trained with, so that both optimise the same return).  ``restarts``
    more searches per family start from random points (:func:`_restarted_search`); ``start``
    maps a family to parameters its first search refines (e.g. the shipped tuning, which is
    then a candidate, so the result is never worse on these episodes).  ``spec`` (a
    :class:`~abb_gym.baselines.specification.Specification` or its text, e.g.
    ``"peak_whirl<=20,run_up<=5"``) replaces the return objective by the least residual under
    its requirements.  Returns the result and, with ``out``, writes it there
    (:func:`write_tuned`)."""
    import cma

    families = tuple(families)
    for fam in families:
        family_class(fam)
    _check_counts(budget=budget, episodes=episodes)
    if popsize is not None and (isinstance(popsize, bool) or not isinstance(
            popsize, (int, np.integer)) or popsize < 2):
        # CMA-ES ranks at least two candidates per generation
        raise ValueError(f"popsize must be an integer >= 2 (got {popsize!r})")
    if isinstance(restarts, bool) or not isinstance(restarts, (int, np.integer)) \
            or not 0 <= restarts <= 100:
        raise ValueError(f"restarts must be an integer from 0 to 100 (got {restarts!r})")
    if spec is not None and not isinstance(spec, Specification):
        spec = Specification.parse(spec, "spec")
    start = dict(start or {})
    for fam, params in start.items():
        if fam not in families:
            raise ValueError(f"start names {fam!r}, which is not tuned here (families: "
                             f"{', '.join(families)})")
        build_family(fam, **params)  # the declared fields validate it
    # before any candidate runs: every input a task will use (a bad one is one error), and
    # the file the result goes to
    check_inputs(env_id, scene_name, preset, seed, **(env_kwargs or {}))
    from ..physics.scene import load_scene
    # the file is named after the scene's name, which `baseline:NAME` looks up, not after the
    # argument: a path argument "dir/my.yaml" made "my.yaml.yaml", which nothing found
    name = load_scene(scene_name).name
    if out is not None:
        check_tuned_path(tuned_path(out, name), force)
    scales = search_scales(scene_name, env_id, preset)
    result: dict[str, Any] = {
        "scene": name, "env": env_id, "preset": preset,
        "env_kwargs": dict(env_kwargs or {}), "episodes": episodes,
        "seed": seed, "optimiser": _optimiser(cma.__version__, budget, restarts, start),
        "objective": OBJECTIVE if spec is None else
        f"least mean residual vibration with {spec} (feasibility first: "
        f"abb_gym.baselines.specification)", "families": {}}
    with ProgressBar(total=budget * (1 + restarts) * len(families), desc=f"tune {scene_name}",
                     unit="candidate", disable=not progress) as bar:
        for fam in families:
            bar.set_postfix_str(fam)
            best, default, n, runs = _restarted_search(
                fam, scene_name, scales, budget, popsize, episodes, seed, preset, env_id,
                executor, bar, env_kwargs, restarts, start.get(fam), spec)
            result["families"][fam] = {
                "params": _rounded(best["params"]),
                "mean_return": round(best["return"], 5),
                "default_mean_return": round(default["return"], 5),
                "mean_run_up_time": round(best["run_up_time"], 4),
                "mean_residual_vibration": round(best["residual_vibration"], 5),
                "at_speed": round(best["at_speed"], 4),
                "candidates": n,
            }
            if spec is not None:
                result["families"][fam].update(
                    mean_peak_whirl=round(best["peak_whirl"], 4),
                    feasible=spec.violation(best) == 0.0, requirements=spec.report(best))
            if len(runs) > 1 or fam in start:
                result["families"][fam]["searches"] = runs
    if out is not None:
        result["path"] = str(write_tuned(result, out, force=force))
    return result


def _optimiser(version: str, budget: int, restarts: int, start: dict) -> str:
    """The ``optimiser`` line of a tuning result."""
    per = (f"{budget} candidates per search, 1 + {restarts} searches per family (IPOP "
           f"restarts from random points)" if restarts else f"{budget} candidates per family")
    text = f"CMA-ES (cma {version}), {per}"
    if start:
        text += f"; the first search refines the given parameters of {', '.join(start)}"
    return text


@dataclass(frozen=True)
class MachineSearch:
    """One machine's search of :func:`tune_per_machine` (a picklable task): machine
    ``episode`` of the seeded test set, reset with ``seed + episode``; ``scales`` the search
    box's units (:func:`search_scales`), ``option_sets`` the reset options every candidate
    runs under (:func:`ball_starts`, or ``((),)``: the machine as drawn)."""
    scene_name: str
    family: str
    episode: int
    seed: int
    preset: str
    budget: int
    env_id: str
    env_kwargs: tuple  # sorted (key, value) pairs
    start: dict[str, Any] | None
    scales: dict[str, float]
    option_sets: tuple


def _search_machine(task: MachineSearch, bar=None) -> dict[str, Any]:
    """Tune ``task.family`` on its machine alone (in this process; ``bar`` counts the
    candidates) and return the best candidate's full evaluation row."""
    seed = task.seed + task.episode
    best, _, n = _cma_search(task.family, task.scene_name, task.scales, task.budget, None, 1,
                             seed, task.preset, task.env_id, None, bar,
                             dict(task.env_kwargs) or None, task.start,
                             option_sets=task.option_sets)
    if bar is not None:
        _shrink_bar(bar, task.budget, n)
    # the search keeps means of a few metrics; the best candidate's episode once more
    # (deterministic: the same numbers) gives all of them
    params = as_candidate(best["params"])
    (row,) = _run_candidates(CandidateTask(task.env_id, task.scene_name, task.preset,
                                           task.family, (params,), (0,), seed,
                                           task.env_kwargs))
    del row["candidate"]
    return dict(row, episode=task.episode, seed=seed, params=best["params"], candidates=n)


def tune_per_machine(scene_name: str, family: str = "knots", episodes: int = 100,
                     seed: int = 0, preset: str = "test", budget: int = 120,
                     env_id: str = ENV_ID, env_kwargs: dict[str, Any] | None = None,
                     executor=None, progress: bool = True,
                     start: dict[str, Any] | None = None,
                     ball_draws: int = 0) -> list[dict[str, Any]]:
    """A clairvoyant open-loop oracle: ``family`` tuned by CMA-ES on each test machine alone.

    Machine ``k`` is episode ``k`` of the seeded test set (the reset with seed ``seed + k``,
    as :func:`abb_gym.evaluation.evaluate.evaluate` runs it); its best candidate of ``budget``
    is scored on that same machine, so the figure knows every parameter of the machine, its
    initial ball angles included: an upper bound for what a controller that has to find out
    can reach with this family, not a policy.  With ``start`` (e.g. the parameters tuned on
    the training distribution) every machine's search refines them and ``start`` is one of its
    candidates, so the oracle never scores below ``start`` on any machine.  Returns one row
    per machine: the episode of its best candidate with every metric an evaluation gives
    (:data:`abb_gym.evaluation.evaluate.METRICS`, ``episode`` = k, ``seed`` = seed + k), plus
    ``params`` and ``candidates`` (how many it tried).

    With ``ball_draws`` = M > 0 the search knows the machine but not where its balls start:
    every candidate is scored by its mean over M runs of machine ``k`` with the balls started
    at angles drawn as the preset draws them (a generator of their own, seeded by ``seed + k``:
    the same draws for every candidate), and the best is then scored on the machine as drawn,
    with ball angles the search never saw.  That is an open-loop planner that knows every
    parameter of the machine (the preset's ``varied`` scales, the imbalance) but not the
    balls; ``start`` is then one of its candidates on the draws, not a floor on the machine.

    ``executor`` (an :class:`abb_gym.execution.Executor`) runs the machines' searches as
    independent tasks, one per machine (a search's CMA-ES generations are batches of a few
    candidates, which the vector environment runs on one core: the machines are what fills
    the others).  Each search is a function of its machine alone, so the rows are the same
    with or without it, bit for bit.  Without it the searches run one after another in this
    process, with a bar counting candidates."""
    _check_counts(budget=budget, episodes=episodes)
    if isinstance(ball_draws, bool) or not isinstance(ball_draws, (int, np.integer)) \
            or ball_draws < 0:
        raise ValueError(f"ball_draws must be an integer >= 0 (got {ball_draws!r})")
    check_inputs(env_id, scene_name, preset, seed, **(env_kwargs or {}))
    family_class(family)
    kw = tuple(sorted((env_kwargs or {}).items()))
    scales = search_scales(scene_name, env_id, preset)
    if ball_draws:
        from ..envs.setup import EnvSetup
        setup = EnvSetup(env_id, scene_name, preset, overrides=env_kwargs)
    tasks = [MachineSearch(scene_name, family, k, seed, preset, budget, env_id, kw, start,
                           scales, ball_starts(setup, seed + k, SEARCH_BALLS_STREAM, ball_draws)
                           if ball_draws else ((),))
             for k in range(episodes)]
    if executor is not None:
        return executor.map(_search_machine, tasks,
                            desc=f"oracle {family} {scene_name}: machines")
    with ProgressBar(total=budget * episodes, desc=f"oracle {family} {scene_name}",
                     unit="candidate", disable=not progress) as bar:
        return [_search_machine(task, bar) for task in tasks]


def _rounded(params: dict[str, Any]) -> dict[str, Any]:
    return {k: ([round(x, 6) for x in v] if isinstance(v, list) else
                (round(v, 6) if isinstance(v, float) else v)) for k, v in params.items()}


def tuned_path(out: str | Path, scene_name: str) -> Path:
    """The file a tuning result for ``scene_name`` goes to: ``out`` if it is a ``.yaml``
    file, else ``out/<scene>.yaml``."""
    out = Path(out)
    return out if out.suffix in (".yaml", ".yml") else out / f"{scene_name}.yaml"


def check_tuned_path(path: Path, force: bool = False) -> None:
    """Raise ValueError if a tuning result may not be written to ``path``: an existing file
    without ``force``, a shipped file of the installed package, a parent that is a file."""
    from .. import resources
    if resources.is_shipped(path) and "site-packages" in path.resolve().parts:
        raise ValueError(f"{str(path)!r} belongs to the installed abb-gym package; write the "
                         f"tuned parameters to your own folder and add it with --configs or "
                         f"${resources.ENV_VAR}")
    if path.exists() and not force:
        raise ValueError(f"{str(path)!r} exists; pass --force to replace it")
    if path.parent.exists() and not path.parent.is_dir():
        raise ValueError(f"cannot write {str(path)!r}: {str(path.parent)!r} is a file")


def write_tuned(result: dict[str, Any], path: str | Path, force: bool = False) -> Path:
    """Write a tuning result to ``path`` (a ``.yaml`` file, or a folder that gets
    ``<scene>.yaml``).  An existing file is replaced only with ``force``; the installed
    package's shipped files never are."""
    path = tuned_path(path, result["scene"])
    check_tuned_path(path, force)
    path.parent.mkdir(parents=True, exist_ok=True)
    header = ("# Tuned baseline parameters (abb-gym tune-baselines); SI units, rad/s, s,\n"
              "# rad/s^2.  Tuned on the training preset; evaluate on the test preset.\n")
    from .._files import write_text
    write_text(path, header + yaml.safe_dump(result, sort_keys=False))
    return path


def sweep(scene_name: str, families=FAMILY_NAMES, n: int = 12, episodes: int = 12,
          seed: int = 0, preset: str = "test", executor=None, env_id: str = ENV_ID,
          progress: bool = True) -> list[dict]:
    """Each family over its box (a Latin hypercube of ``n`` points) on the test preset: rows
    with the mean settled run-up time and residual.  ``progress``: a bar counting the
    candidates (``n`` per family with parameters)."""
    families = tuple(families)
    for fam in families:
        family_class(fam)
    _check_counts(n=n, episodes=episodes)
    check_inputs(env_id, scene_name, preset, seed)
    scales = search_scales(scene_name, env_id, preset)
    rng = np.random.default_rng(seed + 7)
    swept = [fam for fam in families if profiles.search_space(family_class(fam))]
    rows = []
    with ProgressBar(total=n * len(swept), desc=f"sweep {scene_name}", unit="candidate",
                     disable=not progress) as bar:
        for fam in swept:
            bar.set_postfix_str(fam)
            d = len(profiles.search_space(family_class(fam)))
            cube = (np.stack([rng.permutation(n) for _ in range(d)], axis=1)
                    + rng.random((n, d))) / n
            cands = [params_from_unit(fam, x, scales) for x in cube]
            rows += _evaluate_candidates(scene_name, fam, cands, episodes, seed, preset,
                                         executor, env_id=env_id, bar=bar)
    return rows
