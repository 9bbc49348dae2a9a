"""Potential-based reward shaping (abb_gym.rl.shaping): the shaping terms of an episode sum
to the start's potential (so every policy's return moves by the same amount), a bootstrapped
truncation keeps the terminal observation's potential, bad settings name the field, and a
training run with shaping trains and records it."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

pytest.importorskip("stable_baselines3")

from abb_gym.rl.config import TrainConfig, TrainConfigError  # noqa: E402
from abb_gym.rl.env_factory import make_sb3_env  # noqa: E402
from abb_gym.rl.shaping import PotentialShaping, potential_index  # noqa: E402

SPEED = "abb_gym/RunUpSpeed-v0"
ENV = dict(scene="yoshida_odd", preset="varied", control_interval=0.05)


def _episode(bootstrap_truncated: bool, episode_length: float | None, gamma: float,
             action: float, observation: str = "sync_amplitude", target: float | None = None):
    """One episode of sub-environment 0 with and without shaping (same seed, same actions):
    the shaped and plain rewards, the shaped entry of the first and the terminal observation,
    and whether it was truncated."""
    kwargs = dict(ENV, **({} if episode_length is None else {"episode_length": episode_length}))
    plain = make_sb3_env(SPEED, 2, kwargs, bootstrap_truncated=bootstrap_truncated)
    shaped_env = make_sb3_env(SPEED, 2, kwargs, bootstrap_truncated=bootstrap_truncated)
    index = potential_index(shaped_env.unwrapped.setup.obs_names, observation)
    shaped = PotentialShaping(shaped_env, index, 3.0, gamma, target)
    out = {}
    for name, env in (("plain", plain), ("shaped", shaped)):
        env.seed(7)
        obs = env.reset()
        first = obs[0, index]
        rewards = []
        for _ in range(10_000):
            obs, r, done, infos = env.step(np.full((2, 1), action, np.float32))
            rewards.append(float(r[0]))
            if done[0]:
                out[name] = (np.array(rewards), first, infos[0]["terminal_observation"][index],
                             bool(infos[0].get("TimeLimit.truncated")))
                break
    return out


@pytest.mark.parametrize("action", [0.3, 0.9])
def test_the_shaping_of_an_episode_sums_to_the_start_potential(action):
    gamma = 0.98
    out = _episode(False, None, gamma, action)
    plain, first, _, _ = out["plain"]
    shaped, first_s, _, _ = out["shaped"]
    assert first == first_s and len(plain) == len(shaped) > 20
    discount = gamma ** np.arange(len(plain))
    # Ng et al. 1999: sum_t gamma^t F_t = gamma^T Phi(o_T) - Phi(o_0) = -Phi(o_0) = 3 * a_0
    # (Phi = 0 after the end); float32 rewards: tolerance of a few float32 ulps per step
    assert np.sum(discount * (shaped - plain)) == pytest.approx(3.0 * first, abs=1e-4)
    # the shaping is not zero step by step: it moves reward to where the vibration changes
    assert np.max(np.abs(shaped - plain)) > 1e-3


def test_a_target_makes_the_potential_the_distance_from_it():
    # rotor_speed from 0 at rest to 1 at the operating speed: Phi = -3 |o - 1| starts at -3
    # and pays most while the rotor approaches w_op, where a plain -3 o would penalise it
    gamma = 0.98
    out = _episode(False, None, gamma, 0.9, "rotor_speed", 1.0)
    plain, first, _, _ = out["plain"]
    shaped, *_ = out["shaped"]
    assert first == 0.0
    discount = gamma ** np.arange(len(plain))
    assert np.sum(discount * (shaped - plain)) == pytest.approx(3.0 * abs(first - 1.0),
                                                                abs=1e-4)
    # the run-up's first decision moves the rotor towards w_op: positive shaping
    assert shaped[0] - plain[0] > 0.0


def test_a_bootstrapped_truncation_keeps_the_terminal_potential():
    gamma = 0.95
    out = _episode(True, 2.0, gamma, 0.3)  # 2 s: truncated long before the operating speed
    plain, first, last, truncated = out["plain"]
    shaped, *_ = out["shaped"]
    assert truncated
    T = len(plain)
    discount = gamma ** np.arange(T)
    want = gamma ** T * (-3.0 * last) - (-3.0 * first)
    assert np.sum(discount * (shaped - plain)) == pytest.approx(want, abs=1e-4)


def _cfg(**shaping):
    return {"n_envs": 2, "n_timesteps": 256, "policy": "BoundedMlpPolicy",
            "env_kwargs": dict(ENV)}, {"shaping": shaping or None}


@pytest.mark.parametrize("shaping, match", [
    ({"weight": 2.0}, r"shaping.observation' is missing"),
    ({"observation": "sync_amplitude", "weight": -1.0},
     r"shaping: field 'weight' must be in \[0, 1e\+06\]"),
    ({"observation": "sync_amplitude", "gain": 1.0}, r"unknown field\(s\) \['gain'\]"),
    ({"observation": "rotor_speed", "target": "one"}, r"field 'target' must be in"),
    ({"observation": "rotor_speed", "target": float("nan")}, r"field 'target'"),
    ("sync_amplitude", r"'shaping' must be a mapping"),
])
def test_bad_shaping_settings_name_the_field(shaping, match):
    entry, _ = _cfg()
    with pytest.raises(TrainConfigError, match=match):
        TrainConfig.from_mapping(SPEED, entry, "x.yml", {"shaping": shaping})


def test_shaping_belongs_in_the_abb_gym_section():
    entry, _ = _cfg()
    entry["shaping"] = {"observation": "sync_amplitude"}
    with pytest.raises(TrainConfigError, match="'shaping' belongs in the _abb_gym section"):
        TrainConfig.from_mapping(SPEED, entry, "x.yml")


def test_an_unknown_observation_names_the_choices():
    with pytest.raises(ValueError, match=r"one of \[.*'sync_amplitude'.*\] \(got 'amp'\)"):
        potential_index(["rotor_speed@t-1", "sync_amplitude@t-1", "rotor_speed",
                         "sync_amplitude"], "amp")
    assert potential_index(["sync_amplitude@t-1", "sync_amplitude"], "sync_amplitude") == 1


def test_a_shaped_training_run_records_its_shaping(tmp_path, train_config):
    entry, _ = _cfg()
    entry.update(n_steps=64, batch_size=64, n_epochs=1)
    data = {SPEED: entry, "_abb_gym": {"eval_freq": 0, "eval_episodes": 2,
                                       "eval_env_kwargs": {"preset": "varied_test"},
                                       "shaping": {"observation": "sync_amplitude",
                                                   "weight": 5.0}}}
    assert train_config(data, tmp_path) == 0
    stored = yaml.safe_load((tmp_path / "run" / "config.yml").read_text())
    assert stored["_abb_gym"]["shaping"] == {"observation": "sync_amplitude", "weight": 5.0}
    # an observation the environment does not have is refused before training
    data["_abb_gym"]["shaping"]["observation"] = "ball_angle"
    assert train_config(data, tmp_path, name="run2") == 2
