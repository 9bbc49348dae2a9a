"""Native vector environments: ``num_envs`` balancers advanced by one parallel compiled call.

``gym.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point")`` returns one of
these.  All sub-environments share the scene, the preset and the action type; each has its
own episode parameters, random generator and state.  One ``step`` runs
the compiled step of :mod:`abb_gym.envs.kernel` over blocks of up to 128 sub-environments
(``numba.prange`` over blocks, one thread pool launch per step), with the same per-row
arithmetic as the single environment, so sub-environment ``i`` and a single environment reset
with the same seed follow the same trajectory bit for bit.

## Kernel

``kernel="auto"`` (default; or ``$ABB_GYM_KERNEL``) runs, from 16 sub-environments (blocks of
8 lanes or more), a kernel specialised on the scene's ball count and effects, whose lanes the
compiler turns into vector instructions; it is compiled once per such combination (about a
minute, announced on stderr) and cached on disk.  Below that "auto" runs the specialised
kernel only if it needs no compiling (loaded already, or in the on-disk cache), and otherwise,
as ``kernel="generic"`` always does, the general kernel (compiled once for every scene).  Both
give the same numbers bit for bit.

``precision="float32"`` (a preset field; RK4 only) runs the step's lanes in float32: 8
sub-environments per vector instruction instead of 4, 1.24x the env-steps at 1024 (from 64
sub-environments, blocks of 32 lanes; slower than float64 in blocks of 8 or 16), within
1e-4 of float64's rewards and observations (accuracy per scene: ``abb-gym bench accuracy``;
:mod:`abb_gym.physics.batch`, "Precision").  The single environment has float64 only, so a
float32 sub-environment agrees with another float32 one (in any block layout), not with it.

## Seeding

As ``SyncVectorEnv``: ``reset(seed=s)`` seeds sub-environment ``i`` with ``s + i``; a list
gives one seed per sub-environment; ``None`` keeps each generator (creating it from fresh
entropy the first time).  Every draw of sub-environment ``i`` comes from its own generator,
in the order the single environment draws, so the episodes match ``N`` single environments.

## Autoreset

``AutoresetMode.NEXT_STEP`` (gymnasium's default): the step after a sub-environment
terminated or truncated resets it instead of stepping it - its action is ignored, it returns
the first observation of the new episode with reward 0 and both flags False.

## Options

``reset(options=...)`` takes the single environment's options; a value applies to every
sub-environment, or give one value per sub-environment (an array of length ``num_envs``;
``ball_angles`` as an array of shape ``(num_envs, ball_count)``).  ``options["reset_mask"]``
(boolean array) resets only the selected sub-environments.  A reset checks the seeds, the
mask and every selected sub-environment's options (and the stiffness of its episode) before
it changes anything: a rejected reset raises ``ValueError`` naming the field and leaves every
sub-environment and its random generator as they were.

## Info

The single environment's keys as arrays of length ``num_envs`` with gymnasium's ``_key``
masks; ``reward_terms`` is a dict of arrays.  With ``info_level="lean"`` (default) a step
holds ``reward_terms`` (and ``failure``), plus every key, masked by the sub-environments whose
episode ended in that step (the masked entries of ``balanced`` and
``residual_imbalance_ratio`` are 0: at "lean" only the ending sub-environments measure
them); ``info_level="full"`` gives every key at every step.  ``failure``
(object array of messages) appears in steps where some sub-environment failed, masked by
``_failure``; the episode parameters (``imbalance``, ...) appear for the sub-environments
reset in that step.

## Actions

``actions`` of exactly the shape ``(num_envs,) + single_action_space.shape``: anything else
(a transposed batch, which reshaping would scramble, a flat array, text) raises a
``ValueError`` naming both shapes.  Non-finite entries are rejected with a ``ValueError``
before anything moves; entries outside [-1, 1] are clipped with a one-time warning.

## Rendering

``render_mode="rgb_array"``: ``render()`` returns a tuple of frames of the first
``min(num_envs, 4)`` sub-environments.
"""
from __future__ import annotations

from typing import Any, Mapping

import gymnasium as gym
import numpy as np
from gymnasium import logger
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .actions import checked_action
from .display import check_display
from .info import masked, step_info
from ..physics.model import P_U0
from .layout import S_K, S_NREDIST
from .rendering import Renderer
from . import episodes
from .buffers import Buffers
from .checks import check_flag, check_seed, draw_safely
from .step_rows import StepRows, check_actions, read_step
from .setup import EnvSetup, SetupAccess
from .tasks import DWELL_PROFILE, RUN_UP_SPEED, RUN_UP_TORQUE

__all__ = ["BalancerVectorEnv", "RunUpTorqueVectorEnv", "RunUpSpeedVectorEnv",
           "DwellProfileVectorEnv"]

MAX_RENDERED = 4


class BalancerVectorEnv(SetupAccess, VectorEnv):
    """Native vector environment; use the registered subclasses (see the module docstring)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 25,
                "autoreset_mode": AutoresetMode.NEXT_STEP}
    #: the registered id this class makes (:mod:`abb_gym.envs.tasks`); ``task=`` overrides it
    task_id: str | None = None

    def __init__(self, num_envs: int = 1, scene: Any = None, preset: Any = None, *,
                 task: str | None = None, observe_balls: bool = False,
                 render_mode: str | None = None,
                 max_episode_steps: int | None = None, record_history: bool = False,
                 kernel: str | None = None, info_level: str = "lean", **overrides: Any):
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) \
                or num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1 (got {num_envs!r})")
        info_level = check_display(render_mode, self.metadata["render_modes"], info_level)
        self.setup = EnvSetup(task or self.task_id, scene, preset, observe_balls,
                              max_episode_steps, overrides)
        self.info_level = info_level
        self.num_envs = int(num_envs)
        check_flag(record_history, "record_history")
        n_trace = (self.num_envs if record_history
                   else min(self.num_envs, MAX_RENDERED) if render_mode else 0)
        # the buffers first: their check of the machine's memory counts the batched spaces
        self._bufs = Buffers(self.setup, self.num_envs, n_trace=n_trace, kernel=kernel)
        self._table = self._bufs.table
        self.render_mode = render_mode
        self.single_observation_space = self.setup.observation_space
        self.single_action_space = self.setup.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._step_fn = None  # the compiled step, fetched at the first step
        self._rngs: list[np.random.Generator | None] = [None] * self.num_envs
        self._prev_done = np.zeros(self.num_envs, dtype=bool)
        self._started = False
        self._warned_clip = False
        self._renderers: list[Renderer] | None = None
        self._dt = self.setup.control_interval
        self._nq = 3 + self.setup.scene.ball_count
        self._ref_len = self._table.reference_length  # each episode's, updated at resets

    # ------------------------------------------------------------------ pickling
    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderers"] = None
        state["_step_fn"] = None
        return state

    @property
    def kernel(self) -> str:
        """The compiled step in use: "specialised" (specialised on the scene's ball count and
        effects, vector instructions across sub-environments) or "generic" (``kernel="auto"``
        resolves to one of them when the environment is made)."""
        return self._bufs.kernel

    def episode(self, i: int):
        """Sub-environment ``i``'s current episode parameters (:class:`Episode`)."""
        return self._table.episode(i)

    def episode_scene(self, i: int):
        """Sub-environment ``i``'s current episode as a Scene."""
        ep = self._table.episode(i)
        return None if ep is None else ep.scene

    def history(self, i: int) -> dict[str, np.ndarray]:
        """Sub-environment ``i``'s history in its current episode (``record_history=True``;
        see :meth:`abb_gym.envs.setup.Buffers.history`)."""
        return self._bufs.history(i)

    @property
    def observation_names(self) -> list[str]:
        """Names of one sub-environment's observation entries, in order
        (:mod:`abb_gym.envs.observation`)."""
        return list(self.setup.obs_names)

    @property
    def states(self) -> np.ndarray:
        """Copy of the model states, shape (num_envs, state length)."""
        return self._bufs.s.copy()

    @property
    def times(self) -> np.ndarray:
        """Simulated time of each sub-environment's episode [s], shape (num_envs,)."""
        return self._bufs.st[:, S_K] * self._dt

    @property
    def rotor_speeds(self) -> np.ndarray:
        """Rotor speed of each sub-environment [rad/s], shape (num_envs,)."""
        return self._bufs.s[:, self._nq + 2].copy()

    @property
    def imbalances(self) -> np.ndarray:
        """Each sub-environment's primary imbalance now [kg m], shape (num_envs,): the
        episode's, or its laundry's after the redistributions so far (privileged: what an
        oracle knows, not what a drive observes)."""
        return self._bufs.p[:, P_U0].copy()

    @property
    def redistributions(self) -> np.ndarray:
        """Redistributions of the laundry so far in each sub-environment's episode."""
        return self._bufs.st[:, S_NREDIST].astype(np.int64)

    # ------------------------------------------------------------------ API
    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None):
        # everything is checked and computed before any state changes: a rejected reset
        # (bad seed, option, mask or too stiff an episode in any row) leaves every
        # sub-environment and its generator as they were
        n = self.num_envs
        if seed is None:
            seeds: list[int | None] = [None] * n
        elif isinstance(seed, (int, np.integer)) and not isinstance(seed, (bool, np.bool_)):
            first = check_seed(seed)
            seeds = [first + i for i in range(n)]
        else:
            if isinstance(seed, (str, bytes)) or not hasattr(seed, "__len__"):
                raise ValueError(f"seed must be None, an int >= 0 or a list of num_envs = {n} "
                                 f"seeds (got {seed!r})")
            seeds = [check_seed(v, f"seed[{k}]") for k, v in enumerate(seed)]
            if len(seeds) != n:
                raise ValueError(f"seed must be None, an int or a list of num_envs = {n} seeds "
                                 f"(got {len(seeds)})")
        if options is not None and not isinstance(options, Mapping):
            raise ValueError(f"options must be a dict of reset options (got {options!r})")
        options = dict(options) if options else {}
        mask = options.pop("reset_mask", None)
        if mask is None:
            rows = np.arange(n)
        else:
            mask = np.asarray(mask)
            if mask.shape != (n,) or mask.dtype != np.bool_ or not mask.any():
                raise ValueError(f"options['reset_mask'] must be a boolean array of shape "
                                 f"({n},) with at least one True value")
            if not self._started and not mask.all():
                raise ValueError("the first reset() must reset every sub-environment")
            rows = np.flatnonzero(mask)
        row_options = [self._options_for(int(i), options) for i in rows] if options else None
        fresh = {int(i): seeding.np_random(seeds[i])[0] for i in rows
                 if seeds[i] is not None or self._rngs[i] is None}
        rngs = [fresh[int(i)] if int(i) in fresh else self._rngs[i] for i in rows]
        kept = [r for i, r in zip(rows, rngs) if int(i) not in fresh]
        pending = draw_safely(
            lambda: self.setup.prepare_rows(self._table, rows, rngs, row_options), kept)
        # commit
        if isinstance(seed, (int, np.integer)):
            super().reset(seed=int(seed))
        for i, rng in fresh.items():
            self._rngs[i] = rng
        episodes.commit(self._bufs, self._table, pending)
        self._bufs.observe(rows)
        self._bufs.sort_lanes()
        self._prev_done[rows] = False
        self._started = True
        info = self._info(np.ones(n, dtype=bool) if mask is None else mask, reset_rows=rows,
                          level="full")
        return self._bufs.observations.copy(), info

    def _options_for(self, i: int, options: dict[str, Any]) -> dict[str, Any] | None:
        if not options:
            return None
        out = {}
        n = self.num_envs
        nb = self.setup.scene.ball_count
        for key, value in options.items():
            try:
                arr = np.asarray(value) if not isinstance(value, str) else None
            except (TypeError, ValueError):  # ragged lists: draw() names the option
                arr = None
            if key == "ball_angles" and arr is not None and arr.ndim == 2:
                if arr.shape[0] != n:
                    raise ValueError(f"reset option 'ball_angles' must have shape ({nb},) or "
                                     f"({n}, {nb}) (got {arr.shape})")
                out[key] = arr[i]
            elif key != "ball_angles" and arr is not None and arr.ndim == 1:
                if arr.shape[0] != n:
                    raise ValueError(f"reset option {key!r} must be one value or num_envs = "
                                     f"{n} values (got {arr.shape[0]})")
                out[key] = arr[i]
            else:
                out[key] = value
        return out

    def _reset_rows(self, rows: np.ndarray) -> None:
        """Draw and write new episodes of ``rows`` (the automatic reset: no options, and a
        preset whose episodes all suit the integrator, so it cannot be refused)."""
        self.setup.reset_rows(self._bufs, self._table, rows, [self._rngs[i] for i in rows])

    def step(self, actions):
        if not self._started:
            raise gym.error.ResetNeeded("call reset() before step()")
        bf = self._bufs
        n = self.num_envs
        a = checked_action(actions, (n,) + self.single_action_space.shape, "actions")
        if a.dtype != np.float32 and a.dtype != np.float64:
            a = a.astype(np.float64)
        bad, outside = check_actions(a.reshape(n, -1))
        if bad >= 0:
            raise ValueError(f"actions must be finite; entry "
                             f"{tuple(int(v) for v in np.unravel_index(bad, a.shape))} is "
                             f"not (no sub-environment was stepped)")
        if not self._warned_clip and outside:
            logger.warn("actions outside [-1, 1] were clipped (warned once)")
            self._warned_clip = True
        rows = np.flatnonzero(self._prev_done)
        if rows.size:
            self._reset_rows(rows)
            bf.active[:] = 1
            bf.active[rows] = 0
            bf.sort_lanes()
        np.clip(a, -1.0, 1.0, out=bf.act)
        am = self.setup.actions
        if am.works_before_step:
            for i in np.flatnonzero(bf.active):
                am.before_step(self.setup, bf, int(i), bf.act[i],
                               float(self._table.imbalance_phase[i]))
        step = self._step_fn
        if step is None:
            step = self._step_fn = bf.step_function()
        step(*bf.args)
        bf.push_frames()
        if rows.size:
            bf.observe(rows)  # (and their frame stacks start again)
            bf.active[:] = 1
        read = read_step(bf.out)
        self._prev_done = read.done
        info = self._info(np.ones(n, dtype=bool), reset_rows=rows, read=read)
        return bf.observations.copy(), read.reward, read.terminated, read.truncated, info

    def _info(self, mask: np.ndarray, reset_rows: np.ndarray, level: str | None = None,
              read: StepRows | None = None) -> dict[str, Any]:
        """The info of a step (``read``: what :func:`read_step` read after it) or of a reset
        (``level`` "full")."""
        bf = self._bufs
        level = level or self.info_level
        any_done = read is not None and read.any_done
        info = step_info(self.setup, bf.out, bf.st, bf.s, self._ref_len, level, any_done, read)
        if level == "lean" and any_done:
            # the details are for the rows whose episode ended
            terms = masked({"reward_terms": info.pop("reward_terms")}, mask)
            info = masked(info, read.done)
            info.update(terms)
        else:
            info = masked(info, mask)
        if len(reset_rows):
            rmask = np.zeros(self.num_envs, dtype=bool)
            rmask[reset_rows] = True
            info.update(masked(self._table.info(reset_rows), rmask))
        return info

    def render(self):
        if self.render_mode is None:
            logger.warn("render() called without a render_mode; create the vector environment "
                        "with render_mode='rgb_array'")
            return None
        k = min(self.num_envs, MAX_RENDERED)
        if self._renderers is None:
            self._renderers = [Renderer(self.setup.scene, self.setup.operating_speed,
                                        self.setup.episode_length, "rgb_array")
                               for _ in range(k)]
        bf = self._bufs
        frames = []
        for i in range(k):
            steps = int(bf.st[i, S_K])
            frames.append(self._renderers[i].draw(bf.s[i], bf.trace[i, :steps + 1]))
        return tuple(frames)

    def close_extras(self, **kwargs):
        if self._renderers:
            for r in self._renderers:
                r.close()
        self._renderers = None


class RunUpTorqueVectorEnv(BalancerVectorEnv):
    """Vector version of RunUpTorque (see :mod:`abb_gym.envs.torque`)."""

    task_id = RUN_UP_TORQUE.env_id


class RunUpSpeedVectorEnv(BalancerVectorEnv):
    """Vector version of RunUpSpeed (see :mod:`abb_gym.envs.speed`)."""

    task_id = RUN_UP_SPEED.env_id


class DwellProfileVectorEnv(BalancerVectorEnv):
    """Vector version of DwellProfile (see :mod:`abb_gym.envs.dwell`)."""

    task_id = DWELL_PROFILE.env_id
