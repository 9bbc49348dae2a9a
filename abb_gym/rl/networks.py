"""Policy networks for the balancer agents.

``BoundedMlpPolicy`` is SB3's ``MlpPolicy`` (``ActorCriticPolicy``) with the Gaussian mean
passed through ``tanh``, so the mean stays inside the [-1, 1] action box.
``BoundedMlpLstmPolicy`` is the same bound on sb3-contrib's ``MlpLstmPolicy``
(``RecurrentActorCriticPolicy``, trained by ``RecurrentPPO``): a policy with memory, the
alternative to the frame stack (:func:`recurrent_policy_class`; needs sb3-contrib).

Why: the environments clip actions to [-1, 1], and SB3's PPO computes the log-probability of
the *unclipped* sample.  With a plain linear mean, a phase where "always the largest action"
pays (e.g. RunUpSpeed before the agent has learned to reach the operating speed at all)
pushes the mean far beyond 1; afterwards every sample is clipped to the same action, the
advantages no longer depend on the action, and the policy cannot learn to hold back any more
(observed: the agent froze on the maximum-acceleration ramp).  With a bounded mean, the
exploration noise always changes the applied action.  The noise (``log_std``) is unchanged;
samples are still clipped by the environment.

``action_mean_init`` (policy_kwargs; a number or one per action entry, in (-1, 1)) sets the
initial action mean: the output layer starts with near-zero weights (SB3's gain 0.01) and the
bias ``atanh(action_mean_init)``.  On RunUpSpeed, 0.5 starts from Yoshida's 40 rad/s^2 ramp
on yoshida_odd, an episode that reaches the operating speed; from the default 0 the random
walk of the speed almost never reaches it, and the agent learns to stay at rest (it avoids
the vibration at the critical speed and the terminal penalty is too far away).
"""
from __future__ import annotations

import math

from stable_baselines3.common.policies import ActorCriticPolicy
import torch
from torch import nn

__all__ = ["BoundedMlpPolicy", "BoundedMlpLstmPolicy", "POLICIES", "policy_class"]


class _BoundedMean:
    """The ``tanh`` bound on the action mean and its initial value, for any SB3 actor-critic
    policy whose ``_build`` creates ``action_net`` (see the module docstring).

    :param action_mean_init: initial action mean, a number or a sequence (one per action
        entry), each in (-1, 1); default 0.
    """

    def __init__(self, *args, action_mean_init: float | list[float] = 0.0, **kwargs):
        values = (list(action_mean_init) if isinstance(action_mean_init, (list, tuple))
                  else [action_mean_init])
        for v in values:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not -1.0 < v < 1.0:
                raise ValueError(f"policy_kwargs.action_mean_init must be in (-1, 1) (got "
                                 f"{action_mean_init!r})")
        self.action_mean_init = action_mean_init
        super().__init__(*args, **kwargs)

    def _build(self, lr_schedule) -> None:
        super()._build(lr_schedule)
        init = self.action_mean_init
        n = self.action_net.out_features
        values = list(init) if isinstance(init, (list, tuple)) else [init] * n
        if len(values) != n:
            raise ValueError(f"policy_kwargs.action_mean_init must have {n} entries (got "
                             f"{init!r})")
        with torch.no_grad():
            self.action_net.bias.copy_(torch.tensor([math.atanh(float(v)) for v in values]))
        # Tanh has no parameters: the optimizer built by super() already holds every one.
        self.action_net = nn.Sequential(self.action_net, nn.Tanh())

    def _get_constructor_parameters(self) -> dict:
        data = super()._get_constructor_parameters()
        data["action_mean_init"] = self.action_mean_init
        return data


class BoundedMlpPolicy(_BoundedMean, ActorCriticPolicy):
    """``MlpPolicy`` with a ``tanh``-bounded action mean (see the module docstring)."""


def _recurrent_class() -> type:
    try:
        from sb3_contrib.common.recurrent.policies import RecurrentActorCriticPolicy
    except ImportError as exc:
        raise ImportError(f"the recurrent policies (RecurrentPPO) need sb3-contrib: pip install "
                          f"-c constraints.txt 'abb-gym[train]' ({exc})") from exc

    class BoundedMlpLstmPolicy(_BoundedMean, RecurrentActorCriticPolicy):
        """sb3-contrib's ``MlpLstmPolicy`` with a ``tanh``-bounded action mean (see the
        module docstring)."""

    # importable by name, as pickles (SB3's model.zip) and rl_zoo3 refer to it
    BoundedMlpLstmPolicy.__module__ = __name__
    BoundedMlpLstmPolicy.__qualname__ = "BoundedMlpLstmPolicy"
    return BoundedMlpLstmPolicy


def __getattr__(name: str):
    # sb3-contrib is imported only when the recurrent policy is asked for
    if name == "BoundedMlpLstmPolicy":
        cls = _recurrent_class()
        globals()[name] = cls
        return cls
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: import path of each policy class abb-gym builds (SB3's own names map to themselves)
POLICIES = {"MlpPolicy": "MlpPolicy", "MlpLstmPolicy": "MlpLstmPolicy",
            "abb_gym.rl.networks.BoundedMlpPolicy": "BoundedMlpPolicy",
            "abb_gym.rl.networks.BoundedMlpLstmPolicy": "BoundedMlpLstmPolicy"}


def policy_class(name: str):
    """What to pass to the algorithm for the policy ``name`` (a key of :data:`POLICIES`): SB3's
    alias string, or the class."""
    target = POLICIES[name]
    if name == target:
        return target
    return globals()[target] if target in globals() else __getattr__(target)
