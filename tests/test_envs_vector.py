"""Native vector environments: agreement with single environments (autoreset included),
seeding, options, bad actions, rendering, pickling."""
from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest

import abb_gym  # noqa: F401  (registers the ids)
from abb_gym.envs import ENV_IDS, BalancerVectorEnv
from abb_gym.physics.specialise import VECTORISE_FROM

SPEED = "abb_gym/RunUpSpeed-v0"

SHORT = {"episode_length": 0.3, "settle_time": 0.05}


def make_vec(env_id, n, **kw):
    kw.setdefault("info_level", "full")  # these tests read the per-step keys
    return gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **kw)


def compare_with_singles(env_id, n, steps, seed, actions, **kw):
    """Step the vector env and n single envs side by side (NEXT_STEP autoreset)."""
    vec = make_vec(env_id, n, **kw)
    singles = [gym.make(env_id, **{"info_level": "full", **kw}) for _ in range(n)]
    obs, info = vec.reset(seed=seed)
    done = np.zeros(n, dtype=bool)
    for i, env in enumerate(singles):
        o, inf = env.reset(seed=seed + i)
        assert np.array_equal(obs[i], o)
        assert info["imbalance"][i] == inf["imbalance"]
    resets = ends = 0
    for k in range(steps):
        a = actions[k]
        obs, rew, term, trunc, info = vec.step(a)
        for i, env in enumerate(singles):
            if done[i]:
                o, inf = env.reset()
                r, te, tr = 0.0, False, False
                resets += 1
                assert info["_imbalance"][i] and info["imbalance"][i] == inf["imbalance"]
            else:
                o, r, te, tr, inf = env.step(a[i])
                for name, v in inf["reward_terms"].items():
                    assert info["reward_terms"][name][i] == v
                if "failure" in inf:
                    assert info["_failure"][i] and info["failure"][i] == inf["failure"]
            assert np.array_equal(obs[i], o), (k, i)
            assert rew[i] == r and term[i] == te and trunc[i] == tr, (k, i)
            assert info["rotor_speed"][i] == inf["rotor_speed"]
            assert info["whirl_radius"][i] == inf["whirl_radius"]
            assert info["whirl_ratio"][i] == inf["whirl_ratio"]
            assert np.array_equal(info["ball_angles"][i], inf["ball_angles"])
            assert info["balanced"][i] == inf["balanced"]
            done[i] = te or tr
            ends += te or tr
    return resets, ends


@pytest.mark.parametrize("env_id", ENV_IDS[:2])
def test_vector_matches_single_envs_with_autoreset(env_id):
    rng = np.random.default_rng(0)
    n, steps = 3, 75
    actions = rng.uniform(-0.2, 1.0, size=(steps, n, 1)).astype(np.float32)
    resets, ends = compare_with_singles(env_id, n, steps, 123, actions, **SHORT)
    assert ends >= n and resets >= n  # every sub-environment finished and restarted


@pytest.mark.parametrize("env_id", ENV_IDS[:2])
def test_vector_matches_single_envs_on_varied_machines_with_sync_noise_and_frame_stack(env_id):
    """The varied preset (critical speed, damping and the rest drawn per episode; the noisy
    synchronous vibration observed) with a frame stack: sub-environment i and a single
    environment seeded alike agree bit for bit, across autoresets (the stack starts again)."""
    rng = np.random.default_rng(4)
    n, steps = 3, 75
    kw = dict(preset="varied", frame_stack=2, **SHORT)
    vec = make_vec(env_id, n, **kw)
    _, info = vec.reset(seed=321)
    for i in range(n):
        _, inf = gym.make(env_id, **kw).reset(seed=321 + i)
        for key in ("critical_speed_scale", "support_damping_scale", "integration_step"):
            assert info[key][i] == inf[key], key
    assert len(set(info["critical_speed_scale"])) == n
    actions = rng.uniform(-0.2, 1.0, size=(steps, n, 1)).astype(np.float32)
    resets, ends = compare_with_singles(env_id, n, steps, 321, actions, **kw)
    assert ends >= n and resets >= n


@pytest.mark.parametrize("num_envs", [None, 16])
def test_a_reset_environment_steps_like_a_new_one(num_envs):
    """The lanes of the compiled step keep the state and parameters of the row they stepped
    last (``envs.kernel.G_HELD``): after a reset to another machine (the varied preset draws
    critical speed, damping, imbalance, drag per episode) an environment must step exactly
    like a new one reset with the same seed, in the single environment (one lane) and in the
    vector one (lanes of 4)."""
    kw = dict(preset="varied", **SHORT)

    def make():
        if num_envs is None:
            return gym.make(SPEED, **kw)
        return make_vec(SPEED, num_envs, **kw)

    shape = (1,) if num_envs is None else (num_envs, 1)
    actions = np.random.default_rng(9).uniform(0.2, 1.0, size=(6,) + shape)

    def run(env, seed):
        obs, info = env.reset(seed=seed)
        rows = [obs]
        for a in actions:
            obs, reward, *_ = env.step(a)
            rows += [obs, np.atleast_1d(reward)]
        return info, rows

    used = make()
    first, _ = run(used, 1)
    second, stepped = run(used, 2)
    fresh_info, fresh = run(make(), 2)
    assert np.all(np.asarray(first["critical_speed_scale"])
                  != np.asarray(second["critical_speed_scale"]))  # another machine
    for a, b in zip(stepped, fresh):
        assert np.array_equal(a, b)


def test_vectorised_kernel_equals_the_general_one_with_sync_observation():
    n = 40
    vecs = [make_vec("abb_gym/RunUpSpeed-v0", n, kernel=k, preset="varied")
            for k in ("specialised", "generic")]
    rng = np.random.default_rng(3)
    outs = [v.reset(seed=9) for v in vecs]
    assert np.array_equal(outs[0][0], outs[1][0])
    for _ in range(30):
        a = rng.uniform(-0.3, 1.0, size=(n, 1)).astype(np.float32)
        outs = [v.step(a) for v in vecs]
        for x, y in zip(outs[0][:4], outs[1][:4]):
            assert np.array_equal(x, y)


def test_dwell_vector_matches_single_envs():
    rng = np.random.default_rng(1)
    n = 3
    actions = rng.uniform(-1, 1, size=(4, n, 3)).astype(np.float32)
    resets, ends = compare_with_singles("abb_gym/DwellProfile-v0", n, 4, 7, actions,
                                        scene="lu_hung_odd3")
    assert ends == 2 * n and resets == 2 * n  # episode, autoreset, episode, autoreset


@pytest.mark.parametrize("env_id", ["abb_gym/RunUpSpeed-v0", "abb_gym/DwellProfile-v0"])
def test_vectorised_kernel_equals_the_general_one(env_id):
    """The kernel specialised on the scene (vector instructions across the lanes of a block)
    and the general kernel give the same steps bit for bit, over resets and episode ends;
    with more sub-environments than a block has lanes, rows sorted into blocks by step size,
    and episodes of different step sizes (randomised drag) in one block."""
    n = 40
    kw = dict(info_level="full")
    vecs = [make_vec(env_id, n, kernel=k, **kw) for k in ("specialised", "generic")]
    assert [v.unwrapped.kernel for v in vecs] == ["specialised", "generic"]
    blocks = vecs[0].unwrapped._bufs.blocks
    # more than one block, each wide enough for the specialised kernel
    assert n > blocks.lanes >= VECTORISE_FROM
    rng = np.random.default_rng(2)
    outs = [v.reset(seed=5) for v in vecs]
    assert np.array_equal(outs[0][0], outs[1][0])
    steps = np.unique(vecs[0].unwrapped._table.integration_step)
    assert steps.size > 1 or env_id.endswith("Profile-v0")
    for _ in range(3 if env_id.endswith("Profile-v0") else 40):
        a = rng.uniform(-0.3, 1.0, size=(n,) + vecs[0].single_action_space.shape)
        outs = [v.step(a.astype(np.float32)) for v in vecs]
        for x, y in zip(outs[0][:4], outs[1][:4]):
            assert np.array_equal(x, y)
        assert np.array_equal(vecs[0].unwrapped.states, vecs[1].unwrapped.states)


def test_lean_info_holds_the_reward_terms_and_the_final_metrics():
    vec = gym.make_vec("abb_gym/RunUpSpeed-v0", num_envs=3,
                       vectorization_mode="vector_entry_point", **SHORT)
    single = gym.make("abb_gym/RunUpSpeed-v0", **SHORT)
    obs, info = vec.reset(seed=1)
    assert "imbalance" in info and "time" in info  # reset: everything
    single.reset(seed=1)
    a = np.full((3, 1), 0.7, np.float32)
    while True:
        obs, rew, term, trunc, info = vec.step(a)
        o, r, te, tr, inf = single.step(a[0])
        if not (term | trunc).any():
            assert set(info) == {"reward_terms", "_reward_terms"}
            assert set(inf) == {"reward_terms"}
        else:
            break
    done = term | trunc
    assert info["_time"].tolist() == done.tolist() and info["_reward_terms"].all()
    assert te or tr
    assert info["run_up_time"][0] == inf["run_up_time"] and "residual_vibration" in inf
    # finite final metrics agree too (the run-up time above is inf: these episodes are short)
    assert info["time"][0] == inf["time"] > 0
    assert info["rotor_speed"][0] == inf["rotor_speed"] > 0
    with pytest.raises(ValueError, match="info_level must be one of"):
        gym.make("abb_gym/RunUpSpeed-v0", info_level="verbose")


def test_lean_info_measures_the_residual_imbalance_only_where_it_shows_it():
    """At "lean" the step measures the residual imbalance only for the sub-environments whose
    episode ends (their values equal a full-info twin's; the masked entries read 0), and a
    level set between steps is checked and takes effect at the next step."""
    kw = dict(scene="yoshida_odd", max_episode_steps=40)
    lean, full = make_vec(SPEED, 3, info_level="lean", **kw), make_vec(SPEED, 3, **kw)
    # the middle sub-environment's imbalance throws it into the housing at step 18
    options = {"imbalance_ratio": [0.5, 2000.0, 0.5]}
    lean.reset(seed=2, options=options)
    full.reset(seed=2, options=options)
    ended = []
    for k in range(40):
        _, r_lean, te, tr, lean_info = lean.step(np.full((3, 1), 1.0))
        _, r_full, _, _, full_info = full.step(np.full((3, 1), 1.0))
        assert np.array_equal(r_lean, r_full)
        done = te | tr
        if done.any():
            ended.append(done.tolist())
            for key in ("residual_imbalance_ratio", "balanced"):
                assert np.array_equal(lean_info[key][done], full_info[key][done])
                assert not lean_info[key][~done].any()
            assert (lean_info["residual_imbalance_ratio"][done] > 0).all()
    assert ended == [[False, True, False], [True, False, True]]
    single, twin = (gym.make(SPEED, info_level=level, **kw) for level in ("lean", "full"))
    single.reset(seed=1)
    twin.reset(seed=1)
    for k in range(5):
        _, _, _, _, info = single.step(np.array([1.0]))
        _, _, _, _, twin_info = twin.step(np.array([1.0]))
    assert "balanced" not in info
    with pytest.raises(ValueError, match="info_level must be one of"):
        single.unwrapped.info_level = "verbose"
    single.unwrapped.info_level = "full"
    _, _, _, _, info = single.step(np.array([1.0]))
    _, _, _, _, twin_info = twin.step(np.array([1.0]))
    assert info["residual_imbalance_ratio"] == twin_info["residual_imbalance_ratio"] > 0
    assert info["balanced"] == twin_info["balanced"]


def test_make_vec_returns_native_vector_env():
    for env_id in ENV_IDS:
        vec = make_vec(env_id, 4)
        assert isinstance(vec.unwrapped, BalancerVectorEnv)
        assert vec.num_envs == 4
        assert vec.observation_space.shape == (4,) + vec.single_observation_space.shape
        assert vec.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP
        obs, info = vec.reset(seed=0)
        assert obs.shape == vec.observation_space.shape and obs.dtype == np.float32
        assert vec.observation_space.contains(obs)
        obs, rew, term, trunc, info = vec.step(vec.action_space.sample())
        assert vec.observation_space.contains(obs)
        assert rew.shape == (4,) and term.dtype == np.bool_ and trunc.dtype == np.bool_
        assert info["_reward_terms"].all()
        vec.close()


def test_backstop_matches_time_limit():
    vec = make_vec("abb_gym/RunUpSpeed-v0", 2, max_episode_steps=5)
    single = gym.make("abb_gym/RunUpSpeed-v0", max_episode_steps=5)
    vec.reset(seed=0)
    single.reset(seed=0)
    for k in range(5):
        _, r, te, tr, _ = vec.step(np.full((2, 1), 0.5))
        _, r1, te1, tr1, _ = single.step(np.array([0.5]))
        assert r[0] == r1 and tr[0] == tr1 and te[0] == te1
    assert tr.all() and tr1


def test_seed_list_and_options_per_env():
    vec = make_vec("abb_gym/RunUpSpeed-v0", 3)
    _, info = vec.reset(seed=[5, 6, 7], options={"imbalance_ratio": [0.3, 0.5, 0.7],
                                                  "ball_angles": [1.0, -1.0]})
    cap = vec.unwrapped.scene.balancing_capacity
    np.testing.assert_allclose(info["imbalance"], np.array([0.3, 0.5, 0.7]) * cap)
    assert np.array_equal(info["initial_ball_angles"], [[1.0, -1.0]] * 3)
    _, info = vec.reset(options={"ball_angles": [[0.0, 1.0], [1.0, 2.0], [2.0, 3.0]]})
    assert np.array_equal(info["initial_ball_angles"][2], [2.0, 3.0])
    with pytest.raises(ValueError, match="num_envs"):
        vec.reset(options={"imbalance_ratio": [0.3, 0.5]})
    # partial reset: only sub-environment 1 restarts
    vec.step(np.full((3, 1), 1.0))
    mask = np.array([False, True, False])
    obs, info = vec.reset(options={"reset_mask": mask})
    assert obs[1, 0] == 0.0 and obs[0, 0] > 0.0 and obs[2, 0] > 0.0
    assert info["_imbalance"].tolist() == [False, True, False]


def test_vector_bad_actions():
    vec = make_vec("abb_gym/RunUpSpeed-v0", 2)
    vec.reset(seed=0)
    states = vec.unwrapped.states
    bad = np.array([[0.5], [np.nan]])
    with pytest.raises(ValueError, match="finite"):
        vec.step(bad)
    assert np.array_equal(vec.unwrapped.states, states)
    with pytest.raises(ValueError, match="shape"):
        vec.step(np.zeros((3, 1)))
    with pytest.warns(UserWarning, match="clipped"):
        vec.step(np.array([[2.0], [0.0]]))
    with pytest.raises(gym.error.ResetNeeded):
        make_vec("abb_gym/RunUpSpeed-v0", 2).step(np.zeros((2, 1)))
    with pytest.raises(ValueError, match="num_envs"):
        make_vec("abb_gym/RunUpSpeed-v0", 0)


def test_vector_render_and_pickle():
    vec = make_vec("abb_gym/RunUpTorque-v0", 5, render_mode="rgb_array")
    vec.reset(seed=0)
    a = np.full((5, 1), 0.4)
    for _ in range(3):
        vec.step(a)
    frames = vec.render()
    assert isinstance(frames, tuple) and len(frames) == 4
    assert all(f.dtype == np.uint8 and f.shape[2] == 3 for f in frames)
    clone = pickle.loads(pickle.dumps(vec))
    o1, r1, *_ = vec.step(a)
    o2, r2, *_ = clone.step(a)
    assert np.array_equal(o1, o2) and np.array_equal(r1, r2)
    vec.close()


def test_failure_info_is_masked_to_the_rows_that_failed():
    """One sub-environment at full torque overspeeds while the other stays at rest: the
    failure message and its ``_failure`` mask name that row only; also when the other row's
    episode ends (time limit) in the same step, so the mask is not the done mask."""
    def run(max_episode_steps=None):
        env = gym.make_vec("abb_gym/RunUpTorque-v0", num_envs=2,
                           vectorization_mode="vector_entry_point", scene="yoshida_odd",
                           control_interval=0.05, max_episode_steps=max_episode_steps)
        env.reset(seed=0)
        actions = np.array([[1.0], [0.0]], dtype=np.float32)
        for k in range(1, 201):
            _, _, terminated, truncated, info = env.step(actions)
            if "failure" in info:
                env.close()
                return k, terminated, truncated, info
        pytest.fail("full torque never overspeeded in 10 s")

    k, terminated, truncated, info = run()
    assert info["_failure"].tolist() == [True, False]
    assert info["failure"][0].startswith("overspeed") and info["failure"][1] is None
    assert terminated.tolist() == [True, False]
    # the resting row reaches its step limit in the step in which the other one overspeeds
    k_again, terminated, truncated, info = run(max_episode_steps=k)
    assert k_again == k and truncated[1] and not terminated[1]
    assert info["_failure"].tolist() == [True, False]
    assert info["failure"][1] is None


def test_reward_term_named_failure_is_masked_like_the_other_terms():
    """The reward term ``failure`` (a float per row) shares its name with the failure
    messages (None where a row did not fail), whose mask says which rows failed.  The term's
    mask is the info's mask, like its siblings': after a partial reset it names the reset
    rows only."""
    env = gym.make_vec("abb_gym/RunUpSpeed-v0", num_envs=3,
                       vectorization_mode="vector_entry_point", scene="yoshida_odd")
    env.reset(seed=0)
    env.step(np.full((3, 1), 0.5, dtype=np.float32))
    reset_mask = np.array([False, True, False])
    _, info = env.reset(options={"reset_mask": reset_mask})
    terms = info["reward_terms"]
    assert terms["failure"].dtype == np.float64
    for name in ("vibration", "failure"):
        assert terms["_" + name].tolist() == reset_mask.tolist(), name
    _, _, _, _, info = env.step(np.full((3, 1), 0.5, dtype=np.float32))
    assert info["reward_terms"]["_failure"].all() and "failure" not in info
    env.close()


def test_auto_on_a_few_lanes_takes_the_specialised_kernel_when_it_needs_no_compiling():
    """"auto" below VECTORISE_FROM lanes (the single env, small vector envs) runs the
    specialised kernel once it is compiled (here: by an env that asks for it; in the wheel:
    its cache of the default scene), and the general one otherwise; both step bit for bit
    alike."""
    forced = make_vec(SPEED, 1, kernel="specialised")  # one lane: the serial kernel
    forced.reset(seed=0)
    forced.step(np.full((1, 1), 0.5, np.float32))  # compiles or loads the specialised kernel
    single = gym.make(SPEED, info_level="full")
    general = make_vec(SPEED, 1, kernel="generic")
    assert single.unwrapped._bufs.kernel == "specialised"
    assert general.unwrapped.kernel == "generic"
    obs_s, _ = single.reset(seed=4)
    obs_g, _ = general.reset(seed=4)
    assert np.array_equal(obs_s, obs_g[0])
    rng = np.random.default_rng(3)
    for _ in range(60):
        a = rng.uniform(-0.3, 1.0, size=(1, 1)).astype(np.float32)
        out_s = single.step(a[0])
        out_g = general.step(a)
        assert np.array_equal(out_s[0], out_g[0][0])
        assert out_s[1] == out_g[1][0]
        if out_s[2] or out_s[3]:
            break


def test_cached_entry_compiles_nothing():
    from numba import njit

    from abb_gym.physics.specialise import Specialised, resolve_kernel

    @njit  # no on-disk cache: nothing to load
    def scaled(x, k):
        return x * k

    fn = Specialised(scaled, literal=(1,), names=("k",))
    assert fn.cached_entry(2.0, 3) is None
    assert scaled.signatures == []  # asking compiled nothing
    assert fn(2.0, 3) == 6.0
    assert fn.cached_entry(2.0, 3) is not None  # compiled in this process now
    assert resolve_kernel("auto", 1, cached_ok=True) == "cached"
    assert resolve_kernel("auto", 1) == "generic"
    assert resolve_kernel("generic", 1, cached_ok=True) == "generic"
    assert resolve_kernel("auto", VECTORISE_FROM, cached_ok=True) == "specialised"
