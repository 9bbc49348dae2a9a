"""The Python side of an environment: preset, spaces, constants and buffers.

:class:`EnvSetup` resolves the scene and the preset and builds the spaces and the constants
array ``cfg`` of the compiled step (:mod:`abb_gym.envs.kernel`); :class:`Buffers` holds the
arrays of the rows and the blocks the step works in; :meth:`EnvSetup.reset_rows` draws and
writes episodes (:mod:`abb_gym.envs.episodes`).  What an action means is the action model's
(:mod:`abb_gym.envs.actions`); the machine's facts (reference amplitudes, best residual,
static sag) come from :mod:`abb_gym.physics.rotor`.
"""
from __future__ import annotations

import math
import os
from typing import Any, Mapping

import numpy as np
from gymnasium import spaces

from ..physics import batch
from ..physics import drive_law as dl
from ..physics.methods import METHOD_IDS
from ..physics import model as mdl
from ..physics import rotor
from ..physics.scene import Scene, load_scene
from ..physics.simulate import state_names
from ..physics.specialise import resolve_kernel
from . import episodes
from .actions import ActionModel, action_model
from ..configuration import specs
from .config import EnvConfig, PresetError, load_preset
from .display import check_info_level
from . import kernel
from .kernel import G_HELD, N_G_ENV, observe_rows
from .layout import (C_AMAX, C_BACKSTOP, C_BAL_TOL, C_BAND, C_CLEAR, C_DT, C_FILT,
                     C_INFO_FULL, C_KIND, C_METHOD, C_NACT, C_NMAX, C_OBS_BALLS, C_OBS_TIME,
                     C_OVERSPEED, C_SETTLE, C_SPEED_HI, C_SPEED_LO, C_SYNC, C_SYNC_LAG,
                     C_SYNC_NOISE, C_TEP, C_TLIM, C_TREF, C_VIB_HI, C_VSCALE, C_WE, C_WF,
                     C_WOP, C_WR, C_WT, C_WV,
                     FAIL_CLEARANCE, FAIL_NUMERICAL, FAIL_OVERSPEED, N_CFG, N_OUT, N_ST,
                     O_FINDEX, O_FTIME, S_DONE, S_DTMAX, S_K, S_USCALE, T_BALLS, T_T, T_VIB,
                     T_VIBMAX, T_W, T_X, T_Y)

__all__ = ["EnvSetup", "Buffers", "SetupAccess", "check_seed", "check_flag", "draw_safely",
           "MEMORY_LIMIT",
           "MAX_EPISODE_LENGTH", "row_bytes", "trace_bytes", "check_memory"]


def _physical_memory() -> float:
    """The machine's memory [bytes] (16 GiB where the system does not say)."""
    try:
        return float(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, OSError, ValueError):
        return 16.0 * 2 ** 30


#: Largest buffers [bytes] an environment allocates: the machine's memory.  A request beyond
#: it (``num_envs=2**40``, or a recorded history of 1e10 control intervals) is refused with a
#: ValueError naming the argument, not left to numpy's MemoryError or the system's OOM killer.
MEMORY_LIMIT = _physical_memory()
#: Longest automatic episode [s]: the bound of the ``episode_length`` field.
MAX_EPISODE_LENGTH = float(specs(EnvConfig)["episode_length"].le)


def row_bytes(setup: "EnvSetup") -> int:
    """Bytes per environment of :class:`Buffers` (row arrays and compiled-step lanes, without
    the history) and of a vector environment's batched spaces."""
    nb = setup.scene.ball_count
    ns = 2 * (3 + nb)
    rows = (setup.n_actions + ns + mdl.N_PARAMS + nb * mdl.N_BALL_PARAMS
            + setup.n_rows * dl.N_DRIVE + N_ST + N_OUT + 2)
    lanes = (16 * ns + mdl.N_PARAMS + nb * (mdl.N_BALL_PARAMS + mdl.WORK_COLUMNS) + dl.N_DRIVE
             + batch.N_F + max(batch.N_G, N_G_ENV))
    spaces_bounds = 2 * 4 * (setup.obs_dim + setup.n_actions)  # float32 low and high
    return 8 * (rows + lanes) + 4 * setup.obs_dim + 2 + spaces_bounds


def trace_bytes(setup: "EnvSetup") -> int:
    """Bytes of one environment's recorded history (one row per control interval)."""
    return 8 * (setup.max_steps + 1) * (T_BALLS + setup.scene.ball_count)


def _gb(n: float) -> str:
    return f"{n / 1e9:.3g} GB"


def check_memory(setup: "EnvSetup", n: int, n_trace: int) -> None:
    """Raise ValueError, naming the argument and what to change, if the buffers of ``n``
    environments with ``n_trace`` histories need more than :data:`MEMORY_LIMIT`."""
    rows = float(n) * row_bytes(setup)
    trace = float(min(n_trace, n)) * trace_bytes(setup)
    if rows > MEMORY_LIMIT:
        raise ValueError(f"num_envs = {n} needs {_gb(rows)} of buffers ({row_bytes(setup)} "
                         f"bytes per sub-environment), more than this machine's "
                         f"{_gb(MEMORY_LIMIT)}: use fewer sub-environments")
    if rows + trace > MEMORY_LIMIT:
        raise ValueError(f"the history kept by record_history=True or render_mode ("
                         f"{setup.max_steps + 1} control intervals x {min(n_trace, n)} "
                         f"environment(s)) needs {_gb(trace)}, more than this machine's "
                         f"{_gb(MEMORY_LIMIT)}: record no history, or shorten the episode "
                         f"(episode_length = {setup.episode_length:.6g} s, control_interval = "
                         f"{setup.control_interval:g} s) or use fewer sub-environments")


def check_seed(seed: Any, what: str = "seed") -> int | None:
    """``seed`` as a Python int >= 0, or None; anything else (negative, bool, float, text)
    raises ValueError naming ``what`` (gymnasium's seeding raises its own error type)."""
    if seed is None:
        return None
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) \
            or seed < 0:
        raise ValueError(f"{what} must be None or an integer >= 0 (got {seed!r})")
    return int(seed)


def check_flag(value: Any, what: str) -> bool:
    """``value`` if it is True or False (numpy's too), else a ValueError naming ``what``:
    ``"no"`` or ``[]`` are not read as flags."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{what} must be True or False (got {value!r:.80})")
    return bool(value)


def draw_safely(prepare, rngs: list):
    """``prepare()`` (which draws from the generators ``rngs``), with the generators put back
    as they were if it raises: a rejected reset leaves no trace, not even in the random
    streams, so the next reset draws what it would have drawn."""
    saved = [(rng, rng.bit_generator.state) for rng in rngs]
    try:
        return prepare()
    except BaseException:
        for rng, state in saved:
            rng.bit_generator.state = state
        raise


class Buffers:
    """The preallocated arrays of ``n`` environments (rows), in blocks of lanes for the
    compiled step (:mod:`abb_gym.envs.kernel`)."""

    def __init__(self, setup: "EnvSetup", n: int, n_trace: int = 0, kernel: str | None = None,
                 lanes: int | None = None):
        check_memory(setup, n, n_trace)
        nb = setup.scene.ball_count
        ns = 2 * (3 + nb)
        self.act = np.zeros((n, setup.n_actions))
        self.s = np.zeros((n, ns))
        self.p = np.zeros((n, mdl.N_PARAMS))
        self.b = np.zeros((n, nb, mdl.N_BALL_PARAMS))
        self.d = np.zeros((n, setup.n_rows, dl.N_DRIVE))
        self.st = np.zeros((n, N_ST))
        self.st[:, S_DONE] = 1.0
        self.st[:, S_USCALE] = 1.0
        self.obs = np.zeros((n, setup.frame_dim), dtype=np.float32)
        # the last frame_stack observations, oldest first (None: no stacking)
        self.frame_stack = setup.frame_stack
        self.frames = (np.zeros((n, setup.obs_dim), dtype=np.float32)
                       if setup.frame_stack > 1 else None)
        self.out = np.zeros((n, N_OUT))
        k = setup.max_steps + 1 if n_trace > 0 else 0
        self.trace = np.zeros((min(n_trace, n), k, T_BALLS + nb))
        self.active = np.ones(n, dtype=np.uint8)
        self.cfg = setup.cfg
        self.blocks = batch.Blocks(n, nb, lanes, int_rows=N_G_ENV,
                                   precision=setup.config.precision)
        self.blocks.g[:, G_HELD] = -1  # no lane holds a row yet (kernel.G_HELD)
        self.order = np.arange(n, dtype=np.int64)
        self.n_balls = nb
        # blocks of one lane (a single environment, a few sub-environments): the kernel also
        # takes the lane count as a constant
        self.spec = setup.spec | (mdl.SPEC_ONE_LANE if self.blocks.lanes == 1 else 0)
        self.kernel = resolve_kernel(kernel, self.blocks.lanes, cached_ok=True)
        self._step = None
        if self.kernel == "cached":
            # "auto" on a few lanes: the specialised kernel if it needs no compiling
            self._step = self._stepper().cached_entry(*self.kernel_args())
            self.kernel = "generic" if self._step is None else "specialised"

    def step_arrays(self) -> tuple:
        """The arrays of the compiled step, in the order of
        :data:`abb_gym.envs.kernel.STEP_ARRAYS`."""
        return (self.order, self.act, self.s, self.p, self.b, self.d, self.st, self.cfg, self.obs,
                self.out, self.trace, self.active, *self.blocks.arrays())

    def kernel_args(self) -> tuple:
        """Arguments of :data:`abb_gym.envs.kernel.step_serial` / ``step_parallel``: the packed
        :meth:`step_arrays` (rebuild them after replacing any of those arrays), the ball count
        and the effect bits."""
        return kernel.pack_step_arrays(*self.step_arrays()), self.n_balls, self.spec

    def step_function(self):
        """The compiled step's entry point, called with :meth:`kernel_args` (compiled or
        loaded from the cache on the first call)."""
        if self._step is None:
            self._step = self._stepper().entry(*self.kernel_args(),
                                               generic=self.kernel == "generic")
        blocks = self.blocks.s.shape[0]
        # the blocks in parallel on the threads that the free CPUs allow (batch.ParallelCall)
        return batch.ParallelCall(self._step, blocks) if blocks > 1 else self._step

    def _stepper(self):
        return kernel.step_parallel if self.blocks.s.shape[0] > 1 else kernel.step_serial

    def sort_lanes(self) -> None:
        """Group rows of equal step size into the same blocks (after resets), sorted per
        thread's run of blocks (:func:`abb_gym.physics.batch.lane_order`)."""
        # (one block: one run, stepped serially)
        self.order[:] = batch.lane_order(self.st[:, S_DTMAX], self.blocks.lanes,
                                         batch.thread_parts())

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_step"] = None  # compiled entry points do not pickle
        return state

    def history(self, i: int) -> dict[str, np.ndarray]:
        """Row ``i``'s recorded history so far, one entry per control interval boundary
        (``t`` [s], ``x``, ``y`` [m], ``rotor_speed`` [rad/s], ``vibration`` (the interval's
        mean) and ``vibration_max`` [m], ``ball_angles`` [rad] (T, n)); needs a buffer built
        with a trace for that row (``record_history=True``)."""
        if i >= self.trace.shape[0]:
            raise ValueError("no history is recorded: create the environment with "
                             "record_history=True")
        rows = self.trace[i, :int(self.st[i, S_K]) + 1]
        return {"t": rows[:, T_T].copy(), "x": rows[:, T_X].copy(), "y": rows[:, T_Y].copy(),
                "rotor_speed": rows[:, T_W].copy(), "vibration": rows[:, T_VIB].copy(),
                "vibration_max": rows[:, T_VIBMAX].copy(), "ball_angles": rows[:, T_BALLS:].copy()}

    def observe(self, rows: np.ndarray) -> None:
        """Observe ``rows`` after a reset (their frame stacks filled with the first one)."""
        rows = np.asarray(rows, dtype=np.int64)
        observe_rows(rows, self.s, self.p, self.b, self.st, self.cfg, self.obs, self.out,
                     self.trace)
        self.fill_frames(rows)

    @property
    def observations(self) -> np.ndarray:
        """What the environments return: the observations, or their frame stacks."""
        return self.obs if self.frames is None else self.frames

    def fill_frames(self, rows: np.ndarray) -> None:
        """Every frame of ``rows`` := their current observation (the start of an episode)."""
        if self.frames is not None and len(rows):
            self.frames[rows] = np.tile(self.obs[rows], (1, self.frame_stack))

    def push_frames(self) -> None:
        """Shift every row's frames by one and append the current observation (after a
        step)."""
        if self.frames is not None:
            d = self.obs.shape[1]
            self.frames[:, :-d] = self.frames[:, d:].copy()
            self.frames[:, -d:] = self.obs


def _as_int_steps(seconds: float, dt: float) -> int:
    return max(1, int(math.ceil(seconds / dt - 1e-9)))


class EnvSetup:
    """Everything an environment of one kind, scene and preset shares between episodes."""

    def __init__(self, kind: str, scene: Any = "yoshida_odd", preset: Any = "train",
                 observe_balls: bool = False, max_episode_steps: int | None = None,
                 overrides: Mapping[str, Any] | None = None):
        self.actions: ActionModel = action_model(kind)
        self.kind = kind
        if not isinstance(scene, (str, Scene)) and not hasattr(scene, "__fspath__"):
            raise ValueError(f"scene must be a scene name, a path or a Scene (got {scene!r})")
        self.scene = load_scene(scene)
        self.config: EnvConfig = load_preset(preset, **dict(overrides or {}))
        self.observe_balls = check_flag(observe_balls, "observe_balls")
        if max_episode_steps is not None:
            if isinstance(max_episode_steps, bool) or not isinstance(
                    max_episode_steps, (int, np.integer)) or max_episode_steps < 1:
                raise ValueError(f"max_episode_steps must be an integer >= 1 or None "
                                 f"(got {max_episode_steps!r})")
        self.backstop = int(max_episode_steps or 0)
        cfg = self.config
        sc = self.scene
        self.operating_speed = float(cfg.operating_speed or sc.drive_operating_speed)
        self.control_interval = float(cfg.control_interval)
        self.max_acceleration = float(sc.drive_max_acceleration)
        self.torque_limit = float(sc.drive_torque_limit)
        # reference time: the fastest run-up the drive allows
        self.reference_time = self.operating_speed / self.max_acceleration
        dw = cfg.dwell
        self.dwell_acceleration = dw.runup_acceleration * self.max_acceleration
        self.nominal_runup_time = self.operating_speed / self.dwell_acceleration
        am = self.actions
        if cfg.episode_length is not None:
            length = float(cfg.episode_length)
            given = f"field 'episode_length' = {length:g} s"
        else:
            length = am.default_episode_length(self)
            given = f"automatic: {am.episode_length_rule}"
            # the bound of a given episode_length holds for the automatic one as well (a
            # drive of 1e-3 rad/s^2 would otherwise ask for 1e8 s, a ramp of 1e-300 x the
            # drive's acceleration for an infinite episode)
            if not length <= MAX_EPISODE_LENGTH:
                raise PresetError(
                    f"environment preset {cfg.name!r}: the automatic episode length "
                    f"{am.episode_length_rule} = {length:.4g} s (operating_speed = "
                    f"{self.operating_speed:g} rad/s, the scene's drive_max_acceleration = "
                    f"{self.max_acceleration:g} rad/s^2) exceeds {MAX_EPISODE_LENGTH:g} s, the "
                    f"bound of field 'episode_length': give episode_length or a faster run-up")
        self.max_steps = _as_int_steps(length, self.control_interval)
        self.episode_length = self.max_steps * self.control_interval
        self.settle_steps = int(round(cfg.settle_time / self.control_interval))
        if cfg.settle_time > 0 and self.settle_steps == 0:
            self.settle_steps = 1
        if self.settle_steps >= self.max_steps:
            raise PresetError(f"environment preset {cfg.name!r}: field 'settle_time' = "
                              f"{cfg.settle_time:g} s ({self.settle_steps} control intervals "
                              f"of control_interval = {self.control_interval:g} s) must be "
                              f"shorter than the episode, {self.max_steps} intervals "
                              f"({self.episode_length:g} s; {given})")
        am.check(self)
        self.max_speed = am.max_speed(self.operating_speed, cfg)
        # observation scale: the resonance amplitude of the machine with its balancer off,
        # with the scene's imbalance
        self.vibration_scale = rotor.reference_amplitudes(sc, self.operating_speed)[0]
        self.vibration_bound = sc.housing_clearance / self.vibration_scale
        # refuse now a preset whose random machines do not exist (no rotor mass left, sagging
        # onto the housing) or whose random episodes would need millions of RK4 steps per
        # control interval, rather than at an automatic reset in the middle of training
        episodes.check_preset_machines(self)
        episodes.check_preset_stiffness(self)
        self.effort_bound = am.effort_bound(cfg)
        self.n_actions = am.n_actions
        self.n_rows = am.n_rows
        nb = sc.ball_count
        self.sync = cfg.sync_vibration.enabled
        self.frame_stack = int(cfg.frame_stack)
        # one frame: the kernel's observation row
        self.observe_time = bool(cfg.observe_time)
        self.frame_dim = ((5 if self.observe_time else 4) + self.n_actions
                          + (3 if self.sync else 0) + (2 * nb if self.observe_balls else 0))
        self.obs_dim = self.frame_stack * self.frame_dim
        speed_lo, speed_hi = am.speed_bounds(cfg)
        vb = self.vibration_bound
        lo = [speed_lo, -vb, -vb, 0.0]
        hi = [speed_hi, vb, vb, vb]
        names = ["rotor_speed", "vibration_x", "vibration_y", "vibration_amplitude"]
        if self.observe_time:
            lo.append(0.0)
            hi.append(1.0)
            names.append("time_fraction")
        lo += [-1.0] * self.n_actions
        hi += [1.0] * self.n_actions
        names += [f"last_action[{a}]" for a in range(self.n_actions)]
        if self.sync:
            lo += [0.0, -1.0, -1.0]
            hi += [vb, 1.0, 1.0]
            names += ["sync_amplitude", "sync_cos", "sync_sin"]
        if self.observe_balls:
            lo += [-1.0] * (2 * nb)
            hi += [1.0] * (2 * nb)
            names += [f"{fn}(ball_angle[{k}])" for k in range(nb) for fn in ("cos", "sin")]
        k = self.frame_stack
        if k > 1:
            # frames oldest first; "name@t-2" is the entry two control steps back
            names = [n if k - 1 - j == 0 else f"{n}@t-{k - 1 - j}"
                     for j in range(k) for n in names]
        self.observation_space = spaces.Box(np.array(lo * k, np.float32),
                                            np.array(hi * k, np.float32), dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(self.n_actions,), dtype=np.float32)
        self.obs_names = names
        w = cfg.reward
        c = np.zeros(N_CFG)
        c[C_KIND] = am.kind_id
        c[C_DT] = self.control_interval
        c[C_WOP] = self.operating_speed
        c[C_BAND] = cfg.at_speed_tolerance
        c[C_OVERSPEED] = am.overspeed_trip(cfg)
        c[C_TLIM] = self.torque_limit
        c[C_AMAX] = self.max_acceleration
        c[C_CLEAR] = sc.housing_clearance
        c[C_VSCALE] = self.vibration_scale
        c[C_FILT] = 1.0 - math.exp(-self.control_interval / cfg.vibration_filter_time)
        c[C_SETTLE] = self.settle_steps * self.control_interval
        c[C_NMAX] = self.max_steps
        c[C_BACKSTOP] = self.backstop
        c[C_TREF] = self.reference_time
        c[C_WV], c[C_WT], c[C_WE], c[C_WR], c[C_WF] = (w.vibration, w.time, w.effort,
                                                       w.residual, w.failure)
        c[C_NACT] = self.n_actions
        c[C_OBS_BALLS] = 1.0 if self.observe_balls else 0.0
        c[C_SPEED_LO], c[C_SPEED_HI] = speed_lo, speed_hi
        c[C_VIB_HI] = self.vibration_bound
        c[C_BAL_TOL] = cfg.balance_tolerance
        c[C_TEP] = self.episode_length
        c[C_METHOD] = METHOD_IDS[cfg.integrator]
        sync = cfg.sync_vibration
        c[C_SYNC] = 1.0 if sync.enabled else 0.0
        c[C_SYNC_LAG] = sync.lag
        c[C_SYNC_NOISE] = sync.noise * self.vibration_scale  # [m]
        c[C_OBS_TIME] = 1.0 if self.observe_time else 0.0
        self.cfg = c
        self.set_info_level("lean")
        self._state_names = state_names(nb)
        # the compiled step's effect set: the nominal scene's (an episode only rescales the
        # scene's drag, rolling resistance, mass and support damping, so it never needs a term
        # the nominal lacks)
        p_nominal, _ = mdl.pack_parameters(sc)
        row = np.zeros(dl.N_DRIVE)
        row[dl.D_MODE] = am.mode
        self.spec = mdl.spec_of(p_nominal, row)

    # ------------------------------------------------------------------ episodes
    def prepare_rows(self, table: episodes.EpisodeTable, rows, rngs: list,
                     options: list | None = None) -> episodes.Pending:
        """Draw the episodes of ``rows`` (row ``rows[k]`` from generator ``rngs[k]`` with reset
        options ``options[k]``) and compute their start, changing nothing but the generators'
        states (which a caller rolls back on error): :func:`episodes.commit` writes it."""
        imbalance, phase, angles, drag, roll, crit, damp, key = episodes.draw_rows(
            self, rngs, options)
        return episodes.prepare(self, table, rows, imbalance, phase, angles, drag, roll, crit,
                                damp, key)

    def reset_rows(self, bufs: "Buffers", table: episodes.EpisodeTable, rows,
                   rngs: list, options: list | None = None) -> None:
        """Draw the episodes of ``rows`` and write them, all rows at once
        (:meth:`prepare_rows`, then :func:`episodes.commit`)."""
        episodes.commit(bufs, table, self.prepare_rows(table, rows, rngs, options))

    # ------------------------------------------------------------------ info
    def set_info_level(self, level: str) -> None:
        """Whether every step's info shows the residual imbalance (``level`` "full") or only
        an episode's last ("lean"): the compiled step measures it (two sin/cos per ball) only
        for the steps that show it; in the others ``balanced`` and
        ``residual_imbalance_ratio`` are 0, like any masked entry of a vector info."""
        self.cfg[C_INFO_FULL] = 1.0 if level == "full" else 0.0

    def failure_message(self, code: int, out_row: np.ndarray, st_row: np.ndarray,
                        s_row: np.ndarray) -> str:
        t = out_row[O_FTIME]
        if code == FAIL_NUMERICAL:
            name = self._state_names[int(out_row[O_FINDEX])]
            return (f"numerical: the state became non-finite at t = {t:.6g} s in {name!r} "
                    f"(RK4 step {st_row[S_DTMAX]:.3g} s); the episode ended at the last "
                    f"finite state; reduce integration_step")
        if code == FAIL_CLEARANCE:
            return (f"clearance: the whirl radius exceeded the housing clearance "
                    f"{self.scene.housing_clearance:g} m at t = {t:.6g} s")
        if code == FAIL_OVERSPEED:
            nq = s_row.shape[0] // 2
            return (f"overspeed: rotor speed {s_row[nq + 2]:.6g} rad/s beyond "
                    f"{self.config.overspeed:g} x the operating speed {self.operating_speed:g}"
                    f" rad/s at t = {t:.6g} s")
        return ""


class SetupAccess:
    """``scene``, ``config`` and ``info_level`` of an environment that holds an
    :class:`EnvSetup`."""

    setup: EnvSetup

    @property
    def info_level(self) -> str:
        """"lean" or "full" (module docstrings of the environments, Info)."""
        return self._info_level

    @info_level.setter
    def info_level(self, level: Any) -> None:
        # checked whenever set, after construction too, and passed on to the compiled step
        self._info_level = check_info_level(level)
        self.setup.set_info_level(self._info_level)

    @property
    def scene(self) -> Scene:
        """The environment's nominal scene (episodes may randomise it: ``episode_scene``)."""
        return self.setup.scene

    @property
    def config(self) -> EnvConfig:
        """The resolved preset (:class:`abb_gym.envs.config.EnvConfig`)."""
        return self.setup.config
