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
* ``reads_info`` (optional, default True): a policy that never reads ``info`` sets it to
  False, and the evaluation then steps with the lean info (every key only where an episode
  ends), which costs less than the full info of every step.  The metrics are the same.

``resolve(spec, env_id, scene)`` builds a policy from a string ``KIND:ARG`` through a
registry of loaders.  The registry is filled from the ``abb_gym.policies`` entry points of
the installed packages (abb-gym's own: ``baseline:NAME``, a family of
:mod:`abb_gym.baselines.profiles` with its tuned parameters, and ``ppo:PATH``, a trained
agent loaded by :func:`abb_gym.rl.load_policy` with frozen normalisation), and by
:func:`register_loader`.  So this layer never imports the layers above it, and another
package can add its own policy kinds by declaring an entry point::

    [project.entry-points."abb_gym.policies"]
    mpc = "my_package.policies:load_mpc"     # load_mpc(arg, env_id=..., scene=...) -> Policy
"""
from __future__ import annotations

from typing import Any, Callable, Protocol

import numpy as np

ENTRY_POINT_GROUP = "abb_gym.policies"
_LOADERS: dict[str, Callable[..., "Policy"]] = {}


class Policy(Protocol):
    name: str

    def reset(self, env: Any, mask: np.ndarray) -> None: ...

    def act(self, obs: np.ndarray, info: dict) -> np.ndarray: ...


def register_loader(prefix: str, loader: Callable[..., Policy]) -> None:
    """Make ``prefix:ARG`` policy strings resolve through ``loader(arg, env_id=, scene=)``."""
    _LOADERS[prefix] = loader


def _entry_point_loader(prefix: str) -> Callable[..., Policy] | None:
    from importlib.metadata import entry_points
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name == prefix:
            return ep.load()
    return None


def policy_kinds() -> list[str]:
    """The policy kinds that :func:`resolve` accepts."""
    from importlib.metadata import entry_points
    return sorted(set(_LOADERS) | {ep.name for ep in entry_points(group=ENTRY_POINT_GROUP)})


def resolve(spec: str, env_id: str, scene: Any) -> Policy:
    """Policy from ``KIND:ARG`` (see the module docstring)."""
    if not isinstance(spec, str) or ":" not in spec:
        raise ValueError(f"--policy must look like KIND:ARG with KIND one of {policy_kinds()}, "
                         f"e.g. baseline:ramp or ppo:NAME (got {spec!r})")
    prefix, arg = spec.split(":", 1)
    loader = _LOADERS.get(prefix)
    if loader is None:
        try:
            loader = _entry_point_loader(prefix)
        except ImportError as exc:
            raise ValueError(f"policy kind {prefix!r} needs an optional extra that is not "
                             f"installed ({exc}); for ppo: pip install -c constraints.txt "
                             f"'abb-gym[train]'") from None
        if loader is None:
            raise ValueError(f"unknown policy kind {prefix!r} in {spec!r}; use one of "
                             f"{policy_kinds()}")
        _LOADERS[prefix] = loader
    return loader(arg, env_id=env_id, scene=scene)
