"""The Python side of an environment: task, preset, spaces and constants.

:class:`EnvSetup` resolves the task (:mod:`abb_gym.envs.tasks`), the scene and the preset and
builds the spaces (:mod:`abb_gym.envs.observation`) and the constants array ``cfg`` of the
compiled step (:mod:`abb_gym.envs.kernel`); :meth:`EnvSetup.reset_rows` draws and writes
episodes (:mod:`abb_gym.envs.episodes`).  What an action means is the action model's
(:mod:`abb_gym.envs.actions`); the machine's facts (reference amplitudes, best residual,
static sag) come from :mod:`abb_gym.physics.rotor`.  The arrays live in
:class:`abb_gym.envs.buffers.Buffers`, the argument checks in :mod:`abb_gym.envs.checks`.
"""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np
from gymnasium import spaces

from ..configuration import specs
from ..physics import drive_law as dl
from ..physics import model as mdl
from ..physics import rotor
from ..physics.methods import METHOD_IDS
from ..physics.scene import Scene, load_scene
from ..physics.trajectory import state_names
from . import episodes, observation, redistribution, tasks
from .actions import action_model
from .checks import check_flag
from .config import EnvConfig, PresetError, load_task_preset
from .display import check_info_level
from .layout import (C_AMAX, C_BACKSTOP, C_BAL_TOL, C_BAND, C_CLEAR, C_DT, C_FILT,
                     C_INFO_FULL, C_KIND, C_METHOD, C_NACT, C_NMAX, C_OBS, C_OVERSPEED,
                     C_SETTLE, C_SPEED_HI, C_SPEED_LO, C_SYNC, C_SYNC_LAG, C_SYNC_NOISE, C_TEP,
                     C_TLIM, C_TREF, C_VIB_HI, C_VSCALE, C_WE, C_WF, C_WOP, C_WR, C_WT, C_WV,
                     FAIL_CLEARANCE, FAIL_NUMERICAL, FAIL_OVERSPEED, N_CFG, O_FINDEX, O_FTIME,
                     S_DTMAX)

__all__ = ["EnvSetup", "SetupAccess", "MAX_EPISODE_LENGTH"]

#: Longest automatic episode [s]: the bound of the ``episode_length`` field.
MAX_EPISODE_LENGTH = float(specs(EnvConfig)["episode_length"].le)


def _as_int_steps(seconds: float, dt: float) -> int:
    return max(1, int(math.ceil(seconds / dt - 1e-9)))


class EnvSetup:
    """Everything an environment of one task, scene and preset shares between episodes.

    ``task``: a registered id or :class:`~abb_gym.envs.tasks.Task`; ``scene`` and ``preset``
    default to the task's."""

    def __init__(self, task: Any, scene: Any = None, preset: Any = None,
                 observe_balls: bool = False, max_episode_steps: int | None = None,
                 overrides: Mapping[str, Any] | None = None):
        self.task = tasks.get(task)
        scene = self.task.default_scene if scene is None else scene
        preset = self.task.default_preset if preset is None else preset
        if not isinstance(scene, (str, Scene)) and not hasattr(scene, "__fspath__"):
            raise ValueError(f"scene must be a scene name, a path or a Scene (got {scene!r})")
        self.scene = load_scene(scene)
        self.config: EnvConfig = load_task_preset(self.task, preset, overrides)
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
        # what the action model decides, asked in one go now that the preset is known
        am = self.actions = action_model(self.task.action)
        #: the action model's name (``torque``, ``speed``, ``dwell``, ...)
        self.kind = self.task.action
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
        self.effort_bound = am.effort_bound(cfg)
        self.n_actions = am.n_actions
        self.n_rows = am.n_rows
        overspeed_trip = am.overspeed_trip(cfg)
        speed_bounds = am.speed_bounds(cfg)
        # observation scale: the resonance amplitude of the machine with its balancer off,
        # with the scene's imbalance
        self.vibration_scale = rotor.reference_amplitudes(sc, self.operating_speed)[0]
        self.vibration_bound = sc.housing_clearance / self.vibration_scale
        # refuse now a preset whose random machines do not exist (no rotor mass left, sagging
        # onto the housing) or whose random episodes would need millions of RK4 steps per
        # control interval, rather than at an automatic reset in the middle of training
        episodes.check_preset_machines(self)
        episodes.check_preset_stiffness(self)
        self.sync = cfg.sync_vibration.enabled
        self.frame_stack = int(cfg.frame_stack)
        self.observe_time = bool(cfg.observe_time)
        redistribution.check(self)
        self.redistribution_events = redistribution.events(self)
        # the reward's unit of vibration [m] (None: the machine's reference amplitudes)
        self.reward_length_scale = cfg.reward.length_scale
        #: the observation (:mod:`abb_gym.envs.observation`): one frame's entries
        self.observation = observation.layout(self)
        self.frame_dim = self.observation.frame_dim
        self.obs_dim = self.observation.obs_dim
        k = self.frame_stack
        self.observation_space = spaces.Box(np.array(self.observation.low * k, np.float32),
                                            np.array(self.observation.high * k, np.float32),
                                            dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(self.n_actions,), dtype=np.float32)
        self.obs_names = self.observation.names
        w = cfg.reward
        c = np.zeros(N_CFG)
        c[C_KIND] = am.kind_id
        c[C_DT] = self.control_interval
        c[C_WOP] = self.operating_speed
        c[C_BAND] = cfg.at_speed_tolerance
        c[C_OVERSPEED] = overspeed_trip
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
        c[C_SPEED_LO], c[C_SPEED_HI] = speed_bounds
        c[C_VIB_HI] = self.vibration_bound
        c[C_BAL_TOL] = cfg.balance_tolerance
        c[C_TEP] = self.episode_length
        c[C_METHOD] = METHOD_IDS[cfg.integrator]
        sync = cfg.sync_vibration
        c[C_SYNC] = 1.0 if sync.enabled else 0.0
        c[C_SYNC_LAG] = sync.lag
        c[C_SYNC_NOISE] = sync.noise * self.vibration_scale  # [m]
        c[C_OBS:C_OBS + observation.N_SLOTS] = self.observation.offsets
        redistribution.write_constants(self, c)
        self.cfg = c
        self.set_info_level("lean")
        self._state_names = state_names(sc.ball_count)
        # the compiled step's effect set: the nominal scene's (an episode only rescales the
        # scene's drag, rolling resistance, mass and support damping, changes its imbalance
        # or warms its fluid, so it never needs a term the nominal lacks)
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
        return episodes.prepare(self, table, rows, episodes.draw_rows(self, rngs, options))

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

