"""Potential-based reward shaping for training: a denser reward that leaves the task unchanged.

The balancer's largest reward term, the residual vibration, is paid once at the end of a
run-up, seconds after the decisions that decided it.  Shaping adds, per decision,

    F = gamma * Phi(o') - Phi(o),        Phi(o) = -weight * o[observation]
                                    or  Phi(o) = -weight * |o[observation] - target|

with ``o[observation]`` one entry of the observation the policy sees (e.g. ``sync_amplitude``,
the measured synchronous vibration: what a drive reads).  A drop of the vibration pays at
once.  With a ``target`` the potential is the distance from it, e.g. ``rotor_speed`` with
target 1 on RunUpTorque, where the agent must hold the operating speed in the 0.2 % band
itself and the terminal terms alone say only, seconds later, that it never settled.  Why this form (Ng, Harada & Russell 1999, "Policy invariance under reward
transformations"): along any episode the shaping terms telescope to ``gamma^T Phi(o_T) -
Phi(o_0)``, and with ``Phi = 0`` after a true end the sum is ``-Phi(o_0)``, the same for every
policy from the same start.  So every policy's discounted return changes by the same
amount, the ranking of policies (and the optimum) is that of the unshaped task, and the
metrics (run-up time, residual vibration) are those of the environment, which never sees the
shaping.  At a time-limit truncation that PPO bootstraps (``TimeLimit.truncated``), the
episode is treated as going on: ``F = gamma * Phi(o_T) - Phi(o_{T-1})`` with the terminal
observation.

Only training sees it: the wrapper sits between ``VecMonitor`` (which logs the unshaped
episode returns) and ``VecNormalize``; the held-out evaluations use the plain environment.
Config: ``_abb_gym: {shaping: {observation: sync_amplitude, weight: 10.0}}`` or
``{observation: rotor_speed, weight: 50.0, target: 1.0}``
(:class:`ShapingSettings`; :mod:`abb_gym.rl.config`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..configuration import build_section, declare

__all__ = ["ShapingSettings", "shaping_settings", "PotentialShaping", "potential_index"]


@dataclass(frozen=True)
class ShapingSettings:
    """Settings of :class:`PotentialShaping` (the ``_abb_gym.shaping`` mapping)."""

    observation: str = declare(kind="text", doc="observation entry whose value sets the "
                                                "potential (the current frame's, e.g. "
                                                "sync_amplitude)")
    weight: float = declare(1.0, ge=0.0, le=1e6, doc="Phi = -weight x that entry "
                                                     "(reward units per unit of it)")
    target: float | None = declare(None, ge=-1e6, le=1e6, nullable=True,
                                   doc="Phi = -weight x |entry - target| instead (null: the "
                                       "entry itself)")


def shaping_settings(value: Any, where: str, error: type[ValueError]) -> dict[str, Any] | None:
    """The validated ``shaping`` mapping (None: no shaping); ``error`` names the field."""
    settings = build_section(ShapingSettings, value, "shaping", where, error,
                             "a mapping {observation: NAME, weight: W}",
                             {"observation": "an observation entry, e.g. sync_amplitude"})
    if settings is None:
        return None
    out = {"observation": settings.observation, "weight": float(settings.weight)}
    if settings.target is not None:
        out["target"] = float(settings.target)
    return out


def potential_index(names: Sequence[str], observation: str) -> int:
    """Index of the current frame's ``observation`` entry in an observation layout (with a
    frame stack the older frames carry ``@t-k``); ``ValueError`` naming the choices."""
    names = list(names)
    if observation not in names:
        current = [n for n in names if "@" not in n]
        raise ValueError(f"field 'shaping.observation' must be an entry of the training "
                         f"environment's observation, one of {current} (got {observation!r})")
    return names.index(observation)


def _wrapper_base():
    from stable_baselines3.common.vec_env import VecEnvWrapper
    return VecEnvWrapper


def PotentialShaping(venv, index: int, weight: float, gamma: float,
                     target: float | None = None):
    """The shaping wrapper around an SB3 ``VecEnv`` (see the module docstring); built lazily,
    as SB3 is imported on first use.

    :param index: observation entry of the potential.
    :param weight: ``Phi = -weight * obs[index]`` (>= 0).
    :param gamma: the algorithm's discount factor, in (0, 1].
    :param target: if given, ``Phi = -weight * |obs[index] - target|``.
    """
    if not (math.isfinite(weight) and weight >= 0):
        raise ValueError(f"shaping weight must be finite and >= 0 (got {weight!r})")
    if not 0 < gamma <= 1:
        raise ValueError(f"shaping gamma must be in (0, 1] (got {gamma!r})")
    if target is not None and not math.isfinite(target):
        raise ValueError(f"shaping target must be finite or None (got {target!r})")
    return _shaping_class()(venv, int(index), float(weight), float(gamma),
                            None if target is None else float(target))


def _shaping_class():
    VecEnvWrapper = _wrapper_base()

    class _PotentialShaping(VecEnvWrapper):
        def __init__(self, venv, index: int, weight: float, gamma: float,
                     target: float | None):
            super().__init__(venv)
            self.index, self.weight, self.gamma, self.target = index, weight, gamma, target
            self._phi = np.zeros(self.num_envs)

        def potential(self, obs: np.ndarray) -> np.ndarray:
            entry = np.asarray(obs, dtype=np.float64)[..., self.index]
            if self.target is not None:
                entry = np.abs(entry - self.target)
            return -self.weight * entry

        def reset(self):
            obs = self.venv.reset()
            self._phi = self.potential(obs)
            return obs

        def step_wait(self):
            obs, rewards, dones, infos = self.venv.step_wait()
            phi_next = self.potential(obs)
            phi_end = phi_next.copy()
            for i in np.flatnonzero(dones):
                info = infos[i]
                phi_end[i] = (self.potential(info["terminal_observation"])
                              if info.get("TimeLimit.truncated") else 0.0)
            shaping = self.gamma * phi_end - self._phi
            self._phi = phi_next  # a finished episode's row is already the new episode's
            for i, info in enumerate(infos):
                info["shaping"] = float(shaping[i])
            return obs, (rewards + shaping).astype(rewards.dtype), dones, infos

    return _PotentialShaping
