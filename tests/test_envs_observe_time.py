"""``observe_time: false``: the observation without the time fraction.  Every other entry is
the one the environment with the time fraction observes, moved up by one, step for step: the
option changes what a policy sees, never the simulation."""
from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import abb_gym  # noqa: F401  (registers the ids)
from abb_gym.envs import PresetError, load_preset
from abb_gym.rl.env_factory import observation_kwargs, policy_env_fields

IDS = ["abb_gym/RunUpTorque-v0", "abb_gym/RunUpSpeed-v0", "abb_gym/DwellProfile-v0"]
TIME_INDEX = 4


def _without_time(obs: np.ndarray, frame_dim: int) -> np.ndarray:
    """``obs`` (one or several frames, rows last) with each frame's time fraction removed."""
    frames = obs.reshape(obs.shape[:-1] + (-1, frame_dim))
    return np.delete(frames, TIME_INDEX, axis=-1).reshape(obs.shape[:-1] + (-1,))


@pytest.mark.parametrize("env_id", IDS)
def test_every_other_entry_is_the_same_step_for_step(env_id):
    kwargs = dict(preset="varied", frame_stack=2, observe_balls=True,
                  sync_vibration={"enabled": True, "noise": 0.01})
    with_time = gym.make(env_id, **kwargs)
    without = gym.make(env_id, observe_time=False, **kwargs)
    frame_dim = with_time.unwrapped.setup.frame_dim
    assert without.unwrapped.setup.frame_dim == frame_dim - 1
    assert without.observation_space.shape == (2 * (frame_dim - 1),)
    names = with_time.unwrapped.observation_names
    assert without.unwrapped.observation_names == [n for n in names
                                                   if not n.startswith("time_fraction")]
    a, _ = with_time.reset(seed=4)
    b, _ = without.reset(seed=4)
    np.testing.assert_array_equal(b, _without_time(a, frame_dim))
    rng = np.random.default_rng(0)
    moved = False
    for _ in range(25):
        action = rng.uniform(-1.0, 1.0, with_time.action_space.shape).astype(np.float32)
        a, ra, ta, ua, _ = with_time.step(action)
        b, rb, tb, ub, _ = without.step(action)
        assert (rb, tb, ub) == (ra, ta, ua)
        np.testing.assert_array_equal(b, _without_time(a, frame_dim))
        assert b in without.observation_space
        moved |= a.reshape(2, frame_dim)[-1, TIME_INDEX] > 0.0
        if ta or ua:
            break
    assert moved  # the entry removed was the clock, which had advanced


def test_the_vector_environment_leaves_it_out_alike():
    env_id = "abb_gym/RunUpSpeed-v0"
    with_time = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point")
    without = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point",
                           observe_time=False)
    frame_dim = with_time.unwrapped.setup.frame_dim
    a, _ = with_time.reset(seed=7)
    b, _ = without.reset(seed=7)
    actions = np.full((3, 1), 0.4, dtype=np.float32)
    for _ in range(10):
        a, *_ = with_time.step(actions)
        b, *_ = without.step(actions)
    np.testing.assert_array_equal(b, _without_time(a, frame_dim))
    assert without.single_observation_space.shape == (frame_dim - 1,)


@pytest.mark.parametrize("env_id", IDS)
def test_check_env_without_the_time_fraction(env_id, strict_check_env):
    strict_check_env(gym.make(env_id, observe_time=False))


def test_the_setting_is_checked_and_travels_with_an_agent():
    with pytest.raises(PresetError, match="'observe_time' must be true or false"):
        load_preset("train", observe_time=0)
    env = gym.make("abb_gym/RunUpTorque-v0", observe_time=False)
    recorded = policy_env_fields(env)
    assert recorded["observe_time"] is False
    # an evaluation builds the agent's environment with it
    assert observation_kwargs(recorded)["observe_time"] is False
    assert load_preset("train").observe_time is True
