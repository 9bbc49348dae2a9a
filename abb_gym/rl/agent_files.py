"""What an agent folder must hold, and the checks that make a bad one fail with one line.

An agent folder (a run folder of ``abb-gym train``, or a shipped agent in ``agents/trained``)
holds data only: nothing in it is unpickled, so loading a folder from a stranger cannot run
code (:mod:`abb_gym.rl.policy_files`)::

    policy.safetensors     the network: weights, and in the file's metadata its class,
                           keywords and spaces, the env id, action kind and algorithm
    vecnormalize.json      its observation normalisation statistics (absent iff trained
                           without normalisation)
    optimizer.safetensors  optional: the optimiser's state, for a warm start (``init_from``)
    config.yml             the training config and, under ``_run``, the env id and the
                           policy-relevant environment settings (``policy_env``: scene, ...)
    agent.yml              the manifest (below)
    best_policy.safetensors, best_vecnormalize.json, best_optimizer.safetensors
                           optional: the best model during training (``best=True``)

The manifest records what the agent is and what its files are (:func:`write_manifest`;
``abb-gym train`` and ``abb-gym convert-agent`` write it)::

    format: 2
    env_id: abb_gym/RunUpSpeed-v0        # = config.yml _run.env_id = the policy file's
    action_kind: speed                   # = config.yml _run.policy_env.kind = the policy file's
    scene: yoshida_odd                   # = config.yml _run.policy_env.scene
    algo: ppo                            # = the policy file's
    observation:                         # the layout the statistics were fitted on
      size: 6
      names: [rotor_speed, vibration_x, vibration_y, vibration_amplitude, time_fraction,
              'last_action[0]']
    action_size: 1
    reward_weights: {vibration: 1.0, time: 1.0, effort: 0.1, residual: 6.0, failure: 10.0}
    vecnormalize: true                   # the agent needs vecnormalize.json
    files:                               # fingerprints: size [bytes] and sha256
      policy.safetensors: {bytes: 43920, sha256: 7f0c...}
      vecnormalize.json: {bytes: 1032, sha256: 91ab...}

``reward_weights`` are the weights of the agent's held-out evaluation (its config's
evaluation environment, resolved over the preset): the return its ``evaluation.json``
reports, and the one ``abb-gym evaluate`` scores it with unless told otherwise.

:func:`check_folder` runs, in this order, and the first failure is one :class:`AgentError`
(a ``ValueError``: ``abb-gym`` prints it as one line) naming the file and what is wrong:

1. ``config.yml`` exists and is a YAML mapping with a ``_run`` section (``env_id``,
   ``policy_env`` with ``scene``) and a mapping under the env id;
2. ``agent.yml`` exists, is well formed and agrees with ``config.yml`` (env id, scene,
   action kind);
3. the files exist as regular files whose size and sha256 equal the manifest's; a statistics
   file the manifest does not expect is refused.

Reading the files (:func:`abb_gym.rl.agent.load_policy`) then checks that the policy file was
made for the folder's env id, action kind and algorithm: a model copied in from another
agent is refused by name, whatever its size.  The fingerprints catch accidents, not an
attacker who rewrites the manifest as well, which is why nothing here may run code.

**Pickled agents** (abb-gym's first format, ``agent.yml`` ``format: 1`` with ``model.zip`` and
``vecnormalize.pkl``; a plain SB3 ``model.zip``; an rl_zoo3 run folder) are programs as much
as data.  They load only when trusted explicitly (:func:`pickle_trusted`: ``--trust-pickle``
or ``ABB_GYM_TRUST_PICKLE=1``, with a one-line warning naming the files); otherwise one line
refuses them and says how to convert a folder you trust once, for good (``abb-gym
convert-agent``, :mod:`abb_gym.rl.legacy`).
"""
from __future__ import annotations

import hashlib
import os
import re
import shlex
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import yaml

from ..configuration import read_yaml
from ..resources import TRUST_PICKLE_ENV
from .errors import AgentError

__all__ = ["AgentError", "PickleRefused", "TrustedPickleWarning", "AgentFiles", "MANIFEST",
           "FORMAT", "LEGACY_FORMAT", "TRUST_ENV", "check_folder", "write_manifest",
           "file_fingerprint", "pickle_trusted", "require_trust", "evaluation_reward_weights",
           "policy_file_names"]

MANIFEST = "agent.yml"
FORMAT = 2
#: the first format: model.zip and vecnormalize.pkl (pickles), read only when trusted
LEGACY_FORMAT = 1
#: the environment variable that trusts pickled agent files (as ``--trust-pickle`` does)
TRUST_ENV = TRUST_PICKLE_ENV
_HEX64 = re.compile(r"[0-9a-f]{64}")
_REWARD_KEYS = ("vibration", "time", "effort", "residual", "failure")
# the reward's unit of length [m], recorded where the agent's preset sets one (SpinRedistribute)
_REWARD_UNIT = "length_scale"


class PickleRefused(AgentError):
    """Pickled agent files, not trusted (the message says how to convert or trust them)."""


class TrustedPickleWarning(UserWarning):
    """Pickled agent files are being loaded because they were trusted explicitly."""


def policy_file_names(best: bool = False, format: int = FORMAT) -> tuple[str, str, str]:
    """(policy, statistics, optimiser) file names of a folder of ``format``."""
    prefix = "best_" if best else ""
    if format == LEGACY_FORMAT:
        return f"{prefix}model.zip", f"{prefix}vecnormalize.pkl", ""
    return (f"{prefix}policy.safetensors", f"{prefix}vecnormalize.json",
            f"{prefix}optimizer.safetensors")


@dataclass
class AgentFiles:
    """A checked agent folder (:func:`check_folder`)."""

    folder: Path
    config: dict[str, Any]        # the whole config.yml
    run: dict[str, Any]           # its _run section
    entry: dict[str, Any]         # its hyperparameters under the env id
    manifest: dict[str, Any]      # agent.yml
    model_path: Path              # policy.safetensors (format 2) or model.zip (format 1)
    norm_path: Path | None        # None: the agent has no normalisation statistics
    optimizer_path: Path | None = None  # format 2, when recorded

    @property
    def format(self) -> int:
        return int(self.manifest["format"])

    @property
    def env_id(self) -> str:
        return self.manifest["env_id"]

    @property
    def observation_names(self) -> list[str]:
        return list(self.manifest["observation"]["names"])

    @property
    def algo(self) -> str:
        """The algorithm that trained the model (rl_zoo3's ``--algo`` name)."""
        return self.manifest.get("algo") or entry_algorithm(self.entry, self.config)

    @property
    def action_kind(self) -> str | None:
        return self.manifest.get("action_kind") or self.run["policy_env"].get("kind")

    @property
    def reward_weights(self) -> dict[str, float] | None:
        weights = self.manifest.get("reward_weights")
        return dict(weights) if weights is not None else None

    @property
    def pickles(self) -> list[Path]:
        """The files of this folder that are pickles (format 1)."""
        if self.format != LEGACY_FORMAT:
            return []
        return [p for p in (self.model_path, self.norm_path) if p is not None]


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
    return {"bytes": Path(path).stat().st_size, "sha256": h.hexdigest()}


# ------------------------------------------------------------------------ trust
def pickle_trusted(trust: bool | None = None) -> bool:
    """Whether pickled agent files may be loaded: ``trust`` if given, else the environment
    variable :data:`TRUST_ENV` (``1``, ``true`` or ``yes``)."""
    if trust is not None:
        return bool(trust)
    return os.environ.get(TRUST_ENV, "").strip().lower() in ("1", "true", "yes")


def require_trust(source: Path, pickles: Sequence[Path], trust: bool | None = None,
                  convert: str | None = None) -> None:
    """Refuse (:class:`PickleRefused`, one line saying how to convert) to load ``pickles``
    of the agent at ``source`` unless trusted (:func:`pickle_trusted`); when trusted, warn
    once, naming the files (:class:`TrustedPickleWarning`).  ``convert``: the conversion
    command to suggest (default ``abb-gym convert-agent SOURCE``)."""
    names = ", ".join(str(p) for p in pickles)
    if not pickle_trusted(trust):
        how = convert or f"abb-gym convert-agent {shlex.quote(str(source))}"
        raise PickleRefused(f"agent {str(source)!r} is stored as pickles ({names}), which run "
                            f"any code they contain when loaded; if you trust them, convert "
                            f"them once to the safe format with `{how}`, or load them as they "
                            f"are with --trust-pickle (or {TRUST_ENV}=1)")
    if names not in _WARNED:  # once per process and files (loaders run once per task)
        _WARNED.add(names)
        warnings.warn(f"loading pickled agent files, trusted explicitly (they can run code): "
                      f"{names}", TrustedPickleWarning, stacklevel=3)


_WARNED: set[str] = set()


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
        hint = (f"its model.zip is a pickle from before manifests: convert a folder you trust "
                f"with `abb-gym convert-agent {shlex.quote(str(folder))}`"
                if (folder / "model.zip").is_file() else
                "`abb-gym train` and `abb-gym convert-agent` write it")
        raise AgentError(f"agent folder {str(folder)!r} has no {MANIFEST} (the record of its "
                         f"files and of what the agent is); {hint}")
    data = dict(read_yaml(path, "agent manifest", AgentError))
    where = f"agent manifest file {str(path)!r}"

    def fail(key: str, what: str, got: Any = None) -> None:
        got = _get(data, key) if got is None else got
        raise AgentError(f"{where}: {key!r} must be {what} (got {got!r:.200})")

    fmt = data.get("format")
    if isinstance(fmt, bool) or fmt not in (FORMAT, LEGACY_FORMAT):
        fail("format", f"{FORMAT} (this abb-gym reads format {FORMAT}, and format "
                       f"{LEGACY_FORMAT} when trusted)")
    for key in ("env_id", "scene") + (("action_kind", "algo") if fmt == FORMAT else ()):
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
    if fmt == FORMAT:
        weights = data.get("reward_weights")
        if (not isinstance(weights, Mapping)
                or set(weights) - {_REWARD_UNIT} != set(_REWARD_KEYS)
                or not all(_is_weight(v) for v in weights.values())
                or weights.get(_REWARD_UNIT, 1.0) == 0):
            fail("reward_weights", f"a mapping of {', '.join(_REWARD_KEYS)} to numbers >= 0 "
                                   f"(and optionally {_REWARD_UNIT}, > 0 [m])")
    if not isinstance(data.get("vecnormalize"), bool):
        fail("vecnormalize", "true or false")
    model_name, norm_name, _ = policy_file_names(format=fmt)
    files = data.get("files")
    if not isinstance(files, Mapping) or model_name not in files:
        fail("files", f"a mapping of file names to fingerprints, with {model_name}")
    for name, fp in files.items():
        if (not isinstance(fp, Mapping) or not _is_count(fp.get("bytes"), 0)
                or not isinstance(fp.get("sha256"), str) or not _HEX64.fullmatch(fp["sha256"])):
            fail(f"files.{name}", "{bytes: size, sha256: 64 hex digits}", fp)
    if data["vecnormalize"] and norm_name not in files:
        fail("files", f"a mapping that includes {norm_name} (vecnormalize is true)")
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


def _is_weight(value: Any) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool)
            and 0.0 <= value < float("inf"))


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
    """Check an agent folder's files (see the module docstring); nothing is read but the
    YAML files and the files' bytes for their fingerprints.

    :param best: check the best model's files (``best_policy.safetensors``, ...) instead of
        the final model's.
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
    kind = run["policy_env"].get("kind")
    if manifest.get("action_kind") is not None and kind is not None \
            and manifest["action_kind"] != kind:
        raise AgentError(f"{where} records action kind {manifest['action_kind']!r}, config.yml "
                         f"{kind!r}: the files are from different agents")
    fmt = manifest["format"]
    model_name, norm_name, opt_name = policy_file_names(best, fmt)
    files = manifest["files"]
    if model_name not in files:
        raise AgentError(f"{where} records no {model_name} (it lists {sorted(files)})")
    model_path = folder / model_name
    _check_file(model_path, files[model_name], "the policy" if fmt == FORMAT else
                "the PPO model")
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
    opt_path = None
    if opt_name and opt_name in files:
        opt_path = folder / opt_name
        _check_file(opt_path, files[opt_name], "the optimiser's state")
    return AgentFiles(folder, data, run, entry, manifest, model_path, norm_path, opt_path)


# ------------------------------------------------------------------------ writing
def evaluation_reward_weights(env_id: str, run: Mapping[str, Any],
                              config_path: str | Path | None = None) -> dict[str, float]:
    """The resolved reward weights of an agent's held-out evaluation: its ``_run`` section's
    ``eval_env_kwargs`` (else the evaluation environment of its config file) over the preset
    they name (default ``test``)."""
    from .env_factory import eval_env_kwargs, make_native_env
    from .config import load_config
    kwargs = run.get("eval_env_kwargs")
    if not isinstance(kwargs, Mapping):
        if config_path is None:
            raise AgentError(f"no evaluation environment recorded for the agent of {env_id}")
        kwargs = eval_env_kwargs(load_config(config_path, env_id))
    kwargs = dict(kwargs)
    kwargs.setdefault("preset", "test")
    env = make_native_env(env_id, 1, kwargs)
    try:
        reward = env.unwrapped.setup.config.to_dict()["reward"]
    finally:
        env.close()
    out = {k: float(reward[k]) for k in _REWARD_KEYS}
    if reward.get(_REWARD_UNIT) is not None:
        out[_REWARD_UNIT] = float(reward[_REWARD_UNIT])
    return out


def write_manifest(folder: str | Path, observation_names: Sequence[str] | None = None,
                   reward_weights: Mapping[str, float] | None = None,
                   normalised: bool | None = None) -> Path:
    """Write ``agent.yml`` (format 2) for the files in ``folder`` as they are now, after
    checking that they are readable and consistent (config, policy files, statistics);
    returns its path.  Nothing is unpickled.

    :param observation_names: the observation layout of the training environment; None
        builds the environment from ``config.yml`` to read it.
    :param reward_weights: the agent's evaluation weights; None: from ``config.yml``
        (:func:`evaluation_reward_weights`).
    :param normalised: whether the agent normalises observations; None: as ``config.yml``
        trains (its ``normalize``).
    """
    from .config import load_config
    from .env_factory import make_native_env, observation_kwargs
    from .policy_files import load_normalization, policy_metadata

    folder = Path(folder)
    data, run, entry = _read_config(folder)
    env_id, penv = run["env_id"], run["policy_env"]
    config_file = folder / "config.yml"
    if normalised is None:
        try:
            normalised = load_config(config_file, env_id).normalize is not None
        except ValueError as exc:
            raise AgentError(f"agent config file {str(config_file)!r}: {exc}") from None
    if observation_names is None:
        env = make_native_env(env_id, 1, {"scene": penv["scene"], "preset": "test",
                                          **observation_kwargs(penv)})
        try:
            observation_names = [str(n) for n in env.unwrapped.setup.obs_names]
        finally:
            env.close()
    names = list(observation_names)
    weights = (dict(reward_weights) if reward_weights is not None
               else evaluation_reward_weights(env_id, run, config_file))
    from .algorithms import POLICY_NAMES
    # the config names the algorithm when its policy is one abb-gym names (a converted plain
    # SB3 model's entry names the class it had); the policy file always does
    algo = (entry_algorithm(entry, data) if str(entry.get("policy")) in POLICY_NAMES
            else None)
    kind = penv.get("kind")
    files: dict[str, Any] = {}
    action_size = None
    for best in (False, True):
        model_name, norm_name, opt_name = policy_file_names(best)
        model_path, norm_path = folder / model_name, folder / norm_name
        if best and not model_path.exists():
            continue
        if not model_path.is_file():
            raise AgentError(f"{_label(model_path)} is missing or not a file")
        meta = policy_metadata(model_path)
        for key, want in (("env_id", env_id), ("action_kind", kind), ("algo", algo)):
            if want is not None and meta[key] != want:
                raise AgentError(f"{_label(model_path)} is a policy for {key} "
                                 f"{meta[key]!r}, config.yml says {want!r}")
        kind, algo = meta["action_kind"], meta["algo"]
        obs_shape = meta["policy"]["observation_space"]["shape"]
        act_shape = meta["policy"]["action_space"]["shape"]
        if obs_shape != [len(names)] or len(act_shape) != 1 or (
                action_size is not None and act_shape != [action_size]):
            raise AgentError(f"{_label(model_path)} is a policy of observations {obs_shape} "
                             f"and actions {act_shape}; the agent observes {len(names)} "
                             f"entries")
        action_size = act_shape[0]
        files[model_name] = file_fingerprint(model_path)
        if normalised:
            if not norm_path.is_file():
                raise AgentError(f"{_label(norm_path)} is missing or not a file, but "
                                 f"config.yml trains with normalisation")
            load_normalization(norm_path, len(names))
            files[norm_name] = file_fingerprint(norm_path)
        elif norm_path.exists():
            raise AgentError(f"{_label(norm_path)} exists, but config.yml trains without "
                             f"normalisation")
        if (folder / opt_name).is_file():
            files[opt_name] = file_fingerprint(folder / opt_name)
    manifest = {"format": FORMAT, "env_id": env_id, "action_kind": kind,
                "scene": penv["scene"], "algo": algo,
                "observation": {"size": len(names), "names": names},
                "action_size": action_size, "reward_weights": weights,
                "vecnormalize": normalised, "files": files}
    header = ("# abb-gym agent manifest: what the agent is and the fingerprints of its files\n"
              "# (abb_gym.rl.agent_files; checked on load).\n")
    from .._files import write_text
    path = folder / MANIFEST
    write_text(path, header + yaml.safe_dump(manifest, sort_keys=False))
    return path
