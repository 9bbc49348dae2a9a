"""Base class of the balancer environments: observation, reward, episode, info, rendering.

The three environments differ only in their action (see :mod:`abb_gym.envs.torque`,
:mod:`abb_gym.envs.speed`, :mod:`abb_gym.envs.dwell`); everything below is shared.  The
physics is the compiled model of :mod:`abb_gym.physics.model`, advanced by the compiled step
of :mod:`abb_gym.envs.kernel` (bit-compatible with ``simulate`` using the same integrator);
what an action means is :mod:`abb_gym.envs.actions`.
"""
from __future__ import annotations

import textwrap
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import logger
from gymnasium.utils import seeding

from .actions import checked_action
from .display import SINGLE_METADATA, check_display
from .info import step_info
from .layout import ACT_CLIPPED, ACT_NONFINITE, O_ACTFLAG, O_REWARD, O_TERM, O_TRUNC, S_K
from .rendering import Renderer
from . import episode_parameters, episodes, observation
from .buffers import Buffers
from .checks import check_flag, check_seed, draw_safely
from .episodes import Episode
from .setup import EnvSetup, SetupAccess

COMMON_DOC = textwrap.dedent(r"""
    ## Observation Space

    A flat ``Box(obs_dim,)`` of float32: what a drive with a vibration sensor measures, every
    entry normalised and clipped to the bounds below.  ``A_v`` is the steady whirl amplitude at
    resonance of the same rotor without balls, with the scene's imbalance (a fixed scale per
    environment), ``c`` the housing clearance, ``w_op`` the operating speed.

    {observation_table}

    The entries in this order (one left out moves the later ones up; the action size is 1,
    DwellProfile 3).  ``(x_rest, y_rest)`` is the rest position of
    the rotor centre: the origin, or the static sag under gravity (horizontal-axis scenes);
    the vibration radius is the distance from it (equal to the whirl radius without gravity).
    The vibration amplitude is the vibration radius passed through a first-order low-pass of
    time constant ``vibration_filter_time``.  Ball angles are measured from the imbalance.

    **Synchronous vibration** (preset section ``sync_vibration``: ``enabled``, ``lag`` [s],
    ``noise`` [x A_v]; off in ``train``/``test``/``nominal``, on in ``varied``/``varied_test``):
    what a balancing machine or a drive with a once-per-revolution reference reads.  The
    vibration ``(x - x_rest) + i (y - y_rest)`` is demodulated against the angle of the
    rotor's reference mark and low-passed with time constant ``lag`` at every integration step
    (:mod:`abb_gym.physics.sensors`, which derives it); the read-out ``Z`` plus Gaussian noise
    of standard deviation ``noise * A_v`` per component gives ``sync_amplitude = |Z| / A_v``
    and ``(sync_cos, sync_sin) = Z / |Z|`` ((0, 0) while ``Z = 0``, at rest without noise).
    The mark is where the rotor's x axis pointed at t = 0, so the primary imbalance lies at
    the imbalance phase from it (unobserved, random per episode).  At constant speed with the
    balls still, ``|Z|`` is the steady whirl radius and ``arg Z`` the direction of the residual
    imbalance from the mark minus the support's phase lag (about 0 below the critical speed,
    180 deg above): where the balls stand.  ``frame_stack: k`` returns the last k
    observations, oldest first, as one flat vector (:mod:`abb_gym.envs.config`).

    ## Rewards

    Per control interval of length dt; ``T_ref = w_op / drive_max_acceleration`` (the fastest
    run-up the drive allows) makes the terms comparable between machines.  The weights ``w_*``
    come from the preset (``reward:`` section).  Each term is reported in
    ``info["reward_terms"]``; the reward is their sum (in the order listed).

    | Term | Value per interval |
    |------|--------------------|
    | vibration | -w_vibration * (r_mean / A_peak) * dt / T_ref |
    | time | -w_time * dt / T_ref, if the interval ends outside the operating band |
    | effort | -w_effort * integral(u^2 dt) / T_ref |
    | residual | terminal: -w_residual * (vibration over the settling window) / A_op |
    | failure | terminal: -(w_failure + R_max * (T_episode - t) / T_ref + w_residual * c / A_op) |

    * ``r_mean``: the vibration radius averaged over the interval's RK4 steps.
    * With ``reward.length_scale`` set (SpinRedistribute: 1 mm), ``A_peak = A_op`` is that
      length: vibration and residual in that unit, the same for every episode.
    * ``A_peak``, ``A_op``: the same machine with its balancer off (this episode's total mass
      ``M`` and support, this episode's imbalance U; :func:`abb_gym.physics.rotor.
      reference_amplitudes`): the steady Jeffcott amplitude ``U w^2 / sqrt((k - M w^2)^2 +
      (c w)^2)`` (larger of the two axes), at its peak over [0, w_op] and at w_op.  A residual
      ratio of 1 is no better than without a balancer.  U is floored at a tenth of the
      balancing capacity, ``U = max(U0, 0.1 sum m_i R)`` (:func:`abb_gym.physics.rotor.
      imbalance_scale`): below it the balls' own imbalance, not U0, sets the vibration, and
      dividing by U0 would make the return scale as 1/U0 (infinite at a subnormal U0).  The
      reward is continuous and finite down to U0 = 0; every shipped preset draws U0 above
      the floor.
    * The operating band, the settling window and the residual are those of
      :mod:`abb_gym.physics.runup`: "in the band" means ``|w - w_op| <= at_speed_tolerance *
      w_op`` (0.2 %, a drive's speed loop); the run-up completes after an unbroken stay of
      ``settle_time`` in the band, and the residual is the time-average vibration over that
      stay (the settling window).
    * ``u``: torque / torque limit (RunUpTorque) or applied acceleration /
      drive_max_acceleration (RunUpSpeed, DwellProfile).
    * residual: paid on success, and also at truncation - over the current stay in the band
      so far, or at its bound ``w_residual * c / A_op`` if the rotor is not in the band at the
      end - so a run-up too slow to finish, or parked off the band, never pays.
    * failure: ``R_max = w_vibration c / A_peak + w_time + w_effort u_max^2`` bounds the
      penalty rate of any continuation (the whirl cannot exceed c without failing), so the
      failure term is worse than every way of carrying on: ending early never pays.

    ## Starting State

    The rotor is at rest at its rest position (x = y = 0; under gravity the static sag
    x = M g_x / k_x, y = M g_y / k_y), all speeds 0.  The rotor angle is the
    imbalance phase, the balls sit at their initial angles (measured from the imbalance).  The
    episode parameters below are drawn from the preset's ``randomize`` ranges with
    ``self.np_random`` (in this order, one ``random`` call), or set exactly by the reset option
    of the same name (:mod:`abb_gym.envs.episode_parameters`); a range left null keeps the
    scene's value.

    {episode_table}

    The critical speed changes through the supported mass (a load:
    :mod:`abb_gym.envs.config`).  With redistribution of the laundry
    (:mod:`abb_gym.envs.redistribution`) the episode also draws its redistributions, and the
    reset option ``redistributions`` fixes them.
    Under gravity the rest position is the episode's own sag.

    ## Episode End

    * terminated, success: the rotor has stayed ``settle_time`` in the operating band without
      a break (the settling window; leaving the band starts the window again).  The residual
      term is paid.
    * terminated, failure: the whirl radius (measured from the bearing axis, as the scene's
      clearance is) exceeded the housing clearance at an RK4 step, the rotor tripped
      the overspeed limit (RunUpTorque only), or the state became non-finite.  The failure
      term is paid and ``info["failure"]`` says what happened; the observation is that of the
      last finite state.
    * truncated: ``episode_length`` has elapsed; the residual term is paid (see Rewards).
    * With redistribution of the laundry (SpinRedistribute), an unbroken ``tumble_time``
      below the tumble speed redistributes it (:mod:`abb_gym.envs.redistribution`): the
      episode goes on with the new load.
      The environment truncates itself (episode lengths depend on the scene); ``gym.make``
      wraps the RunUp* environments in a ``TimeLimit`` of exactly this length
      (``env.spec.max_episode_steps``; see :mod:`abb_gym.envs`).

    ## Info

    ``info_level="lean"`` (default) keeps the per-step ``info`` to ``reward_terms`` (and
    ``failure`` when one happens): the step of a training loop pays for nothing else.  The
    step that ends an episode (terminated or truncated), and ``reset``, carry every key below,
    so the final info always holds the run-up metrics.  ``info_level="full"`` gives every key at
    every step.  ``env.unwrapped.info_level`` may be changed between steps (a bad value is a
    ValueError naming the levels).  At "lean" the step measures the residual imbalance
    (``balanced``, ``residual_imbalance_ratio``: two sin/cos per ball) only for the step that
    ends an episode.

    | Key | Meaning |
    |-----|---------|
    | reward_terms | dict vibration, time, effort, residual, failure (sum = reward) |
    | time | simulated time [s] |
    | rotor_speed | [rad/s] |
    | whirl_radius | sqrt(x^2 + y^2) [m] |
    | whirl_ratio | whirl radius / the episode's reference length (Yoshida's W_r / e) |
    | vibration_radius | distance of the rotor centre from its rest position [m] |
    | peak_whirl_radius | largest whirl radius so far [m] |
    | ball_angles | ball angles from the imbalance, unwrapped [rad] |
    | first_at_speed | time the band was first reached [s] (inf until then) |
    | run_up_time | start of the current stay in the band [s] (inf while out): at the end of a
      completed episode, the settled run-up time |
    | at_speed | the rotor is in the operating band |
    | time_at_speed | length of the current stay in the band [s] |
    | settled | the run-up completed (a stay of settle_time) |
    | residual_vibration | time-average vibration over the settling window so far [m] (inf
      before the window has begun) |
    | peak_vibration | largest vibration before the settled entry [m] |
    | peak_speed | largest rotor speed so far [rad/s] |
    | time_above_band | time spent above the band [s] (overspeed) |
    | balanced | residual imbalance within ``balance_tolerance`` of the best the balls can do |
    | residual_imbalance_ratio | abs(U0 + sum m_i (E e^{i gam} + R e^{i ph_i})) / U0 |
    | redistributions | redistributions of the laundry so far (0 without redistribution) |
    | failure | only on a failure: what happened |

    At reset, ``info`` also holds the episode's parameters (the table under Starting State, by
    their info keys), ``integration_step`` and ``static_deflection``;
    ``env.unwrapped.episode_scene`` is the episode as a Scene.

    ## Arguments

    ``scene`` (name, path or Scene; default "yoshida_odd"), ``preset`` (name in
    ``configs/envs``, path, dict or EnvConfig; default "train"), ``observe_balls`` (False),
    ``render_mode`` (None, "rgb_array", "human"), ``max_episode_steps`` (backstop, None),
    ``record_history`` (False: keep a per-interval history, :meth:`history`), ``info_level``
    ("lean" or "full", above), and any preset field as a keyword (``control_interval=0.02``,
    ``reward={"time": 2.0}``, ``sync_vibration={"enabled": True, "noise": 0.002}``,
    ``frame_stack=4``, ...).

    ## Bad input

    Actions outside [-1, 1] are clipped with a warning the first time.  Non-finite actions
    (NaN, inf) are rejected with a ``ValueError`` and the state is left unchanged.  An action
    must have exactly the action space's shape (no reshaping: a scalar, ``(1, 1, 1)`` or text
    raises ``ValueError`` naming the expected and the given shape).

    ``reset`` checks everything (seed: None or an int >= 0; every option) before it changes
    anything: a rejected reset raises ``ValueError`` naming the field and leaves the
    environment, its random generator included, as it was.  Angles (the imbalance phase and
    the ball angles) are reduced to [-pi, pi]: ``1e16`` gives the machine of
    ``math.remainder(1e16, 2 pi)``.  Under RK4, an episode whose ball drag or rolling
    resistance would force a step more than 100 x shorter than its rotation needs
    (``ball_drag_scale=1e6``: millions of steps per control interval) is refused with a
    ``ValueError`` that says what to use (``integrator="etdrk4"`` or smaller scales); a
    preset whose ``randomize`` ranges allow such episodes is refused when the environment is
    made (:mod:`abb_gym.envs.episodes`).
""")
COMMON_DOC = COMMON_DOC.replace("{observation_table}", observation.doc_table()).replace(
    "{episode_table}", episode_parameters.doc_table())
__doc__ += COMMON_DOC


#: the single environment's names for ``Buffers.first_row`` (views of its only row: action,
#: observation, output, status, state)
_ROW_VIEWS = ("_act_row", "_obs_row", "_out_row", "_st_row", "_s_row")

class BalancerEnv(SetupAccess, gym.Env):
    """Common implementation of every task; ``gym.make`` with a registered id, or a subclass
    that names its task."""

    metadata = SINGLE_METADATA
    #: the registered id this class makes (:mod:`abb_gym.envs.tasks`); ``task=`` overrides it
    task_id: str | None = None

    def __init__(self, scene: Any = None, preset: Any = None, *, task: str | None = None,
                 observe_balls: bool = False, render_mode: str | None = None,
                 max_episode_steps: int | None = None, record_history: bool = False,
                 info_level: str = "lean", **overrides: Any):
        info_level = check_display(render_mode, self.metadata["render_modes"], info_level)
        self.setup = EnvSetup(task or self.task_id, scene, preset, observe_balls,
                              max_episode_steps, overrides)
        self.info_level = info_level
        if self.setup.config.precision != "float64":
            raise ValueError(
                f"precision = {self.setup.config.precision!r} is for the vector environment "
                f"(gym.make_vec(..., vectorization_mode='vector_entry_point'), from 64 "
                f"sub-environments): it computes 8 sub-environments per instruction, and one "
                f"environment alone runs slower in float32 than in 'float64', the single "
                f"environment's only precision")
        self.observation_space = self.setup.observation_space
        self.action_space = self.setup.action_space
        self.render_mode = render_mode
        # one frame per control interval plays back in real time
        self.metadata = dict(self.metadata,
                             render_fps=max(1, round(1.0 / self.setup.control_interval)))
        check_flag(record_history, "record_history")
        self._bufs = Buffers(self.setup, 1, n_trace=1 if (render_mode or record_history) else 0)
        self._table = self._bufs.table
        self._step_fn = None  # the compiled step, fetched at the first step
        self._renderer: Renderer | None = None
        self._episode: Episode | None = None
        self._done = False
        self._warned_clip = False
        self._warned_done = False
        self.last_profile = None
        self._nq = 3 + self.setup.scene.ball_count
        self._dt = self.setup.control_interval
        # plain attributes, read at every step (a property would cost each read a call)
        self.__dict__.update(zip(_ROW_VIEWS, self._bufs.first_row))

    # ------------------------------------------------------------------ internals
    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        for key in ("_renderer", "_step_fn", *_ROW_VIEWS):
            state.pop(key, None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._renderer = None
        self._step_fn = None
        self.__dict__.update(zip(_ROW_VIEWS, self._bufs.first_row))  # (made again by Buffers)

    @property
    def episode_scene(self):
        """The current episode as a Scene (randomised imbalance, drag, rolling resistance)."""
        return None if self._episode is None else self._episode.scene

    @property
    def episode(self) -> Episode | None:
        """The current episode's parameters."""
        return self._episode

    @property
    def integration_step(self) -> float | None:
        """RK4 step bound of the current episode [s]."""
        return None if self._episode is None else self._episode.integration_step

    @property
    def observation_names(self) -> list[str]:
        """Names of the observation entries, in order (see the Observation Space table)."""
        return list(self.setup.obs_names)

    def history(self) -> dict[str, np.ndarray]:
        """The current episode's history (``record_history=True``; see
        :meth:`abb_gym.envs.setup.Buffers.history`): DwellProfile's one step holds the whole
        run-up."""
        return self._bufs.history(0)

    @property
    def state(self) -> np.ndarray:
        """Copy of the model state ``[x, y, th, ph_1..n, x', y', th', ph_1'..n']``."""
        return self._s_row.copy()

    # ------------------------------------------------------------------ API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        # everything is checked and computed before any state changes: a rejected reset
        # (bad seed, bad option, too stiff an episode) leaves the environment as it was
        seed = check_seed(seed)
        if seed is not None:
            rng, seed_value = seeding.np_random(seed)
        else:
            rng, seed_value = self.np_random, None
        pending = draw_safely(
            lambda: self.setup.prepare_rows(self._table, [0], [rng], [options]), [rng])
        if seed is not None:
            self._np_random, self._np_random_seed = rng, seed_value
        episodes.commit(self._bufs, self._table, pending)
        self._bufs.observe(np.zeros(1, dtype=np.int64))
        ep = self._episode = self._table.episode(0)
        self._done = False
        self.last_profile = None
        info = self._info(level="full")
        info.update(ep.as_info())
        if self.render_mode == "human":
            self.render()
        return self._obs_row.copy(), info

    def step(self, action):
        if self._episode is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        if self._done and not self._warned_done:
            logger.warn("step() called after the episode ended (terminated or truncated); "
                        "it returns the last observation with reward 0 - call reset()")
            self._warned_done = True
        a = checked_action(action, self.action_space.shape)
        extra = None
        if not self._done and self.setup.actions.works_before_step:
            a = a.astype(np.float64, copy=False)
            self._check_finite(a, action)
            clipped = np.clip(a, -1.0, 1.0)
            if np.any(clipped != a):
                self._warn_clipped(action)
            a = clipped
            extra = self.setup.actions.before_step(self.setup, self._bufs, 0, a,
                                                   float(self._table.imbalance_phase[0]))
            if extra:
                self.last_profile = extra.pop("profile", None)
        self._act_row[...] = a  # (in place, converted to float64; [:] cost 0.3 us more)
        bf = self._bufs
        step = self._step_fn
        if step is None:
            step = self._step_fn = bf.step_function()
        step(*bf.args)
        bf.push_frames()
        out = self._out_row
        flag = out[O_ACTFLAG]
        if flag == ACT_NONFINITE:
            self._check_finite(a, action)
        if flag == ACT_CLIPPED:
            self._warn_clipped(action)
        terminated = bool(out[O_TERM] != 0.0)
        truncated = bool(out[O_TRUNC] != 0.0)
        self._done = terminated or truncated
        info = self._info(done=self._done)
        if extra:
            info.update(extra)
        if self.render_mode == "human":
            self.render()
        return self._obs_row.copy(), float(out[O_REWARD]), terminated, truncated, info

    @staticmethod
    def _check_finite(a: np.ndarray, action) -> None:
        if not np.all(np.isfinite(a)):
            bad = int(np.argmax(~np.isfinite(a)))
            raise ValueError(f"action must be finite; entry {bad} of {action!r} is not (the "
                             f"step was not taken)")

    def _warn_clipped(self, action) -> None:
        if not self._warned_clip:
            logger.warn(f"action {action!r} outside [-1, 1] was clipped (warned once)")
            self._warned_clip = True

    def _info(self, level: str | None = None, done: bool = False) -> dict[str, Any]:
        # the episode's reference length lives in the table (it survives pickling with it)
        return step_info(self.setup, self._out_row, self._st_row, self._s_row,
                         float(self._table.reference_length[0]), level or self.info_level, done)

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; create the environment "
                            "with render_mode='rgb_array' or 'human'")
            return None
        if self._renderer is None:
            self._renderer = Renderer(self.setup.scene, self.setup.operating_speed,
                                      self.setup.episode_length, self.render_mode)
        bf = self._bufs
        if bf.trace.shape[0] == 0:
            bf.record_history(self.setup.max_steps + 1)
        k = int(self._st_row[S_K]) if self._episode is not None else 0
        return self._renderer.draw(self._s_row, bf.trace[0, :k + 1])

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
