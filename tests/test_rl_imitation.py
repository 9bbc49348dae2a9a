"""Behaviour cloning before PPO (:mod:`abb_gym.rl.imitation`): the clone acts like its
teacher, the normalisation statistics come from the teacher's states, the config validates."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.vec_env import VecNormalize  # noqa: E402

from abb_gym.rl.config import TrainConfig, TrainConfigError  # noqa: E402
from abb_gym.rl.env_factory import make_sb3_env  # noqa: E402
from abb_gym.rl.imitation import DEMO_SEED, clone, demonstrations  # noqa: E402
from abb_gym.rl.networks import BoundedMlpPolicy  # noqa: E402

SPEED = "abb_gym/RunUpSpeed-v0"
KW = {"scene": "yoshida_odd", "preset": "train", "control_interval": 0.05}


def test_demonstrations_are_the_teachers_episodes_in_order():
    demo = demonstrations("baseline:ramp", SPEED, KW, episodes=3, chunk=2)
    ep = demo["episode"]
    assert set(ep) == {0, 1, 2} and np.all(np.diff(ep) >= 0)
    assert demo["obs"].shape[0] == demo["actions"].shape[0] == demo["rewards"].shape[0]
    # the ramp's deadbeat accelerations: the same action in every episode's first step
    firsts = demo["actions"][np.r_[0, np.flatnonzero(np.diff(ep)) + 1]]
    assert np.allclose(firsts, firsts[0]) and abs(float(firsts[0, 0])) > 0.1
    assert DEMO_SEED > 10_000_000  # far from the test sets (seed 1000) and training (0 ...)


def test_the_clone_acts_like_its_teacher():
    venv = make_sb3_env(SPEED, 4, KW)
    env = VecNormalize(venv, gamma=0.99)
    model = PPO(BoundedMlpPolicy, env, seed=0, device="cpu", n_steps=64, batch_size=64,
                policy_kwargs={"net_arch": [32, 32]})
    before = env.obs_rms.count
    record = clone(model, env, {"policy": "baseline:ramp", "episodes": 8, "epochs": 40,
                                "log_std": -2.0, "learning_rate": 3e-3}, SPEED, KW, 0.99)
    assert env.obs_rms.count > before + record["steps"] - 1  # fed the teacher's states
    assert record["action_mse"] < 0.01
    assert float(model.policy.log_std.detach().max()) == -2.0
    # on a fresh teacher episode, the clone's deterministic actions follow the teacher's
    demo = demonstrations("baseline:ramp", SPEED, KW, episodes=1)
    acts, _ = model.predict(env.normalize_obs(demo["obs"]), deterministic=True)
    assert np.mean(np.abs(acts - demo["actions"])) < 0.1
    env.close()


def test_the_imitate_section_is_checked():
    def config(imitate):
        return TrainConfig.from_mapping(SPEED, {"n_envs": 2, "n_timesteps": 10},
                                        extra={"imitate": imitate})
    assert config({"policy": "baseline:knots"}).imitate["episodes"] == 256
    with pytest.raises(TrainConfigError, match="imitate.policy"):
        config({"episodes": 4})
    with pytest.raises(TrainConfigError, match="imitate"):
        config({"policy": "baseline:knots", "epochs": 0})
    with pytest.raises(TrainConfigError, match="belongs in"):
        TrainConfig.from_mapping(SPEED, {"n_envs": 2, "n_timesteps": 10,
                                         "imitate": {"policy": "baseline:knots"}})


def test_the_imitate_section_survives_overrides_and_the_written_config():
    # a run's config.yml and a command-line override must keep cloning (a dropped section
    # trains plain PPO without a word)
    cfg = TrainConfig.from_mapping(SPEED, {"n_envs": 2, "n_timesteps": 10},
                                   extra={"imitate": {"policy": "baseline:knots",
                                                      "epochs": 7}})
    assert cfg.with_overrides(n_timesteps=20, eval_freq=5).imitate["epochs"] == 7
    data = cfg.to_file_data()
    again = TrainConfig.from_mapping(SPEED, data[SPEED], extra=data["_abb_gym"])
    assert again.imitate == cfg.imitate
