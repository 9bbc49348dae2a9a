"""``abb_gym/SpinRedistribute-v0``: spin a washing machine whose laundry can be redistributed.

## Description

A front-loading washer (scene ``washer``: horizontal axis, a 12-ball oil balancer) must reach
its spin speed with as little vibration as it can.  The laundry's imbalance is random and can
exceed what the ball ring cancels; then the balls clump opposite it and no speed profile helps
(:mod:`abb_gym.envs.redistribution`).  But below the tumble speed the laundry tumbles and
lands anew: a drum that stays slow for the tumble time redistributes it, a new imbalance of
new size and phase (:mod:`abb_gym.physics.laundry`).  The drive sees the load only through
the vibration: the housing's motion, its synchronous (1x) amplitude and phase, at the
distribution speed, during the ramp and at spin.  The agent decides when to run up, and
whether to drop back and redistribute a load that is too large, trading the residual orbit
at spin against the time a retry costs.  This is the task where feedback pays: the right
decision depends on a load the drive can only sense during the episode.

## Action Space

As RunUpSpeed (:mod:`abb_gym.envs.speed`): ``Box(-1, 1, (1,), float32)``, the rotor
acceleration ``a * drive_max_acceleration`` [rad/s^2] over the control interval, the speed
kept in [0, w_op].

## Presets

``laundry`` (training) and ``laundry_test`` (held out), ``configs/envs/``; the task fixes
``redistribution.enabled``.  The reward measures the vibration in millimetres
(``reward.length_scale: 1e-3``).
"""
from __future__ import annotations

from .base import COMMON_DOC, BalancerEnv
from .tasks import SPIN_REDISTRIBUTE
from .vector import BalancerVectorEnv

__all__ = ["SpinRedistributeEnv", "SpinRedistributeVectorEnv"]


class SpinRedistributeEnv(BalancerEnv):
    task_id = SPIN_REDISTRIBUTE.env_id


class SpinRedistributeVectorEnv(BalancerVectorEnv):
    """Vector version of SpinRedistribute (see :mod:`abb_gym.envs.spin`)."""

    task_id = SPIN_REDISTRIBUTE.env_id


SpinRedistributeEnv.__doc__ = __doc__ + COMMON_DOC
