"""Action models: what an action of each environment means, in one place per kind.

=========  =================================================================================
kind       action (``Box(-1, 1)``) and its drive
=========  =================================================================================
torque     motor torque ``a * drive_torque_limit``, held for the control interval: one
           ``MODE_MOTOR`` drive row per interval (``MotorDrive.constant_torque`` exactly)
speed      rotor acceleration ``a * drive_max_acceleration``, applied by a speed-loop drive
           whose speed stays in [0, w_op]: one ``MODE_PRESCRIBED`` row per interval
dwell      dwell start speed, length and acceleration of a whole run-up profile, decided
           once per episode: the profile's rows are written and the whole episode runs
=========  =================================================================================

Each kind is an :class:`ActionModel` (the Python side: sizes, bounds, episode length, the
rows at reset and before a step) plus its branch of the compiled :func:`write_interval_row`
and :func:`whole_episode`.  A new action type either adds both here, or is an
:class:`ActionModel` with ``kind_id = KIND_ROWS`` whose :meth:`~ActionModel.before_step`
writes each interval's drive rows from Python (no compiled change, at a few microseconds per
row and step), registered with :func:`register_action_model`; a task then names it
(:mod:`abb_gym.envs.tasks`).
"""
from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from .._numba import njit
from ..physics import drive_law as dl
from ..physics.drives import SpeedProfile
from .config import PresetError
from .layout import S_J, S_NSEG

__all__ = ["ActionModel", "ACTION_MODELS", "KIND_TORQUE", "KIND_SPEED", "KIND_DWELL",
           "KIND_ROWS", "write_interval_row", "whole_episode", "rows_from_python",
           "dwell_profile", "dwell_action", "action_model", "checked_action",
           "register_action_model"]

KIND_TORQUE = 0
KIND_SPEED = 1
KIND_DWELL = 2
# an action model whose Python side writes each control interval's drive rows
# (:meth:`ActionModel.before_step`): a new action semantic needs no compiled branch
KIND_ROWS = 3


# --------------------------------------------------------------------------- compiled side
@njit(cache=True, inline="always")
def whole_episode(kind):
    """True if one action decides the whole episode (the step runs it to its end)."""
    return kind == KIND_DWELL


@njit(cache=True, inline="always")
def rows_from_python(kind):
    """True if the Python side wrote the drive rows of the step (the compiled step keeps
    them)."""
    return kind == KIND_DWELL or kind == KIND_ROWS


@njit(cache=True, inline="always")
def write_interval_row(kind, d, a, t0, th, w, dt, operating_speed, max_acceleration,
                       torque_limit):
    """Write the drive row ``d`` of one control interval from the clipped action ``a`` at
    time ``t0`` [s], rotor angle ``th`` [rad] and speed ``w`` [rad/s]."""
    if kind == KIND_TORQUE:
        dl.write_motor_row(d, t0, a * torque_limit, torque_limit)
    else:
        # a speed loop with a speed limit: the interval ends exactly on the limit
        alpha = a * max_acceleration
        hi = (operating_speed - w) / dt
        lo = -w / dt
        if alpha > hi:
            alpha = hi
        if alpha < lo:
            alpha = lo
        dl.write_prescribed_row(d, t0, th, w, alpha)


# --------------------------------------------------------------------------- Python side
def checked_action(action: Any, shape: tuple[int, ...], what: str = "action") -> np.ndarray:
    """``action`` as an array of numbers of exactly ``shape``, in its own dtype (no
    reshaping, no broadcasting: a transposed batch would scramble the actions); anything else
    (another shape, a scalar for a vector, booleans, text, objects) raises a one-line
    ValueError naming the expected and the given shape or dtype.  (The single environment
    writes it into its float64 action row directly: converting first cost 0.8 us a step.)"""
    try:
        a = np.asarray(action)
    except (TypeError, ValueError):
        a = None
    if a is None or a.dtype.kind not in "fiu" or a.shape != shape:
        got = ("an unreadable value" if a is None else
               f"dtype {a.dtype} of shape {a.shape}" if a.dtype.kind not in "fiu"
               else f"shape {a.shape}")
        raise ValueError(f"{what} must be an array of numbers of shape {shape} in [-1, 1] "
                         f"(got {got}, {type(action).__name__})")
    return a


class ActionModel:
    """The Python side of one action kind (see the module docstring).  ``setup`` arguments are
    :class:`abb_gym.envs.setup.EnvSetup`, ``bufs`` :class:`~abb_gym.envs.setup.Buffers`, ``ep``
    :class:`~abb_gym.envs.episodes.Episode`."""

    name = ""
    kind_id = -1
    mode = dl.MODE_PRESCRIBED  # drive mode of the rows
    n_actions = 1
    n_rows = 1  # drive rows per environment

    def speed_bounds(self, config) -> tuple[float, float]:
        """Bounds of the observed rotor speed / w_op."""
        return 0.0, 1.0

    def max_speed(self, operating_speed: float, config) -> float:
        """Largest rotor speed [rad/s] an episode can reach (it sizes the integration step)."""
        return operating_speed

    #: :meth:`default_episode_length` in words (for messages)
    episode_length_rule = "2.5 operating_speed / drive_max_acceleration + settle_time"

    def default_episode_length(self, setup: Any) -> float:
        """Episode length [s] when the preset leaves it automatic."""
        return 2.5 * setup.reference_time + setup.config.settle_time

    def effort_bound(self, config) -> float:
        """Largest (command / limit)^2 the effort term can see."""
        return 1.0

    def overspeed_trip(self, config) -> float:
        """Speed / w_op beyond which the drive trips (terminated, failure penalty)."""
        return math.inf

    def check(self, setup: Any) -> None:
        """Raise PresetError if the preset does not suit this action type."""

    def reset_rows(self, d: np.ndarray, phase: np.ndarray, setup: Any) -> None:
        """Drive rows ``d`` (environments x rows x N_DRIVE, zeroed) at the start of episodes
        with rotor angles ``phase`` [rad] (each episode's imbalance phase; rotor at rest)."""
        d[..., dl.D_MODE] = self.mode
        if self.mode == dl.MODE_PRESCRIBED:
            d[..., dl.D_TH0] = np.asarray(phase)[:, None]
        else:
            d[..., dl.D_TLIM] = setup.torque_limit

    def before_step(self, setup: Any, bufs: Any, i: int, action: np.ndarray,
                    phase: float) -> dict[str, Any] | None:
        """Python-side work before the compiled step of row ``i`` (clipped ``action``, the
        episode's imbalance phase [rad]); returns extra info for that row, or None."""
        return None

    @functools.cached_property
    def works_before_step(self) -> bool:
        """True if this kind overrides :meth:`before_step` (the others skip the call)."""
        return type(self).before_step is not ActionModel.before_step

    @property
    def whole_episode_action(self) -> bool:
        """True if one action decides the whole episode (an episode is one step)."""
        return self.kind_id == KIND_DWELL


class TorqueAction(ActionModel):
    name = "torque"
    kind_id = KIND_TORQUE
    mode = dl.MODE_MOTOR

    def speed_bounds(self, config):
        return -config.overspeed, config.overspeed

    def max_speed(self, operating_speed, config):
        return operating_speed * config.overspeed

    def overspeed_trip(self, config):
        return config.overspeed


class SpeedAction(ActionModel):
    name = "speed"
    kind_id = KIND_SPEED


class DwellAction(ActionModel):
    name = "dwell"
    kind_id = KIND_DWELL
    n_actions = 3
    n_rows = 4  # ramp, dwell, ramp, hold

    episode_length_rule = ("(1 + dwell.time_range[1] max(0, 1 - dwell.accel_range[0])) "
                           "operating_speed / (dwell.runup_acceleration drive_max_acceleration)"
                           " + settle_time + 2 control_interval")

    def default_episode_length(self, setup):
        # the slowest profile: the longest dwell at the lowest dwell acceleration
        dw = setup.config.dwell
        slowest_dwell = dw.time_range[1] * setup.nominal_runup_time
        return (setup.nominal_runup_time + slowest_dwell * max(0.0, 1.0 - dw.accel_range[0])
                + setup.config.settle_time + 2.0 * setup.control_interval)

    def effort_bound(self, config):
        dw = config.dwell
        return max(1.0, (dw.runup_acceleration
                         * max(abs(dw.accel_range[0]), abs(dw.accel_range[1]))) ** 2)

    def check(self, setup):
        dw = setup.config.dwell
        wc = setup.scene.critical_speed
        if dw.speed_range[0] * wc > setup.operating_speed:
            raise PresetError(f"environment preset {setup.config.name!r}: field "
                              f"'dwell.speed_range' starts above operating_speed "
                              f"({dw.speed_range[0]:g} x the critical speed {wc:.4g} rad/s > "
                              f"{setup.operating_speed:.4g} rad/s)")

    def before_step(self, setup, bufs, i, action, phase):
        profile, params = dwell_profile(setup, action, phase)
        _, rows = profile.segment_table(setup.episode_length + setup.control_interval)
        d = bufs.d[i]
        d[:] = 0.0
        d[:len(rows)] = rows
        bufs.st[i, S_NSEG] = len(rows)
        bufs.st[i, S_J] = 0.0
        return {"profile": profile, "dwell": params}


ACTION_MODELS: dict[str, ActionModel] = {m.name: m for m in (TorqueAction(), SpeedAction(),
                                                             DwellAction())}


def register_action_model(model: ActionModel) -> ActionModel:
    """Add an action model by its name (a task names it: :mod:`abb_gym.envs.tasks`).  A model
    with ``kind_id = KIND_ROWS`` writes each interval's drive rows in :meth:`before_step`, so
    it needs no change of the compiled step."""
    if not model.name:
        raise ValueError("an action model needs a name")
    ACTION_MODELS[model.name] = model
    return model


def _lerp(rng, u: float) -> float:
    return rng[0] + 0.5 * (u + 1.0) * (rng[1] - rng[0])


def dwell_profile(setup: Any, action, phase: float = 0.0
                  ) -> tuple[SpeedProfile, dict[str, float]]:
    """The speed profile and physical parameters of a clipped DwellProfile action.

    Dwell start speed, duration and acceleration are mapped linearly from [-1, 1] to their
    ranges; the dwell is then shortened so that the speed stays in [0, w_op]."""
    dw = setup.config.dwell
    a = [float(v) for v in action]
    alpha = setup.dwell_acceleration
    wop = setup.operating_speed
    w_s = min(_lerp(dw.speed_range, a[0]) * setup.scene.critical_speed, wop)
    t_c = _lerp(dw.time_range, a[1]) * setup.nominal_runup_time
    a_c = _lerp(dw.accel_range, a[2]) * alpha
    if a_c < 0:
        t_c = min(t_c, w_s / -a_c)
    elif a_c > 0:
        t_c = min(t_c, (wop - w_s) / a_c)
    after = min(max(w_s + a_c * t_c, 0.0), wop)
    segs = ((w_s / alpha, alpha), (t_c, a_c), ((wop - after) / alpha, alpha))
    profile = SpeedProfile(segments=segs, initial_angle=phase)
    params = {"dwell_speed": w_s, "dwell_time": t_c, "dwell_acceleration": a_c,
              "runup_acceleration": alpha, "dwell_start_time": w_s / alpha}
    return profile, params


def dwell_action(setup: Any, profile: SpeedProfile) -> np.ndarray:
    """The DwellProfile action that encodes ``profile``'s dwell (inverse of
    :func:`dwell_profile`).  The profile must be ramp - dwell - ramp at the environment's
    run-up acceleration; other shapes raise ValueError."""
    dw = setup.config.dwell
    segs = profile.segments
    alpha = setup.dwell_acceleration
    if len(segs) < 2 or abs(segs[0][1] - alpha) > 1e-9 * alpha:
        raise ValueError("a DwellProfile action needs a ramp at the environment's run-up "
                         f"acceleration {alpha:g} rad/s^2 followed by a dwell")
    w_s = segs[0][0] * alpha
    t_c, a_c = segs[1]

    def unlerp(rng, v):
        return 2.0 * (v - rng[0]) / (rng[1] - rng[0]) - 1.0

    a = np.array([unlerp(dw.speed_range, w_s / setup.scene.critical_speed),
                  unlerp(dw.time_range, t_c / setup.nominal_runup_time),
                  unlerp(dw.accel_range, a_c / alpha)])
    action = np.clip(a, -1.0, 1.0).astype(np.float32)
    # the round trip must give the profile back: anything else (more knots, another final
    # ramp, a dwell outside the action ranges) is not a DwellProfile action
    encoded = dwell_profile(setup, action, profile.initial_angle)[0]
    if not _same_speeds(encoded, profile, setup.operating_speed):
        raise ValueError("the profile is not ramp - dwell - ramp to the operating speed at the "
                         f"environment's run-up acceleration {alpha:g} rad/s^2 within the "
                         "preset's dwell ranges, so no DwellProfile action encodes it")
    return action


def _same_speeds(p: SpeedProfile, q: SpeedProfile, operating_speed: float) -> bool:
    """Whether two profiles reach the same speeds at every breakpoint of either (to 1e-3 of
    the operating speed: the action is float32)."""
    knots = np.concatenate([p.breakpoints, q.breakpoints])
    times = np.unique(np.concatenate([knots, [knots.max() + 1.0]]))
    return bool(np.all(np.abs(p.speed(times) - q.speed(times)) <= 1e-3 * operating_speed))


def action_model(kind: str) -> ActionModel:
    """The action model of ``kind`` (``torque``, ``speed`` or ``dwell``)."""
    if kind not in ACTION_MODELS:
        raise ValueError(f"kind must be one of {list(ACTION_MODELS)} (got {kind!r})")
    return ACTION_MODELS[kind]
