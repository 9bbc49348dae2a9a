"""An agent's network, optimiser state and observation statistics as data: safetensors and
JSON, read without unpickling anything.

Why not SB3's own files: ``model.zip`` stores the policy class, the spaces and the
hyperparameters as cloudpickles, and ``vecnormalize.pkl`` is a pickle; reading either runs
whatever code the file contains.  A model file from a stranger must be data, not a program,
as the ecosystem's move from pickle to safetensors (weights) plus JSON (metadata) intends.

=============================  ===============================================================
file                           content
=============================  ===============================================================
``policy.safetensors``         the SB3 policy's ``state_dict`` (``safetensors.torch``), and in
                               the file's metadata what rebuilds it: the policy class, its
                               constructor keywords and spaces (:func:`describe_policy`), and
                               the env id, action kind and algorithm it was trained for
``optimizer.safetensors``      the optimiser's state (Adam's moments and step), its parameter
                               groups in the metadata: what a warm start continues from
``vecnormalize.json``          the observation (and return) statistics of SB3's
                               ``VecNormalize`` with its settings (:func:`normalization_state`)
=============================  ===============================================================

Rebuilding (:func:`build_policy`) calls the class with the recorded keywords, as SB3's
``BasePolicy.load`` does with the pickled ones, then loads the weights (exact names and
shapes).  Only classes on an allow-list are built: the policy classes abb-gym trains
(:data:`POLICY_CLASSES`), ``torch.nn`` activations, ``torch.optim`` optimisers and SB3's
feature extractors; every other value must be plain data (numbers, text, lists, mappings).
A file that asks for anything else is refused with one :class:`~abb_gym.rl.errors.AgentError`.

Floats keep every bit: tensors are stored as they are, statistics and spaces as JSON numbers
(Python writes the shortest text that reads back to the same double).
"""
from __future__ import annotations

import importlib
import json
import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .errors import AgentError

__all__ = ["POLICY_CLASSES", "POLICY_FILE", "OPTIMIZER_FILE", "NORMALIZATION_FILE",
           "describe_policy", "build_policy", "save_policy", "load_policy_file",
           "policy_metadata", "save_optimizer", "load_optimizer", "FrozenNormalizer",
           "normalization_state", "save_normalization", "load_normalization",
           "restore_normalization", "save_model_files", "LoadedModel"]

POLICY_FILE = "policy.safetensors"
OPTIMIZER_FILE = "optimizer.safetensors"
NORMALIZATION_FILE = "vecnormalize.json"
_POLICY_FORMAT = "abb-gym policy 1"
_OPTIMIZER_FORMAT = "abb-gym optimizer 1"
_NORMALIZATION_FORMAT = "abb-gym vecnormalize 1"

#: the policy classes a policy file may name (import path -> the algorithms that train it)
POLICY_CLASSES = {
    "abb_gym.rl.networks.BoundedMlpPolicy": ("ppo",),
    "abb_gym.rl.networks.BoundedMlpLstmPolicy": ("ppo_lstm",),
    "abb_gym.rl.networks.StartedSACPolicy": ("sac",),
    "abb_gym.rl.networks.StartedTQCPolicy": ("tqc",),
    "stable_baselines3.common.policies.ActorCriticPolicy": ("ppo",),
    "sb3_contrib.common.recurrent.policies.RecurrentActorCriticPolicy": ("ppo_lstm",),
    "stable_baselines3.sac.policies.SACPolicy": ("sac",),
    "sb3_contrib.tqc.policies.TQCPolicy": ("tqc",),
}
#: where the classes a policy's keywords may name live, and the base class they must have
_CLASS_HOMES = {"torch.nn": "torch.nn.Module", "torch.optim": "torch.optim.Optimizer",
                "stable_baselines3.common.torch_layers":
                    "stable_baselines3.common.torch_layers.BaseFeaturesExtractor"}
#: constructor keywords not recorded: rebuilt for inference without them
_DROPPED = ("observation_space", "action_space", "lr_schedule")
#: constructor keywords SB3's ``_get_constructor_parameters`` leaves out (its pickled
#: ``policy_kwargs`` carried them), read from the policy: keyword -> (attribute, reading)
_UNRECORDED = {
    "share_features_extractor": ("share_features_extractor", bool),
    "lstm_hidden_size": ("lstm_hidden_state_shape", lambda shape: int(shape[2])),
    "n_lstm_layers": ("lstm_hidden_state_shape", lambda shape: int(shape[0])),
    "shared_lstm": ("shared_lstm", bool),
    "enable_critic_lstm": ("enable_critic_lstm", bool),
    "lstm_kwargs": ("lstm_kwargs", dict),
}


def _error(message: str) -> Exception:
    return AgentError(message)


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


# ------------------------------------------------------------------------ the description
def _class_path(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


def _public_path(cls: type) -> str | None:
    """``home.Name`` if ``cls`` is reachable as ``Name`` from one of :data:`_CLASS_HOMES`."""
    for home in _CLASS_HOMES:
        module = importlib.import_module(home)
        if getattr(module, cls.__name__, None) is cls:
            return f"{home}.{cls.__name__}"
    return None


def _plain(value: Any, where: str) -> Any:
    """``value`` as YAML/JSON data: classes by import path (``{"class": ...}``), tuples as
    ``{"tuple": [...]}``; anything else that is not plain data raises ValueError."""
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return value.item() if isinstance(value, np.generic) else value
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, type):
        path = _public_path(value)
        if path is None:
            raise ValueError(f"{where}: the class {_class_path(value)} is not one a policy "
                             f"file may name ({', '.join(_CLASS_HOMES)})")
        return {"class": path}
    if isinstance(value, tuple):
        return {"tuple": [_plain(v, where) for v in value]}
    if isinstance(value, list):
        return [_plain(v, where) for v in value]
    if isinstance(value, Mapping):
        if not all(isinstance(k, str) for k in value):
            raise ValueError(f"{where}: mapping keys must be text")
        return {k: _plain(v, f"{where}.{k}") for k, v in value.items()}
    raise ValueError(f"{where}: a {type(value).__name__} is not data a policy file can hold")


def _unplain(value: Any, where: str) -> Any:
    if value is None or isinstance(value, (bool, str, int, float)):
        return value
    if isinstance(value, list):
        return [_unplain(v, where) for v in value]
    if isinstance(value, dict):
        if set(value) == {"class"}:
            return _allowed_class(value["class"], where)
        if set(value) == {"tuple"} and isinstance(value["tuple"], list):
            return tuple(_unplain(v, where) for v in value["tuple"])
        return {str(k): _unplain(v, f"{where}.{k}") for k, v in value.items()}
    raise _error(f"{where}: unexpected value {value!r:.60}")


def _allowed_class(path: Any, where: str) -> type:
    """The class ``path`` if it lives in one of :data:`_CLASS_HOMES` and has its base."""
    if not isinstance(path, str) or "." not in path:
        raise _error(f"{where}: {path!r:.80} is not a class path")
    home, _, name = path.rpartition(".")
    if home not in _CLASS_HOMES or not name.isidentifier() or name.startswith("_"):
        raise _error(f"{where}: class {path!r:.80} is not allowed in a policy file (only "
                     f"{', '.join(f'{h}.*' for h in _CLASS_HOMES)})")
    cls = getattr(importlib.import_module(home), name, None)
    base_home, _, base_name = _CLASS_HOMES[home].rpartition(".")
    base = getattr(importlib.import_module(base_home), base_name)
    if not (isinstance(cls, type) and issubclass(cls, base)):
        raise _error(f"{where}: {path!r:.80} is not a {_CLASS_HOMES[home]}")
    return cls


def _box(space: Any, where: str) -> dict[str, Any]:
    from gymnasium import spaces
    if not isinstance(space, spaces.Box):
        raise ValueError(f"{where}: only Box spaces are recorded (got {type(space).__name__})")
    low, high = np.asarray(space.low), np.asarray(space.high)

    def compact(a: np.ndarray) -> Any:
        flat = a.ravel()
        return float(flat[0]) if flat.size and np.all(flat == flat[0]) else a.tolist()
    return {"shape": list(space.shape), "dtype": str(space.dtype),
            "low": compact(low), "high": compact(high)}


def _unbox(data: Any, where: str) -> Any:
    from gymnasium import spaces
    if not isinstance(data, dict) or set(data) != {"shape", "dtype", "low", "high"}:
        raise _error(f"{where} must be {{shape, dtype, low, high}} (got {data!r:.80})")
    shape = data["shape"]
    if not (isinstance(shape, list) and shape and all(isinstance(n, int) and 0 < n <= 100_000
                                                     for n in shape)):
        raise _error(f"{where}.shape must be a list of sizes (got {shape!r:.80})")
    if data["dtype"] not in ("float32", "float64"):
        raise _error(f"{where}.dtype must be float32 or float64 (got {data['dtype']!r:.40})")
    bounds = []
    for key in ("low", "high"):
        value = data[key]
        try:
            arr = np.broadcast_to(np.asarray(value, dtype=np.float64), tuple(shape))
        except (TypeError, ValueError):
            raise _error(f"{where}.{key} must be a number or a list of shape {shape}") from None
        if np.isnan(arr).any():
            raise _error(f"{where}.{key} holds NaN")
        bounds.append(arr.astype(data["dtype"]))
    return spaces.Box(bounds[0], bounds[1], tuple(shape), dtype=np.dtype(data["dtype"]))


def describe_policy(policy: Any) -> dict[str, Any]:
    """What rebuilds ``policy`` (an SB3 policy): its class, its constructor keywords (SB3's
    ``_get_constructor_parameters``, the same that ``BasePolicy.save`` pickles) and its
    spaces, as plain data."""
    path = _class_path(type(policy))
    if path not in POLICY_CLASSES:
        raise ValueError(f"policy class {path} cannot be written as a policy file (one of "
                         f"{sorted(POLICY_CLASSES)})")
    params = dict(policy._get_constructor_parameters())
    for key, (attribute, read) in _UNRECORDED.items():
        if key not in params and hasattr(policy, attribute):
            params[key] = read(getattr(policy, attribute))
    kwargs = {k: _plain(v, f"policy keyword {k!r}") for k, v in params.items()
              if k not in _DROPPED}
    return {"class": path, "kwargs": kwargs,
            "observation_space": _box(policy.observation_space, "observation space"),
            "action_space": _box(policy.action_space, "action space")}


def _policy_class(path: Any) -> type:
    if path not in POLICY_CLASSES:
        raise _error(f"policy class {path!r:.80} is not one abb-gym builds (one of "
                     f"{sorted(POLICY_CLASSES)})")
    module, _, name = path.rpartition(".")
    if module == "abb_gym.rl.networks":
        from . import networks
        return getattr(networks, name)
    from .algorithms import import_class
    return import_class(module, name, f"the policy {name}")


def build_policy(description: Mapping[str, Any]) -> Any:
    """A new SB3 policy (random weights, on the CPU) of ``description``
    (:func:`describe_policy`); one AgentError if the description is not a valid one."""
    if not isinstance(description, Mapping) or set(description) != {
            "class", "kwargs", "observation_space", "action_space"}:
        raise _error("the policy description must hold class, kwargs, observation_space and "
                     "action_space")
    cls = _policy_class(description["class"])
    kwargs = description["kwargs"]
    if not isinstance(kwargs, dict):
        raise _error("the policy's kwargs must be a mapping")
    kwargs = _unplain(kwargs, "policy kwargs")
    obs_space = _unbox(description["observation_space"], "observation_space")
    act_space = _unbox(description["action_space"], "action_space")
    try:
        return cls(obs_space, act_space, lambda _: 0.0, **kwargs)
    except Exception as exc:  # a keyword the class does not take, a bad architecture
        raise _error(f"policy {description['class']} cannot be built from the recorded "
                     f"keywords ({_one_line(exc)})") from None


# ------------------------------------------------------------------------ policy.safetensors
def save_policy(policy: Any, path: str | Path, env_id: str, action_kind: str,
                algo: str) -> Path:
    """Write ``policy``'s weights and description to ``path`` (whole or not at all)."""
    from safetensors.torch import save_model

    from .._files import replacing_path
    description = describe_policy(policy)
    # a description that would rebuild another network is never written
    rebuilt = {k: tuple(v.shape) for k, v in build_policy(description).state_dict().items()}
    if rebuilt != {k: tuple(v.shape) for k, v in policy.state_dict().items()}:
        raise ValueError(f"the recorded keywords of {description['class']} rebuild another "
                         f"network (tensors {sorted(rebuilt)[:4]}...): a keyword SB3 does not "
                         f"report is missing from policy_files._UNRECORDED")
    metadata = {"format": _POLICY_FORMAT, "env_id": env_id, "action_kind": action_kind,
                "algo": algo, "policy": json.dumps(description)}
    with replacing_path(path) as tmp:
        save_model(policy, str(tmp), metadata=metadata)
    return Path(path)


def policy_metadata(path: str | Path) -> dict[str, Any]:
    """The metadata of a policy file (``env_id``, ``action_kind``, ``algo``, ``policy``: the
    description), read from its header only; one AgentError naming the file if it is not
    one."""
    from safetensors import safe_open

    label = f"agent file {str(path)!r}"
    try:
        with safe_open(str(path), framework="pt", device="cpu") as fh:
            meta = dict(fh.metadata() or {})
    except Exception as exc:  # safetensors raises its own error types for a bad header
        raise _error(f"{label} cannot be read as a safetensors file ({_one_line(exc)})") \
            from None
    if meta.get("format") != _POLICY_FORMAT:
        raise _error(f"{label} is not an abb-gym policy file (its format is "
                     f"{meta.get('format')!r:.60}, not {_POLICY_FORMAT!r})")
    for key in ("env_id", "action_kind", "algo"):
        if not meta.get(key):
            raise _error(f"{label} records no {key}")
    try:
        description = json.loads(meta.get("policy", ""))
    except json.JSONDecodeError:
        raise _error(f"{label}: its policy description is not JSON") from None
    return {"env_id": meta["env_id"], "action_kind": meta["action_kind"],
            "algo": meta["algo"], "policy": description}


def load_policy_file(path: str | Path) -> tuple[Any, dict[str, Any]]:
    """The SB3 policy in ``path`` (rebuilt, weights loaded, evaluation mode) and the file's
    metadata (:func:`policy_metadata`)."""
    from safetensors.torch import load_model

    meta = policy_metadata(path)
    try:
        policy = build_policy(meta["policy"])
    except ValueError as exc:
        raise _error(f"agent file {str(path)!r}: {exc}") from None
    try:
        load_model(policy, str(path), strict=True, device="cpu")
    except Exception as exc:  # missing, unexpected or misshapen tensors
        raise _error(f"agent file {str(path)!r}: the weights do not fit the recorded network "
                     f"({_one_line(exc)})") from None
    policy.set_training_mode(False)
    return policy, meta


# ------------------------------------------------------------------------ optimizer.safetensors
def save_optimizer(optimizer: Any, path: str | Path) -> Path:
    """Write a torch optimiser's state (tensors) and parameter groups (metadata)."""
    import torch
    from safetensors.torch import save_file

    from .._files import replacing_path
    state = optimizer.state_dict()
    tensors: dict[str, Any] = {}
    scalars: dict[str, dict[str, Any]] = {}
    for pid, entries in state["state"].items():
        for name, value in entries.items():
            if isinstance(value, torch.Tensor):
                tensors[f"state.{pid}.{name}"] = value.detach().cpu().contiguous()
            else:
                scalars.setdefault(str(pid), {})[name] = _plain(value, f"optimizer {name}")
    groups = [_plain(g, "optimizer parameter group") for g in state["param_groups"]]
    metadata = {"format": _OPTIMIZER_FORMAT, "param_groups": json.dumps(groups),
                "scalars": json.dumps(scalars)}
    with replacing_path(path) as tmp:
        save_file(tensors, str(tmp), metadata=metadata)
    return Path(path)


def load_optimizer(optimizer: Any, path: str | Path) -> None:
    """Load the state :func:`save_optimizer` wrote into ``optimizer`` (the same parameters);
    one AgentError naming the file otherwise."""
    from safetensors import safe_open

    label = f"agent file {str(path)!r}"
    try:
        with safe_open(str(path), framework="pt", device="cpu") as fh:
            meta = dict(fh.metadata() or {})
            tensors = {k: fh.get_tensor(k) for k in fh.keys()}
        if meta.get("format") != _OPTIMIZER_FORMAT:
            raise ValueError(f"its format is {meta.get('format')!r:.60}")
        groups = _unplain(json.loads(meta["param_groups"]), "optimizer")
        scalars = json.loads(meta["scalars"])
        state: dict[int, dict[str, Any]] = {}
        for key, value in tensors.items():
            _, pid, name = key.split(".", 2)
            state.setdefault(int(pid), {})[name] = value
        for pid, entries in scalars.items():
            state.setdefault(int(pid), {}).update(_unplain(entries, "optimizer"))
        optimizer.load_state_dict({"state": state, "param_groups": groups})
    except Exception as exc:  # noqa: BLE001 - header, JSON and torch errors alike
        raise _error(f"{label} cannot be loaded as the optimiser's state "
                     f"({_one_line(exc)})") from None


# ------------------------------------------------------------------------ vecnormalize.json
class FrozenNormalizer:
    """VecNormalize's observation statistics that never update: ``normalize_obs`` is SB3's
    ``VecNormalize.normalize_obs`` (the same arithmetic, so the same float32 bits)."""

    def __init__(self, mean: np.ndarray, var: np.ndarray, clip_obs: float, epsilon: float,
                 norm_obs: bool = True):
        self.mean = np.array(mean, dtype=np.float64)
        self.var = np.array(var, dtype=np.float64)
        self.clip_obs = float(clip_obs)
        self.epsilon = float(epsilon)
        self.norm_obs = bool(norm_obs)
        self.training = False
        self.norm_reward = False

    @classmethod
    def from_vecnormalize(cls, vn) -> "FrozenNormalizer":
        return cls(vn.obs_rms.mean, vn.obs_rms.var, vn.clip_obs, vn.epsilon, vn.norm_obs)

    def normalize_obs(self, obs: np.ndarray) -> np.ndarray:
        if not self.norm_obs:
            return obs
        out = np.clip((obs - self.mean) / np.sqrt(self.var + self.epsilon), -self.clip_obs,
                      self.clip_obs)
        return out.astype(np.float32)


def _rms(rms: Any) -> dict[str, Any]:
    return {"mean": np.asarray(rms.mean, np.float64).tolist(),
            "var": np.asarray(rms.var, np.float64).tolist(), "count": float(rms.count)}


def normalization_state(vn: Any) -> dict[str, Any]:
    """Everything of an SB3 ``VecNormalize`` that its pickle keeps and a later run needs: the
    observation and return statistics and the settings."""
    return {"format": _NORMALIZATION_FORMAT, "norm_obs": bool(vn.norm_obs),
            "norm_reward": bool(vn.norm_reward), "clip_obs": float(vn.clip_obs),
            "clip_reward": float(vn.clip_reward), "gamma": float(vn.gamma),
            "epsilon": float(vn.epsilon), "obs_rms": _rms(vn.obs_rms),
            "ret_rms": _rms(vn.ret_rms)}


def save_normalization(vn: Any, path: str | Path) -> Path:
    """Write :func:`normalization_state` of ``vn`` to ``path`` as JSON (whole or not at all)."""
    from .._files import write_text
    return write_text(path, json.dumps(normalization_state(vn), indent=1) + "\n")


def _vector(value: Any, size: int | None, what: str, label: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64) if isinstance(value, list) and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in value) else None
    if arr is None or arr.ndim != 1 or (size is not None and arr.shape != (size,)):
        want = f"{size} numbers" if size is not None else "a list of numbers"
        raise _error(f"{label}: {what} must be {want}")
    if not np.all(np.isfinite(arr)):
        raise _error(f"{label}: {what} holds non-finite values")
    return arr


def load_normalization(path: str | Path, obs_size: int) -> tuple[FrozenNormalizer, dict]:
    """The frozen observation normaliser of ``path`` (statistics of ``obs_size``
    observations) and the whole state; one AgentError naming the file and the field
    otherwise."""
    from ..configuration import MAX_FILE_BYTES
    label = f"agent file {str(path)!r}"
    try:
        with open(path, "rb") as fh:
            raw = fh.read(MAX_FILE_BYTES + 1)
        if len(raw) > MAX_FILE_BYTES:
            raise ValueError(f"larger than {MAX_FILE_BYTES} bytes")
        data = json.loads(raw.decode("utf-8"))
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise _error(f"{label} cannot be read as normalisation statistics "
                     f"({_one_line(exc)})") from None
    if not isinstance(data, dict) or data.get("format") != _NORMALIZATION_FORMAT:
        raise _error(f"{label} is not an abb-gym statistics file (format "
                     f"{_NORMALIZATION_FORMAT!r})")
    for key in ("norm_obs", "norm_reward"):
        if not isinstance(data.get(key), bool):
            raise _error(f"{label}: {key!r} must be true or false")
    for key in ("clip_obs", "clip_reward", "epsilon", "gamma"):
        v = data.get(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                or v <= 0:
            raise _error(f"{label}: {key!r} must be a number > 0 (got {v!r:.40})")
    for key in ("obs_rms", "ret_rms"):
        rms = data.get(key)
        if not isinstance(rms, dict) or set(rms) != {"mean", "var", "count"}:
            raise _error(f"{label}: {key!r} must be {{mean, var, count}}")
        size = obs_size if key == "obs_rms" else None
        mean = _vector(rms["mean"] if key == "obs_rms" else np.ravel(rms["mean"]).tolist(),
                       size, f"{key}.mean", label)
        var = _vector(rms["var"] if key == "obs_rms" else np.ravel(rms["var"]).tolist(),
                      size, f"{key}.var", label)
        if np.any(var < 0):
            raise _error(f"{label}: {key}.var holds negative values")
        count = rms["count"]
        if isinstance(count, bool) or not isinstance(count, (int, float)) \
                or not math.isfinite(count) or count < 0:
            raise _error(f"{label}: {key}.count must be a number >= 0")
        if key == "obs_rms":
            obs_mean, obs_var = mean, var
    norm = FrozenNormalizer(obs_mean, obs_var, data["clip_obs"], data["epsilon"],
                            data["norm_obs"])
    return norm, data


def restore_normalization(vn: Any, state: Mapping[str, Any]) -> None:
    """Copy the statistics of :func:`load_normalization`'s ``state`` into a training
    ``VecNormalize`` (which keeps updating them), as loading its pickle did."""
    from stable_baselines3.common.running_mean_std import RunningMeanStd
    for key in ("obs_rms", "ret_rms"):
        rms = state[key]
        current = getattr(vn, key)
        new = RunningMeanStd(shape=np.shape(current.mean))
        new.mean = np.array(rms["mean"], dtype=np.float64).reshape(np.shape(current.mean))
        new.var = np.array(rms["var"], dtype=np.float64).reshape(np.shape(current.var))
        new.count = float(rms["count"])
        setattr(vn, key, new)


def save_model_files(folder: str | Path, model: Any, env_id: str, action_kind: str, algo: str,
                     prefix: str = "") -> list[Path]:
    """Write an SB3 algorithm's policy, optimiser state and (if it trains on a
    ``VecNormalize``) statistics into ``folder`` as ``<prefix>policy.safetensors``,
    ``<prefix>optimizer.safetensors`` and ``<prefix>vecnormalize.json``; returns the paths."""
    folder = Path(folder)
    paths = [save_policy(model.policy, folder / f"{prefix}{POLICY_FILE}", env_id, action_kind,
                         algo)]
    optimizer = getattr(model.policy, "optimizer", None)
    if optimizer is not None:
        paths.append(save_optimizer(optimizer, folder / f"{prefix}{OPTIMIZER_FILE}"))
    vn = model.get_vec_normalize_env()
    if vn is not None:
        paths.append(save_normalization(vn, folder / f"{prefix}{NORMALIZATION_FILE}"))
    return paths


# ------------------------------------------------------------------------ the loaded model
class LoadedModel:
    """An SB3 policy with the part of the algorithm's interface evaluation uses
    (``policy``, ``observation_space``, ``action_space``, ``predict``): what
    :class:`~abb_gym.rl.agent.PPOPolicy` acts with, whether the policy came from a policy
    file or a trusted ``model.zip``."""

    def __init__(self, policy: Any):
        self.policy = policy
        self.observation_space = policy.observation_space
        self.action_space = policy.action_space

    def predict(self, observation, state=None, episode_start=None, deterministic=False):
        return self.policy.predict(observation, state, episode_start, deterministic)
