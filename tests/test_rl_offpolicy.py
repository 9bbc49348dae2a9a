"""Off-policy algorithms (SAC of Stable-Baselines3, TQC of sb3-contrib), chosen by
``_abb_gym.algo``: the config names the field when the choice and the policy disagree, a
short run trains, saves, loads (the algorithm read back from the run's config) and is
evaluated."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

pytest.importorskip("stable_baselines3")
pytest.importorskip("sb3_contrib")

from abb_gym.rl import load_config, load_policy  # noqa: E402
from abb_gym.rl.config import TrainConfig, TrainConfigError, zoo_problems  # noqa: E402

SPEED = "abb_gym/RunUpSpeed-v0"
ENTRY = {"n_envs": 2, "n_timesteps": 300, "policy": "MlpPolicy",
         "normalize": "dict(norm_obs=True, norm_reward=True)",
         "policy_kwargs": "dict(net_arch=[16, 16])",
         "learning_starts": 100, "batch_size": 32, "buffer_size": 1000,
         "env_kwargs": {"scene": "yoshida_odd", "preset": "varied", "control_interval": 0.05}}


@pytest.mark.parametrize("algo, cls", [("sac", "SAC"), ("tqc", "TQC")])
def test_an_off_policy_agent_trains_loads_and_is_evaluated(algo, cls, tmp_path, train_config):
    from abb_gym.evaluation.evaluate import evaluate
    data = {SPEED: dict(ENTRY), "_abb_gym": {"algo": algo, "eval_freq": 0, "eval_episodes": 2,
                                            "eval_env_kwargs": {"preset": "varied_test"}}}
    assert zoo_problems(data) == []
    assert train_config(data, tmp_path) == 0
    run = tmp_path / "run"
    assert load_config(tmp_path / "run.yml").algo == algo
    stored = yaml.safe_load((run / "config.yml").read_text())
    assert stored["_abb_gym"]["algo"] == algo
    pol = load_policy(run)
    assert type(pol.model).__name__ == cls and not pol.recurrent
    result = evaluate(SPEED, "yoshida_odd", f"ppo:{run}", episodes=2, seed=0,
                      preset="varied_test")
    assert all(np.isfinite(e["return"]) for e in result.episodes)


@pytest.mark.parametrize("entry, algo, match", [
    ({"policy": "BoundedMlpPolicy"}, "sac", r"field 'policy' must be MlpPolicy for algo 'sac'"),
    ({"policy": "MlpLstmPolicy"}, "ppo", r"field 'algo' is 'ppo', but policy 'MlpLstmPolicy' is "
                                         r"trained by 'ppo_lstm'"),
    ({}, "a2c", r"field 'algo' must be one of \['ppo', 'ppo_lstm', 'sac', 'tqc'\]"),
    ({"n_epochs": 4}, "sac", r"unknown key\(s\) \['n_epochs'\].*SAC keywords"),
])
def test_the_algorithm_and_its_keys_are_checked(entry, algo, match):
    raw = {"n_envs": 2, "policy": "MlpPolicy", **entry}
    with pytest.raises(TrainConfigError, match=match):
        TrainConfig.from_mapping(SPEED, raw, "x.yml", {"algo": algo})


def test_a_ppo_config_keeps_no_algo_key():
    cfg = load_config("runup_speed_yoshida_odd_varied")
    assert cfg.algo == "ppo" and "algo" not in cfg.abb_gym_settings()
    lstm = load_config("runup_speed_yoshida_odd_varied_lstm")
    assert lstm.algo == "ppo_lstm" and "algo" not in lstm.abb_gym_settings()
