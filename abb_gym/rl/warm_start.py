"""Start training from another run's model: fine-tuning, or training in stages.

With ``_abb_gym: {init_from: {folder: runs/x, model: best}}`` (or ``abb-gym train
--init-from runs/x``), training builds the network of its own config as always, then loads
the weights of the agent folder's ``best_policy.safetensors`` or ``policy.safetensors`` into
it (exact names and shapes), the optimiser's state (``optimizer.safetensors``) when the
folder has it, and its observation statistics (``best_vecnormalize.json`` /
``vecnormalize.json``) into the training ``VecNormalize``, which keeps updating them.
Nothing is unpickled; a folder of abb-gym's first format (``model.zip``,
``vecnormalize.pkl``: pickles) is read only when trusted (``--trust-pickle``), with SB3's
``set_parameters``.  Everything else comes from the new config: the
learning rate and its schedule, the clip range, the reward weights and the band of the
training environment, the number of steps; the step counter starts at 0 again.  This is
rl_zoo3's ``--trained-agent`` (``-i``), which also takes the hyperparameters of the new file.

Why: to fine-tune a run at other settings (a lower learning rate, a narrower band, other
reward weights) without training the first stage again, or to continue a run.  It is not a
cure for an unstable training: on RunUpTorque, fine-tuning the best model of a run that
settled 77 % of its evaluation machines lost it within 100-200k steps at every setting tried
(docs/what-was-tried.md).

The settings are read with the rest of the config (:class:`abb_gym.rl.config.WarmStartSettings`).
The folder is checked before any training (:func:`abb_gym.rl.agent_files.check_folder`: the
fingerprints of its files), and must be an agent of the same environment id, algorithm and
observation layout, trained at the same policy-relevant preset fields
(:data:`abb_gym.rl.env_factory.POLICY_FIELDS`: the same ones an evaluation checks, and the same
control interval), with normalisation statistics exactly when the new config normalises.
The run's ``config.yml`` records the folder, the model and its sha256 under
``_run.init_from``.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping

__all__ = ["warm_start_files", "load_warm_start"]


def warm_start_files(settings: Mapping[str, Any], env_id: str, algo: str, setup: Any,
                     normalize: bool, run_dir: str | Path | None = None):
    """The checked agent files to start from (:class:`~abb_gym.rl.agent_files.AgentFiles`);
    :class:`~abb_gym.rl.agent_files.AgentError` naming the mismatch otherwise.  ``setup``:
    the resolved setup of the new run's environment (``env.unwrapped.setup``); ``run_dir``:
    the new run's folder, which must be another one (it would overwrite the files)."""
    from .agent_files import AgentError, check_folder
    from .env_factory import policy_env_mismatch

    folder = Path(settings["folder"])
    if not folder.is_dir():
        raise AgentError(f"init_from.folder {str(folder)!r} is not a folder (an agent folder "
                         f"of abb-gym train: model.zip, config.yml, agent.yml)")
    if run_dir is not None and folder.resolve() == Path(run_dir).resolve():
        raise AgentError(f"init_from.folder {str(folder)!r} is the new run's own folder: "
                         f"training would overwrite the model it starts from")
    files = check_folder(folder, best=settings["model"] == "best")
    if files.pickles:  # checked with the rest, before any training
        from .agent_files import require_trust
        require_trust(folder, files.pickles)
    where = f"init_from {str(folder)!r}"
    if files.env_id != env_id:
        raise AgentError(f"{where} is an agent of {files.env_id!r}, this config trains "
                         f"{env_id!r}")
    if files.algo != algo:
        raise AgentError(f"{where} was trained by {files.algo!r}, this config by {algo!r}")
    if files.observation_names != list(setup.obs_names):
        raise AgentError(f"{where} observes {files.observation_names}, this config's "
                         f"environment {list(setup.obs_names)} (the observation settings "
                         f"must match)")
    # the same preset fields an evaluation checks, and the same decision interval: a network
    # fine-tuned at another interval, speed or filter would start from actions that mean
    # something else
    parent_env = files.run["policy_env"]
    problem = policy_env_mismatch(parent_env, setup)
    interval = parent_env.get("control_interval")
    if problem is None and interval is not None and not math.isclose(
            interval, setup.control_interval, rel_tol=1e-9):
        problem = (f"preset field 'control_interval' of the environment "
                   f"({setup.control_interval:g} s) differs from the agent's ({interval:g} s)")
    if problem is not None:
        raise AgentError(f"{where}: {problem}")
    if (files.norm_path is not None) != bool(normalize):
        have = "has" if files.norm_path is not None else "has no"
        want = "normalises" if normalize else "does not normalise"
        raise AgentError(f"{where} {have} observation statistics and this config {want} "
                         f"observations: the network would see other inputs than it learnt on")
    return files


def load_warm_start(model: Any, env: Any, files: Any) -> dict[str, Any]:
    """Load ``files`` (from :func:`warm_start_files`) into ``model`` and, if ``env`` is a
    ``VecNormalize``, its statistics into ``env``; returns the ``_run.init_from`` record."""
    from stable_baselines3.common.vec_env import VecNormalize

    from .agent_files import AgentError, _one_line

    normalizing = isinstance(env, VecNormalize) and files.norm_path is not None
    if files.pickles:  # abb-gym's first format, trusted in warm_start_files
        from .legacy import read_vecnormalize
        try:
            model.set_parameters(str(files.model_path), exact_match=True, device="cpu")
        except Exception as exc:  # a network of another shape: torch's error names the tensors
            raise AgentError(f"init_from: the network of {str(files.model_path)!r} does not "
                             f"match this config's policy ({_one_line(exc)})") from None
        if normalizing:
            stats = read_vecnormalize(files.norm_path, env.observation_space.shape[0])
            env.obs_rms = stats.obs_rms.copy()
            env.ret_rms = stats.ret_rms.copy()
    else:
        from safetensors.torch import load_model

        from .policy_files import load_normalization, load_optimizer, restore_normalization
        try:
            load_model(model.policy, str(files.model_path), strict=True, device="cpu")
        except Exception as exc:  # a network of another shape: the message names the tensors
            raise AgentError(f"init_from: the network of {str(files.model_path)!r} does not "
                             f"match this config's policy ({_one_line(exc)})") from None
        if files.optimizer_path is not None:
            load_optimizer(model.policy.optimizer, files.optimizer_path)
        if normalizing:
            _, state = load_normalization(files.norm_path, env.observation_space.shape[0])
            restore_normalization(env, state)
    # check_folder has just matched the file against this fingerprint of its manifest
    name = files.model_path.name
    return {"folder": str(files.folder), "model": name,
            "sha256": files.manifest["files"][name]["sha256"]}
