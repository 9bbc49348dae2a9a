"""What an agent folder must hold, and the checks that make a bad one fail with one line.

An agent folder (a run folder of ``abb-gym train``, or a shipped agent in ``agents/trained``)::

    model.zip              SB3 PPO model
    vecnormalize.pkl       its VecNormalize statistics (absent iff trained without them)
    config.yml             the training config and, under ``_run``, the env id and the
                           policy-relevant environment settings (``policy_env``: scene, ...)
    agent.yml              the manifest (below)
    best_model.zip,        optional: the best model during training (``best=True``)
    best_vecnormalize.pkl

The manifest records what the files are and what the observation normalisation was fitted
on, when the agent was saved (:func:`write_manifest`; ``abb-gym train`` writes it)::

    format: 1
    env_id: abb_gym/RunUpSpeed-v0        # = config.yml _run.env_id
    scene: yoshida_odd                   # = config.yml _run.policy_env.scene
    observation:                         # the layout the statistics were fitted on
      size: 6
      names: [rotor_speed, vibration_x, vibration_y, vibration_amplitude, time_fraction,
              'last_action[0]']
    action_size: 1
    vecnormalize: true                   # the agent needs vecnormalize.pkl
    files:                               # fingerprints: size [bytes] and sha256
      model.zip: {bytes: 149613, sha256: 7f0c...}
      vecnormalize.pkl: {bytes: 2572, sha256: 91ab...}

:func:`check_folder` runs, in this order, and the first failure is one :class:`AgentError`
(a ``ValueError``: ``abb-gym`` prints it as one line) naming the file and what is wrong:

1. ``config.yml`` exists and is a YAML mapping with a ``_run`` section (``env_id``,
   ``policy_env`` with ``scene``) and a mapping under the env id;
2. ``agent.yml`` exists, is well formed and agrees with ``config.yml`` (env id, scene);
3. the model (and, if recorded, the statistics) exist as regular files whose size and sha256
   equal the manifest's; a statistics file the manifest does not expect is refused.

So a deleted, truncated, replaced or foreign file is refused before anything is unpickled.
:func:`load_vecnormalize` and :func:`load_model` then read the files, turning every failure
into one line too, and check the statistics' and the model's sizes against the manifest.
Pickles run code when read: load only agents you trust (the fingerprints catch accidents,
not an attacker who rewrites the manifest as well).

For a folder saved before manifests existed, check the files by hand, then::

    python -m abb_gym.rl.agent_files FOLDER [FOLDER ...]
"""
from __future__ import annotations

import hashlib
import math
import pickle
import re
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import yaml

from ..configuration import ConfigError, read_yaml

__all__ = ["AgentError", "AgentFiles", "MANIFEST", "FORMAT", "check_folder",
           "load_vecnormalize", "load_model", "write_manifest", "file_fingerprint"]

MANIFEST = "agent.yml"
FORMAT = 1
_HEX64 = re.compile(r"[0-9a-f]{64}")


class AgentError(ConfigError):
    """An agent folder is incomplete or inconsistent (the message names the file)."""


@dataclass
class AgentFiles:
    """A checked agent folder (:func:`check_folder`)."""

    folder: Path
    config: dict[str, Any]        # the whole config.yml
    run: dict[str, Any]           # its _run section
    entry: dict[str, Any]         # its hyperparameters under the env id
    manifest: dict[str, Any]      # agent.yml
    model_path: Path
    norm_path: Path | None        # None: the agent has no normalisation statistics

    @property
    def env_id(self) -> str:
        return self.manifest["env_id"]

    @property
    def observation_names(self) -> list[str]:
        return list(self.manifest["observation"]["names"])

    @property
    def algo(self) -> str:
        """The algorithm that trained the model (rl_zoo3's ``--algo`` name)."""
        return entry_algorithm(self.entry, self.config)


def entry_algorithm(entry: Mapping[str, Any], data: Mapping[str, Any] | None = None) -> str:
    """The algorithm of a config entry: ``_abb_gym.algo`` of the whole file ``data`` if set,
    else the one its ``policy`` implies (``ppo``, ``ppo_lstm``)."""
    from .algorithms import algorithm_of
    from .config import section_algorithm
    return algorithm_of(str(entry.get("policy", "MlpPolicy")), section_algorithm(data or {}))


def _label(path: Path) -> str:
    return f"agent file {str(path)!r}"


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def file_fingerprint(path: Path) -> dict[str, Any]:
    """``{"bytes": size, "sha256": hex digest}`` of a file."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return {"bytes": path.stat().st_size, "sha256": h.hexdigest()}


# ------------------------------------------------------------------------ config.yml
def _read_config(folder: Path) -> tuple[dict, dict, dict]:
    path = folder / "config.yml"
    data = dict(read_yaml(path, "agent config", AgentError))
    where = f"agent config file {str(path)!r}"
    run = data.get("_run")
    if not isinstance(run, Mapping):
        raise AgentError(f"{where} has no '_run' mapping (the env id and environment settings "
                         f"the agent was trained with)")
    env_id = run.get("env_id")
    if not isinstance(env_id, str) or not env_id:
        raise AgentError(f"{where}: '_run.env_id' must be an environment id (got {env_id!r})")
    penv = run.get("policy_env")
    if not isinstance(penv, Mapping) or not isinstance(penv.get("scene"), str):
        raise AgentError(f"{where}: '_run.policy_env' must be a mapping with the training "
                         f"'scene' (got {penv!r})")
    entry = data.get(env_id)
    if not isinstance(entry, Mapping):
        raise AgentError(f"{where} has no hyperparameter mapping under its env id {env_id!r}")
    return data, dict(run), dict(entry)


# ------------------------------------------------------------------------ agent.yml
def _read_manifest(folder: Path) -> dict[str, Any]:
    path = folder / MANIFEST
    if not path.exists() and not path.is_symlink():
        raise AgentError(f"agent folder {str(folder)!r} has no {MANIFEST} (the record of its "
                         f"files and of what its normalisation was fitted on); for a folder "
                         f"saved before abb-gym wrote one, check its files, then run "
                         f"'python -m abb_gym.rl.agent_files {shlex.quote(str(folder))}'")
    data = dict(read_yaml(path, "agent manifest", AgentError))
    where = f"agent manifest file {str(path)!r}"

    def fail(key: str, what: str, got: Any = None) -> None:
        got = _get(data, key) if got is None else got
        raise AgentError(f"{where}: {key!r} must be {what} (got {got!r})")

    if data.get("format") != FORMAT or isinstance(data.get("format"), bool):
        fail("format", f"{FORMAT} (this abb-gym reads format {FORMAT})")
    for key in ("env_id", "scene"):
        if not isinstance(data.get(key), str) or not data[key]:
            fail(key, "a non-empty text")
    obs = data.get("observation")
    if not isinstance(obs, Mapping):
        fail("observation", "a mapping with 'size' and 'names'")
    size = obs.get("size")
    if not _is_count(size):
        fail("observation.size", "an integer >= 1")
    names = obs.get("names")
    if (not isinstance(names, list) or len(names) != size
            or not all(isinstance(n, str) for n in names)):
        fail("observation.names", f"a list of {size} names")
    if not _is_count(data.get("action_size")):
        fail("action_size", "an integer >= 1")
    if not isinstance(data.get("vecnormalize"), bool):
        fail("vecnormalize", "true or false")
    files = data.get("files")
    if not isinstance(files, Mapping) or "model.zip" not in files:
        fail("files", "a mapping of file names to fingerprints, with model.zip")
    for name, fp in files.items():
        if (not isinstance(fp, Mapping) or not _is_count(fp.get("bytes"), 0)
                or not isinstance(fp.get("sha256"), str) or not _HEX64.fullmatch(fp["sha256"])):
            fail(f"files.{name}", "{bytes: size, sha256: 64 hex digits}", fp)
    if data["vecnormalize"] and "vecnormalize.pkl" not in files:
        fail("files", "a mapping that includes vecnormalize.pkl (vecnormalize is true)")
    return data


def _get(data: Mapping, dotted: str) -> Any:
    node: Any = data
    for part in dotted.split("."):
        if not isinstance(node, Mapping):
            return None
        node = node.get(part)
    return node


def _is_count(value: Any, minimum: int = 1) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= minimum


def _check_file(path: Path, fingerprint: Mapping[str, Any], what: str) -> None:
    label = _label(path)
    if not path.exists():
        raise AgentError(f"{label} is missing ({what}; {MANIFEST} records it)")
    if path.is_dir():
        raise AgentError(f"{label} is a directory, not a file ({what})")
    if not path.is_file():
        raise AgentError(f"{label} is not a regular file ({what})")
    size = path.stat().st_size
    if size == 0:
        raise AgentError(f"{label} is empty ({what}; {MANIFEST} records "
                         f"{fingerprint['bytes']} bytes)")
    if size != fingerprint["bytes"]:
        raise AgentError(f"{label} has {size} bytes, {MANIFEST} records "
                         f"{fingerprint['bytes']}: truncated or replaced ({what})")
    digest = file_fingerprint(path)["sha256"]
    if digest != fingerprint["sha256"]:
        raise AgentError(f"{label} is not the file the agent was saved with: its sha256 "
                         f"{digest[:12]}... differs from {fingerprint['sha256'][:12]}... in "
                         f"{MANIFEST} (modified, or another agent's {what})")


def check_folder(folder: str | Path, best: bool = False) -> AgentFiles:
    """Check an agent folder's files (see the module docstring); nothing is unpickled.

    :param best: check ``best_model.zip`` / ``best_vecnormalize.pkl`` instead of the final
        model and statistics.
    """
    folder = Path(folder)
    data, run, entry = _read_config(folder)
    manifest = _read_manifest(folder)
    where = f"agent manifest file {str(folder / MANIFEST)!r}"
    if manifest["env_id"] != run["env_id"]:
        raise AgentError(f"{where} records env id {manifest['env_id']!r}, config.yml "
                         f"{run['env_id']!r}: the files are from different agents")
    if manifest["scene"] != run["policy_env"]["scene"]:
        raise AgentError(f"{where} records scene {manifest['scene']!r}, config.yml "
                         f"{run['policy_env']['scene']!r}: the files are from different agents")
    prefix = "best_" if best else ""
    model_name, norm_name = f"{prefix}model.zip", f"{prefix}vecnormalize.pkl"
    files = manifest["files"]
    if model_name not in files:
        raise AgentError(f"{where} records no {model_name} (it lists {sorted(files)})")
    model_path = folder / model_name
    _check_file(model_path, files[model_name], "the PPO model")
    norm_path = folder / norm_name
    if manifest["vecnormalize"]:
        if norm_name not in files:
            raise AgentError(f"{where} records no {norm_name} for {model_name}")
        if not norm_path.exists():
            raise AgentError(f"{_label(norm_path)} is missing: the agent was trained on "
                             f"normalised observations and would act on raw ones without "
                             f"these statistics")
        _check_file(norm_path, files[norm_name], "the observation normalisation statistics")
    else:
        if norm_path.exists():
            raise AgentError(f"{_label(norm_path)} does not belong to this agent: {MANIFEST} "
                             f"records that it was trained without normalisation")
        norm_path = None
    return AgentFiles(folder, data, run, entry, manifest, model_path, norm_path)


# ------------------------------------------------------------------------ reading the files
def load_vecnormalize(path: Path, obs_size: int) -> Any:
    """The VecNormalize statistics in ``path``, frozen (``training=False,
    norm_reward=False``); one :class:`AgentError` if the file is not statistics of
    ``obs_size`` observations."""
    from stable_baselines3.common.vec_env import VecNormalize

    label = _label(path)
    try:
        with open(path, "rb") as fh:
            vn = pickle.load(fh)
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
                         f"observation has {obs_size} entries ({MANIFEST})")
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(var)) and np.all(var >= 0)):
        raise AgentError(f"{label} holds non-finite or negative observation statistics")
    clip, eps = state.get("clip_obs"), state.get("epsilon")
    if not all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in (clip, eps)):
        raise AgentError(f"{label}: clip_obs and epsilon must be > 0 (got {clip!r}, {eps!r})")
    vn.training = False
    vn.norm_reward = False
    return vn


def load_model(path: Path, obs_size: int, action_size: int | None = None,
               custom_objects: dict | None = None, algo: str = "ppo") -> Any:
    """The SB3 model in ``path`` (on the CPU), trained by ``algo`` (``ppo``, or ``ppo_lstm``:
    RecurrentPPO); one :class:`AgentError` if it cannot be read or its spaces are not
    ``obs_size`` observations and ``action_size`` actions (None: any)."""
    from .algorithms import ALGORITHMS, algorithm_class

    algorithm = algorithm_class(algo)
    label = _label(path)
    try:
        model = algorithm.load(path, device="cpu", custom_objects=custom_objects)
    except Exception as exc:  # zip, pickle and torch errors: every one means a bad file
        raise AgentError(f"{label} cannot be read as an SB3 {ALGORITHMS[algo][1]} model "
                         f"({_one_line(exc)})") from None
    obs_shape = tuple(getattr(model.observation_space, "shape", None) or ())
    act_shape = tuple(getattr(model.action_space, "shape", None) or ())
    want_act = act_shape if action_size is None else (action_size,)
    if obs_shape != (obs_size,) or len(act_shape) != 1 or act_shape != want_act:
        raise AgentError(f"{label} is a model of observations {obs_shape} and actions "
                         f"{act_shape}; the agent's are ({obs_size},) and "
                         f"({action_size or 'n'},)")
    return model


def custom_objects_for(entry: Mapping[str, Any]) -> dict | None:
    """SB3 ``custom_objects`` for a config entry: the network class by its current name
    (agents of the first wave pickled an older module path for it)."""
    from . import networks
    policy = str(entry.get("policy", ""))
    for path, name in networks.POLICIES.items():
        if path != name and policy.endswith(name):  # abb-gym's own classes, not SB3's aliases
            return {"policy_class": getattr(networks, name)}
    return None


# ------------------------------------------------------------------------ writing
def _observation_names(env_id: str, policy_env: Mapping[str, Any]) -> list[str]:
    from .env_factory import make_native_env, observation_kwargs
    env = make_native_env(env_id, 1, {"scene": policy_env["scene"], "preset": "test",
                                      **observation_kwargs(policy_env)})
    try:
        return [str(n) for n in env.unwrapped.setup.obs_names]
    finally:
        env.close()


def write_manifest(folder: str | Path, observation_names: Sequence[str] | None = None
                   ) -> Path:
    """Write ``agent.yml`` for the files in ``folder`` as they are now, after checking that
    they are readable and consistent (config, model, statistics); returns its path.

    :param observation_names: the observation layout of the training environment; None
        builds the environment from ``config.yml`` to read it.
    """
    from .config import load_config

    folder = Path(folder)
    data, run, entry = _read_config(folder)
    env_id, penv = run["env_id"], run["policy_env"]
    try:
        normalised = load_config(folder / "config.yml", env_id).normalize is not None
    except ValueError as exc:
        raise AgentError(f"agent config file {str(folder / 'config.yml')!r}: {exc}") from None
    names = (list(observation_names) if observation_names is not None
             else _observation_names(env_id, penv))
    custom = custom_objects_for(entry)
    files: dict[str, Any] = {}
    action_size = None
    for prefix in ("", "best_"):
        model_path = folder / f"{prefix}model.zip"
        norm_path = folder / f"{prefix}vecnormalize.pkl"
        if prefix and not model_path.exists():
            continue
        if not model_path.is_file():
            raise AgentError(f"{_label(model_path)} is missing or not a file")
        model = load_model(model_path, len(names), action_size, custom,
                           entry_algorithm(entry, data))
        action_size = int(model.action_space.shape[0])
        files[model_path.name] = file_fingerprint(model_path)
        if normalised:
            if not norm_path.is_file():
                raise AgentError(f"{_label(norm_path)} is missing or not a file, but "
                                 f"config.yml trains with normalisation")
            load_vecnormalize(norm_path, len(names))
            files[norm_path.name] = file_fingerprint(norm_path)
        elif norm_path.exists():
            raise AgentError(f"{_label(norm_path)} exists, but config.yml trains without "
                             f"normalisation")
    manifest = {"format": FORMAT, "env_id": env_id, "scene": penv["scene"],
                "observation": {"size": len(names), "names": names},
                "action_size": action_size, "vecnormalize": normalised, "files": files}
    header = ("# abb-gym agent manifest: the files of this agent and what its observation\n"
              "# normalisation was fitted on (abb_gym.rl.agent_files; checked on load).\n")
    path = folder / MANIFEST
    path.write_text(header + yaml.safe_dump(manifest, sort_keys=False))
    return path


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m abb_gym.rl.agent_files FOLDER...``: write each folder's manifest."""
    import argparse
    p = argparse.ArgumentParser(prog="python -m abb_gym.rl.agent_files",
                                description="write agent.yml for agent folders you trust")
    p.add_argument("folders", nargs="+", type=Path)
    args = p.parse_args(argv)
    for folder in args.folders:
        try:
            print(f"wrote {write_manifest(folder)}")
        except ValueError as exc:
            print(f"agent_files: error: {exc}", file=sys.stderr)
            return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
