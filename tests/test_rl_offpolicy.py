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
from abb_gym.rl.config import TrainConfig, TrainConfigError  # noqa: E402
from abb_gym.rl.zoo import zoo_problems  # noqa: E402

SPEED = "abb_gym/RunUpSpeed-v0"
ENTRY = {"n_envs": 2, "n_timesteps": 300, "policy": "MlpPolicy",
         "normalize": "dict(norm_obs=True, norm_reward=True)",
         "policy_kwargs": "dict(net_arch=[16, 16])",
         "learning_starts": 100, "batch_size": 32, "buffer_size": 1000,
         "env_kwargs": {"scene": "yoshida_odd", "preset": "varied", "control_interval": 0.05}}


@pytest.mark.parametrize("algo, cls, policy", [
    ("sac", "SAC", "MlpPolicy"), ("tqc", "TQC", "MlpPolicy"),
    ("sac", "SAC", "abb_gym.rl.networks.StartedSACPolicy"),
    ("tqc", "TQC", "abb_gym.rl.networks.StartedTQCPolicy")])
def test_an_off_policy_agent_trains_loads_and_is_evaluated(algo, cls, policy, tmp_path,
                                                           train_config):
    from abb_gym.evaluation.evaluate import evaluate
    entry = dict(ENTRY, policy=policy)
    if policy != "MlpPolicy":
        entry["policy_kwargs"] = "dict(net_arch=[16, 16], action_mean_init=0.5)"
    data = {SPEED: entry, "_abb_gym": {"algo": algo, "eval_freq": 0, "eval_episodes": 2,
                                       "eval_env_kwargs": {"preset": "varied_test"}}}
    assert zoo_problems(data) == []
    assert train_config(data, tmp_path) == 0
    run = tmp_path / "run"
    assert load_config(tmp_path / "run.yml").algo == algo
    stored = yaml.safe_load((run / "config.yml").read_text())
    # written only where the policy does not imply it
    assert stored["_abb_gym"].get("algo") == (algo if policy == "MlpPolicy" else None)
    assert load_config(run / "config.yml").algo == algo
    pol = load_policy(run)
    assert type(pol.model).__name__ == cls and not pol.recurrent
    assert type(pol.model.policy).__name__ == policy.split(".")[-1].replace("MlpPolicy",
                                                                             f"{cls}Policy")
    result = evaluate(SPEED, "yoshida_odd", f"ppo:{run}", episodes=2, seed=0,
                      preset="varied_test")
    assert all(np.isfinite(e["return"]) for e in result.episodes)


@pytest.mark.parametrize("entry, algo, match", [
    ({"policy": "BoundedMlpPolicy"}, "sac",
     r"field 'policy' must be one of \['MlpPolicy', "
     r"'abb_gym.rl.networks.StartedSACPolicy'\] for algo 'sac'"),
    ({"policy": "abb_gym.rl.networks.StartedTQCPolicy"}, "sac", r"for algo 'sac'"),
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


@pytest.mark.parametrize("name", ["StartedSACPolicy", "StartedTQCPolicy"])
def test_a_started_actor_begins_at_its_initial_mean(name):
    """SAC and TQC start at zero acceleration, where a run-up never begins; the started
    policies' deterministic action is action_mean_init before any training (the mean layer's
    weights shrunk 100x), and the stored constructor keeps it."""
    import torch
    from abb_gym.rl import networks
    from abb_gym.rl.algorithms import algorithm_class
    from abb_gym.rl.env_factory import make_sb3_env
    venv = make_sb3_env(SPEED, 2, ENTRY["env_kwargs"])
    algo = "sac" if "SAC" in name else "tqc"
    model = algorithm_class(algo)(getattr(networks, name), venv, learning_starts=10,
                                  policy_kwargs={"net_arch": [16, 16],
                                                 "action_mean_init": 0.5}, seed=0)
    obs = venv.reset()
    act, _ = model.predict(obs, deterministic=True)
    np.testing.assert_allclose(act, 0.5, atol=0.05)
    plain = algorithm_class(algo)("MlpPolicy", venv, policy_kwargs={"net_arch": [16, 16]},
                                  seed=0)
    assert np.all(np.abs(plain.predict(obs, deterministic=True)[0]) < 0.3)
    assert model.policy._get_constructor_parameters()["action_mean_init"] == 0.5
    with pytest.raises(ValueError, match=r"action_mean_init must be in \(-1, 1\)"):
        algorithm_class(algo)(getattr(networks, name), venv,
                              policy_kwargs={"action_mean_init": 1.0})
    assert isinstance(model.actor.mu, torch.nn.Linear)
