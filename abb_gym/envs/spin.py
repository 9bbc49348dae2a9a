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

## Observation

What a washer's drive measures (the Observation Space table below): the drum speed, the
housing's vibration and its filtered amplitude, the synchronous (1x) vibration's amplitude and
phase against the drum's reference mark (``sync_vibration``, on in the ``laundry`` presets:
lag 0.5 s, read-out noise 0.002 A_v), the time fraction, the last action and the number of
redistributions so far (over ``redistribution.max_count``).  Not the load: at the
distribution speed (90-100 rpm, below the tub's modes) the vibration grows with the load, but
the balls, which drift towards the heavy side below resonance, add to it, so it is a noisy
sign of a load the balls cannot cancel.

## Rewards

The terms of the Rewards table, with the ``laundry`` preset's weights and unit
(``reward.length_scale`` = 1 mm):

| Term | Weight | Meaning here |
|------|--------|--------------|
| residual | 6 per mm | the orbit at spin over the settling window (10 s) |
| time | 1 per T_ref = 25.1 s | every interval spent off spin |
| failure | 10 + the bound of the rest | a cabinet hit (the whirl beyond the housing clearance) |
| vibration, effort | 0 | - |

A retry from spin (down to a tumble, the tumble time, back up: about 44 s off spin) costs
44 / 25.1 = 1.75, about what a 0.3 mm residual costs (6 x 0.3 = 1.8).  A load beyond the
balancer's effective capacity ``C_eff`` (:func:`abb_gym.physics.laundry.effective_capacity`)
leaves a residual ``(U - C_eff)``, its steady orbit at spin, whatever the profile: the
open-loop floor.

## Episode End

As RunUpSpeed's: success after ``settle_time`` (10 s) at spin, failure at a cabinet hit, and
truncation after ``episode_length`` (300 s).  Leaving the band before the settling window
completes (to redistribute) starts the window again.

## Presets

``laundry`` (training) and ``laundry_test`` (held out), ``configs/envs/``; the task fixes
``redistribution.enabled``.  Scenes: ``washer`` (the default) and ``washer_reduced`` (four
heavier balls of the same capacity, three times cheaper: the training scene).
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
