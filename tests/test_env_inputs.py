"""Bad input to the environments and the sweep commands: a result, or one ValueError naming the
field, and never a half-done change.

* A rejected reset (single or vector, any row) leaves every row, its random generator and the
  episode table exactly as they were.
* Actions must have exactly the action space's shape (a transposed batch is not reshaped).
* The reward stays finite and continuous down to zero imbalance (the imbalance floor).
* Angles far beyond 2 pi give the machine of their remainder, bit for bit.
* Episodes too stiff for RK4 are refused up front with what to use instead.
* Sweep commands check every input before any task is dispatched (one line, exit 2).

The hypothesis tests draw reset options, masks, seeds and action arrays at random.
"""
from __future__ import annotations

import math
import time

import gymnasium as gym
import numpy as np
import pytest

import abb_gym  # noqa: F401  (registers the environments)
from abb_gym.cli import main
from abb_gym.envs import episodes
from abb_gym.envs.setup import EnvSetup
from abb_gym.envs.vector import DwellProfileVectorEnv, RunUpSpeedVectorEnv
from abb_gym.physics import rotor
from abb_gym.physics.scene import list_scenes, load_scene

try:
    from hypothesis import HealthCheck, event, given, settings
    from hypothesis import strategies as st
except ImportError:  # the test extra is not installed
    st = None

N = 3  # sub-environments of the vector environments below


def single(env_id: str = "abb_gym/RunUpSpeed-v0", **kw):
    return gym.make(env_id, **kw).unwrapped


def snapshot(env, scratch: bool = True) -> dict:
    """Everything a reset may change: the buffers, the episode table, the generators.
    ``scratch=False`` leaves out the compiled step's input and output rows (``act``, ``out``),
    which a step refused for a non-finite action may have used: they are rewritten by the
    next step and hold no state."""
    bf, tb = env._bufs, env._table
    names = ("s", "p", "b", "d", "st", "obs", "order") + (("act", "out") if scratch else ())
    out = {name: getattr(bf, name).copy() for name in names}
    out.update({f"table.{k}": np.copy(v) for k, v in vars(tb).items()
                if isinstance(v, np.ndarray)})
    if hasattr(env, "_rngs"):
        out["rngs"] = [None if r is None else r.bit_generator.state for r in env._rngs]
        out["prev_done"] = env._prev_done.copy()
    rng = getattr(env, "_np_random", None)
    out["np_random"] = None if rng is None else rng.bit_generator.state
    return out


def assert_unchanged(before: dict, after: dict) -> None:
    assert before.keys() == after.keys()
    for key, value in before.items():
        if isinstance(value, np.ndarray):
            assert np.array_equal(value, after[key], equal_nan=True), key
        else:
            assert value == after[key], key


def one_line(exc: pytest.ExceptionInfo) -> str:
    msg = str(exc.value)
    assert "\n" not in msg, msg
    return msg


# --------------------------------------------------------------------------- atomic resets
def test_a_rejected_vector_reset_changes_nothing():
    vec = RunUpSpeedVectorEnv(N)
    twin = RunUpSpeedVectorEnv(N)
    for env in (vec, twin):
        env.reset(seed=1)
        env.step(np.ones((N, 1)))
    before = snapshot(vec)
    bad = [
        {"options": {"imbalance_ratio": [0.3, -1.0, 0.5]}},  # row 1 invalid, row 0 valid
        {"options": {"ball_drag_scale": [1.0, 1.0, 1e6]}},  # row 2 too stiff for RK4
        {"options": {"imbalance_ratio": 0.5, "imbalence": 1.0}},
        {"seed": [5, 6, -1]},
        {"seed": 7, "options": {"ball_angles": [[0.0, 1.0], [0.0, np.nan], [0.0, 2.0]]}},
        {"options": {"reset_mask": [True, False, True], "imbalance_phase": "x"}},
    ]
    for kwargs in bad:
        with pytest.raises(ValueError) as exc:
            vec.reset(**kwargs)
        one_line(exc)
        assert_unchanged(before, snapshot(vec))
    # the generators were not advanced: the next reset draws what the twin draws
    for env in (vec, twin):
        env.reset()
    assert_unchanged(snapshot(twin), snapshot(vec))


def test_a_rejected_single_reset_changes_nothing():
    env, twin = single(), single()
    for e in (env, twin):
        e.reset(seed=3)
        e.step(np.array([1.0]))
    before = snapshot(env)
    for kwargs in ({"seed": 9, "options": {"imbalance_ratio": -1.0}},
                   {"options": {"ball_drag_scale": 1e6}},
                   {"seed": 9, "options": {"ball_angles": [0.0]}},
                   {"seed": -1}, {"seed": True}, {"seed": 1.5}, {"seed": "0"}):
        with pytest.raises(ValueError) as exc:
            env.reset(**kwargs)
        assert ("seed" in one_line(exc)) == ("options" not in kwargs)
        assert_unchanged(before, snapshot(env))
    assert env.episode.imbalance == twin.episode.imbalance
    for e in (env, twin):
        e.reset()
    assert_unchanged(snapshot(twin), snapshot(env))
    # a NumPy integer is a seed like any other
    a, _ = env.reset(seed=np.int64(4))
    b, _ = twin.reset(seed=4)
    assert np.array_equal(a, b)


# --------------------------------------------------------------------------- action shapes
@pytest.mark.parametrize("action", [0.5, np.float32(0.5), np.zeros((1, 1, 1)), np.zeros((1, 1)),
                                    np.zeros(2), np.array(["a"]), np.array([True]),
                                    np.array([1 + 0j]), [None], "0.5", [[0.1], [0.2]]])
def test_single_env_actions_need_the_exact_shape(action):
    env = single()
    env.reset(seed=0)
    before = snapshot(env)
    with pytest.raises(ValueError) as exc:
        env.step(action)
    assert "(1,)" in one_line(exc)
    assert_unchanged(before, snapshot(env))
    env.step(np.array([0.5]))  # the right shape goes through
    env.step([0.5])


def test_vector_actions_need_the_exact_shape():
    """A transposed (3, 64) batch for 64 DwellProfile environments would scramble the actions
    if it were reshaped; it is refused, in one line naming both shapes."""
    vec = DwellProfileVectorEnv(64, kernel="generic")
    vec.reset(seed=0)
    before = snapshot(vec)
    for actions in (np.zeros((3, 64)), np.zeros(192), np.zeros((64, 3, 1)), np.zeros((64, 1, 3)),
                    np.zeros((64, 3)).astype(str), np.zeros((64, 3), bool), 0.0):
        with pytest.raises(ValueError) as exc:
            vec.step(actions)
        msg = one_line(exc)
        assert "(64, 3)" in msg and len(msg) < 300, msg
        assert_unchanged(before, snapshot(vec))
    assert "(3, 64)" in str(pytest.raises(ValueError, vec.step, np.zeros((3, 64))).value)


# --------------------------------------------------------------------------- reward scale
def episode_return(env, **options) -> float:
    env.reset(seed=0, options=dict(options, imbalance_phase=0.0, ball_angles=[0.5, -0.5],
                                   ball_drag_scale=1.0, rolling_resistance_scale=1.0))
    total, done = 0.0, False
    while not done:
        _, r, term, trunc, _ = env.step(np.array([1.0]))
        total += r
        done = term or trunc
    return total


def test_the_return_is_finite_and_continuous_down_to_zero_imbalance():
    env = single()
    cap = env.scene.balancing_capacity
    at_zero = episode_return(env, imbalance=0.0)
    assert math.isfinite(at_zero)
    for u in (5e-324, 1e-300, 1e-9 * cap, 1e-6 * cap):
        r = episode_return(env, imbalance=u)
        # without the floor: -3.4e6 at 1e-6 capacities, -inf at the subnormal imbalance
        assert math.isfinite(r) and r == pytest.approx(at_zero, rel=1e-4), (u, r, at_zero)
    # the scale itself is continuous at 0 and leaves imbalances above the floor as they are
    floor = rotor.IMBALANCE_FLOOR * cap
    assert rotor.imbalance_scale(env.scene, 0.0) == floor
    assert rotor.imbalance_scale(env.scene, 5e-324) == floor
    assert rotor.imbalance_scale(env.scene, 0.3 * cap) == 0.3 * cap


def test_shipped_scenes_and_presets_lie_above_the_imbalance_floor():
    """The floor changes no shipped episode: every scene's imbalance and every preset's
    imbalance range are above a tenth of the balancing capacity."""
    for name in list_scenes():
        sc = load_scene(name)
        assert sc.imbalance >= rotor.IMBALANCE_FLOOR * sc.balancing_capacity, name
    for preset in ("train", "test"):
        lo = EnvSetup("abb_gym/RunUpSpeed-v0", "yoshida_odd", preset).config.randomize.imbalance_ratio[0]
        assert lo >= rotor.IMBALANCE_FLOOR, preset


# --------------------------------------------------------------------------- angles
def test_angles_far_beyond_two_pi_give_the_machine_of_their_remainder():
    big = {"imbalance_phase": 1e16, "ball_angles": [1e16, -3e9]}
    reduced = {"imbalance_phase": float(np.mod(1e16, 2 * np.pi)),
               "ball_angles": [float(np.mod(1e16, 2 * np.pi)), float(np.mod(-3e9, 2 * np.pi))]}
    runs = []
    for options in (big, reduced):
        env = single()
        _, info = env.reset(seed=0, options=options)
        assert -math.pi <= info["imbalance_phase"] <= math.pi
        assert np.all(np.abs(info["initial_ball_angles"]) <= math.pi)
        runs.append([env.step(np.array([1.0]))[0] for _ in range(60)])
    assert np.array_equal(runs[0], runs[1])
    # angles in [-pi, pi] are kept bit for bit
    env = single()
    _, info = env.reset(seed=0, options={"imbalance_phase": math.pi,
                                         "ball_angles": [-math.pi, 0.1]})
    assert info["imbalance_phase"] == math.pi
    assert info["initial_ball_angles"].tolist() == [-math.pi, 0.1]


# --------------------------------------------------------------------------- stiff episodes
def test_an_episode_too_stiff_for_rk4_is_refused_at_once_with_what_to_use():
    env = single()
    env.reset(seed=0)
    start = time.perf_counter()
    with pytest.raises(ValueError) as exc:
        env.reset(options={"ball_drag_scale": 1e6})
    assert time.perf_counter() - start < 5.0
    msg = one_line(exc)
    assert "ball_drag_scale=1e+06" in msg and "integrator='etdrk4'" in msg
    # the method the message names takes it at its ordinary step
    env = single(integrator="etdrk4")
    env.reset(seed=0, options={"ball_drag_scale": 1e6})
    start = time.perf_counter()
    _, reward, *_ = env.step(np.array([1.0]))
    assert time.perf_counter() - start < 5.0 and math.isfinite(reward)
    # a moderately stiff episode still runs (a few times the ordinary work)
    single().reset(seed=0, options={"ball_drag_scale": 20.0})


def test_a_preset_whose_random_episodes_are_too_stiff_is_refused_when_made():
    with pytest.raises(ValueError, match="randomize ranges allow it.*integrator='etdrk4'"):
        gym.make("abb_gym/RunUpSpeed-v0", randomize={"ball_drag_scale": [1.0, 1e3]})
    with pytest.raises(ValueError, match="etdrk4"):
        RunUpSpeedVectorEnv(2, randomize={"rolling_resistance_scale": [1e3, 1e3],
                                          "ball_drag_scale": [1e3, 1e3]})
    gym.make("abb_gym/RunUpSpeed-v0", randomize={"ball_drag_scale": [1.0, 1e3]},
             integrator="etdrk4")
    gym.make("abb_gym/RunUpSpeed-v0", randomize={"ball_drag_scale": [1.0, 1e3]},
             integration_step=1e-4)  # an explicit step is the user's choice


@pytest.mark.parametrize("scene", list_scenes())
def test_every_shipped_scene_and_preset_is_well_inside_the_stiffness_bound(scene, monkeypatch):
    """A fifth of the bound still accepts every shipped preset's random episodes (the stiffest,
    washer's test preset, needs 15 x)."""
    monkeypatch.setattr(episodes, "MAX_STIFFNESS", episodes.MAX_STIFFNESS / 5)
    for preset in ("train", "test", "nominal"):
        for env_id in ("abb_gym/RunUpTorque-v0", "abb_gym/RunUpSpeed-v0",
                       "abb_gym/DwellProfile-v0"):
            EnvSetup(env_id, scene, preset)
    if scene == "washer":
        for preset in ("laundry", "laundry_test"):
            EnvSetup("abb_gym/SpinRedistribute-v0", scene, preset)


# --------------------------------------------------------------------------- sweep commands
def _refuse(*args, **kwargs):
    raise AssertionError("a task was dispatched before the inputs were checked")


@pytest.mark.parametrize("argv, names", [
    (["study", "settling", "--scene", "nope"], "nope"),
    (["study", "ball-position", "--scene", ""], "scene"),
    (["tune-baselines", "--preset", "nope", "--dry-run"], "nope"),
    (["tune-baselines", "--seed", "-1", "--dry-run"], "--seed"),
    (["tune-baselines", "--env-kwargs", "observe_balls=3", "--dry-run"], "observe_balls"),
    (["tune-baselines", "--env-kwargs", "randomize={ball_drag_scale: [1, 1000]}", "--dry-run"],
     "etdrk4"),
    (["stability-map", "--members", "0"], "--members"),
    (["stability-map", "--omega", "nan"], "--omega"),
    (["stability-map", "--omega", "-2"], "--omega"),
    (["stability-map", "--x-range", "0", "nan"], "--x-range"),
    (["stability-map", "--x", "bogus"], "bogus"),
    (["stability-map", "--balls", "0"], "--balls"),
    (["evaluate", "--policy", "baseline:ramp", "--env", "bogus"], "bogus"),
    (["evaluate", "--policy", "baseline:ramp", "--seed", "-1"], "--seed"),
    (["evaluate", "--policy", "replay:baseline:nope"], "nope"),
    (["evaluate", "--policy", "baseline:ramp", "--sweep", "2", "--sweep-episodes", "0"],
     "--sweep-episodes"),
])
def test_sweep_commands_check_every_input_before_any_task(argv, names, tmp_path, capsys,
                                                          monkeypatch):
    from abb_gym.execution.core import Executor
    monkeypatch.setattr(Executor, "map", _refuse)
    for target in ("abb_gym.evaluation.studies._map", "abb_gym.evaluation.studies.simulate",
                   "abb_gym.evaluation.evaluate._run_chunk_task",
                   "abb_gym.baselines.tuner._run_candidates"):
        monkeypatch.setattr(target, _refuse)
    out = tmp_path / "out"
    assert main([*argv, "--out", str(out)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"abb-gym {argv[0]}: error: "), lines
    assert names in lines[0], lines[0]
    assert not out.exists()  # nothing was written either


def test_the_study_functions_check_their_points_before_running(monkeypatch):
    from abb_gym.evaluation import studies
    monkeypatch.setattr(studies, "_map", _refuse)
    with pytest.raises(ValueError, match="dwell_time"):
        studies.settling_study("yoshida_odd", dwell_times=(0.3, -1.0))
    with pytest.raises(ValueError, match="ball_mass"):
        studies.ball_position_study("yoshida_odd", masses=(1e-3, -1.0))


def test_stability_map_checks_its_settings_before_dispatching(monkeypatch):
    from abb_gym.analysis import Groups, stability_map
    from abb_gym.execution import Executor
    ex = Executor(workers=1, progress=False)
    monkeypatch.setattr(Executor, "map", _refuse)
    grid = (("zeta", [0.05, 0.1]), ("Omega", [1.5, 2.0]))
    for kwargs, name in (({"n_members": 0}, "n_members"), ({"n_members": 2.5}, "n_members"),
                         ({"omega": math.nan}, "Omega"), ({"tol": -1.0}, "tol")):
        with pytest.raises(ValueError, match=name):
            stability_map(Groups(), *grid, executor=ex, **kwargs)
    with pytest.raises(ValueError, match="Omega"):
        stability_map(Groups(), ("zeta", [0.05]), ("Omega", [-1.0, 2.0]), executor=ex)


# --------------------------------------------------------------------------- hypothesis
if st is None:
    def test_random_vector_resets_and_actions():
        pytest.skip("needs hypothesis (the test extra)")
else:
    FIELDS = {  # option -> (valid values, invalid values)
        "imbalance_ratio": ([0.0, 0.3, 1.2], [-0.1, math.nan, math.inf, "a", None]),
        "imbalance": ([0.0, 1e-6, 5e-324], [-1e-6, math.nan]),
        "imbalance_phase": ([0.0, -3.0, 1e16], [math.nan, "x", None]),
        "ball_drag_scale": ([0.5, 1.0, 20.0], [0.0, -1.0, 1e7, math.inf]),
        "rolling_resistance_scale": ([0.0, 1.0, 2.0], [-1.0, math.nan]),
        "ball_angles": ([[0.1, -0.2], [1e9, 0.0]], [[0.1], [0.0, math.nan], "ab"]),
    }

    def _field_value(name):
        good, bad = FIELDS[name]
        one = st.one_of(st.sampled_from(good), st.sampled_from(bad))
        if name == "ball_angles":
            per_row = st.lists(st.sampled_from(good + bad[:2]), min_size=N, max_size=N)
            wrong = st.lists(st.sampled_from(good), min_size=1, max_size=N + 1)
            return st.one_of(st.sampled_from(good), one, per_row,
                             wrong.map(lambda v: np.array(v)))
        per_row = st.lists(st.sampled_from(good + bad[:2]), min_size=N, max_size=N)
        wrong = st.lists(st.sampled_from(good), min_size=1, max_size=N + 2)
        return st.one_of(st.sampled_from(good), one, per_row, wrong)

    OPTIONS = st.dictionaries(st.sampled_from(sorted(FIELDS) + ["imbalence"]),
                              st.just(None), max_size=3).flatmap(
        lambda keys: st.fixed_dictionaries({k: (_field_value(k) if k in FIELDS
                                                else st.just(1.0)) for k in keys}))
    MASKS = st.one_of(st.none(), st.lists(st.booleans(), min_size=N, max_size=N),
                      st.lists(st.booleans(), min_size=1, max_size=N + 1))
    SEEDS = st.one_of(st.none(), st.integers(-2, 2 ** 40),
                      st.lists(st.one_of(st.none(), st.integers(-1, 50)), min_size=N - 1,
                               max_size=N + 1),
                      st.sampled_from([True, 1.5, "3"]))
    SHAPES = st.one_of(st.sampled_from([(N, 1), (1,), (1, N), (N,), (1, 1), ()]),
                       st.lists(st.integers(1, 4), min_size=0, max_size=3).map(tuple))
    DTYPES = st.one_of(st.sampled_from([np.float32, np.float64, np.int64]),
                       st.sampled_from([np.bool_, np.complex128, np.str_, object]))
    VALUES = st.sampled_from([0.0, 0.5, -1.0, -2.0, math.nan, math.inf])

    _ENVS: dict = {}

    def _env(kind: str):
        if kind not in _ENVS:
            env = RunUpSpeedVectorEnv(N, kernel="generic") if kind == "vector" else single()
            env.reset(seed=0)
            _ENVS[kind] = env
        return _ENVS[kind]

    def _named(msg: str, names) -> bool:
        return any(n in msg for n in names)

    @settings(max_examples=400, deadline=None, database=None,
              suppress_health_check=[HealthCheck.too_slow])
    @given(options=OPTIONS, mask=MASKS, seed=SEEDS)
    def test_random_vector_resets_give_a_result_or_change_nothing(options, mask, seed):
        vec = _env("vector")
        opts = dict(options)
        if mask is not None:
            opts["reset_mask"] = np.array(mask)
        before = snapshot(vec)
        try:
            obs, info = vec.reset(seed=seed, options=opts)
        except ValueError as exc:
            msg = str(exc)
            assert "\n" not in msg, msg
            assert _named(msg, [*options, "seed", "reset_mask", "num_envs"]), msg
            assert_unchanged(before, snapshot(vec))
            event("refused")
            return
        event("reset")
        rows = np.arange(N) if mask is None else np.flatnonzero(mask)
        assert vec.observation_space.contains(obs)
        kept = np.setdiff1d(np.arange(N), rows)
        assert np.array_equal(vec.states[kept], before["s"][kept])
        assert info["_imbalance"].tolist() == [i in rows for i in range(N)]
        for i in rows:
            assert np.all(np.abs(vec.episode(int(i)).ball_angles) <= math.pi)

    @settings(max_examples=300, deadline=None, database=None,
              suppress_health_check=[HealthCheck.too_slow])
    @given(kind=st.sampled_from(["vector", "single"]), shape=st.one_of(st.none(), SHAPES),
           dtype=DTYPES, value=VALUES)
    def test_random_actions_are_taken_or_refused_by_shape(kind, shape, dtype, value):
        env = _env(kind)
        expected = (N, 1) if kind == "vector" else (1,)
        shape = expected if shape is None else shape
        try:
            with np.errstate(invalid="ignore"):  # nan as an integer: any integer will do
                action = np.full(shape, value).astype(dtype)
        except (TypeError, ValueError, OverflowError):
            return  # not an array numpy can make: nothing to hand over
        before = snapshot(env, scratch=False)
        try:
            result = env.step(action)
        except ValueError as exc:
            msg = str(exc)
            assert "\n" not in msg, msg
            assert str(expected) in msg or "finite" in msg, msg
            assert_unchanged(before, snapshot(env, scratch=False))
            event("refused")
            return
        event("stepped")
        assert shape == expected and action.dtype.kind in "fiu", (shape, action.dtype)
        assert np.all(np.isfinite(action.astype(float)))
        assert len(result) == 5
        if kind == "single" and (result[2] or result[3]):
            env.reset(seed=0)
