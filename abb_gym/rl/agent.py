"""Trained PPO agents as evaluation policies, with frozen normalisation.

:func:`load_policy` reads a run folder (or a shipped agent in ``agents/trained/<name>``)::

    run/
      model.zip          SB3 PPO model
      vecnormalize.pkl   VecNormalize statistics (absent if the run did not normalise)
      config.yml         the training config (zoo style, keyed by the env id) and, under
                         ``_run``, the env id, seed and the agent's policy-relevant
                         environment settings (``policy_env``)

and returns a :class:`PPOPolicy`, which implements the evaluation ``Policy`` protocol of
:mod:`abb_gym.evaluation.registry` (``reset(env, mask)``, ``act(obs, info)``) on a native
vector environment.  The VecNormalize statistics are frozen (``training=False,
norm_reward=False``): evaluation never updates them.  Actions are the deterministic policy
mean unless ``deterministic=False``.

Environment checks (``reset``): the observation and action shapes must equal the agent's
(``observe_balls`` in particular), and the policy-relevant preset fields
(:data:`abb_gym.rl.config.POLICY_FIELDS`) must match.  An agent trained with a control interval
``k`` times the environment's (``k`` an integer) holds each action for ``k`` steps (a zero-order
hold, as the training environment did), deciding on the observation at the start of each
hold; a mismatch raises ``ValueError`` naming the field.  ``policy.env_kwargs`` lists the
``gym.make_vec`` keywords the agent needs besides ``scene`` and ``preset`` (e.g.
``{"observe_balls": True}``).
"""
from __future__ import annotations

import math
import pickle
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["PPOPolicy", "load_policy", "trained_dir", "resolve_agent_path"]


def trained_dir() -> Path:
    """Folder of the shipped agents (``agents/trained``; package data in a wheel)."""
    from .. import resources
    return resources.shipped_folder("agents")


def resolve_agent_path(path: str | Path) -> Path:
    """A run folder from a path (folder or its ``model.zip``) or an agent's name on the search
    path of :mod:`abb_gym.resources` (user folders first, then the shipped agents)."""
    from .. import resources
    p = Path(path)
    if p.is_file() and p.suffix == ".zip":
        p = p.parent
    if not (p / "model.zip").is_file():
        found = resources.find("agents", str(path))
        if found is not None:
            p = found
    if not (p / "model.zip").is_file():
        raise ValueError(f"no PPO agent at {str(path)!r}: expected a folder with model.zip "
                         f"(a run folder) or an agent name, one of "
                         f"{resources.names('agents')}")
    return p


class PPOPolicy:
    """A trained SB3 PPO model with frozen observation normalisation (see module docstring).

    :param model: the SB3 ``PPO`` model.
    :param vecnormalize: a ``VecNormalize`` (frozen here) or None.
    :param config: the ``_run`` section of the run's ``config.yml`` (``env_id``,
        ``policy_env``...), or {}.
    :param name: policy name in tables.
    :param deterministic: use the policy mean.
    """

    def __init__(self, model: Any, vecnormalize: Any = None, config: dict | None = None,
                 name: str = "ppo", deterministic: bool = True):
        self.model = model
        self.vecnormalize = vecnormalize
        if vecnormalize is not None:
            vecnormalize.training = False
            vecnormalize.norm_reward = False
        self.config = dict(config or {})
        self.name = name
        self.deterministic = bool(deterministic)
        self.env_id = self.config.get("env_id")
        self.policy_env: dict[str, Any] = dict(self.config.get("policy_env") or {})
        self.env_kwargs: dict[str, Any] = {}
        if self.policy_env.get("observe_balls"):
            self.env_kwargs["observe_balls"] = True
        self._repeat = 1
        self._count: np.ndarray | None = None
        self._last: np.ndarray | None = None

    # ------------------------------------------------------------------ checks
    def check_env(self, env: Any) -> int:
        """Check that ``env`` (a vector environment) matches the agent; return the action
        repeat (control-interval ratio).  Raises ``ValueError`` naming the mismatch."""
        obs_shape = tuple(self.model.observation_space.shape)
        act_shape = tuple(self.model.action_space.shape)
        env_obs = tuple(env.single_observation_space.shape)
        env_act = tuple(env.single_action_space.shape)
        want_balls = self.policy_env.get("observe_balls")
        if env_obs != obs_shape:
            hint = (f" (the agent was trained with observe_balls={want_balls})"
                    if want_balls is not None else "")
            raise ValueError(f"observation shape {env_obs} of the environment does not match "
                             f"the agent's {obs_shape}{hint}")
        if env_act != act_shape:
            raise ValueError(f"action shape {env_act} of the environment does not match the "
                             f"agent's {act_shape} (trained on {self.env_id})")
        native = getattr(env, "unwrapped", env)
        setup = getattr(native, "setup", None)
        if setup is None or not self.policy_env:
            return 1
        kind = self.policy_env.get("kind")
        if kind is not None and kind != setup.kind:
            raise ValueError(f"the agent was trained on {self.env_id} (action kind {kind!r}); "
                             f"the environment's action kind is {setup.kind!r}")
        conf = setup.config.to_dict()
        for key in ("vibration_filter_time", "dwell"):
            if key in self.policy_env and conf[key] != self.policy_env[key]:
                raise ValueError(f"preset field {key!r} of the environment "
                                 f"({conf[key]!r}) differs from the agent's "
                                 f"({self.policy_env[key]!r})")
        for key, have in (("operating_speed", setup.operating_speed),
                          ("episode_length", setup.episode_length)):
            want = self.policy_env.get(key)
            if want is not None and not math.isclose(have, want, rel_tol=1e-9):
                raise ValueError(f"preset field {key!r} of the environment ({have:g}) differs "
                                 f"from the agent's ({want:g})")
        want_dt = self.policy_env.get("control_interval")
        if want_dt is None:
            return 1
        ratio = want_dt / setup.control_interval
        k = int(round(ratio))
        if k < 1 or abs(ratio - k) > 1e-6:
            raise ValueError(f"preset field 'control_interval' of the environment "
                             f"({setup.control_interval:g} s) must equal the agent's "
                             f"({want_dt:g} s) or divide it by an integer")
        if k > 1 and setup.kind == "dwell":
            raise ValueError("preset field 'control_interval' must equal the agent's for "
                             "DwellProfile")
        return k

    # ------------------------------------------------------------------ Policy protocol
    def reset(self, env: Any, mask: np.ndarray) -> None:
        """Start the episodes of the sub-environments in ``mask`` (checks ``env`` first)."""
        n = env.num_envs
        if self._count is None or self._count.shape[0] != n:
            self._repeat = self.check_env(env)
            self._count = np.zeros(n, dtype=np.int64)
            self._last = np.zeros((n,) + tuple(self.model.action_space.shape),
                                  dtype=np.float32)
        self._count[np.asarray(mask, bool)] = 0

    def predict(self, obs: np.ndarray) -> np.ndarray:
        """Actions for raw observations (normalised with the frozen statistics)."""
        obs = np.asarray(obs, dtype=np.float32)
        if self.vecnormalize is not None:
            obs = self.vecnormalize.normalize_obs(obs)
        act, _ = self.model.predict(obs, deterministic=self.deterministic)
        return np.clip(np.asarray(act, dtype=np.float32), -1.0, 1.0)

    def act(self, obs: np.ndarray, info: dict | None = None) -> np.ndarray:
        if self._count is None:
            raise RuntimeError("call reset(env, mask) before act()")
        if self._repeat == 1:
            return self.predict(obs)
        due = self._count % self._repeat == 0
        if due.any():
            self._last[due] = self.predict(obs)[due]
        self._count += 1
        return self._last.copy()


def _load_vecnormalize(path: Path):
    if not path.exists():
        return None
    with open(path, "rb") as fh:
        vn = pickle.load(fh)
    vn.training = False
    vn.norm_reward = False
    return vn


def load_policy(path: str | Path, env_id: str | None = None, scene: Any = None, *,
                deterministic: bool = True, best: bool = False, name: str | None = None
                ) -> PPOPolicy:
    """Load a trained agent as an evaluation policy with frozen VecNormalize statistics.

    :param path: run folder, its ``model.zip``, or a shipped agent's name
        (``agents/trained/<name>``).
    :param env_id: if given, must equal the id the agent was trained on.
    :param scene: if given and different from the training scene, a warning is issued (the
        agent still runs: its observations are normalised per machine).
    :param best: load ``best_model.zip`` / ``best_vecnormalize.pkl`` (best evaluation) instead
        of the final model.
    """
    from stable_baselines3 import PPO

    from ..configuration import read_yaml
    from .networks import BoundedMlpPolicy

    folder = resolve_agent_path(path)
    cfg_path = folder / "config.yml"
    data = read_yaml(cfg_path, "agent config") if cfg_path.exists() else {}
    config = dict(data.get("_run") or {})
    entry = data.get(config.get("env_id")) or {}
    trained_id = config.get("env_id")
    if env_id is not None and trained_id is not None and env_id != trained_id:
        raise ValueError(f"agent {str(folder)!r} was trained on {trained_id}, not {env_id}")
    scene_name = getattr(scene, "name", scene)
    trained_scene = (config.get("policy_env") or {}).get("scene")
    if scene_name is not None and trained_scene is not None and scene_name != trained_scene:
        import warnings
        warnings.warn(f"agent {folder.name!r} was trained on scene {trained_scene!r}; "
                      f"evaluating it on {scene_name!r}", stacklevel=2)
    model_file = folder / ("best_model.zip" if best else "model.zip")
    norm_file = folder / ("best_vecnormalize.pkl" if best else "vecnormalize.pkl")
    if not model_file.exists():
        raise ValueError(f"{str(model_file)!r} does not exist")
    # the network class by its current name (agents of the first wave pickled an older
    # module path for it)
    custom = ({"policy_class": BoundedMlpPolicy}
              if str(entry.get("policy", "")).endswith("BoundedMlpPolicy") else None)
    model = PPO.load(model_file, device="cpu", custom_objects=custom)
    vn = _load_vecnormalize(norm_file)
    return PPOPolicy(model, vn, config, name=name or f"ppo:{folder.name}",
                     deterministic=deterministic)


def load_ppo(arg: str, env_id: str | None = None, scene: Any = None, **_: Any) -> PPOPolicy:
    """The policy of ``ppo:NAME|PATH`` (the ``abb_gym.policies`` entry point)."""
    return load_policy(arg, env_id=env_id, scene=scene)
