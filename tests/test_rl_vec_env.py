"""The SB3 adapter over the native vector environment: SB3's same-step reset semantics.

Reference: SB3's own ``DummyVecEnv`` over single environments seeded alike must produce the
same observations, rewards, dones, terminal observations and truncation flags, and the step
after an episode end must be a real step of the new episode (not gymnasium's NEXT_STEP
reset step).
"""
from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("torch")

from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor, VecNormalize  # noqa: E402

import abb_gym  # noqa: E402,F401
from abb_gym.rl.env_factory import make_native_env, make_sb3_env  # noqa: E402
from abb_gym.rl.vec_env import NativeVecEnv, split_info  # noqa: E402

SPEED = "abb_gym/RunUpSpeed-v0"
# short episodes: 6 control steps of 50 ms end in truncation
SHORT = dict(scene="yoshida_odd", preset="train", control_interval=0.05, episode_length=0.3,
             settle_time=0.1)


def _actions(rng, n, k=1):
    return rng.uniform(-1.0, 1.0, size=(n, k)).astype(np.float32)


def test_matches_dummy_vec_env_over_single_envs():
    n, steps = 3, 20
    ours = make_sb3_env(SPEED, n, SHORT)
    ref = DummyVecEnv([lambda: gym.make(SPEED, **SHORT) for _ in range(n)])
    ours.seed(7)
    ref.seed(7)
    o1, o2 = ours.reset(), ref.reset()
    np.testing.assert_array_equal(o1, o2)
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(steps):
        a = _actions(rng, n)
        o1, r1, d1, i1 = ours.step(a)
        o2, r2, d2, i2 = ref.step(a)
        np.testing.assert_array_equal(o1, o2)
        np.testing.assert_allclose(r1, r2, rtol=0, atol=1e-6)
        np.testing.assert_array_equal(d1, d2)
        for a_, b_ in zip(i1, i2):
            assert a_["TimeLimit.truncated"] == b_["TimeLimit.truncated"]
            assert ("terminal_observation" in a_) == ("terminal_observation" in b_)
            if "terminal_observation" in a_:
                ends += 1
                np.testing.assert_array_equal(a_["terminal_observation"],
                                              b_["terminal_observation"])
                # lean info: the run-up metrics come with the step that ends an episode
                assert a_["time"] == pytest.approx(b_["time"])
                assert a_["settled"] == b_["settled"]
            assert a_.keys() - {"is_success"} == b_.keys()  # is_success: the adapter's own
            assert a_["reward_terms"] == pytest.approx(b_["reward_terms"])
    assert ends >= 2 * n  # several episodes ended and were compared


def test_same_step_reset_and_next_step_is_real():
    env = make_sb3_env(SPEED, 2, SHORT)
    env.seed(0)
    obs = env.reset()
    dt = 0.05
    a = np.full((2, 1), 0.5, np.float32)
    for k in range(1, 6):
        obs, rew, done, infos = env.step(a)
        assert not done.any()
    obs, rew, done, infos = env.step(a)  # 6th step: truncated at 0.3 s
    assert done.all()
    for i in range(2):
        assert infos[i]["TimeLimit.truncated"] is True
        assert infos[i]["is_success"] is False
        term = infos[i]["terminal_observation"]
        assert term[4] == pytest.approx(1.0)          # time fraction at the end
        assert obs[i][4] == 0.0                       # returned obs: the new episode
        assert obs[i][0] == 0.0                       # at rest
        assert "imbalance" in env.reset_infos[i]      # reset info of the new episode
    obs, rew, done, infos = env.step(a)  # a real step of the new episode
    assert not done.any()
    for i in range(2):
        assert obs[i][4] == pytest.approx(dt / 0.3, rel=1e-5)
        assert obs[i][0] > 0.0                        # the action was applied
        assert obs[i][5] == pytest.approx(0.5)        # last action
        assert rew[i] != 0.0


def test_dwell_profile_every_step_ends_and_resets():
    env = make_sb3_env("abb_gym/DwellProfile-v0", 2, dict(scene="yoshida_odd"))
    env.seed(1)
    env.reset()
    for _ in range(2):
        obs, rew, done, infos = env.step(np.zeros((2, 3), np.float32))
        assert done.all()
        for inf in infos:
            assert inf["TimeLimit.truncated"] is False   # terminated, never truncated
            assert "terminal_observation" in inf
            assert isinstance(inf["is_success"], bool)
        assert np.isfinite(rew).all()


def test_info_keys_keep_only_the_episode_end_keys_and_the_same_steps():
    """Training's adapter (info_keys=()) drops the per-step infos but keeps what SB3 reads at
    an episode's end; observations and rewards are those of the adapter with every key."""
    lean, full = make_sb3_env(SPEED, 2, SHORT, info_keys=()), make_sb3_env(SPEED, 2, SHORT)
    for env in (lean, full):
        env.seed(4)
    assert np.array_equal(lean.reset(), full.reset())
    rng = np.random.default_rng(0)
    for step in range(6):
        act = _actions(rng, 2)
        o1, r1, d1, i1 = lean.step(act)
        o2, r2, d2, i2 = full.step(act)
        assert np.array_equal(o1, o2) and np.array_equal(r1, r2) and np.array_equal(d1, d2)
        for a, b, done in zip(i1, i2, d1):
            assert "reward_terms" in b and "reward_terms" not in a
            if done:
                assert np.array_equal(a["terminal_observation"], b["terminal_observation"])
                assert a["TimeLimit.truncated"] == b["TimeLimit.truncated"]
    assert d1.all()  # the 6-step episodes ended


def test_truncation_can_be_treated_as_termination():
    env = make_sb3_env(SPEED, 1, SHORT, bootstrap_truncated=False)
    env.seed(0)
    env.reset()
    for _ in range(6):
        _, _, done, infos = env.step(np.ones((1, 1), np.float32))
    assert done[0] and infos[0]["TimeLimit.truncated"] is False


def test_seeding_options_and_attributes():
    env = make_sb3_env(SPEED, 2, SHORT)
    env.seed(3)
    a = env.reset()
    env.seed(3)
    b = env.reset()
    np.testing.assert_array_equal(a, b)
    assert env.reset_infos[0]["imbalance"] != env.reset_infos[1]["imbalance"]
    env.set_options({"imbalance_ratio": 0.5, "imbalance_phase": 0.0})
    env.reset()
    assert env.reset_infos[0]["imbalance_phase"] == 0.0
    cap = env.unwrapped.scene.balancing_capacity
    assert env.reset_infos[1]["imbalance"] == pytest.approx(0.5 * cap)
    env.set_options([{"imbalance_ratio": 0.4}, {"imbalance_ratio": 0.6}])
    env.reset()
    assert env.reset_infos[0]["imbalance"] == pytest.approx(0.4 * cap)
    assert env.reset_infos[1]["imbalance"] == pytest.approx(0.6 * cap)
    env.set_options([{"imbalance_ratio": 0.4}, {}])
    with pytest.raises(ValueError, match="same keys"):
        env.reset()
    assert env.get_attr("render_mode") == [None, None]
    assert env.get_attr("num_envs", indices=[1]) == [2]
    assert env.env_is_wrapped(gym.Wrapper) == [False, False]
    assert env.env_method("episode_scene", 0)[0].name == "yoshida_odd"


def test_wrappers_and_info_split():
    env = VecNormalize(VecMonitor(make_sb3_env(SPEED, 2, SHORT)))
    env.seed(0)
    env.reset()
    episodes = 0
    for _ in range(12):
        _, _, done, infos = env.step(np.ones((2, 1), np.float32))
        episodes += sum("episode" in inf for inf in infos)
    assert episodes == 4  # two 6-step episodes per sub-environment, logged by VecMonitor
    info = {"a": np.array([1, 2]), "_a": np.array([True, False]),
            "d": {"x": np.array([3, 4]), "_x": np.array([True, True])},
            "_d": np.array([True, True])}
    assert split_info(info, 2) == [{"a": 1, "d": {"x": 3}}, {"d": {"x": 4}}]


def test_rejects_unsupported_env():
    class Fake:
        single_observation_space = gym.spaces.Discrete(3)
        single_action_space = gym.spaces.Box(-1, 1, (1,))
        metadata = {}
        num_envs = 1
    with pytest.raises(ValueError, match="Box"):
        NativeVecEnv(Fake())
    native = make_native_env(SPEED, 1, SHORT)
    native.metadata = dict(native.metadata, autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    with pytest.raises(ValueError, match="NEXT_STEP"):
        NativeVecEnv(native)
