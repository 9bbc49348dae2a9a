"""Train Stable-Baselines3 PPO on a balancer environment from a zoo-style config.

Library code calls :func:`train`; the command line (``abb-gym train``, ``agents/train.py``)
is :mod:`abb_gym.cli.train`.

What one run does:

1. builds the native vector environment of the config (``n_envs`` sub-environments, one
   compiled parallel step) behind the SB3 adapter :class:`~abb_gym.rl.vec_env.NativeVecEnv`,
   with ``VecMonitor`` (episode statistics), the potential-based reward shaping (if
   ``shaping``: :mod:`abb_gym.rl.shaping`) and ``VecNormalize`` (if ``normalize``), and
   narrows the machines' ranges early in training (if ``curriculum``:
   :mod:`abb_gym.rl.curriculum`);
2. trains ``PPO`` (``RecurrentPPO`` for a recurrent policy, SAC or TQC if the config's
   ``algo`` says so: :func:`~abb_gym.rl.config.algorithm_of`) for ``n_timesteps``
   environment steps with the seed (Python, NumPy, torch,
   the environments' generators and the action space), a progress bar, a test-set evaluation
   every ``eval_freq`` steps and checkpoints every ``checkpoint_freq`` steps;
3. writes the run folder (default ``runs/<config>/s<seed>-<time>``, git-ignored):

=============================  ==============================================================
file                           content
=============================  ==============================================================
``policy.safetensors``         final network (weights and what rebuilds it; no pickle:
                               :mod:`abb_gym.rl.policy_files`)
``optimizer.safetensors``      its optimiser's state (for a warm start, ``init_from``)
``vecnormalize.json``          its VecNormalize statistics (frozen on loading:
                               :func:`abb_gym.rl.load_policy` does)
``best_policy.safetensors``,   the network (optimiser, statistics) with the best test-set
``best_optimizer...``,         score (mean return on the held-out test preset)
``best_vecnormalize.json``
``config.yml``                 the config as run (zoo style, keyed by the env id, reusable
                               with ``--config``) and ``_run``: seed, policy-relevant
                               environment settings, evaluation environment, wall time,
                               env-steps/s, versions, final evaluation
``evaluations.csv``            one row per evaluation: timesteps, wall time, the test-set
                               summary
``evaluations.npz``            SB3 ``EvalCallback`` layout: timesteps, results (episode
                               returns), ep_lengths
``evaluation.json``            final test-set evaluation of the final model (summary +
                               episodes)
``agent.yml``                  manifest: env id, action kind, observation layout, reward
                               weights and the fingerprints of the files
                               (:mod:`abb_gym.rl.agent_files`; checked when loaded)
``checkpoints/``               ``ppo_<steps>_steps/`` with the three model files
=============================  ==============================================================

With ``tensorboard_log`` (:func:`train`'s argument or the config's ``_abb_gym`` key), SB3 also
writes TensorBoard event files there, one run ``<config>_s<seed>_<n>`` per training: the
``train/`` losses, the ``rollout/`` episode returns and lengths, and the ``eval/`` test-set
means of every evaluation (``tensorboard --logdir DIR``).

The evaluation is a fixed seeded test set (``eval_seed``, ``eval_episodes``) on the ``test``
preset (see :mod:`abb_gym.rl.rollout` for the metrics).  Wall time and env-steps/s are printed
at the end and stored in ``config.yml``.
"""
from __future__ import annotations

import csv
import json
import math
import os
import platform
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .._files import replacing, write_text
from ..progress import ProgressBar
from .algorithms import algorithm_class
from .config import TrainConfig
from .env_factory import eval_env_kwargs, make_sb3_env, policy_env_fields
from .agent import PPOPolicy
from .policy_files import FrozenNormalizer, save_model_files
from ..evaluation.evaluate import summarise
from .rollout import KEY_METRICS, brief, run_episodes

__all__ = ["train", "RunResult", "FrozenNormalizer", "TestSetEvalCallback", "train_trial",
           "seeded_trial", "default_run_dir", "check_tensorboard_log", "tensorboard_run_name"]



def evaluate_model(model, env_id: str, env_kwargs: dict[str, Any], meta: dict[str, Any],
                   episodes: int, seed: int) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Test-set evaluation of an in-memory model with frozen copies of its statistics."""
    vn = model.get_vec_normalize_env()
    norm = FrozenNormalizer.from_vecnormalize(vn) if vn is not None else None
    policy = PPOPolicy(model, norm, meta, name="ppo")
    kw = dict(env_kwargs)
    records = run_episodes(policy, env_id, episodes=episodes, seed=seed,
                           scene=kw.pop("scene", "yoshida_odd"), preset=kw.pop("preset", "test"),
                           **kw)
    return summarise(records), records


def _callbacks_base():
    from stable_baselines3.common.callbacks import BaseCallback
    return BaseCallback


def _make_eval_callback_class():
    BaseCallback = _callbacks_base()

    class _TestSetEvalCallback(BaseCallback):
        """Evaluate on the fixed test set every ``eval_freq`` env steps; keep the best model."""

        def __init__(self, env_id: str, env_kwargs: dict, run_dir: Path, eval_freq: int,
                     episodes: int, seed: int, meta: dict, verbose: int = 0,
                     algo: str = "ppo"):
            super().__init__(verbose)
            self.env_id = env_id
            self.algo = algo
            self.action_kind = meta["policy_env"]["kind"]
            self.env_kwargs = env_kwargs
            self.run_dir = Path(run_dir)
            self.eval_freq = int(eval_freq)
            self.episodes = int(episodes)
            self.seed = int(seed)
            self.meta = meta
            self.best = -math.inf
            self.last_eval = 0
            self.rows: list[dict[str, Any]] = []
            self.npz = {"timesteps": [], "results": [], "ep_lengths": []}
            self.t0 = time.perf_counter()
            self.seconds = 0.0  # spent in evaluations

        def _on_training_start(self) -> None:
            self.t0 = time.perf_counter()

        def _on_step(self) -> bool:
            if self.eval_freq <= 0 or self.num_timesteps - self.last_eval < self.eval_freq:
                return True
            self.last_eval = self.num_timesteps
            self._run_eval()
            return True

        def _run_eval(self) -> None:
            start = time.perf_counter()
            summary, records = evaluate_model(self.model, self.env_id, self.env_kwargs,
                                              self.meta, self.episodes, self.seed)
            self.seconds += time.perf_counter() - start
            means = brief(summary)
            # eval_time_s: the evaluations' own share of wall_time_s so far (so that a
            # time-to-target counts the training, not how often it was measured)
            row = {"timesteps": self.num_timesteps,
                   "wall_time_s": round(time.perf_counter() - self.t0, 2),
                   "eval_time_s": round(self.seconds, 2)}
            for k in KEY_METRICS:
                row[k] = means[k]
                row[k + "_ci_low"] = summary[k]["ci_low"]
                row[k + "_ci_high"] = summary[k]["ci_high"]
            self.rows.append(row)
            for k in KEY_METRICS:
                self.logger.record(f"eval/{k}", means[k])
            self.npz["timesteps"].append(self.num_timesteps)
            self.npz["results"].append([r["return"] for r in records])
            self.npz["ep_lengths"].append([r["steps"] for r in records])
            self._write()
            if means["return"] > self.best:
                self.best = means["return"]
                save_model_files(self.run_dir, self.model, self.env_id, self.action_kind,
                                 self.algo, prefix="best_")
            if self.verbose:
                # the residual is measured in the operating band only: none reached it, none
                unit = records[0].get("length_unit", "W_r/e") if records else "W_r/e"
                residual = (f"{means['residual_vibration']:.3f} {unit}"
                            if math.isfinite(means["residual_vibration"])
                            else "n/a (no episode settled)")
                print(f"eval @ {self.num_timesteps}: return {means['return']:.3f}, at speed "
                      f"{means['at_speed']:.2f}, residual vibration {residual}, run-up time "
                      f"{means['run_up_time']:.2f} s, peak {means['peak_whirl']:.1f}, "
                      f"balanced {means['balanced']:.2f}", flush=True)

        def _write(self) -> None:
            with replacing(self.run_dir / "evaluations.csv", "w", newline="") as fh:
                w = csv.DictWriter(fh, fieldnames=list(self.rows[0]))
                w.writeheader()
                w.writerows(self.rows)
            with replacing(self.run_dir / "evaluations.npz", "wb") as fh:
                np.savez(fh, timesteps=np.array(self.npz["timesteps"]),
                         results=np.array(self.npz["results"]),
                         ep_lengths=np.array(self.npz["ep_lengths"]))

        def _on_training_end(self) -> None:
            if self.eval_freq > 0 and self.num_timesteps != self.last_eval:
                self.last_eval = self.num_timesteps
                self._run_eval()

    return _TestSetEvalCallback


def _make_progress_callback_class():
    BaseCallback = _callbacks_base()

    class _ProgressBar(BaseCallback):
        """The training bar (:class:`abb_gym.progress.ProgressBar`: plain lines in a log),
        stopped at its total: PPO collects whole rollouts of ``n_steps x n_envs`` steps, so
        training runs past ``n_timesteps`` unless it is a multiple of that, and SB3's own bar
        counts on past its total."""

        def _on_training_start(self) -> None:
            total = self.locals["total_timesteps"] - self.model.num_timesteps
            self.pbar = ProgressBar(total=total, desc="train", unit="step")

        def _on_step(self) -> bool:
            left = self.pbar.total - self.pbar.n
            if left > 0:
                self.pbar.update(min(self.training_env.num_envs, left))
            return True

        def _on_training_end(self) -> None:
            self.pbar.close()

    return _ProgressBar


def _make_throughput_class():
    BaseCallback = _callbacks_base()

    class _Throughput(BaseCallback):
        """When the first environment step of training ended and how many steps it made:
        that step compiles the environment's kernel when it is not cached yet (20-110 s),
        which a throughput must not include."""

        def _on_training_start(self) -> None:
            self.first: tuple[float, int] | None = None

        def _on_step(self) -> bool:
            if self.first is None:
                self.first = (time.perf_counter(), int(self.num_timesteps))
            return True

    return _Throughput


def _make_checkpoint_class():
    BaseCallback = _callbacks_base()

    class _Checkpoints(BaseCallback):
        """Every ``save_freq`` calls (vector steps), the model's files in the safe format
        (:func:`~abb_gym.rl.policy_files.save_model_files`) in
        ``checkpoints/ppo_<steps>_steps/``: SB3's ``CheckpointCallback`` writes pickles."""

        def __init__(self, save_freq: int, folder: Path, meta: dict, algo: str):
            super().__init__(0)
            self.save_freq, self.folder = int(save_freq), Path(folder)
            self.env_id, self.kind, self.algo = meta["env_id"], meta["policy_env"]["kind"], algo

        def _on_step(self) -> bool:
            if self.n_calls % self.save_freq == 0:
                target = self.folder / f"ppo_{self.num_timesteps}_steps"
                target.mkdir(parents=True, exist_ok=True)
                save_model_files(target, self.model, self.env_id, self.kind, self.algo)
            return True

    return _Checkpoints


def Checkpoints(*args, **kwargs):
    """The checkpoint callback (built lazily: SB3 is imported on first use)."""
    return _make_checkpoint_class()(*args, **kwargs)


def TrainingBar():
    """The training progress bar (built lazily: SB3 is imported on first use)."""
    return _make_progress_callback_class()()


def training_throughput(steps: int, wall: float, first: tuple[float, int] | None,
                        start: float, evaluation_s: float) -> float:
    """Environment steps per second of training proper [1/s]: the steps after the first
    one over the time after it (``first``: its end time and the step count then, or None),
    less ``evaluation_s`` seconds of test-set evaluations, whose first one compiles the
    evaluation environment.  The first step compiles the training environment's kernel when
    it is not cached: counted in, it made a 60 s training look 3x slower than it ran."""
    if first is None:
        return steps / wall if wall > 0 else math.nan
    t_first, n_first = first
    seconds = wall - (t_first - start) - evaluation_s
    return (steps - n_first) / seconds if seconds > 0 and steps > n_first else math.nan


def TestSetEvalCallback(*args, **kwargs):
    """The test-set evaluation callback (built lazily: SB3 is imported on first use)."""
    return _make_eval_callback_class()(*args, **kwargs)


@dataclass
class RunResult:
    """What :func:`train` returns."""

    run_dir: Path
    wall_time_s: float
    env_steps: int
    env_steps_per_s: float
    evaluation: dict[str, Any]
    #: env-steps/s without the first step (the compile) and the evaluations
    #: (:func:`training_throughput`)
    training_steps_per_s: float = math.nan


def _versions() -> dict[str, str]:
    import gymnasium
    import stable_baselines3
    import torch
    import abb_gym
    return {"abb_gym": abb_gym.__version__,
            "stable_baselines3": stable_baselines3.__version__, "torch": torch.__version__,
            "gymnasium": gymnasium.__version__, "numpy": np.__version__,
            "python": platform.python_version()}


def default_run_dir(cfg: TrainConfig, seed: int, root: str | os.PathLike = "runs") -> Path:
    stem = Path(cfg.source).stem if cfg.source else cfg.env_id.split("/")[-1]
    return Path(root) / stem / f"s{seed}-{time.strftime('%Y%m%d-%H%M%S')}"


def _yaml_safe(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _yaml_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_yaml_safe(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return None if math.isnan(v) else v
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, str):
        return str(obj)  # str subclasses (torch's version) are not YAML-safe
    return obj


def _repo_relative(path: str) -> str:
    """``path`` relative to the repository root when inside it (portable run folders)."""
    if not path:
        return path
    root = Path(__file__).resolve().parents[2]
    try:
        return str(Path(path).resolve().relative_to(root))
    except ValueError:
        return str(path)


def write_config(run_dir: Path, cfg: TrainConfig, meta: dict[str, Any]) -> None:
    data = {**_yaml_safe(cfg.to_file_data()), "_run": _yaml_safe(meta)}
    write_text(run_dir / "config.yml", yaml.safe_dump(data, sort_keys=False))


def check_tensorboard_log(value: Any) -> Path | None:
    """The TensorBoard folder ``value`` (None: none) as a path; ``ValueError`` if it is not a
    path or names a file, ``ImportError`` naming the package if TensorBoard is missing (both
    before any training starts)."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (str, os.PathLike)) or not str(value):
        raise ValueError(f"tensorboard_log must be a folder path (got {value!r})")
    path = Path(value)
    if path.exists() and not path.is_dir():
        raise ValueError(f"tensorboard_log {str(path)!r} is a file, not a folder")
    try:
        from torch.utils.tensorboard import SummaryWriter  # noqa: F401
    except ImportError as exc:
        raise ImportError(f"tensorboard_log needs the tensorboard package: pip install "
                          f"tensorboard (part of abb-gym[train]) ({exc})") from exc
    return path


def tensorboard_run_name(cfg: TrainConfig, seed: int) -> str:
    """TensorBoard run name of a training run, ``<config>_s<seed>`` (SB3 appends ``_<n>``)."""
    stem = Path(cfg.source).stem if cfg.source else cfg.env_id.split("/")[-1]
    return f"{stem}_s{int(seed)}"


def train(cfg: TrainConfig, *, seed: int = 0, run_dir: str | os.PathLike | None = None,
          progress: bool = True, verbose: int = 0, torch_threads: int | None = 1,
          final_eval: bool = True,
          tensorboard_log: str | os.PathLike | None = None) -> RunResult:
    """Train PPO as ``cfg`` says and write the run folder (see the module docstring).

    :param seed: seed of everything random in training (>= 0).
    :param run_dir: output folder (default :func:`default_run_dir`); created if missing.
    :param progress: show a progress bar (:mod:`abb_gym.progress`), ending at ``cfg.n_timesteps``
        (training itself ends with the rollout that reaches it).
    :param torch_threads: ``torch.set_num_threads`` (1 is fastest for these small networks on
        a busy 2-core machine); None leaves torch's default.
    :param final_eval: evaluate the final model on the test set (``evaluation.json``).
    :param tensorboard_log: folder of TensorBoard event files (SB3's ``tensorboard_log``,
        overrides the config's): the training curves, the ``rollout/`` episode statistics and
        the ``eval/`` test-set means, in ``<folder>/<config>_s<seed>_<n>``; needs the
        ``tensorboard`` package (training extra).  None: the config's, else no TensorBoard.
    """
    import torch
    from stable_baselines3.common.callbacks import CallbackList
    from stable_baselines3.common.utils import set_random_seed
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0 (got {seed!r})")
    ppo_kw = cfg.ppo_kwargs()
    if tensorboard_log is not None:
        ppo_kw["tensorboard_log"] = tensorboard_log
    tb_dir = check_tensorboard_log(ppo_kw.get("tensorboard_log"))
    if tb_dir is not None:
        ppo_kw["tensorboard_log"] = str(tb_dir)
    if torch_threads is not None:
        torch.set_num_threads(int(torch_threads))
    run_dir = Path(run_dir) if run_dir is not None else default_run_dir(cfg, seed)
    run_dir.mkdir(parents=True, exist_ok=True)
    set_random_seed(seed)

    # info_keys=(): nothing in training reads the per-step infos (VecMonitor keeps its own
    # episode sums; the episode-end keys stay), and splitting them per sub-environment was
    # the adapter's largest cost (abb-gym bench speed, the SB3 adapter row)
    venv = make_sb3_env(cfg.env_id, cfg.n_envs, cfg.env_kwargs,
                        bootstrap_truncated=cfg.bootstrap_truncated, info_keys=())
    warm = None
    if cfg.init_from is not None:  # checked before any training
        from .warm_start import load_warm_start, warm_start_files
        warm = warm_start_files(cfg.init_from, cfg.env_id, cfg.algo, venv.unwrapped.setup,
                                cfg.normalize is not None, run_dir)
    env = VecMonitor(venv)  # logs the unshaped returns
    if cfg.shaping is not None:
        from .shaping import PotentialShaping, potential_index
        index = potential_index(venv.unwrapped.setup.obs_names, cfg.shaping["observation"])
        env = PotentialShaping(env, index, cfg.shaping["weight"], ppo_kw.get("gamma", 0.99),
                               cfg.shaping.get("target"))
    if cfg.normalize is not None:
        norm_kw = dict(cfg.normalize)
        norm_kw.setdefault("gamma", ppo_kw.get("gamma", 0.99))
        env = VecNormalize(env, **norm_kw)
    eval_kwargs = eval_env_kwargs(cfg)
    meta: dict[str, Any] = {
        "env_id": cfg.env_id, "seed": int(seed), "config_source": _repo_relative(cfg.source),
        "policy_env": policy_env_fields(venv.unwrapped), "eval_env_kwargs": eval_kwargs,
        "command": " ".join(sys.argv), "versions": _versions(),
    }
    if tb_dir is not None:
        meta["tensorboard_log"] = _repo_relative(str(tb_dir))

    from .networks import policy_class
    algorithm = algorithm_class(cfg.algo)
    model = algorithm(policy_class(cfg.policy), env, seed=int(seed), device="cpu",
                      verbose=verbose, **ppo_kw)
    if tb_dir is None:
        # without a logger of its own, SB3 makes an empty folder tempdir/SB3-<time> on every
        # learn(): this one writes where SB3's default would (stdout when verbose), nowhere else
        from stable_baselines3.common.logger import configure
        model.set_logger(configure(str(run_dir), ["stdout"] if verbose else []))
    if warm is not None:
        meta["init_from"] = load_warm_start(model, env, warm)
    if cfg.imitate is not None:
        from .imitation import clone
        meta["imitate"] = clone(model, env, cfg.imitate, cfg.env_id, cfg.env_kwargs,
                                ppo_kw.get("gamma", 0.99))
    write_config(run_dir, cfg, meta)
    # first: the first step's end is taken before any other callback runs (an evaluation)
    throughput = _make_throughput_class()()
    callbacks = [throughput]
    eval_cb = TestSetEvalCallback(cfg.env_id, eval_kwargs, run_dir, cfg.eval_freq,
                                  cfg.eval_episodes, cfg.eval_seed, meta,
                                  verbose=max(verbose, int(progress is False)), algo=cfg.algo)
    callbacks.append(eval_cb)
    if cfg.curriculum is not None:
        from .curriculum import CurriculumCallback
        callbacks.append(CurriculumCallback(cfg.curriculum, cfg.n_timesteps))
    if cfg.oversample is not None:
        from .curriculum import OversampleCallback
        callbacks.append(OversampleCallback(cfg.oversample, seed))
    if cfg.checkpoint_freq > 0:
        callbacks.append(Checkpoints(max(cfg.checkpoint_freq // cfg.n_envs, 1),
                                     run_dir / "checkpoints", meta, cfg.algo))
    if progress:
        callbacks.append(TrainingBar())
    t0 = time.perf_counter()
    model.learn(cfg.n_timesteps, callback=CallbackList(callbacks), progress_bar=False,
                tb_log_name=tensorboard_run_name(cfg, seed))
    wall = time.perf_counter() - t0
    steps = int(model.num_timesteps)
    save_model_files(run_dir, model, cfg.env_id, meta["policy_env"]["kind"], cfg.algo)
    rate = training_throughput(steps, wall, throughput.first, t0, eval_cb.seconds)
    meta.update({"wall_time_s": round(wall, 1), "env_steps": steps,
                 "env_steps_per_s": round(steps / wall, 1),
                 "training_steps_per_s": None if math.isnan(rate) else round(rate, 1),
                 "evaluations": eval_cb.rows[-1] if eval_cb.rows else None})
    evaluation: dict[str, Any] = {}
    if final_eval:
        evaluation, records = evaluate_model(model, cfg.env_id, eval_kwargs, meta,
                                             cfg.eval_episodes, cfg.eval_seed)
        write_text(run_dir / "evaluation.json", json.dumps(
            _yaml_safe({"env_id": cfg.env_id, "env_kwargs": eval_kwargs,
                        "seed": cfg.eval_seed, "summary": evaluation, "episodes": records}),
            indent=1))
        meta["final_evaluation"] = brief(evaluation)
    write_config(run_dir, cfg, meta)
    # last, over the files as they now are: the manifest fingerprints them
    from .agent_files import write_manifest
    write_manifest(run_dir, observation_names=venv.unwrapped.setup.obs_names)
    env.close()
    return RunResult(run_dir, wall, steps, steps / wall, evaluation, rate)


# ---------------------------------------------------------------------- command line
def train_trial(config: dict) -> dict:
    """Trainable for :func:`abb_gym.execution.tune.run_trials` (one seed of a config)."""
    cfg = TrainConfig.from_mapping(config["env_id"], config["hyperparams"],
                                   config.get("source", ""), config.get("settings"))
    res = train(cfg, seed=int(config["seed"]), run_dir=config["run_dir"], progress=False,
                tensorboard_log=config.get("tensorboard_log"))
    out = dict(brief(res.evaluation)) if res.evaluation else {}
    out.update({"wall_time_s": res.wall_time_s, "env_steps_per_s": res.env_steps_per_s,
                "run_dir": str(res.run_dir)})
    return _yaml_safe(out)


def seeded_trial(config: dict) -> dict:
    """Trainable: one seed, run folder ``<run_dir>/s<seed>``."""
    config = dict(config)
    config["run_dir"] = str(Path(config["run_dir"]) / f"s{config['seed']}")
    return train_trial(config)
