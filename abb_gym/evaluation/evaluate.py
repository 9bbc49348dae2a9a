"""Policy-versus-baseline evaluation on a fixed, seeded test set.

Episode ``k`` of a test set with seed ``S`` is the environment reset with seed ``S + k`` on the
evaluation preset (``test``: wider ranges than training, imbalance up to 1.3 x the balancing
capacity; see ``configs/envs/``).  So every policy meets the same machines in the same
order, whatever the number of sub-environments, workers or executor.

Episodes run in chunks (one executor task per chunk; a chunk is one native vector
environment with a sub-environment per episode, stepped until every episode has ended once).
Per episode the metrics of :mod:`abb_gym.evaluation.metrics` come from the environment's
run-up accumulator (the quantities its reward uses) and its recorded history (one entry per
control interval, also for DwellProfile's single step), plus the return.  Drive energy: exact
``int |T w| dt`` on RunUpTorque (T = action x torque limit); elsewhere an estimate with the
rigid spinning inertia, ``int |(J_spin a + b_0 w) w| dt``.

:func:`summarise` gives means with 95 % confidence intervals (Student t for means, Wilson
score for shares).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import gymnasium as gym
import numpy as np

from ..physics.rotor import spinning_inertia
from ..envs import tasks
from ..envs.episode_parameters import machine_changes
from ..progress import ProgressBar
from . import metrics as mt
from .registry import Policy, resolve
from .statistics import mean_interval, share_ci

UNITS = {**mt.METRICS, "return": "-"}
METRICS = tuple(UNITS)
SHARES = tuple(k for k, u in UNITS.items() if u == "share")
NONNEGATIVE = tuple(k for k in METRICS if k not in SHARES and k != "return")


@dataclass(frozen=True)
class Chunk:
    """One executor task: episodes ``indices`` of the test set under one policy."""
    env_id: str
    scene: str
    preset: str
    policy: str
    seed: int
    indices: tuple[int, ...]
    record: tuple[int, ...] = ()
    env_kwargs: tuple[tuple[str, Any], ...] = ()
    # reset options for every episode of the chunk (e.g. ``ball_angles``: the same machines
    # with the balls started elsewhere); values as tuples, so that a chunk stays hashable
    reset_options: tuple[tuple[str, Any], ...] = ()
    # the hold after each settled episode that measures its balancing [s] (0: none, as the
    # tuner's candidates need only their return): abb_gym.evaluation.metrics.HOLD_TIME
    hold: float = mt.HOLD_TIME


@dataclass
class Rollout:
    """Histories of one episode, with the attribute names of a Trajectory for the plots."""
    scene: Any
    t: np.ndarray
    rotor_speed: np.ndarray
    whirl_ratio: np.ndarray
    ball_angles: np.ndarray
    actions: np.ndarray

    @property
    def n_balls(self) -> int:
        return self.ball_angles.shape[1]


@dataclass
class EvaluationResult:
    policy: str
    env_id: str
    scene: str
    preset: str
    seed: int
    episodes: list[dict] = field(default_factory=list)
    rollouts: dict[int, Rollout] = field(default_factory=dict)
    params: dict[str, Any] = field(default_factory=dict)  # the policy's parameters, if any
    # the resolved reward weights of the test set, and where they came from
    reward_weights: dict[str, float] = field(default_factory=dict)
    reward_source: str = ""
    # the environment's other keywords (integrator, control_interval, observation settings):
    # the same agent on the same seeds gives other episodes under another integrator
    env_kwargs: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        return summarise(self.episodes)

    @property
    def length_unit(self) -> str:
        """The unit of the lengths among the metrics (:func:`abb_gym.evaluation.metrics.
        length_unit`: W_r/e, or the task's unit such as mm)."""
        return self.episodes[0].get("length_unit", "W_r/e") if self.episodes else "W_r/e"


def make_env(env_id: str, scene: str, preset: str, num_envs: int, **env_kwargs):
    """The native vector environment of a chunk, recording every sub-environment's history,
    with the full per-step info (a policy may read ``time`` and ``rotor_speed`` from it;
    :func:`run_chunk` makes it lean for a policy that declares ``reads_info = False``)."""
    env_kwargs.setdefault("info_level", "full")
    return gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        scene=scene, preset=preset, record_history=True, **env_kwargs)


def run_chunk(chunk: Chunk, policy=None, on_step=None) -> tuple[list[dict], dict[int, Rollout]]:
    """Run the chunk's episodes; returns (per-episode metrics, recorded rollouts).

    ``policy``: None (resolve ``chunk.policy``), a Policy, or a callable ``f(env) -> Policy``
    (for policies that depend on the environment, e.g. one profile per sub-environment).
    Episode indices may repeat (the same machine under different candidates of a sweep).
    ``on_step(env, done)``, if given, is called after the reset and after every step, with
    the episodes ended so far (``abb-gym render`` draws its frames there)."""
    n = len(chunk.indices)
    env = make_env(chunk.env_id, chunk.scene, chunk.preset, n, **dict(chunk.env_kwargs))
    if policy is None:
        policy = resolve(chunk.policy, chunk.env_id, chunk.scene)
    elif not hasattr(policy, "act"):
        policy = policy(env)
    native = env.unwrapped
    if getattr(policy, "reads_info", True) is False \
            and "info_level" not in dict(chunk.env_kwargs):
        # the final info of each episode is all the metrics read; the lean info holds every
        # key where an episode ends (the full info of every step was most of the Python cost
        # of a tuner's small batches)
        native.info_level = "lean"
    setup = native.setup
    options = {key: list(v) if isinstance(v, tuple) else v for key, v in chunk.reset_options}
    obs, info = env.reset(seed=[chunk.seed + k for k in chunk.indices], options=options or None)
    policy.reset(env, np.ones(n, bool))
    if on_step is not None:
        on_step(env, np.zeros(n, bool))
    actions = np.zeros((setup.max_steps + 1, n, setup.n_actions))
    counts = np.zeros(n, dtype=np.int64)
    ret = np.zeros(n)
    done = np.zeros(n, bool)
    episodes, rollouts = [None] * n, {}
    name = getattr(policy, "name", chunk.policy)
    unit, unit_label = mt.length_unit(setup)
    hold_time = chunk.hold
    while not done.all():
        act = np.asarray(policy.act(obs, info), dtype=np.float32)
        obs, reward, term, trunc, info = env.step(act)
        live = ~done
        ret[live] += reward[live]
        actions[np.minimum(counts, setup.max_steps), np.arange(n)] = act.reshape(n, -1)
        counts += live
        for j in np.flatnonzero(live & (term | trunc)):
            k = chunk.indices[j]
            hist = native.history(int(j))
            act_j = actions[:counts[j], j].copy()
            final = {key: (v[j] if isinstance(v, np.ndarray) else v) for key, v in info.items()
                     if not key.startswith("_") and key != "reward_terms"}
            ref_len = unit or native.episode_scene(int(j)).reference_length
            hold = (_hold(native, int(j), hist, ref_len, hold_time)
                    if final["settled"] and hold_time > 0 else None)
            row = mt.rollout_metrics(setup, final, hist, ref_len,
                                     torque=_drive_torque(setup, hist["t"], hist["rotor_speed"],
                                                          act_j), hold=hold)
            row.update(episode=k, seed=chunk.seed + k, policy=name, steps=len(act_j),
                       length_unit=unit_label, **{"return": float(ret[j])})
            episodes[j] = row
            if k in chunk.record and k not in rollouts:
                xs, ys = native.episode(int(j)).static_deflection
                vib = np.hypot(hist["x"] - xs, hist["y"] - ys)
                rollouts[k] = Rollout(setup.scene, hist["t"], hist["rotor_speed"],
                                      vib / ref_len, hist["ball_angles"], act_j)
        done |= live & (term | trunc)
        if on_step is not None:
            on_step(env, done.copy())
    env.close()
    return episodes, rollouts


def _hold(native: Any, j: int, hist: dict, unit: float, hold: float) -> dict[str, float]:
    """:func:`abb_gym.evaluation.metrics.hold_metrics` of sub-environment ``j``, whose episode
    just ended at speed: its machine now (the laundry's imbalance after any redistribution),
    its final state and its recorded vibration."""
    from ..physics import variants
    setup = native.setup
    ep = native.episode(j)
    scene = variants.variant_scene(ep.nominal, **{
        **machine_changes(ep.values),
        "imbalance": float(native.imbalances[j])})
    xs, ys = ep.static_deflection
    tolerance = mt.balance_tolerance(scene, setup.operating_speed, setup.config.balance_tolerance)
    return mt.hold_metrics(scene, native.states[j], setup.operating_speed, (xs, ys), hist["t"],
                           hist["vibration"], setup.config.settle_time, tolerance, unit, hold)


def _drive_torque(setup, t, w, act):
    """Motor torque [N m] at the history's samples: the command on RunUpTorque, else the rigid
    spinning-inertia estimate ``J_spin w' + b_0 w``."""
    if setup.kind == "torque":
        return np.concatenate([[0.0], act[:len(t) - 1, 0] * setup.torque_limit])
    accel = np.gradient(w, t) if len(t) > 1 else np.zeros_like(w)
    return spinning_inertia(setup.scene) * accel + setup.scene.bearing_drag * w


#: the most episodes one evaluation runs (a million run-ups is hours of computing already)
MAX_EPISODES = 1_000_000


def chunks(env_id: str, scene: str, policy: str, episodes: int, seed: int, preset: str = "test",
           chunk_size: int = 32, record: Sequence[int] = (0,), **env_kwargs) -> list[Chunk]:
    if episodes < 1 or episodes > MAX_EPISODES:
        raise ValueError(f"episodes must be in [1, {MAX_EPISODES}] (got {episodes})")
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1 (got {chunk_size})")
    kw = tuple(sorted(env_kwargs.items()))
    return [Chunk(env_id, scene, preset, policy, int(seed),
                  tuple(range(a, min(a + chunk_size, episodes))),
                  tuple(r for r in record if a <= r < a + chunk_size), kw)
            for a in range(0, episodes, chunk_size)]


def env_ids() -> list[str]:
    """The registered environment ids (those a chunk can run: the task registry's)."""
    return tasks.task_ids()


def check_inputs(env_id: str, scene: Any, preset: str = "test", seed: Any = 0,
                 policy: str | None = None, **env_kwargs: Any) -> Policy | None:
    """Check in this process what every task of an evaluation or a sweep will use, before any
    is dispatched: the environment id, the seed (an int >= 0: episode k is seed + k), the
    scene, the preset and the keywords (by making one sub-environment, which compiles
    nothing), and the policy (``replay:`` specs down to the recorded one).  Raises ValueError
    naming the input, so a bad one is one error, not the same error from every task.
    Returns the policy the spec runs in the end (``replay:SPEC``: SPEC's), or None."""
    from ..envs.checks import check_seed
    tasks.get(env_id)  # a registered task, or an error naming the ids
    if check_seed(seed, "seed") is None:  # episode k is seed + k: no "fresh entropy" here
        raise ValueError("seed must be an integer >= 0 (got None)")
    make_env(env_id, scene, preset, 1, **env_kwargs).close()
    spec, resolved = policy, None
    while spec is not None:
        resolved = resolve(spec, env_id, scene)
        spec = spec[len("replay:"):] if spec.startswith("replay:") else None
    return resolved


def _innermost(policy: str, env_id: str, scene: Any):
    """The policy a spec runs in the end (``replay:SPEC`` records SPEC)."""
    while policy.startswith("replay:"):
        policy = policy[len("replay:"):]
    return resolve(policy, env_id, scene)


def policy_env_kwargs(env_id: str, scene: Any, policy: str) -> dict[str, Any]:
    """The environment keywords ``policy`` needs (an agent's ``observe_balls``,
    ``sync_vibration`` and ``frame_stack``: ``policy.env_kwargs``), also inside ``replay:``."""
    return _needs(_innermost(policy, env_id, scene))


def _needs(inner: Any) -> dict[str, Any]:
    return dict(getattr(inner, "env_kwargs", None) or {})


def policy_env_id(env_id: str, scene: Any, preset: str, policy: str, **env_kwargs: Any) -> str:
    """The environment ``policy`` is evaluated on: ``env_id``, except on DwellProfile for a
    baseline its one action cannot express (a ``knots`` profile, a dwell at another run-up
    acceleration, a closed-loop controller), which runs on RunUpSpeed instead.  The machines
    are the same: every kind draws episode ``k`` from the same preset and seed (tested), and
    DwellProfile pays what RunUpSpeed pays for the same profile, interval by interval."""
    if tasks.get(env_id).baselines_on is None:
        return env_id
    return _env_for(_innermost(policy, env_id, scene), env_id, scene, preset, env_kwargs)


def _env_for(inner: Any, env_id: str, scene: Any, preset: str, env_kwargs: dict) -> str:
    """:func:`policy_env_id` of the resolved innermost policy."""
    acts_on = getattr(inner, "acts_on", None)
    fallback = tasks.get(env_id).baselines_on
    if fallback is None or acts_on is None:
        return env_id
    from ..envs.setup import EnvSetup
    setup = EnvSetup(env_id, scene, preset, **{k: v for k, v in env_kwargs.items()
                                                if k == "observe_balls"})
    return env_id if acts_on(setup) else fallback


def _run_chunk_task(chunk: Chunk):
    """(episodes, rollouts, the policy's parameters) of one chunk."""
    policy = resolve(chunk.policy, chunk.env_id, chunk.scene)
    episodes, rollouts = run_chunk(chunk, policy)
    return episodes, rollouts, dict(getattr(policy, "params", None) or {})


def evaluate(env_id: str, scene: str, policy: str, episodes: int = 100, seed: int = 0,
             preset: str = "test", chunk_size: int = 32, record: Sequence[int] = (0,),
             executor=None, **env_kwargs) -> EvaluationResult:
    """Evaluate ``policy`` (``baseline:NAME`` or ``ppo:PATH``) on the seeded test set.

    ``executor`` (:class:`abb_gym.execution.Executor`) runs the chunks in parallel; None runs
    them in this process (the vector environment already uses both cores).  Every input is
    checked before any chunk runs (:func:`check_inputs`).  On DwellProfile, a baseline its
    action cannot express runs on RunUpSpeed, on the same machines (:func:`policy_env_id`);
    the result's ``env_id`` says where it ran.  The environments carry the keywords the policy
    needs (:func:`policy_env_kwargs`: a trained agent's observation settings) and, unless
    ``env_kwargs`` sets a ``reward``, the reward weights a trained agent was evaluated with
    when it was trained (``policy.reward_weights``); the result records the weights."""
    inner = check_inputs(env_id, scene, preset, seed, policy, **env_kwargs)
    source = "env_kwargs" if "reward" in env_kwargs else f"preset {preset}"
    env_kwargs = {**_needs(inner), **env_kwargs}
    recorded = getattr(inner, "reward_weights", None)
    if "reward" not in env_kwargs and recorded:
        env_kwargs["reward"] = dict(recorded)
        source = f"recorded with {policy}"
    env_id = _env_for(inner, env_id, scene, preset, env_kwargs)
    tasks = chunks(env_id, scene, policy, episodes, seed, preset, chunk_size, record,
                   **env_kwargs)
    if executor is None:  # this process; the vector environment already uses every core
        parts = [_run_chunk_task(c) for c in ProgressBar(tasks, desc=f"evaluate {policy}",
                                                         disable=len(tasks) < 2)]
    else:
        parts = executor.map(_run_chunk_task, tasks, desc=f"evaluate {policy}")
    result = EvaluationResult(policy, env_id, scene, preset, seed,
                              reward_weights=reward_weights(env_id, scene, preset, **env_kwargs),
                              reward_source=source,
                              env_kwargs={k: v for k, v in env_kwargs.items() if k != "reward"})
    for eps, rolls, params in parts:
        result.episodes.extend(eps)
        result.rollouts.update(rolls)
        result.params = params
    if result.episodes:
        result.policy = result.episodes[0]["policy"]
    return result


def reward_weights(env_id: str, scene: Any, preset: str = "test", **env_kwargs: Any
                   ) -> dict[str, float]:
    """The reward weights an environment of these arguments uses (the preset's, with
    ``env_kwargs["reward"]`` over them)."""
    env = make_env(env_id, scene, preset, 1, **env_kwargs)
    try:
        return dict(env.unwrapped.setup.config.to_dict()["reward"])
    finally:
        env.close()


def summarise(episodes: list[dict]) -> dict[str, Any]:
    """Mean and 95 % confidence interval of every metric (shares: Wilson interval).
    ``n`` counts the finite values (time to speed is NaN for runs that never got there).  A
    metric the episodes do not carry (runs kept from before it existed, or not measured: the
    oracle's runs have no hold) has a NaN mean and ``n`` 0, shown as n/a."""
    out: dict[str, Any] = {"episodes": len(episodes),
                           "length_unit": episodes[0].get("length_unit", "W_r/e")
                           if episodes else "W_r/e"}
    for key in METRICS:
        vals = np.array([float(e.get(key, math.nan)) for e in episodes])
        if key in SHARES and not all(key in e for e in episodes):
            out[key] = {"mean": math.nan, "ci_low": math.nan, "ci_high": math.nan, "n": 0}
        elif key in SHARES:
            p, lo, hi = share_ci(int(np.nansum(vals)), len(vals))
            out[key] = {"mean": p, "ci_low": lo, "ci_high": hi, "n": len(vals)}
        else:
            out[key] = mean_interval(vals, nonnegative=key in NONNEGATIVE)
    return out
