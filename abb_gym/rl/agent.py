"""Trained PPO agents as evaluation policies, with frozen normalisation.

:func:`load_policy` reads a run folder (or a shipped agent in ``agents/trained/<name>``)::

    run/
      model.zip          SB3 PPO model
      vecnormalize.pkl   VecNormalize statistics (absent if the run did not normalise)
      config.yml         the training config (zoo style, keyed by the env id) and, under
                         ``_run``, the env id, seed and the agent's policy-relevant
                         environment settings (``policy_env``)
      agent.yml          the manifest: fingerprints of the files and what the normalisation
                         was fitted on (env id, scene, observation layout)

checks that the folder is complete and self-consistent (:mod:`abb_gym.rl.agent_files`: a
missing, foreign or corrupt file is one :class:`~abb_gym.rl.agent_files.AgentError` naming
it) and returns a :class:`PPOPolicy`, which implements the evaluation ``Policy`` protocol of
:mod:`abb_gym.evaluation.registry` (``reset(env, mask)``, ``act(obs, info)``) on a native
vector environment.  The VecNormalize statistics are frozen (``training=False,
norm_reward=False``): evaluation never updates them.  Actions are the deterministic policy
mean unless ``deterministic=False``.

A recurrent agent (sb3-contrib's ``RecurrentPPO``, an LSTM policy) keeps one memory per
sub-environment: ``reset(env, mask)`` starts it afresh for the sub-environments in ``mask``,
and a sub-environment's memory advances only when it decides (once per held action).

Environment checks (``reset``): the observation and action shapes must equal the agent's
(``observe_balls`` in particular), the observation layout the one recorded in ``agent.yml``,
and the policy-relevant preset fields
(:data:`abb_gym.rl.env_factory.POLICY_FIELDS`) must match.  An agent trained with a control interval
``k`` times the environment's (``k`` an integer) holds each action for ``k`` steps (a zero-order
hold, as the training environment did), deciding on the observation at the start of each
hold; a mismatch raises ``ValueError`` naming the field.  ``policy.env_kwargs`` lists the
``gym.make_vec`` keywords the agent needs besides ``scene`` and ``preset`` (e.g.
``{"observe_balls": True}``, and the observation's preset fields ``sync_vibration`` and
``frame_stack`` it was trained with); :func:`abb_gym.evaluation.evaluate.evaluate` builds the
agent's environments with them.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .env_factory import observation_kwargs, policy_env_mismatch

__all__ = ["PPOPolicy", "load_policy", "trained_dir", "resolve_agent_path"]


def trained_dir() -> Path:
    """Folder of the shipped agents (``agents/trained``; package data in a wheel)."""
    from .. import resources
    return resources.shipped_folder("agents")


def resolve_agent_path(path: str | Path) -> Path:
    """A run folder from a path (folder or its ``model.zip``) or an agent's name on the search
    path of :mod:`abb_gym.resources` (user folders first, then the shipped agents)."""
    from .. import resources
    from .agent_files import AgentError
    p = Path(path)
    if p.is_file() and p.suffix == ".zip":
        p = p.parent
    if not (p / "model.zip").is_file():
        found = resources.find("agents", str(path))
        if found is not None:
            p = found
    if not (p / "model.zip").is_file():
        if p.is_dir() and (p / "config.yml").exists():  # an agent folder with a bad model
            what = "is a directory" if (p / "model.zip").is_dir() else "is missing"
            raise AgentError(f"agent file {str(p / 'model.zip')!r} {what} (the PPO model)")
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
    :param observation_names: the observation layout the agent was trained on (its
        ``agent.yml``), checked against the environment's; None: not checked.
    """

    reads_info = False  # the evaluation's hint: the agent sees the observation only

    def __init__(self, model: Any, vecnormalize: Any = None, config: dict | None = None,
                 name: str = "ppo", deterministic: bool = True,
                 observation_names: list[str] | None = None):
        self.model = model
        self.vecnormalize = vecnormalize
        if vecnormalize is not None:
            vecnormalize.training = False
            vecnormalize.norm_reward = False
        self.config = dict(config or {})
        self.name = name
        self.deterministic = bool(deterministic)
        self.observation_names = (None if observation_names is None
                                  else [str(n) for n in observation_names])
        self.env_id = self.config.get("env_id")
        self.policy_env: dict[str, Any] = dict(self.config.get("policy_env") or {})
        self.env_kwargs: dict[str, Any] = observation_kwargs(self.policy_env)
        self._repeat = 1
        self._single = False
        self._count: np.ndarray | None = None
        self._last: np.ndarray | None = None
        # a recurrent policy (RecurrentPPO): its LSTM state (h, c), each (layers, n, hidden),
        # and which sub-environments start an episode at their next decision
        self.recurrent = hasattr(getattr(model, "policy", None), "lstm_hidden_state_shape")
        self._state: tuple[np.ndarray, ...] | None = None
        self._starts: np.ndarray | None = None

    # ------------------------------------------------------------------ checks
    def check_env(self, env: Any) -> int:
        """Check that ``env`` (a vector or a single environment) matches the agent; return the
        action repeat (control-interval ratio).  Raises ``ValueError`` naming the mismatch."""
        obs_shape = tuple(self.model.observation_space.shape)
        act_shape = tuple(self.model.action_space.shape)
        env_obs = tuple(getattr(env, "single_observation_space", env.observation_space).shape)
        env_act = tuple(getattr(env, "single_action_space", env.action_space).shape)
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
        env_names = getattr(setup, "obs_names", None)
        if self.observation_names is not None and env_names is not None:
            diff = [k for k, (a, b) in enumerate(zip(env_names, self.observation_names))
                    if a != b]
            if diff:
                k = diff[0]
                raise ValueError(f"observation entry {k} of the environment is "
                                 f"{env_names[k]!r}; the agent's normalisation was fitted on "
                                 f"{self.observation_names[k]!r} there")
        if setup is None or not self.policy_env:
            return 1
        problem = policy_env_mismatch(self.policy_env, setup)
        if problem is not None:
            raise ValueError(f"{problem}; the agent was trained on {self.env_id}")
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
    def reset(self, env: Any, mask: np.ndarray | bool | None = None) -> None:
        """Start the episodes of the sub-environments in ``mask`` (None: all; checks ``env``
        first).  ``env`` may be a single environment (``gym.make``): :meth:`act` then takes
        one observation and returns one action."""
        single = not hasattr(env, "num_envs")  # gymnasium wrappers forward no attributes
        n = 1 if single else int(env.num_envs)
        if self._count is None or self._count.shape[0] != n or single != self._single:
            self._repeat = self.check_env(env)
            self._single = single
            self._count = np.zeros(n, dtype=np.int64)
            self._last = np.zeros((n,) + tuple(self.model.action_space.shape),
                                  dtype=np.float32)
            if self.recurrent:
                layers, _, hidden = self.model.policy.lstm_hidden_state_shape
                self._state = tuple(np.zeros((layers, n, hidden), dtype=np.float32)
                                    for _ in range(2))
                self._starts = np.ones(n, dtype=bool)
        if mask is None:
            mask = np.ones(n, dtype=bool)
        mask = np.broadcast_to(np.asarray(mask, bool), (n,))
        self._count[mask] = 0
        if self.recurrent:
            self._starts[mask] = True  # the policy zeroes their LSTM state at the decision

    def predict(self, obs: np.ndarray, due: np.ndarray | None = None) -> np.ndarray:
        """Actions for raw observations (normalised with the frozen statistics).  A recurrent
        policy advances the memory of the sub-environments in ``due`` (None: all) and keeps
        the others' (they hold their last action and do not decide now)."""
        obs = np.asarray(obs, dtype=np.float32)
        if self.vecnormalize is not None:
            obs = self.vecnormalize.normalize_obs(obs)
        if not self.recurrent:
            act, _ = self.model.predict(obs, deterministic=self.deterministic)
        else:
            act, state = self.model.predict(obs, state=self._state,
                                            episode_start=self._starts,
                                            deterministic=self.deterministic)
            due = slice(None) if due is None else due
            for kept, new in zip(self._state, state):
                kept[:, due] = new[:, due]
            self._starts[due] = False
        return np.clip(np.asarray(act, dtype=np.float32), -1.0, 1.0)

    def act(self, obs: np.ndarray, info: dict | None = None) -> np.ndarray:
        """Actions for the observation batch (one action for one observation after
        ``reset`` of a single environment)."""
        if self._count is None:
            raise RuntimeError("call reset(env, mask) before act()")
        if self._single:
            return self._act(np.asarray(obs)[None])[0]
        return self._act(obs)

    def _act(self, obs: np.ndarray) -> np.ndarray:
        if self._repeat == 1:
            return self.predict(obs)
        due = self._count % self._repeat == 0
        if due.any():
            self._last[due] = self.predict(obs, due)[due]
        self._count += 1
        return self._last.copy()


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
    from .agent_files import check_folder, custom_objects_for, load_model, load_vecnormalize

    folder = resolve_agent_path(path)
    files = check_folder(folder, best=best)
    config = files.run
    trained_id = files.env_id
    if env_id is not None and env_id != trained_id:
        raise ValueError(f"agent {str(folder)!r} was trained on {trained_id}, not {env_id}")
    scene_name = getattr(scene, "name", scene)
    trained_scene = files.manifest["scene"]
    if scene_name is not None and scene_name != trained_scene:
        import warnings
        warnings.warn(f"agent {folder.name!r} was trained on scene {trained_scene!r}; "
                      f"evaluating it on {scene_name!r}", stacklevel=2)
    obs_size = files.manifest["observation"]["size"]
    # the statistics first: reading them is cheap, the model costs a torch load
    vn = (load_vecnormalize(files.norm_path, obs_size) if files.norm_path is not None
          else None)
    model = load_model(files.model_path, obs_size, files.manifest["action_size"],
                       custom_objects_for(files.entry), files.algo)
    return PPOPolicy(model, vn, config, name=name or f"ppo:{folder.name}",
                     deterministic=deterministic,
                     observation_names=files.observation_names)


def load_ppo(arg: str, env_id: str | None = None, scene: Any = None, **_: Any) -> PPOPolicy:
    """The policy of ``ppo:NAME|PATH`` (the ``abb_gym.policies`` entry point)."""
    return load_policy(arg, env_id=env_id, scene=scene)
