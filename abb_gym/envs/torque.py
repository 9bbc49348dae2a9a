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

## How a policy must start to learn

Action 0 holds the rotor at rest.  A policy whose actions start around 0 (SB3's
``MlpPolicy``) never meets the operating speed and learns to stay there: plain PPO at the
registered defaults scored -198.3 with 0 of 16 machines at speed after 100 000 steps, at a
0.01 s and at a 0.05 s control interval alike (:mod:`abb_gym.envs.learning`).  Start the
policy on a run-up: :class:`abb_gym.rl.networks.BoundedMlpPolicy` with ``action_mean_init``
0.5 (0.3 for the torque), as every shipped config does.  ``gym.make`` warns once.
"""
from __future__ import annotations

from .base import COMMON_DOC, BalancerEnv
from .tasks import RUN_UP_TORQUE

__all__ = ["RunUpTorqueEnv"]


class RunUpTorqueEnv(BalancerEnv):
    task_id = RUN_UP_TORQUE.env_id


RunUpTorqueEnv.__doc__ = __doc__ + COMMON_DOC
