"""Policy networks for the balancer agents.

``BoundedMlpPolicy`` is SB3's ``MlpPolicy`` (``ActorCriticPolicy``) with the Gaussian mean
passed through ``tanh``, so the mean stays inside the [-1, 1] action box.
``BoundedMlpLstmPolicy`` is the same bound on sb3-contrib's ``MlpLstmPolicy``
(``RecurrentActorCriticPolicy``, trained by ``RecurrentPPO``): a policy with memory, the
alternative to the frame stack (needs sb3-contrib).  ``StartedSACPolicy`` and
``StartedTQCPolicy`` are SAC's and TQC's own ``MlpPolicy`` (already squashed by ``tanh``) with
an initial action mean ``action_mean_init``, for the same reason as below.

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

from .algorithms import import_class

__all__ = ["BoundedMlpPolicy", "BoundedMlpLstmPolicy", "StartedSACPolicy", "StartedTQCPolicy",
           "POLICIES", "policy_class"]


class _MeanInit:
    """``action_mean_init``: a number or a sequence (one per action entry), each in (-1, 1),
    checked when the policy is made and stored with it."""

    def __init__(self, *args, action_mean_init: float | list[float] = 0.0, **kwargs):
        values = (list(action_mean_init) if isinstance(action_mean_init, (list, tuple))
                  else [action_mean_init])
        for v in values:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not -1.0 < v < 1.0:
                raise ValueError(f"policy_kwargs.action_mean_init must be in (-1, 1) (got "
                                 f"{action_mean_init!r})")
        self.action_mean_init = action_mean_init
        super().__init__(*args, **kwargs)

    def _mean_bias(self, n: int) -> torch.Tensor:
        """``atanh`` of the initial mean, one per action entry (a tanh turns it back)."""
        init = self.action_mean_init
        values = list(init) if isinstance(init, (list, tuple)) else [init] * n
        if len(values) != n:
            raise ValueError(f"policy_kwargs.action_mean_init must have {n} entries (got "
                             f"{init!r})")
        return torch.tensor([math.atanh(float(v)) for v in values])

    def _get_constructor_parameters(self) -> dict:
        data = super()._get_constructor_parameters()
        data["action_mean_init"] = self.action_mean_init
        return data


class _BoundedMean(_MeanInit):
    """The ``tanh`` bound on the action mean and its initial value, for any SB3 actor-critic
    policy whose ``_build`` creates ``action_net`` (see the module docstring)."""

    def _build(self, lr_schedule) -> None:
        super()._build(lr_schedule)
        with torch.no_grad():
            self.action_net.bias.copy_(self._mean_bias(self.action_net.out_features))
        # Tanh has no parameters: the optimizer built by super() already holds every one.
        self.action_net = nn.Sequential(self.action_net, nn.Tanh())


class _StartedActor(_MeanInit):
    """The initial action of an off-policy squashed-Gaussian actor (SAC, TQC): their actions
    are already ``tanh`` of the Gaussian, whose mean starts at 0, i.e. at zero acceleration,
    where a run-up never starts.  Here the mean layer starts with its weights shrunk 100x
    and the bias ``atanh(action_mean_init)``, as BoundedMlpPolicy does for PPO."""

    def make_actor(self, features_extractor=None):
        actor = super().make_actor(features_extractor)
        with torch.no_grad():
            actor.mu.weight.mul_(0.01)
            actor.mu.bias.copy_(self._mean_bias(actor.mu.out_features))
        return actor


class BoundedMlpPolicy(_BoundedMean, ActorCriticPolicy):
    """``MlpPolicy`` with a ``tanh``-bounded action mean (see the module docstring)."""


def _started_sac_class() -> type:
    from stable_baselines3.sac.policies import SACPolicy

    class StartedSACPolicy(_StartedActor, SACPolicy):
        """SAC's ``MlpPolicy`` with ``action_mean_init`` (see :class:`_StartedActor`)."""

    return _named(StartedSACPolicy)


def _started_tqc_class() -> type:
    TQCPolicy = import_class("sb3_contrib.tqc.policies", "TQCPolicy", "TQC")

    class StartedTQCPolicy(_StartedActor, TQCPolicy):
        """TQC's ``MlpPolicy`` with ``action_mean_init`` (see :class:`_StartedActor`)."""

    return _named(StartedTQCPolicy)


def _named(cls: type) -> type:
    # importable by name, as pickles (SB3's model.zip) and rl_zoo3 refer to it
    cls.__module__ = __name__
    cls.__qualname__ = cls.__name__
    return cls


def _recurrent_class() -> type:
    RecurrentActorCriticPolicy = import_class("sb3_contrib.common.recurrent.policies",
                                              "RecurrentActorCriticPolicy",
                                              "the recurrent policy (RecurrentPPO)")

    class BoundedMlpLstmPolicy(_BoundedMean, RecurrentActorCriticPolicy):
        """sb3-contrib's ``MlpLstmPolicy`` with a ``tanh``-bounded action mean (see the
        module docstring)."""

    return _named(BoundedMlpLstmPolicy)


_LAZY = {"BoundedMlpLstmPolicy": _recurrent_class, "StartedSACPolicy": _started_sac_class,
         "StartedTQCPolicy": _started_tqc_class}


def __getattr__(name: str):
    # built on first use: sb3-contrib is imported only when one of its policies is asked for
    if name in _LAZY:
        cls = _LAZY[name]()
        globals()[name] = cls
        return cls
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: import path of each policy class abb-gym builds (SB3's own names map to themselves)
POLICIES = {"MlpPolicy": "MlpPolicy", "MlpLstmPolicy": "MlpLstmPolicy",
            "abb_gym.rl.networks.BoundedMlpPolicy": "BoundedMlpPolicy",
            "abb_gym.rl.networks.BoundedMlpLstmPolicy": "BoundedMlpLstmPolicy",
            "abb_gym.rl.networks.StartedSACPolicy": "StartedSACPolicy",
            "abb_gym.rl.networks.StartedTQCPolicy": "StartedTQCPolicy"}


def policy_class(name: str):
    """What to pass to the algorithm for the policy ``name`` (a key of :data:`POLICIES`): SB3's
    alias string, or the class."""
    target = POLICIES[name]
    if name == target:
        return target
    return globals()[target] if target in globals() else __getattr__(target)
