"""The policy interface of the evaluation, and the registry that turns ``--policy`` strings
into policies.

A policy acts on a *vector* environment (one row per sub-environment)::

    class Policy(Protocol):
        name: str
        def reset(self, env, mask: np.ndarray) -> None: ...
        def act(self, obs: np.ndarray, info: dict) -> np.ndarray: ...

* ``reset(env, mask)`` is called after the environment reset the sub-environments selected by
  the boolean ``mask`` (at the start, and after every episode end); ``env`` is the vector
  environment (``env.single_action_space``, ``env.unwrapped`` scene and presets).
* ``act(obs, info)`` returns actions of shape ``(num_envs,) + single_action_space.shape``
  from the observation batch and the info dict of the last step or reset (arrays of length
  ``num_envs``: ``time`` [s], ``rotor_speed`` [rad/s], ...).

``resolve(spec, env_id, scene)`` builds a policy from a string: ``baseline:NAME`` (a family
of :mod:`abb_gym.baselines.profiles`, with tuned parameters from ``configs/baselines/`` when
they exist), or ``ppo:PATH`` (a run folder with ``model.zip`` and ``vecnormalize.pkl``,
loaded by :func:`abb_gym.rl.load_policy` with frozen normalisation).
"""
from __future__ import annotations

from typing import Any, Callable, Protocol

import numpy as np

_LOADERS: dict[str, Callable[..., "Policy"]] = {}


class Policy(Protocol):
    name: str

    def reset(self, env: Any, mask: np.ndarray) -> None: ...

    def act(self, obs: np.ndarray, info: dict) -> np.ndarray: ...


def register_loader(prefix: str, loader: Callable[..., Policy]) -> None:
    """Make ``prefix:ARG`` policy strings resolve through ``loader(arg, env_id=, scene=)``."""
    _LOADERS[prefix] = loader


def resolve(spec: str, env_id: str, scene: Any) -> Policy:
    """Policy from ``baseline:NAME`` or ``ppo:PATH`` (see the module docstring)."""
    if ":" not in spec:
        raise ValueError(f"--policy must look like baseline:NAME or ppo:PATH (got {spec!r})")
    prefix, arg = spec.split(":", 1)
    if prefix not in _LOADERS:
        if prefix == "ppo":  # registered on import of the optional training extra
            try:
                from .. import rl  # noqa: F401
            except ImportError as exc:
                raise ValueError(f"ppo policies need the training extra: pip install "
                                 f"'abb-gym[train]' ({exc})") from None
        elif prefix == "baseline":
            from . import baseline_policies  # noqa: F401
    if prefix not in _LOADERS:
        raise ValueError(f"unknown policy kind {prefix!r} in {spec!r}; use one of "
                         f"{sorted(set(_LOADERS) | {'baseline', 'ppo'})}")
    return _LOADERS[prefix](arg, env_id=env_id, scene=scene)
