"""``abb_gym/RunUpSpeed-v0``: draw the run-up speed profile step by step.

## Description

The rotor angle is prescribed (a drive with a stiff speed loop, infinite drive inertia, as in
Yoshida 2014): every control interval the agent sets the rotor acceleration, and the support
and the balls respond.  The agent draws the speed profile an interval at a time: how fast to
cross the critical speed, whether to dwell near it so the balls can move to the balancing
position, and when to reach the operating speed.

## Action Space

``Box(-1, 1, (1,), float32)``.

| Index | Action | Scaling |
|-------|--------|---------|
| 0 | rotor acceleration | a * drive_max_acceleration [rad/s^2], constant over the interval |

Speed limits: the speed is kept in [0, w_op].  The applied acceleration over an interval dt
starting at speed w is ``clip(a * alpha_max, -w / dt, (w_op - w) / dt)``, so that the speed at
the end of the interval lands exactly on the limit instead of crossing it (a speed-loop drive
with a speed limit).  Each interval is one ``MODE_PRESCRIBED`` drive row (start time, angle,
speed, acceleration), so driving the environment with the accelerations of a
``SpeedProfile`` whose breakpoints fall on control instants reproduces
``simulate(scene, profile)`` to rounding.  The effort term uses the applied acceleration.

## Episode length

Default ``episode_length = 2.5 w_op / drive_max_acceleration + settle_time`` (7.5 s + 1 s on
``yoshida_odd``: the thesis run-up at 40 rad/s^2 takes 6 s).
"""
from __future__ import annotations

from .base import COMMON_DOC, BalancerEnv
from .learning import START_TO_LEARN_DOC
from .tasks import RUN_UP_SPEED

__doc__ += START_TO_LEARN_DOC

__all__ = ["RunUpSpeedEnv"]


class RunUpSpeedEnv(BalancerEnv):
    task_id = RUN_UP_SPEED.env_id


RunUpSpeedEnv.__doc__ = __doc__ + COMMON_DOC
