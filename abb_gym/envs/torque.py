"""``abb_gym/RunUpTorque-v0``: run the balancer up by commanding the motor torque.

## Description

The rotor spin is a degree of freedom (Spannan eq. 4.16): every control interval the agent
sets the motor torque, and the rotor, the support and the balls respond through the full
coupled model, including the balls' reaction on the rotor.  Near the critical speed the whirl
absorbs drive power (the Sommerfeld effect), so a weak or hesitant torque can leave the rotor
stuck at resonance; the agent must bring it through the critical speed, reach the operating
speed and hold it there while the balls settle.

## Action Space

``Box(-1, 1, (1,), float32)``.

| Index | Action | Scaling |
|-------|--------|---------|
| 0 | motor torque | a * drive_torque_limit [N m], held for the control interval |

The drive row is ``MODE_MOTOR`` with speed gain 0 and torque ``a * drive_torque_limit``
(exactly ``MotorDrive.constant_torque`` over the interval).  The scene's bearing drag acts in
addition.  The rotor may turn backwards; ``|w| > overspeed * w_op`` trips the drive
(terminated, failure penalty).  RK4 steps are sized for ``overspeed * w_op``.

## Episode length

Default ``episode_length = 2.5 w_op / drive_max_acceleration + settle_time`` (7.5 s + 1 s on
``yoshida_odd``).
"""
from __future__ import annotations

from .base import COMMON_DOC, BalancerEnv
from .learning import START_TO_LEARN_DOC
from .tasks import RUN_UP_TORQUE

__doc__ += START_TO_LEARN_DOC

__all__ = ["RunUpTorqueEnv"]


class RunUpTorqueEnv(BalancerEnv):
    task_id = RUN_UP_TORQUE.env_id


RunUpTorqueEnv.__doc__ = __doc__ + COMMON_DOC
