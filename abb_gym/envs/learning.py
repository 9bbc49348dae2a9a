"""What an RL user needs to know before training on a run-up task: a one-time warning.

The RunUp* tasks start the rotor at rest, and their action 0 holds it there: a zero
acceleration (RunUpSpeed) or a zero torque (RunUpTorque).  A policy whose actions start
around 0, as SB3's ``MlpPolicy`` does (mean 0, and a mean that may run past the [-1, 1] box
where the environment clips every sample alike), drifts around rest, never meets the
operating speed and learns to stay there: the vibration at the critical speed is a cost it
sees long before the terminal penalty.  Measured on ``abb_gym/RunUpSpeed-v0`` at the
registered defaults (``yoshida_odd``, preset ``train``), SB3 PPO with its defaults and 4
environments through ``make_vec_env``, seed 0, deterministic evaluation on 16 machines of
the ``train`` preset (seeds 1000-1015):

=============================================  ========  ==========  ==============
policy                                         steps     return      at speed
=============================================  ========  ==========  ==============
``MlpPolicy``, control interval 0.01 s         20 000    -198.3      0 of 16
``MlpPolicy``, control interval 0.01 s         100 000   -198.3      0 of 16
``MlpPolicy``, control interval 0.05 s         20 000    -198.3      0 of 16
``MlpPolicy``, control interval 0.05 s         100 000   -198.3      0 of 16
``BoundedMlpPolicy``, 0.5, 0.01 s              0         -4.3        16 of 16
``BoundedMlpPolicy``, 0.5, 0.01 s              20 000    -4.3        16 of 16
``BoundedMlpPolicy``, 0.5, 0.05 s              20 000    -4.2        16 of 16
=============================================  ========  ==========  ==============

So what learns is the start of the policy, not the control interval: every shipped config
uses :class:`abb_gym.rl.networks.BoundedMlpPolicy` (the Gaussian mean inside the action box)
with ``action_mean_init`` 0.5 (0.3 for the torque), whose first actions run Yoshida's
40 rad/s^2 ramp up to the operating speed, and a 0.05 s control interval (5x fewer decisions
per episode; not what makes it learn).  The registered defaults stay as they are: changing
the action's meaning (0 = the nominal ramp) or the ``train`` preset's control interval would
change every seeded trajectory, the tuned baselines and the shipped agents' environments, and
the second would not help.

Instead ``gym.make`` and ``gym.make_vec`` of a RunUp* id warn once per process
(:class:`LearningDefaultsWarning`) when called from a user's code, or from a library such as
SB3's ``make_vec_env`` (so is :func:`abb_gym.rl.make_sb3_env`): abb-gym's own tools, which
know, make their environments silently.  ``warnings.filterwarnings("ignore",
category=LearningDefaultsWarning)`` silences it.
"""
from __future__ import annotations

import sys
import warnings

from .tasks import RUN_UP_SPEED, RUN_UP_TORQUE, Task

#: the section of the RunUp* ids' docstrings (their documentation pages) that says so
START_TO_LEARN_DOC = '''
## How a policy must start to learn

Action 0 holds the rotor at rest.  A policy whose actions start around 0 (SB3's
``MlpPolicy``) never meets the operating speed and learns to stay there: plain PPO at the
registered defaults scored -198.3 with 0 of 16 machines at speed after 100 000 steps, at a
0.01 s and at a 0.05 s control interval alike (:mod:`abb_gym.envs.learning`).  Start the
policy on a run-up: :class:`abb_gym.rl.networks.BoundedMlpPolicy` with ``action_mean_init``
0.5 (0.3 for the torque), as every shipped config does.  ``gym.make`` warns once.
'''

__all__ = ["LearningDefaultsWarning", "advise", "ADVICE"]


class LearningDefaultsWarning(UserWarning):
    """A run-up task was made for a user: how a policy must start to learn it."""


#: env id -> the policy start every shipped config of it uses
ADVICE = {RUN_UP_SPEED.env_id: 0.5, RUN_UP_TORQUE.env_id: 0.3}
#: modules between gym.make and the code that asked for the environment
TRANSPARENT = ("gymnasium", "abb_gym.envs", "abb_gym.rl.env_factory", "abb_gym.rl.vec_env")
_advised: set[str] = set()


def _asker() -> tuple[int, str]:
    """(stack level from :func:`advise`'s caller, module) of the first frame that is neither
    gymnasium nor the making of the environment: who asked for it."""
    frame, level = sys._getframe(2), 2
    while frame is not None:
        module = frame.f_globals.get("__name__", "")
        if not module.startswith(TRANSPARENT):
            return level, module
        frame, level = frame.f_back, level + 1
    return level, ""


def advise(task: Task) -> None:
    """Warn once per process and id, when a user's code makes ``task`` (module docstring)."""
    init = ADVICE.get(task.env_id)
    if init is None or task.env_id in _advised:
        return
    level, module = _asker()
    if module.startswith("abb_gym") or module == "":
        return  # abb-gym's own tools
    _advised.add(task.env_id)
    warnings.warn(
        f"{task.env_id}: the rotor starts at rest and action 0 holds it there, so a policy "
        f"that starts with mean action 0 (SB3's MlpPolicy) never reaches the operating speed "
        f"and learns to stay at rest (plain PPO: return -198, never at speed, after 20k and "
        f"100k steps, at control intervals of 0.01 and 0.05 s alike).  Start it from a run-up: "
        f"policy abb_gym.rl.networks.BoundedMlpPolicy with policy_kwargs "
        f"action_mean_init={init} (every shipped config, with control_interval=0.05; see "
        f"abb_gym.envs.learning).  Silence: warnings.filterwarnings('ignore', "
        f"category=abb_gym.envs.learning.LearningDefaultsWarning)",
        LearningDefaultsWarning, stacklevel=level)
