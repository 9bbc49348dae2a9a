"""Agents stored as pickles: read only when trusted, and converted once to the safe format.

Three kinds of folder or file hold an agent as pickles:

=================  ==========================================================================
kind               what
=================  ==========================================================================
``abb-gym``        abb-gym's first format: ``model.zip``, ``vecnormalize.pkl``, ``config.yml``
                   and an ``agent.yml`` of ``format: 1`` (or none, from before manifests)
``rl_zoo3``        an rl_zoo3 run folder (``logs/ppo/<env>_<n>``): ``<env>.zip``,
                   ``best_model.zip`` and ``<env>/`` with ``vecnormalize.pkl``, ``config.yml``
                   and ``args.yml`` (the env id, algorithm and environment keywords)
``sb3``            a plain SB3 ``model.zip`` (a file, or a folder holding it), with the
                   ``vecnormalize.pkl`` beside it when there is one; it records no env id and
                   no environment settings: the caller gives them
=================  ==========================================================================

SB3 reads ``model.zip`` with cloudpickle and ``vecnormalize.pkl`` is a pickle: either runs the
code it contains.  So :func:`load_pickled` first asks :func:`~abb_gym.rl.agent_files.require_trust`
(``--trust-pickle`` or ``ABB_GYM_TRUST_PICKLE=1``; refused in one line otherwise), and
:func:`convert_agent` (``abb-gym convert-agent``) writes a folder of data
(:mod:`abb_gym.rl.agent_files`) from a trusted one, after which no pickle is needed again.
The rl_zoo3 YAML files are read without unpickling too: their ``OrderedDict`` tag is taken as
a mapping, and any other Python tag is refused.
"""
from __future__ import annotations

import math
import pickle
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .agent_files import (LEGACY_FORMAT, MANIFEST, AgentError, _label, _one_line, check_folder,
                          evaluation_reward_weights, file_fingerprint, require_trust,
                          write_manifest)

__all__ = ["PickledAgent", "find_pickled", "load_pickled", "convert_agent", "read_model",
           "read_vecnormalize", "read_zoo_yaml"]


@dataclass
class PickledAgent:
    """An agent stored as pickles (see the module docstring), before anything is read."""

    kind: str                      # "abb-gym", "rl_zoo3" or "sb3"
    source: Path                   # the folder or file the caller named
    model_path: Path
    norm_path: Path | None
    env_id: str | None = None
    algo: str = "ppo"
    env_kwargs: dict[str, Any] = field(default_factory=dict)   # of the training environment
    eval_env_kwargs: dict[str, Any] | None = None
    hyperparams: dict[str, Any] = field(default_factory=dict)  # the config entry
    config: dict[str, Any] | None = None   # an abb-gym folder's config.yml
    manifest: dict[str, Any] | None = None  # its format-1 agent.yml, if any

    @property
    def pickles(self) -> list[Path]:
        return [p for p in (self.model_path, self.norm_path) if p is not None]


# ------------------------------------------------------------------------ finding them
def _zoo_parts(folder: Path) -> tuple[Path, Path] | None:
    """(the run's ``<env>/`` folder, its final model) of an rl_zoo3 run folder, or None."""
    for sub in sorted(p for p in folder.iterdir() if p.is_dir()):
        if (sub / "args.yml").is_file() and (folder / f"{sub.name}.zip").is_file():
            return sub, folder / f"{sub.name}.zip"
    return None


def find_pickled(path: str | Path, best: bool = False) -> PickledAgent | None:
    """The pickled agent at ``path`` (a folder or a ``.zip``), or None if ``path`` is not one
    (a safe agent folder, or nothing).  Reads YAML only, never a pickle."""
    path = Path(path)
    prefix = "best_" if best else ""
    if path.is_file() and path.suffix == ".zip":
        folder = path.parent
        if (folder / "config.yml").is_file() and path.name in ("model.zip", "best_model.zip") \
                and not (folder / "policy.safetensors").is_file():
            return find_pickled(folder, best=path.name == "best_model.zip")
        norm = folder / "vecnormalize.pkl"
        return PickledAgent("sb3", path, path, norm if norm.is_file() else None)
    if not path.is_dir():
        return None
    manifest_path = path / MANIFEST
    if (path / "config.yml").is_file() and (path / f"{prefix}model.zip").is_file():
        manifest = None
        if manifest_path.is_file():
            from ..configuration import read_yaml
            manifest = read_yaml(manifest_path, "agent manifest", AgentError)
            if manifest.get("format") != LEGACY_FORMAT:
                return None  # a safe folder that kept its old pickles beside
        norm = path / f"{prefix}vecnormalize.pkl"
        return PickledAgent("abb-gym", path, path / f"{prefix}model.zip",
                            norm if norm.is_file() else None, manifest=manifest)
    zoo = _zoo_parts(path)
    if zoo is not None:
        return _zoo_agent(path, *zoo, best=best)
    if (path / "model.zip").is_file() and not manifest_path.exists():
        norm = path / "vecnormalize.pkl"
        return PickledAgent("sb3", path, path / "model.zip", norm if norm.is_file() else None)
    return None


def read_zoo_yaml(path: Path) -> Any:
    """An rl_zoo3 YAML file (written by ``yaml.dump`` of an ``OrderedDict``), read as data."""
    import yaml

    from ..configuration import MAX_FILE_BYTES, YamlInputError, strict_yaml_loader

    class ZooLoader(strict_yaml_loader()):
        pass

    def ordered(loader, node):
        (pairs,) = loader.construct_sequence(node, deep=True)
        if not all(isinstance(p, list) and len(p) == 2 for p in pairs):
            raise YamlInputError("an OrderedDict tag without key-value pairs")
        return {k: v for k, v in pairs}

    ZooLoader.add_constructor("tag:yaml.org,2002:python/object/apply:collections.OrderedDict",
                              ordered)
    ZooLoader.add_constructor("tag:yaml.org,2002:python/tuple",
                              lambda loader, node: tuple(loader.construct_sequence(node)))
    label = f"rl_zoo3 file {str(path)!r}"
    try:
        if path.stat().st_size > MAX_FILE_BYTES:
            raise AgentError(f"{label} is larger than {MAX_FILE_BYTES} bytes")
        return yaml.load(path.read_text(encoding="utf-8"), Loader=ZooLoader)  # noqa: S506
    except (OSError, UnicodeDecodeError, yaml.YAMLError, YamlInputError) as exc:
        raise AgentError(f"{label} cannot be read as data ({_one_line(exc)})") from None


def _zoo_agent(folder: Path, params: Path, final: Path, best: bool) -> PickledAgent:
    args = read_zoo_yaml(params / "args.yml")
    hyper = read_zoo_yaml(params / "config.yml") if (params / "config.yml").is_file() else {}
    where = f"rl_zoo3 run {str(folder)!r}"
    if not isinstance(args, Mapping) or not isinstance(args.get("env"), str):
        raise AgentError(f"{where}: args.yml names no env id ('env')")
    if not isinstance(hyper, Mapping):
        raise AgentError(f"{where}: config.yml is not a mapping of hyperparameters")
    for key in ("frame_stack", "env_wrapper", "vec_env_wrapper"):
        if hyper.get(key):
            raise AgentError(f"{where} trained with {key!r}, which abb-gym cannot rebuild for "
                             f"an evaluation")
    env_kwargs = dict(hyper.get("env_kwargs") or {})
    if args.get("env_kwargs") is not None:  # rl_zoo3's enjoy: the command line's win
        env_kwargs = dict(args["env_kwargs"])
    eval_kwargs = args.get("eval_env_kwargs")
    model = folder / "best_model.zip" if best else final
    if not model.is_file():
        raise AgentError(f"{_label(model)} is missing (the rl_zoo3 run's "
                         f"{'best' if best else 'final'} model)")
    norm = params / "vecnormalize.pkl"
    return PickledAgent("rl_zoo3", folder, model, norm if norm.is_file() else None,
                        env_id=args["env"], algo=str(args.get("algo") or "ppo"),
                        env_kwargs=env_kwargs,
                        eval_env_kwargs=dict(eval_kwargs) if eval_kwargs else None,
                        hyperparams=dict(hyper))


# ------------------------------------------------------------------------ reading the pickles
def read_vecnormalize(path: Path, obs_size: int) -> Any:
    """The VecNormalize statistics pickled in ``path`` (trusted), frozen (``training=False,
    norm_reward=False``); one :class:`AgentError` if the file is not statistics of
    ``obs_size`` observations."""
    from stable_baselines3.common.vec_env import VecNormalize

    label = _label(path)
    try:
        with open(path, "rb") as fh:
            vn = pickle.load(fh)  # noqa: S301 - trusted explicitly (require_trust)
    except Exception as exc:  # a pickle can fail in any way its content dictates
        raise AgentError(f"{label} cannot be read as VecNormalize statistics "
                         f"({_one_line(exc)})") from None
    if not isinstance(vn, VecNormalize):
        raise AgentError(f"{label} holds a {type(vn).__name__}, not VecNormalize statistics")
    # read the unpickled attributes from the instance itself: SB3's VecEnvWrapper looks a
    # missing one up on its (absent) wrapped environment and recurses without end
    state = vars(vn)
    if not isinstance(state.get("norm_obs"), bool):
        raise AgentError(f"{label} has no norm_obs flag (a VecNormalize without it cannot "
                         f"normalise)")
    rms = state.get("obs_rms")
    mean, var = getattr(rms, "mean", None), getattr(rms, "var", None)
    if not (isinstance(mean, np.ndarray) and isinstance(var, np.ndarray)):
        raise AgentError(f"{label} has no observation statistics (obs_rms.mean, obs_rms.var)")
    if mean.shape != (obs_size,) or var.shape != (obs_size,):
        raise AgentError(f"{label} holds statistics of {mean.shape} observations; the agent's "
                         f"observation has {obs_size} entries")
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(var)) and np.all(var >= 0)):
        raise AgentError(f"{label} holds non-finite or negative observation statistics")
    for key in ("clip_obs", "epsilon", "clip_reward", "gamma"):
        v = state.get(key)
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise AgentError(f"{label}: {key} must be > 0 (got {v!r})")
    if getattr(state.get("ret_rms"), "mean", None) is None:
        raise AgentError(f"{label} has no return statistics (ret_rms)")
    vn.training = False
    vn.norm_reward = False
    return vn


def _custom_objects(policy: Any) -> dict | None:
    """SB3 ``custom_objects`` for a config entry's policy: the network class by its current
    name (agents of the first wave pickled an older module path for it)."""
    from . import networks
    policy = str(policy or "")
    for path, name in networks.POLICIES.items():
        if path != name and policy.endswith(name):  # abb-gym's own classes, not SB3's aliases
            return {"policy_class": getattr(networks, name)}
    return None


def read_model(path: Path, algo: str, obs_size: int | None = None,
               action_size: int | None = None, custom_objects: dict | None = None) -> Any:
    """The SB3 model pickled in ``path`` (trusted; on the CPU), trained by ``algo``; one
    :class:`AgentError` if it cannot be read or its spaces are not ``obs_size`` observations
    and ``action_size`` actions (None: any)."""
    from .algorithms import ALGORITHMS, algorithm_class

    if algo not in ALGORITHMS:
        raise AgentError(f"{_label(path)}: unknown algorithm {algo!r} (one of "
                         f"{list(ALGORITHMS)})")
    algorithm = algorithm_class(algo)
    label = _label(path)
    try:
        model = algorithm.load(path, device="cpu", custom_objects=custom_objects)
    except Exception as exc:  # zip, pickle and torch errors: every one means a bad file
        raise AgentError(f"{label} cannot be read as an SB3 {ALGORITHMS[algo][1]} model "
                         f"({_one_line(exc)})") from None
    obs_shape = tuple(getattr(model.observation_space, "shape", None) or ())
    act_shape = tuple(getattr(model.action_space, "shape", None) or ())
    want_obs = obs_shape if obs_size is None else (obs_size,)
    want_act = act_shape if action_size is None else (action_size,)
    if len(obs_shape) != 1 or obs_shape != want_obs or len(act_shape) != 1 \
            or act_shape != want_act:
        raise AgentError(f"{label} is a model of observations {obs_shape} and actions "
                         f"{act_shape}; the agent's are ({obs_size or 'n'},) and "
                         f"({action_size or 'n'},)")
    return model


@dataclass
class LoadedPickles:
    """What :func:`load_pickled` read: the model, its statistics, and what the agent is."""

    model: Any
    vecnormalize: Any
    env_id: str
    algo: str
    run: dict[str, Any]            # a config.yml ``_run`` section (read or made up)
    entry: dict[str, Any]
    config: dict[str, Any]         # the whole config.yml (read or made up)
    observation_names: list[str] | None
    reward_weights: dict[str, float] | None
    best_model: Any = None         # an abb-gym folder's best model and statistics, if any
    best_vecnormalize: Any = None


def _environment(env_id: str, env_kwargs: Mapping[str, Any]) -> tuple[dict, list[str]]:
    """(the policy-relevant settings, the observation names) of the environment
    ``env_kwargs`` make."""
    from .env_factory import make_native_env, policy_env_fields
    kwargs = {k: v for k, v in env_kwargs.items() if k not in ("preset",)}
    kwargs["preset"] = env_kwargs.get("preset", "train")
    env = make_native_env(env_id, 1, kwargs)
    try:
        return policy_env_fields(env), [str(n) for n in env.unwrapped.setup.obs_names]
    finally:
        env.close()


def load_pickled(agent: PickledAgent, trust: bool | None = None, env_id: str | None = None,
                 env_kwargs: Mapping[str, Any] | None = None, best: bool = False,
                 with_best: bool = False) -> LoadedPickles:
    """Read a pickled agent, if trusted (:func:`~abb_gym.rl.agent_files.require_trust`;
    :class:`~abb_gym.rl.agent_files.PickleRefused` otherwise).  ``env_id`` and
    ``env_kwargs`` describe the environment of a plain SB3 model (which records neither);
    for the other kinds ``env_id``, when given, must be the agent's.  ``with_best``: an
    abb-gym folder's best model too (``best_model``), to convert it."""
    if agent.kind == "abb-gym":
        return _load_abb_gym(agent, trust, env_id, best, with_best)
    require_trust(agent.source, agent.pickles, trust)
    if agent.kind == "rl_zoo3":
        if env_id is not None and env_id != agent.env_id:
            raise AgentError(f"rl_zoo3 run {str(agent.source)!r} trained on {agent.env_id}, "
                             f"not {env_id}")
        env_id, kwargs = agent.env_id, agent.env_kwargs
        eval_kwargs = agent.eval_env_kwargs or kwargs
    else:
        if env_id is None:
            raise AgentError(f"a plain SB3 model ({str(agent.source)!r}) records no "
                             f"environment id: name it (--env)")
        kwargs = dict(env_kwargs or {})
        eval_kwargs = kwargs
    if agent.kind == "sb3" and env_kwargs is None:
        # nothing recorded and nothing given: the evaluation's environment is taken as the
        # agent's (shapes are still checked); convert-agent asks for the settings
        penv, names, weights = {}, None, None
    else:
        penv, names = _environment(env_id, kwargs)
        weights = evaluation_reward_weights(env_id, {"eval_env_kwargs": {
            **{k: v for k, v in eval_kwargs.items() if k != "preset"},
            "preset": eval_kwargs.get("preset", "test")}})
    size = len(names) if names is not None else None
    model = read_model(agent.model_path, agent.algo, size, None,
                       _custom_objects(agent.hyperparams.get("policy")))
    vn = (read_vecnormalize(agent.norm_path, model.observation_space.shape[0])
          if agent.norm_path is not None else None)
    entry = dict(agent.hyperparams) or {
        "policy": f"{type(model.policy).__module__}.{type(model.policy).__qualname__}"}
    entry.setdefault("normalize", vn is not None)
    entry["env_kwargs"] = dict(kwargs)
    run = {"env_id": env_id, "policy_env": penv, "eval_env_kwargs": dict(eval_kwargs),
           "converted_from": {"kind": agent.kind, "source": str(agent.source),
                              "model": agent.model_path.name,
                              "sha256": file_fingerprint(agent.model_path)["sha256"]}}
    config: dict[str, Any] = {env_id: entry, "_run": run}
    if agent.algo in ("sac", "tqc"):
        config["_abb_gym"] = {"algo": agent.algo}
    return LoadedPickles(model, vn, env_id, agent.algo, run, entry, config, names, weights)


def _load_abb_gym(agent: PickledAgent, trust: bool | None, env_id: str | None,
                  best: bool, with_best: bool) -> LoadedPickles:
    folder = agent.source
    if agent.manifest is not None:
        files = check_folder(folder, best=best)  # the fingerprints, before any unpickling
        config, run, entry = files.config, files.run, files.entry
        names = files.observation_names
        obs_size, act_size = files.manifest["observation"]["size"], files.manifest[
            "action_size"]
    else:
        from .agent_files import _read_config
        config, run, entry = _read_config(folder)
        names, obs_size, act_size = None, None, None
    if env_id is not None and env_id != run["env_id"]:
        raise ValueError(f"agent {str(folder)!r} was trained on {run['env_id']}, not {env_id}")
    from .agent_files import entry_algorithm
    algo = entry_algorithm(entry, config)
    prefixes = ["best_"] if best else [""] + (["best_"] if with_best else [])
    pickles = [p for prefix in prefixes
               for p in (folder / f"{prefix}model.zip", folder / f"{prefix}vecnormalize.pkl")
               if p.is_file()]
    require_trust(folder, pickles, trust)
    if names is None:
        penv = run["policy_env"]
        from .env_factory import make_native_env, observation_kwargs
        env = make_native_env(run["env_id"], 1, {"scene": penv["scene"], "preset": "test",
                                                 **observation_kwargs(penv)})
        try:
            names = [str(n) for n in env.unwrapped.setup.obs_names]
        finally:
            env.close()
        obs_size = len(names)
    custom = _custom_objects(entry.get("policy"))

    def pair(prefix: str):
        model = read_model(folder / f"{prefix}model.zip", algo, obs_size, act_size, custom)
        norm = folder / f"{prefix}vecnormalize.pkl"
        return model, (read_vecnormalize(norm, obs_size) if norm.is_file() else None)

    model, vn = pair("best_" if best else "")
    best_model = best_vn = None
    if with_best and not best and (folder / "best_model.zip").is_file():
        best_model, best_vn = pair("best_")
    weights = evaluation_reward_weights(run["env_id"], run, folder / "config.yml")
    return LoadedPickles(model, vn, run["env_id"], algo, run, entry, config, names, weights,
                         best_model, best_vn)


# ------------------------------------------------------------------------ converting
def convert_agent(source: str | Path, out: str | Path | None = None, *,
                  trust: bool | None = True, env_id: str | None = None,
                  env_kwargs: Mapping[str, Any] | None = None, algo: str | None = None,
                  remove_pickles: bool = False) -> Path:
    """Write the safe agent folder (:mod:`abb_gym.rl.agent_files`) of the pickled agent at
    ``source``; returns the folder.

    :param out: the new folder; None: ``source`` itself (an abb-gym folder only: its pickles
        stay beside the new files unless ``remove_pickles``).
    :param trust: converting reads the pickles, so it needs them trusted; the default says
        that whoever converts trusts them (``abb-gym convert-agent`` is that statement).
    :param env_id, env_kwargs: the environment of a plain SB3 model (which records neither).
    :param algo: the algorithm of a plain SB3 model (default ``ppo``).
    """
    from .policy_files import (NORMALIZATION_FILE, OPTIMIZER_FILE, POLICY_FILE,
                               save_normalization, save_optimizer, save_policy)

    source = Path(source)
    agent = find_pickled(source)
    if agent is None:
        raise AgentError(f"{str(source)!r} is not a pickled agent (an abb-gym folder with "
                         f"model.zip, an rl_zoo3 run folder or an SB3 model.zip)")
    if algo is not None:
        agent.algo = algo
    loaded = load_pickled(agent, trust, env_id, env_kwargs, with_best=True)
    target = Path(out) if out is not None else None
    if target is None:
        if agent.kind != "abb-gym":
            raise AgentError(f"{str(source)!r} is an {agent.kind} model: give the new folder "
                             f"(--out)")
        target = agent.source
    target.mkdir(parents=True, exist_ok=True)
    if target.resolve() != Path(agent.source).resolve() and agent.source.is_dir():
        if agent.kind == "abb-gym":  # its reports travel with it; its pickles do not
            for p in agent.source.iterdir():
                if p.is_file() and p.suffix not in (".zip", ".pkl") and p.name != MANIFEST:
                    shutil.copy2(p, target / p.name)
    if agent.kind != "abb-gym" or not (target / "config.yml").is_file():
        import yaml

        from .._files import write_text
        write_text(target / "config.yml", yaml.safe_dump(_yaml_data(loaded.config),
                                                         sort_keys=False))
    kind = loaded.run["policy_env"].get("kind")

    def write(prefix: str, model: Any, vn: Any) -> None:
        save_policy(model.policy, target / f"{prefix}{POLICY_FILE}", loaded.env_id, kind,
                    loaded.algo)
        if getattr(model.policy, "optimizer", None) is not None:
            save_optimizer(model.policy.optimizer, target / f"{prefix}{OPTIMIZER_FILE}")
        if vn is not None:
            save_normalization(vn, target / f"{prefix}{NORMALIZATION_FILE}")

    write("", loaded.model, loaded.vecnormalize)
    if loaded.best_model is not None:
        write("best_", loaded.best_model, loaded.best_vecnormalize)
    write_manifest(target, loaded.observation_names, loaded.reward_weights,
                   normalised=loaded.vecnormalize is not None)
    if remove_pickles and target.resolve() == Path(agent.source).resolve():
        for name in ("model.zip", "vecnormalize.pkl", "best_model.zip",
                     "best_vecnormalize.pkl"):
            (target / name).unlink(missing_ok=True)
    return target


def _yaml_data(obj: Any) -> Any:
    """``obj`` with tuples as lists and NumPy scalars as numbers (safe_dump writes them)."""
    if isinstance(obj, Mapping):
        return {str(k): _yaml_data(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_yaml_data(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj
