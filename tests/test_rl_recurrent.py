"""Recurrent agents (sb3-contrib's RecurrentPPO with an LSTM policy): the algorithm follows
from the config's policy, a short run trains, saves and loads, and a loaded agent keeps one
memory per sub-environment that restarts with its episode and advances only when the
sub-environment decides."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

pytest.importorskip("stable_baselines3")
pytest.importorskip("sb3_contrib")
pytest.importorskip("torch")

from abb_gym.rl import load_config, load_policy, make_native_env  # noqa: E402
from abb_gym.rl.algorithms import algorithm_of  # noqa: E402
from abb_gym.rl.config import TrainConfig, TrainConfigError  # noqa: E402
from abb_gym.rl.zoo import zoo_problems  # noqa: E402

SPEED = "abb_gym/RunUpSpeed-v0"
LSTM = "abb_gym.rl.networks.BoundedMlpLstmPolicy"

SMOKE = {SPEED: {
    "n_envs": 4, "n_timesteps": 512, "policy": LSTM,
    "normalize": "dict(norm_obs=True, norm_reward=True)",
    "n_steps": 64, "batch_size": 128, "n_epochs": 2,
    "policy_kwargs": "dict(net_arch=[16], lstm_hidden_size=8, activation_fn=nn.Tanh, "
                     "action_mean_init=0.5)",
    "env_kwargs": {"scene": "yoshida_odd", "preset": "varied", "control_interval": 0.05},
}, "_abb_gym": {"eval_freq": 0, "eval_episodes": 2, "eval_env_kwargs": {"preset": "varied_test"}}}


@pytest.fixture(scope="module")
def lstm_run(tmp_path_factory, train_config):
    root = tmp_path_factory.mktemp("lstm")
    assert train_config(SMOKE, root, seed=2) == 0
    return root / "run"


def test_the_policy_chooses_the_algorithm():
    assert algorithm_of("abb_gym.rl.networks.BoundedMlpPolicy") == "ppo"
    assert algorithm_of("MlpPolicy") == "ppo"
    assert algorithm_of("MlpLstmPolicy") == "ppo_lstm"
    assert algorithm_of(LSTM) == "ppo_lstm"
    cfg = TrainConfig.from_mapping(SPEED, SMOKE[SPEED])
    assert cfg.algo == "ppo_lstm"
    # keywords are checked against the algorithm's own: RecurrentPPO has no rollout_buffer_class
    with pytest.raises(TrainConfigError, match="RecurrentPPO keywords"):
        TrainConfig.from_mapping(SPEED, dict(SMOKE[SPEED], rollout_buffer_class=None))
    TrainConfig.from_mapping(SPEED, dict(SMOKE[SPEED], policy="BoundedMlpPolicy",
                                         rollout_buffer_class=None))


def test_the_shipped_recurrent_config_is_a_zoo_file():
    cfg = load_config("runup_speed_yoshida_odd_varied_lstm")
    assert cfg.algo == "ppo_lstm"
    assert zoo_problems("runup_speed_yoshida_odd_varied_lstm") == []
    assert "frame_stack" not in cfg.env_kwargs  # memory from the LSTM, not a frame stack


def test_a_recurrent_agent_trains_saves_and_loads(lstm_run):
    from sb3_contrib import RecurrentPPO
    from abb_gym.rl.networks import BoundedMlpLstmPolicy

    pol = load_policy(lstm_run, env_id=SPEED)
    assert pol.recurrent
    assert isinstance(pol.model, RecurrentPPO)
    assert type(pol.model.policy) is BoundedMlpLstmPolicy
    assert isinstance(pol.model.policy.action_net[-1], __import__("torch").nn.Tanh)
    stored = yaml.safe_load((lstm_run / "config.yml").read_text())
    assert stored[SPEED]["policy"] == LSTM
    # the run's config trains again as it is
    assert load_config(lstm_run / "config.yml").algo == "ppo_lstm"


def _reference_actions(model, obs_seq, starts, due):
    """Actions of one sub-environment, the LSTM stepped by hand: ``starts[t]`` marks an
    episode start, ``due[t]`` a decision (otherwise the last action is held)."""
    state, last, out = None, None, []
    for t, o in enumerate(obs_seq):
        if due[t]:
            last, state = model.predict(o[None], state=state,
                                        episode_start=np.array([starts[t]]),
                                        deterministic=True)
            last = np.clip(last[0], -1, 1)
        out.append(last)
    return np.array(out)


@pytest.mark.parametrize("control_interval, repeat", [(0.05, 1), (0.025, 2)])
def test_each_sub_environment_keeps_its_own_memory(lstm_run, control_interval, repeat):
    """Two sub-environments, the second restarting its episode at step 4: each one's actions
    equal its own LSTM run by hand (memory advanced at its decisions only, zeroed at its
    episode start), whatever the other does."""
    pol = load_policy(lstm_run)
    env = make_native_env(SPEED, 2, dict(scene="yoshida_odd", preset="varied_test",
                                         control_interval=control_interval, **pol.env_kwargs))
    pol.reset(env)
    rng = np.random.default_rng(0)
    n = env.single_observation_space.shape[0]
    obs = rng.normal(size=(10, 2, n)).astype(np.float32)
    got = []
    for t in range(10):
        if t == 4:
            pol.reset(env, np.array([False, True]))
        got.append(pol.act(obs[t]).copy())
    got = np.array(got)
    norm = pol.vecnormalize.normalize_obs
    t = np.arange(10)
    due0 = t % repeat == 0
    due1 = np.where(t < 4, t % repeat == 0, (t - 4) % repeat == 0)
    starts0 = t == 0
    starts1 = (t == 0) | (t == 4)
    want0 = _reference_actions(pol.model, norm(obs[:, 0]), starts0, due0)
    want1 = _reference_actions(pol.model, norm(obs[:, 1]), starts1, due1)
    np.testing.assert_allclose(got[:, 0], want0, atol=1e-6)
    np.testing.assert_allclose(got[:, 1], want1, atol=1e-6)
    # the memory matters: without the episode restart the second one acts differently
    stale = _reference_actions(pol.model, norm(obs[:, 1]), starts0, due0 if repeat == 1
                               else t % repeat == 0)
    assert not np.allclose(stale[4:], want1[4:], atol=1e-6)


def test_a_recurrent_agent_is_evaluated_and_replayed(lstm_run):
    from abb_gym.evaluation.evaluate import evaluate
    for spec in (f"ppo:{lstm_run}", f"replay:ppo:{lstm_run}"):
        result = evaluate(SPEED, "yoshida_odd", spec, episodes=2, seed=0, preset="varied_test")
        assert len(result.episodes) == 2
        assert all(np.isfinite(e["return"]) for e in result.episodes)
