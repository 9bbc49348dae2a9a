"""Training from another run's model (abb_gym.rl.warm_start): the weights and statistics
arrive unchanged, the run records where it started, and every mismatch is refused, naming it,
before any training."""
from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest
import yaml

pytest.importorskip("stable_baselines3")
pytest.importorskip("torch")

from abb_gym.cli import main as cli_main  # noqa: E402
from abb_gym.rl.agent_files import AgentError  # noqa: E402
from abb_gym.rl.config import TrainConfig, TrainConfigError  # noqa: E402
from abb_gym.rl.env_factory import make_sb3_env  # noqa: E402
from abb_gym.rl.warm_start import load_warm_start, warm_start_files  # noqa: E402

SPEED = "abb_gym/RunUpSpeed-v0"
TORQUE = "abb_gym/RunUpTorque-v0"

PARENT = {
    "n_envs": 2, "n_timesteps": 512, "policy": "BoundedMlpPolicy",
    "normalize": {"norm_obs": True, "norm_reward": True},
    "n_steps": 128, "batch_size": 128, "n_epochs": 2, "gamma": 0.99,
    "learning_rate": 3e-4,
    "policy_kwargs": {"net_arch": [16, 16], "activation_fn": "Tanh", "action_mean_init": 0.5},
    "env_kwargs": {"scene": "yoshida_odd", "preset": "train", "control_interval": 0.05},
    "eval_freq": 10_000, "eval_episodes": 2, "eval_seed": 5, "checkpoint_freq": 0,
}


@pytest.fixture(scope="module")
def parent(tmp_path_factory, train_config):
    root = tmp_path_factory.mktemp("warm")
    assert train_config({SPEED: PARENT}, root, seed=2, name="parent") == 0
    return root / "parent"


def _config(folder, model="final", env_id=SPEED, **changes) -> TrainConfig:
    entry = copy.deepcopy(PARENT)
    settings = {k: entry.pop(k) for k in ("eval_freq", "eval_episodes", "eval_seed",
                                          "checkpoint_freq")}
    entry.update(changes)
    settings["init_from"] = {"folder": str(folder), "model": model}
    return TrainConfig.from_mapping(env_id, entry, "child.yml", settings)


def _model_and_env(cfg: TrainConfig):
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from abb_gym.rl.networks import policy_class
    venv = make_sb3_env(cfg.env_id, cfg.n_envs, cfg.env_kwargs)
    env = VecNormalize(venv, **cfg.normalize) if cfg.normalize is not None else venv
    model = PPO(policy_class(cfg.policy), env, seed=9, device="cpu", **cfg.ppo_kwargs())
    return model, env, venv


@pytest.mark.parametrize("value, match", [
    (5, r"'init_from' must be a mapping"),
    ({"model": "best"}, r"'init_from.folder' is missing"),
    ({"folder": "runs/x", "model": "last"}, r"field 'model' must be one of \['best', 'final'\]"),
    ({"folder": "runs/x", "step": 3}, r"init_from.*step"),
    ({"folder": ""}, r"'init_from.folder' must be a folder path"),
])
def test_bad_init_from_settings_name_the_field(value, match):
    entry = {k: v for k, v in PARENT.items() if k not in ("eval_freq", "eval_episodes",
                                                          "eval_seed", "checkpoint_freq")}
    with pytest.raises(TrainConfigError, match=match):
        TrainConfig.from_mapping(SPEED, entry, "x.yml", {"init_from": value})
    with pytest.raises(TrainConfigError, match=r"belongs in the _abb_gym section"):
        TrainConfig.from_mapping(SPEED, dict(entry, init_from="runs/x"), "x.yml")


@pytest.mark.parametrize("model", ["final", "best"])
def test_the_model_starts_with_its_parents_weights_and_statistics(parent, model):
    from stable_baselines3 import PPO
    prefix = "best_" if model == "best" else ""
    cfg = _config(parent, model)
    child, env, venv = _model_and_env(cfg)
    want = PPO.load(parent / f"{prefix}model.zip", device="cpu").policy.state_dict()
    fresh = child.policy.state_dict()
    assert any(not np.array_equal(fresh[k].numpy(), want[k].numpy()) for k in want)
    files = warm_start_files(cfg.init_from, cfg.env_id, cfg.algo, venv.unwrapped.setup, True)
    record = load_warm_start(child, env, files)
    got = child.policy.state_dict()
    assert set(got) == set(want)
    for key in want:
        np.testing.assert_array_equal(got[key].numpy(), want[key].numpy(), err_msg=key)
    with open(parent / f"{prefix}vecnormalize.pkl", "rb") as fh:
        stats = pickle.load(fh)
    np.testing.assert_array_equal(env.obs_rms.mean, stats.obs_rms.mean)
    np.testing.assert_array_equal(env.obs_rms.var, stats.obs_rms.var)
    assert env.obs_rms is not stats.obs_rms and env.training  # a copy that keeps learning
    manifest = yaml.safe_load((parent / "agent.yml").read_text())
    assert record == {"folder": str(parent), "model": f"{prefix}model.zip",
                      "sha256": manifest["files"][f"{prefix}model.zip"]["sha256"]}
    env.close()


def test_a_warm_started_run_records_its_parent(parent, tmp_path):
    child = tmp_path / "child"
    path = tmp_path / "child.yml"
    path.write_text(yaml.safe_dump({SPEED: dict(PARENT, n_timesteps=256)}))
    assert cli_main(["train", "--config", str(path), "--seed", "1", "--out", str(child),
                     "--init-from", str(parent), "--no-progress"]) == 0
    conf = yaml.safe_load((child / "config.yml").read_text())
    manifest = yaml.safe_load((parent / "agent.yml").read_text())
    assert conf["_abb_gym"]["init_from"] == {"folder": str(parent), "model": "best"}
    assert conf["_run"]["init_from"]["sha256"] == manifest["files"]["best_model.zip"]["sha256"]
    # the run's config.yml trains again as it is
    assert TrainConfig.from_mapping(SPEED, conf[SPEED], "", conf["_abb_gym"]).init_from == \
        {"folder": str(parent), "model": "best"}


def test_mismatched_parents_are_refused_before_training(parent, tmp_path, capsys):
    def files(cfg, run_dir=None):
        venv = make_sb3_env(cfg.env_id, 1, cfg.env_kwargs)
        try:
            return warm_start_files(cfg.init_from, cfg.env_id, cfg.algo, venv.unwrapped.setup,
                                    cfg.normalize is not None, run_dir)
        finally:
            venv.close()

    with pytest.raises(AgentError, match=r"is an agent of 'abb_gym/RunUpSpeed-v0', this "
                                         r"config trains 'abb_gym/RunUpTorque-v0'"):
        files(_config(parent, env_id=TORQUE))
    with pytest.raises(AgentError, match=r"has observation statistics and this config does "
                                         r"not normalise"):
        files(_config(parent, normalize=False))
    with pytest.raises(AgentError, match=r"observes .* this config's environment"):
        files(_config(parent, env_kwargs=dict(PARENT["env_kwargs"], frame_stack=2)))
    # the policy-relevant preset fields, as an evaluation checks them, and the same interval
    env_kwargs = PARENT["env_kwargs"]
    with pytest.raises(AgentError, match=r"preset field 'control_interval' of the environment "
                                         r"\(0\.01 s\) differs from the agent's \(0\.05 s\)"):
        files(_config(parent, env_kwargs=dict(env_kwargs, control_interval=0.01)))
    with pytest.raises(AgentError, match=r"preset field 'vibration_filter_time'"):
        files(_config(parent, env_kwargs=dict(env_kwargs, vibration_filter_time=0.2)))
    with pytest.raises(AgentError, match=r"preset field 'episode_length'"):
        files(_config(parent, env_kwargs=dict(env_kwargs, episode_length=3.0)))
    with pytest.raises(AgentError, match=r"preset field 'operating_speed'"):
        files(_config(parent, env_kwargs=dict(env_kwargs, operating_speed=500.0)))
    # what a fine-tune may change: the band and the reward
    assert files(_config(parent, env_kwargs=dict(env_kwargs, at_speed_tolerance=0.005,
                                                 reward={"residual": 3.0}))).env_id == SPEED
    with pytest.raises(AgentError, match=r"the new run's own folder"):
        files(_config(parent), run_dir=parent)
    with pytest.raises(AgentError, match=r"is not a folder"):
        files(_config(tmp_path / "nothing"))
    # another network: refused when the weights are loaded, naming the file
    cfg = _config(parent, policy_kwargs=dict(PARENT["policy_kwargs"], net_arch=[8, 8]))
    model, env, venv = _model_and_env(cfg)
    with pytest.raises(AgentError, match=r"does not match this config's policy"):
        load_warm_start(model, env, files(cfg))
    env.close()
    # the command line says so and trains nothing
    path = tmp_path / "torque.yml"
    path.write_text(yaml.safe_dump({TORQUE: PARENT}))
    assert cli_main(["train", "--config", str(path), "--out", str(tmp_path / "t"),
                     "--init-from", str(parent), "--no-progress"]) == 2
    assert "is an agent of" in capsys.readouterr().err
    assert not (tmp_path / "t" / "model.zip").exists()
