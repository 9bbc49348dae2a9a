"""Stable-Baselines3 ``VecEnv`` over the native gymnasium vector environment.

The balancer's native vector environment (:mod:`abb_gym.envs.vector`) follows gymnasium's
``AutoresetMode.NEXT_STEP``: the step after an episode end resets that sub-environment and
ignores its action.  Stable-Baselines3 expects the older *same-step* convention instead.
:class:`NativeVecEnv` converts one into the other without copying any physics:

==========================  ===============================================================
SB3 expects                 what the adapter does
==========================  ===============================================================
``step`` returns            ``(obs, rewards, dones, infos)``: ``dones = terminated |
                            truncated``, rewards as float32, ``infos`` a list of one dict
                            per sub-environment (the native ``info`` split by its ``_key``
                            masks; ``reward_terms`` stays a dict)
same-step reset             every finished sub-environment is reset inside the same
                            ``step`` through ``reset(options={"reset_mask": dones})``; the
                            returned ``obs`` row is the first observation of the new episode,
                            so the *next* ``step`` is a real step that uses the action
``terminal_observation``    the last observation of the finished episode, in its ``info``
``TimeLimit.truncated``     ``truncated and not terminated`` in every ``info`` (as
                            ``DummyVecEnv``); with ``bootstrap_truncated=False`` it is always
                            False, i.e. PPO treats the time limit as a true end (the
                            balancer pays its terminal residual term at truncation too)
``is_success``              at an episode end: terminated without a failure (SB3 logs it as
                            ``rollout/success_rate``)
``reset_infos``             the reset ``info`` of each sub-environment (episode parameters)
``seed(s)`` then ``reset``  sub-environment ``i`` is seeded with ``s + i`` (as SB3's
                            ``DummyVecEnv`` and gymnasium's ``SyncVectorEnv``); seeds are used
                            once, later resets continue each generator
``set_options``             options of the next ``reset`` (one dict for all, or a list with
                            one dict per sub-environment and the same keys)
==========================  ===============================================================

``get_attr``/``set_attr``/``env_method`` act on the one native vector environment (all
sub-environments share the scene and preset): ``get_attr(name)`` returns its attribute once per
requested index; ``env_method`` calls the method once and repeats the result.

Only ``Box`` observation and action spaces are supported (the balancer's spaces are flat
boxes).
"""
from __future__ import annotations

from typing import Any, Iterable, Sequence

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import (VecEnv, VecEnvIndices,
                                                           VecEnvStepReturn)

__all__ = ["NativeVecEnv", "split_info"]


def split_info(info: dict[str, Any], n: int, rows: Iterable[int] | None = None
               ) -> list[dict[str, Any]]:
    """Split a gymnasium vector ``info`` (arrays with ``_key`` masks) into ``n`` dicts.

    ``rows`` restricts the work to those sub-environments (the others get empty dicts).
    Nested dicts (``reward_terms``) are split recursively; a key is present in dict ``i`` only
    where its mask is true.
    """
    out: list[dict[str, Any]] = [{} for _ in range(n)]
    idx = range(n) if rows is None else list(rows)
    for key, value in info.items():
        if key.startswith("_"):
            continue
        mask = info.get("_" + key)
        if isinstance(value, dict):
            sub = split_info(value, n, idx)
            for i in idx:
                if mask is None or mask[i]:
                    out[i][key] = sub[i]
            continue
        for i in idx:
            if mask is None or mask[i]:
                out[i][key] = value[i]
    return out


class NativeVecEnv(VecEnv):
    """SB3 ``VecEnv`` view of a native balancer vector environment (see the module docstring).

    :param env: the native vector environment, e.g. ``gym.make_vec(id, num_envs=N,
        vectorization_mode="vector_entry_point", ...)``, with ``AutoresetMode.NEXT_STEP`` and
        ``reset(options={"reset_mask": mask})``.
    :param bootstrap_truncated: report truncations as ``TimeLimit.truncated`` (SB3 then
        bootstraps the value of the terminal observation).  Default True.
    :param info_keys: keep only these keys in the per-step ``infos`` (None: all keys).  The
        episode-end keys (``terminal_observation``, ``TimeLimit.truncated``, ``is_success``)
        are always present; a smaller set makes ``step`` a little cheaper.
    """

    def __init__(self, env: gym.vector.VectorEnv, *, bootstrap_truncated: bool = True,
                 info_keys: Sequence[str] | None = None):
        if not isinstance(env.single_observation_space, gym.spaces.Box) or \
                not isinstance(env.single_action_space, gym.spaces.Box):
            raise ValueError("NativeVecEnv supports Box observation and action spaces only "
                             f"(got {env.single_observation_space}, "
                             f"{env.single_action_space})")
        mode = env.metadata.get("autoreset_mode")
        if mode is not None and getattr(mode, "name", str(mode)) != "NEXT_STEP":
            raise ValueError(f"NativeVecEnv needs a vector environment with autoreset mode "
                             f"NEXT_STEP (got {mode})")
        self.venv_native = env
        self.bootstrap_truncated = bool(bootstrap_truncated)
        self.info_keys = None if info_keys is None else tuple(info_keys)
        super().__init__(env.num_envs, env.single_observation_space, env.single_action_space)
        self._actions: np.ndarray | None = None
        self._started = False

    # ------------------------------------------------------------------ helpers
    @property
    def unwrapped(self) -> gym.vector.VectorEnv:
        """The native vector environment (its ``setup``, ``scene``, ``config``)."""
        return self.venv_native.unwrapped

    def _split(self, info: dict[str, Any], rows=None) -> list[dict[str, Any]]:
        if self.info_keys is not None:
            info = {k: v for k, v in info.items()
                    if k in self.info_keys or k[1:] in self.info_keys}
        return split_info(info, self.num_envs, rows)

    def _reset_kwargs(self) -> dict[str, Any]:
        kwargs: dict[str, Any] = {}
        if any(s is not None for s in self._seeds):
            kwargs["seed"] = list(self._seeds)
        opts = self._options
        if any(opts):
            first = opts[0]
            if all(o == first for o in opts):
                kwargs["options"] = dict(first)
            else:
                keys = set(first)
                if any(set(o) != keys for o in opts):
                    raise ValueError("set_options: per-environment options must all have the "
                                     "same keys (or give one dict for all environments)")
                kwargs["options"] = {k: np.asarray([o[k] for o in opts]) for k in keys}
        return kwargs

    # ------------------------------------------------------------------ VecEnv API
    def reset(self):
        obs, info = self.venv_native.reset(**self._reset_kwargs())
        self.reset_infos = self._split(info)
        self._reset_seeds()
        self._reset_options()
        self._started = True
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise RuntimeError("step_wait() called without step_async()")
        obs, rewards, terminated, truncated, info = self.venv_native.step(self._actions)
        self._actions = None
        dones = np.logical_or(terminated, truncated)
        infos = self._split(info)
        failed = info.get("_failure")
        for i, d in enumerate(dones):
            inf = infos[i]
            if d:
                inf["terminal_observation"] = obs[i].copy()
                inf["TimeLimit.truncated"] = bool(self.bootstrap_truncated and truncated[i]
                                                  and not terminated[i])
                inf["is_success"] = bool(terminated[i] and not (failed is not None
                                                                and failed[i]))
            else:
                inf["TimeLimit.truncated"] = False
        if dones.any():
            obs, rinfo = self.venv_native.reset(options={"reset_mask": dones})
            rows = np.flatnonzero(dones)
            split = self._split(rinfo, rows)
            for i in rows:
                self.reset_infos[i] = split[i]
        return obs, np.asarray(rewards, dtype=np.float32), dones, infos

    def close(self) -> None:
        self.venv_native.close()

    def _indices(self, indices: VecEnvIndices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, (int, np.integer)):
            return [int(indices)]
        return list(indices)

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        value = getattr(self.venv_native, attr_name)
        return [value for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        setattr(self.venv_native, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None,
                   **method_kwargs) -> list[Any]:
        result = getattr(self.venv_native, method_name)(*method_args, **method_kwargs)
        return [result for _ in self._indices(indices)]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper],
                       indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        frames = self.venv_native.render() if self.render_mode == "rgb_array" else None
        frames = list(frames or ())
        return frames + [None] * (self.num_envs - len(frames))
