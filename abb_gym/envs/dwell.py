"""``abb_gym/DwellProfile-v0``: choose the dwell of a run-up profile, then watch the whole run.

## Description

The hand-designed baseline of Yoshida (2014) as a one-step decision problem (a contextual
bandit): the agent picks the three parameters of a "variable-speed period" (dwell), and the
episode simulates the complete run-up with that profile - ramp, dwell near the critical speed,
ramp to the operating speed, settling window - and returns its score.  It is the bridge
between the dwell-profile baseline and the step-by-step RunUpSpeed environment: the return is
exactly what RunUpSpeed would pay, interval by interval, for the same profile (the profile's
breakpoints are integrated exactly, not rounded to control instants).

## Action Space

``Box(-1, 1, (3,), float32)``; each entry is mapped linearly from [-1, 1] to its range
(``lerp([lo, hi], a) = lo + (a + 1) (hi - lo) / 2``, ranges from the preset's ``dwell:``
section).  ``alpha_run = dwell.runup_acceleration * drive_max_acceleration`` and
``T_run = w_op / alpha_run``.

| Index | Action | Scaling (default ranges) |
|-------|--------|--------------------------|
| 0 | dwell start speed w_s | lerp(speed_range, a0) * critical speed, <= w_op ([0.5, 1.5]) |
| 1 | dwell duration t_c | lerp(time_range, a1) * T_run ([0, 0.25]) |
| 2 | acceleration during the dwell a_c | lerp(accel_range, a2) * alpha_run ([-1, 1]) |

The profile is ``SpeedProfile`` segments: ``(w_s / alpha_run, alpha_run)``, ``(t_c, a_c)``,
``((w_op - w_end) / alpha_run, alpha_run)``, then the hold at w_op.  The dwell is shortened
so that the speed stays in [0, w_op] (``t_c <= w_s / -a_c`` for a deceleration,
``t_c <= (w_op - w_s) / a_c`` for an acceleration).  On ``yoshida_odd`` alpha_run = 40
rad/s^2, the thesis's run-up; its reference dwell (100 rad/s for 0.5 s at constant speed) is
the action ``[0, -1/3, 0]``.  ``env.unwrapped.last_profile`` holds the profile of the last
step and ``info["dwell"]`` its physical parameters, so ``simulate(env.unwrapped.episode_scene,
env.unwrapped.last_profile, ...)`` replays it.

## Episode length

One step.  The simulated time is the run-up plus the settling window; the default
``episode_length`` (``T_run + t_c,max (1 - accel_range[0]) + settle_time + 2 dt``) covers the
slowest profile the action ranges allow, so every episode ends terminated (success or
failure).  The observation returned by ``reset`` carries no information about the machine
beyond the ball angles (with ``observe_balls=True``): the decision is taken before the run.
The registered ``max_episode_steps`` is 2, a backstop that never cuts an episode (a limit of 1
would make gymnasium's TimeLimit report every episode as truncated).
"""
from __future__ import annotations

from .base import COMMON_DOC, BalancerEnv
from .tasks import DWELL_PROFILE

__all__ = ["DwellProfileEnv"]


class DwellProfileEnv(BalancerEnv):
    task_id = DWELL_PROFILE.env_id


DwellProfileEnv.__doc__ = __doc__ + COMMON_DOC
