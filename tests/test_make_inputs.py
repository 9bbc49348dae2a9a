"""Bad keyword arguments to ``gym.make`` and ``gym.make_vec``: the answer is an environment whose
every keyword took effect, or a ValueError (PresetError, SceneError) naming the keyword; never
another exception type, a hang, a NaN in the spaces or the first observations, or a keyword
silently ignored.

First one regression test per class of bad input found by fuzzing, then property-based tests
(hypothesis) over the keywords of the three ids, single and vector.  The property runs make
environments and reset them; they step once only when the step is cheap (a few thousand RK4
steps), so the file takes well under a minute.  ``ABB_GYM_FUZZ_SCALE=20`` runs 20 times the
examples with a fresh seed.

Outside the project's reach: ``gym.make``'s own ``max_episode_steps`` (gymnasium's TimeLimit
raises TypeError for a non-integer) and ``disable_env_checker`` are consumed by gymnasium
before the environment sees them; the vector environment receives ``max_episode_steps`` and
checks it (tested below).
"""
from __future__ import annotations

import math
import os
import warnings

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import abb_gym  # noqa: F401  (registers the environments)
from abb_gym.configuration import ConfigError, build, specs
from abb_gym.envs import PresetError, episode_steps
from abb_gym.envs.tasks import TASKS

from abb_gym.envs import buffers as env_setup
from abb_gym.envs.config import _SECTIONS, EnvConfig, RewardWeights
from abb_gym.physics import SimulationError
from abb_gym.physics.scene import list_scenes, load_scene

# the ids that run on any scene (SpinRedistribute needs a washer: tests/test_spin.py)
ENV_IDS = tuple(t.env_id for t in TASKS.values() if not t.settings)

SPEED, TORQUE, DWELL = "abb_gym/RunUpSpeed-v0", "abb_gym/RunUpTorque-v0", "abb_gym/DwellProfile-v0"


def make_vec(env_id, num_envs=2, **kwargs):
    return gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        **kwargs)


def one_line(exc: pytest.ExceptionInfo) -> str:
    msg = str(exc.value)
    assert "\n" not in msg, msg
    return msg


@pytest.fixture(autouse=True)
def _quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # gymnasium's render-mode and checker warnings
        yield


# ================================================================== regression, class by class
# ------------------------------------------- keys of mixed types (sorted() raised TypeError)
def test_keys_of_any_type_are_named_not_sorted(tmp_path):
    for kwargs, where in (({"preset": {1: 2, None: 3}}, "unknown field"),
                          ({"reward": {1: 2, "time": 1.0, None: 3}}, "'reward'"),
                          ({"preset": {"randomize": {"a": 1, 2: 3}}}, "'randomize'")):
        with pytest.raises(PresetError, match=where) as exc:
            gym.make(SPEED, **kwargs)
        assert "None" in one_line(exc) or "2" in str(exc.value)
    path = tmp_path / "odd.yaml"
    path.write_text("1: 2\n~: 3\ncontrol_interval: 0.02\n")
    with pytest.raises(PresetError, match="unknown field"):
        gym.make(SPEED, preset=str(path))
    with pytest.raises(ConfigError, match="unknown field"):
        build(RewardWeights, {1: 2.0, None: 1.0, "time": 1.0}, "weights")
    env = gym.make(SPEED).unwrapped
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(seed=0, options={1: 0.5, None: 0.5})


# --------------------------------------- render_mode / info_level that are not text
# gym.make called render_mode.endswith() (AttributeError, TypeError); ``in`` on an array is
# ambiguous (a ValueError that names nothing)
ODD_MODES = [True, 1, b"rgb_array", ["human"], np.array(["human", "rgb_array"]), {"a": 1},
             np.array([1.0, 2.0])]


@pytest.mark.parametrize("mode", ODD_MODES, ids=repr)
def test_a_render_mode_that_is_not_text_is_named(mode):
    for env_id in ENV_IDS:
        with pytest.raises(ValueError, match="render_mode"):
            gym.make(env_id, render_mode=mode)
        with pytest.raises(ValueError, match="render_mode"):
            make_vec(env_id, render_mode=mode)


@pytest.mark.parametrize("level", [None, True, 1, ["lean"], np.array(["lean", "full"]), "LEAN"],
                         ids=repr)
def test_an_info_level_that_is_not_lean_or_full_is_named(level):
    for make in (gym.make, make_vec):
        with pytest.raises(ValueError, match="info_level"):
            make(SPEED, info_level=level)


def test_text_render_modes_keep_gymnasiums_wrappers():
    env = gym.make(SPEED, render_mode="rgb_array_list")
    assert isinstance(env, gym.wrappers.RenderCollection)
    assert env.unwrapped.render_mode == "rgb_array"
    assert gym.make(SPEED, render_mode="human").unwrapped.render_mode == "human"
    assert gym.make(SPEED, render_mode=None).unwrapped.render_mode is None
    with pytest.raises(ValueError, match="render_mode"):
        gym.make(SPEED, render_mode="rgb")


# ------------------------------------------- memory beyond the machine (MemoryError before)
def test_buffers_beyond_the_machine_are_refused_before_allocating(monkeypatch):
    with pytest.raises(ValueError, match="num_envs") as exc:
        make_vec(SPEED, num_envs=2 ** 40)
    assert "fewer sub-environments" in one_line(exc)
    long = {"episode_length": 1e5, "control_interval": 1e-5}  # 1e10 control intervals
    for kwargs in ({"record_history": True}, {"render_mode": "rgb_array"}):
        with pytest.raises(ValueError, match="record_history") as exc:
            gym.make(SPEED, **long, **kwargs)
        assert "episode_length" in one_line(exc)
        with pytest.raises(ValueError, match="record_history"):
            make_vec(SPEED, **long, **kwargs)
    assert gym.make(SPEED, **long).unwrapped.setup.max_steps == 10 ** 10  # no history: fine
    # the bound is the machine's memory: a small one shows both checks deterministically
    per_row = env_setup.row_bytes(gym.make(SPEED).unwrapped.setup)
    monkeypatch.setattr(env_setup, "MEMORY_LIMIT", 100 * per_row)
    make_vec(SPEED, num_envs=50)
    with pytest.raises(ValueError, match="num_envs = 200"):
        make_vec(SPEED, num_envs=200)
    with pytest.raises(ValueError, match="record_history"):
        make_vec(SPEED, num_envs=50, record_history=True)


# ------------------------------------ the automatic episode length (OverflowError before)
def test_the_automatic_episode_is_bounded_like_a_given_one():
    slow = load_scene("yoshida_odd", drive_max_acceleration=1e-3)  # 2.5 x 240 / 1e-3 s
    for env_id in (SPEED, TORQUE):
        with pytest.raises(PresetError, match="episode_length") as exc:
            gym.make(env_id, scene=slow)
        assert "drive_max_acceleration" in one_line(exc)
        with pytest.raises(PresetError, match="episode_length"):
            episode_steps(env_id, scene=slow)
        assert gym.make(env_id, scene=slow, episode_length=100.0).spec.max_episode_steps == \
            10_000 == episode_steps(env_id, scene=slow, episode_length=100.0)
    with pytest.raises(PresetError, match="dwell.runup_acceleration"):
        gym.make(DWELL, dwell={"runup_acceleration": 5e-324})
    env = gym.make(DWELL, dwell={"runup_acceleration": 1e-3}).unwrapped
    assert math.isfinite(env.setup.episode_length) and env.setup.episode_length < 1e5


# ----------------------------------------- an operating speed of 5e-324 (NaN observations)
def test_operating_speeds_have_the_scenes_floor():
    for w in (5e-324, 1e-6, -0.0, 0.0):
        with pytest.raises(PresetError, match="operating_speed"):
            gym.make(SPEED, operating_speed=w)
    # the floor itself gives finite spaces, observations and rewards
    for env_id in ENV_IDS:
        # (a dwell starts from 0.5 x the critical speed by default: above 1e-3 rad/s)
        extra = {"dwell": {"speed_range": [0.0, 1e-6]}} if env_id == DWELL else {}
        env = gym.make(env_id, operating_speed=1e-3, episode_length=1.5, **extra)
        assert np.all(np.isfinite(env.observation_space.low))
        assert np.all(np.isfinite(env.observation_space.high))
        obs, _ = env.reset(seed=0)
        assert env.observation_space.contains(obs)
        for _ in range(2):
            obs, reward, term, trunc, _ = env.step(env.action_space.sample() * 0.0)
            assert np.all(np.isfinite(obs)) and math.isfinite(reward)
            if term or trunc:
                break


# ------------------------------------ cross-field messages name what the user can change
def test_a_settle_time_longer_than_the_episode_names_what_sets_the_episode():
    with pytest.raises(PresetError, match="settle_time") as exc:
        gym.make(SPEED, control_interval=10.0)
    assert "control_interval" in one_line(exc) and "automatic" in str(exc.value)
    with pytest.raises(PresetError, match="settle_time") as exc:
        gym.make(SPEED, episode_length=1.0)
    assert "'episode_length' = 1 s" in one_line(exc)
    with pytest.raises(PresetError, match="operating_speed") as exc:  # stiff at 1e5 rad/s
        gym.make(SPEED, operating_speed=1e5)
    with pytest.raises(PresetError, match="operating_speed"):  # dwell above the speed
        gym.make(DWELL, operating_speed=1.0)


# ------------------------------------------- settle_time = 0 (a NaN residual term before)
def test_a_settling_window_of_zero_length_is_refused():
    for env_id in ENV_IDS:
        with pytest.raises(PresetError, match="settle_time"):
            gym.make(env_id, settle_time=0.0)
    # the shortest window is one control interval: the residual is that interval's vibration
    env = gym.make(SPEED, settle_time=5e-324)
    env.reset(seed=0)
    while True:
        obs, reward, term, trunc, info = env.step(np.ones(1, dtype=np.float32))
        assert math.isfinite(reward) and np.all(np.isfinite(obs))
        if term or trunc:
            break
    assert info["settled"] and math.isfinite(info["residual_vibration"])
    assert math.isfinite(info["reward_terms"]["residual"])


def test_unknown_keywords_list_every_environment_keyword():
    with pytest.raises(PresetError, match="'kernel'") as exc:
        gym.make(SPEED, kernel="generic")  # a keyword of the vector environment only
    for name in ("record_history", "info_level", "max_episode_steps", "num_envs"):
        assert name in one_line(exc)


# --------------------------------------------- an empty kernel name (silently "auto" before)
def test_an_empty_kernel_name_is_refused():
    with pytest.raises(ValueError, match="kernel"):
        make_vec(SPEED, kernel="")
    from abb_gym import simulate
    from abb_gym.physics import SpeedProfile
    with pytest.raises(ValueError, match="kernel"):
        simulate(load_scene("yoshida_odd"), SpeedProfile.ramp(40.0), 0.01, kernel="")
    assert make_vec(SPEED, kernel=None).kernel in ("generic", "specialised")


# ----------------------------- episode_steps accepted what gym.make refuses (ignored keywords)
@pytest.mark.parametrize("kwargs, name", [
    ({"observe_balls": "no"}, "observe_balls"),
    ({"info_level": "verbose"}, "info_level"),
    ({"render_mode": True}, "render_mode"),
    ({"record_history": "yes"}, "record_history"),
    ({"preset": {"bogus": 1}}, "bogus"),
    ({"max_episode_steps": 0}, "max_episode_steps"),
])
def test_episode_steps_checks_what_gym_make_checks(kwargs, name):
    for env_id in ENV_IDS:
        with pytest.raises(ValueError, match=name):
            episode_steps(env_id, **kwargs)
    with pytest.raises(ValueError, match="env_id"):
        episode_steps(["abb_gym/RunUpSpeed-v0"])
    assert episode_steps(DWELL, control_interval=0.02) == 1


# ================================================================== property-based
SCALE = max(1, int(os.environ.get("ABB_GYM_FUZZ_SCALE", "1")))
PROPERTY = settings(deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                           HealthCheck.filter_too_much])

junk = st.one_of(
    st.none(), st.booleans(), st.text(max_size=4), st.binary(max_size=3),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-10 ** 30, max_value=10 ** 30),
    st.lists(st.one_of(st.floats(), st.text(max_size=2), st.none()), max_size=3),
    st.dictionaries(st.one_of(st.text(max_size=2), st.integers(), st.none()), st.integers(),
                    max_size=2),
    st.sampled_from([np.True_, np.float64(np.nan), np.array(1.0), np.array([1.0, 2.0]),
                     np.array(["a"]), np.int64(3), complex(1.0, 1.0), object(), 5e-324, -0.0,
                     1e308, 2 ** 80, [[1.0, 2.0]], (1.0,), "1e-3", "nan", "<dir>", "<binary>",
                     "<empty>", "<missing>", ""]),
)

CONFIG = specs(EnvConfig)
SECTION_SPECS = {name: specs(cls) for name, cls in _SECTIONS.items()}
SCALARS = sorted(n for n in CONFIG if n not in _SECTIONS)


def _number_in(spec):
    """Numbers within a declared range, the bounds included, log-uniform as well."""
    lo = spec.ge if spec.ge is not None else spec.gt
    hi = spec.le if spec.le is not None else spec.lt
    inner = st.floats(lo, hi, exclude_min=spec.gt is not None, exclude_max=spec.lt is not None)
    ends = [v for v, ok in ((lo, spec.gt is None), (hi, spec.lt is None)) if ok]
    if lo >= 0 and hi > 0:
        low = max(lo, hi * 1e-12, 1e-300)
        logs = st.floats(math.log10(low), math.log10(hi)).map(lambda e: min(hi, 10.0 ** e))
        inner = st.one_of(inner, logs.filter(lambda v: v > lo or spec.gt is None))
    return st.one_of(st.sampled_from(ends), inner) if ends else inner


def _good(spec):
    if spec.kind == "choice":
        return st.sampled_from(spec.choices)
    if spec.kind == "text":
        return st.text(max_size=6)
    if spec.kind == "flag":
        return st.booleans()
    one = _number_in(spec)
    if spec.kind == "range":
        pair = st.tuples(one, one).map(lambda p: [min(p), max(p)])
        one = st.one_of(one, pair)
    return st.one_of(st.none(), one) if spec.nullable else one


def chance(draw, p: float) -> bool:
    """True with probability ``p`` (``st.floats(0, 1) < p`` is true far more often: Hypothesis
    favours 0.0)."""
    return draw(st.sampled_from(range(100))) < 100 * p


@st.composite
def section(draw, name, junk_share=0.15):
    out = {}
    table = SECTION_SPECS[name]
    for key in draw(st.lists(st.sampled_from(sorted(table) + ["bogus"]), max_size=3,
                             unique=True)):
        out[key] = draw(junk) if key not in table or chance(draw, junk_share) \
            else draw(_good(table[key]))
    return out


@st.composite
def preset_fields(draw, junk_share=0.15):
    out = {}
    for key in draw(st.lists(st.sampled_from(SCALARS + sorted(_SECTIONS) + ["bogus_field"]),
                             max_size=4, unique=True)):
        if key in _SECTIONS:
            out[key] = draw(section(key)) if not chance(draw, junk_share) else draw(junk)
        elif key not in CONFIG or chance(draw, junk_share):
            out[key] = draw(junk)
        else:
            out[key] = draw(_good(CONFIG[key]))
    return out


@st.composite
def make_kwargs(draw, vector: bool):
    kw = draw(preset_fields())
    if draw(st.booleans()):
        kw["scene"] = draw(junk) if chance(draw, 0.2) \
            else draw(st.sampled_from(list_scenes()))
    if chance(draw, 0.4):
        kw["preset"] = draw(junk) if chance(draw, 0.2) else draw(st.one_of(
            st.sampled_from(["train", "test", "nominal"]), preset_fields(),
            preset_fields().map(lambda d: {**d, "base": "test"})))
    flags = {"observe_balls": st.booleans(), "record_history": st.booleans(),
             "info_level": st.sampled_from(["lean", "full"]),
             "render_mode": st.sampled_from([None, "rgb_array"] if vector
                                            else [None, "rgb_array", "human", "rgb_array_list"])}
    if vector:
        flags["kernel"] = st.sampled_from([None, "auto", "generic", "specialised"])
        flags["max_episode_steps"] = st.one_of(st.none(), st.integers(1, 10 ** 6))
    for key in draw(st.lists(st.sampled_from(sorted(flags)), max_size=3, unique=True)):
        kw[key] = draw(junk) if chance(draw, 0.15) else draw(flags[key])
    if not vector and chance(draw, 0.2):  # gymnasium's own: integers only
        kw["max_episode_steps"] = draw(st.integers(1, 10 ** 6))
    if vector:
        kw["num_envs"] = draw(junk) if chance(draw, 0.15) else draw(st.integers(1, 3))
    return kw


@pytest.fixture(scope="module")
def paths(tmp_path_factory):
    root = tmp_path_factory.mktemp("odd_paths")
    (root / "binary.yaml").write_bytes(bytes(range(256)))
    (root / "empty.yaml").write_text("")
    return {"<dir>": str(root), "<binary>": str(root / "binary.yaml"),
            "<empty>": str(root / "empty.yaml"), "<missing>": str(root / "missing.yaml")}


def _resolve(value, paths):
    """The path placeholders of ``junk`` made real, anywhere in ``value``."""
    if isinstance(value, str) and value in paths:
        return paths[value]
    if isinstance(value, dict):
        return {k: _resolve(v, paths) for k, v in value.items()}
    return value


VOCABULARY = (set(CONFIG) | {k for t in SECTION_SPECS.values() for k in t}
              | {"scene", "preset", "base", "bogus", "bogus_field", "observe_balls",
                 "record_history", "info_level", "render_mode", "kernel", "max_episode_steps",
                 "num_envs"})


def _names(kwargs) -> set[str]:
    """The names an error about ``kwargs`` may give: every key the strategies use (not the
    keys of a junk mapping: ``{"": 0}`` would match any message), nested ones also as
    ``section.key``."""
    names = set()
    for key, value in kwargs.items():
        if key not in VOCABULARY:
            continue
        names.add(key)
        if isinstance(value, dict) and key in set(_SECTIONS) | {"preset"}:
            names |= _names(value)
            names |= {f"{key}.{k}" for k in value if k in VOCABULARY}
    return names


def _as_number(v):
    return float(v.strip()) if isinstance(v, str) else float(v)


def _expected(spec, v):
    if v is None:
        return None
    if spec.kind in ("choice", "text"):
        return v
    if spec.kind == "range":
        if isinstance(v, (list, tuple)):
            return tuple(_as_number(x) for x in v)
        return (_as_number(v), _as_number(v))
    if spec.kind == "integer":
        return int(_as_number(v))
    return _as_number(v)


def _check_took_effect(native, kwargs, vector):
    """Every keyword is visible on the environment (none silently ignored)."""
    cfg = native.config
    preset = kwargs.get("preset")
    layers = ([preset] if isinstance(preset, dict) else []) + [kwargs]
    for layer in layers:  # the overrides last: they win
        for key, value in layer.items():
            if key in SCALARS and not (key == "name" and value is None):
                if key in kwargs and layer is not kwargs:
                    continue  # overridden
                expected = _expected(CONFIG[key], value)
                if key == "description" and value is None:
                    expected = ""
                assert getattr(cfg, key) == expected, (key, value)
            elif key in _SECTIONS and isinstance(value, dict):
                for sub, v in value.items():
                    if isinstance(kwargs.get(key), dict) and layer is not kwargs \
                            and sub in kwargs[key]:
                        continue
                    got = getattr(getattr(cfg, key), sub)
                    assert got == _expected(SECTION_SPECS[key][sub], v), (key, sub, v)
    if kwargs.get("scene") is not None:  # (None: the task's default scene)
        assert native.scene.name == kwargs["scene"]
    setup = native.setup
    nb = setup.scene.ball_count
    obs_dim = setup.obs_dim
    frame = ((5 if setup.config.observe_time else 4) + setup.n_actions
             + (3 if setup.config.sync_vibration.enabled else 0)
             + (2 * nb if kwargs.get("observe_balls") else 0))
    assert obs_dim == frame * setup.config.frame_stack
    assert native.info_level == kwargs.get("info_level", "lean")
    mode = kwargs.get("render_mode")
    assert native.render_mode == ("rgb_array" if mode == "rgb_array_list" else mode)
    if vector:
        assert native.num_envs == kwargs["num_envs"]
        if kwargs.get("kernel") in ("generic", "specialised"):
            assert native.kernel == kwargs["kernel"]
        if kwargs.get("max_episode_steps") is not None:
            assert setup.backstop == kwargs["max_episode_steps"]


CHEAP_STEP = 5e4  # RK4 steps: a property example steps only if one step costs at most this


def _use(env, native, vector, kwargs):
    """Reset, check the first observation and info, and step once if the step is cheap."""
    assert np.all(np.isfinite(env.observation_space.low))
    assert np.all(np.isfinite(env.observation_space.high))
    if kwargs.get("render_mode") is not None:  # a reset draws a frame: not here
        event("not reset")
        return
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs), obs
    for key, value in info.items():
        if isinstance(value, (float, np.ndarray)) and np.asarray(value).dtype.kind == "f":
            assert not np.any(np.isnan(value)), key
    setup = native.setup
    step = native.integration_step if not vector else float(native.episode(0).integration_step)
    work = (setup.episode_length if setup.kind == "dwell" else setup.control_interval) / step
    if work > CHEAP_STEP or kwargs.get("kernel") == "specialised":
        event("not stepped")
        return
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    obs, reward, term, trunc, info = env.step(action)
    assert np.all(np.isfinite(obs)) and np.all(np.isfinite(reward))
    event("stepped")


def _made_or_named(make, kwargs, vector):
    names = _names(kwargs)
    try:
        env = make(**kwargs)
    except (ValueError, SimulationError) as err:
        msg = str(err)
        assert "\n" not in msg, msg
        assert any(n in msg for n in names), (msg, sorted(names))
        event(f"refused: {type(err).__name__}")
        return
    event("made")
    native = env.unwrapped
    _check_took_effect(native, kwargs, vector)
    _use(env, native, vector, kwargs)
    env.close()


def _fuzz(make, kwargs, vector: bool) -> None:
    with warnings.catch_warnings(), pytest.MonkeyPatch.context() as mp:
        warnings.simplefilter("ignore")
        mp.setattr(env_setup, "MEMORY_LIMIT", 2e8)  # no example allocates more than 200 MB
        _made_or_named(make, kwargs, vector=vector)


@settings(PROPERTY, max_examples=400 * SCALE)
@given(env_id=st.sampled_from(ENV_IDS), kwargs=make_kwargs(vector=False))
def test_gym_make_gives_an_environment_or_an_error_naming_the_keyword(env_id, kwargs, paths):
    _fuzz(lambda **kw: gym.make(env_id, **kw), _resolve(kwargs, paths), vector=False)


@settings(PROPERTY, max_examples=300 * SCALE)
@given(env_id=st.sampled_from(ENV_IDS), kwargs=make_kwargs(vector=True))
def test_gym_make_vec_gives_an_environment_or_an_error_naming_the_keyword(env_id, kwargs, paths):
    _fuzz(lambda **kw: gym.make_vec(env_id, vectorization_mode="vector_entry_point", **kw),
          _resolve(kwargs, paths), vector=True)
