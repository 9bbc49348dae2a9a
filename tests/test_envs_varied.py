"""The ``varied`` and ``varied_test`` presets: machines that differ per episode in what decides
the best run-up (critical speed through the load, imbalance, ball drag, rolling resistance,
support damping), none of it observed."""
from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import abb_gym  # noqa: F401  (registers the ids)
from abb_gym.envs import PresetError, load_preset
from abb_gym.envs.tasks import TASKS

from abb_gym.envs import episodes
from abb_gym.physics import variants
from abb_gym.envs.layout import S_AOP, S_AREF, S_XS, S_YS
from abb_gym.physics import rotor
from abb_gym.physics.scene import load_scene
from abb_gym.physics.steps import default_step

# the ids that run on any scene (SpinRedistribute needs a washer: tests/test_spin.py)
ENV_IDS = tuple(t.env_id for t in TASKS.values() if not t.settings)

SPEED = "abb_gym/RunUpSpeed-v0"
SCENES = ("yoshida_odd", "spannan_cfrp")


def vec(n, **kw):
    return gym.make_vec(SPEED, num_envs=n, vectorization_mode="vector_entry_point", **kw)


@pytest.mark.parametrize("scene", SCENES)
@pytest.mark.parametrize("preset, lo, hi", [("varied", 0.7, 1.3), ("varied_test", 0.65, 1.35)])
def test_drawn_critical_speeds_span_the_stated_range(scene, preset, lo, hi):
    assert load_preset(preset).randomize.critical_speed_scale == (lo, hi)
    n = 200
    env = vec(n, scene=scene, preset=preset)
    _, info = env.reset(seed=0)
    nominal = load_scene(scene).critical_speed
    scale = info["critical_speed_scale"]
    assert lo <= scale.min() < lo + 0.03 and hi - 0.03 < scale.max() <= hi
    # the episodes' machines: critical speed = scale x nominal, through the mass alone
    for i in range(0, n, 20):
        sc = env.unwrapped.episode_scene(i)
        assert sc.critical_speed == pytest.approx(scale[i] * nominal, rel=1e-12)
        assert sc.total_mass == pytest.approx(load_scene(scene).total_mass / scale[i] ** 2,
                                              rel=1e-12)
        assert sc.support_stiffness_x == load_scene(scene).support_stiffness_x
        assert sc.imbalance == pytest.approx(info["imbalance"][i], rel=1e-15)
        assert sc.support_damping_x == pytest.approx(
            load_scene(scene).support_damping_x * info["support_damping_scale"][i], rel=1e-15)
    damping = info["support_damping_scale"]
    rz = env.unwrapped.config.randomize
    assert rz.support_damping_scale[0] <= damping.min() and damping.max() <= \
        rz.support_damping_scale[1]


def test_draws_are_reproducible_with_seeds():
    a, b = vec(8, preset="varied"), vec(8, preset="varied")
    _, ia = a.reset(seed=11)
    _, ib = b.reset(seed=11)
    for key in ("critical_speed_scale", "support_damping_scale", "imbalance",
                "imbalance_phase", "ball_drag_scale", "rolling_resistance_scale",
                "initial_ball_angles", "integration_step"):
        assert np.array_equal(ia[key], ib[key]), key
    _, ic = b.reset(seed=12)
    assert not np.array_equal(ia["critical_speed_scale"], ic["critical_speed_scale"])
    # the single environment draws the same machine from the same seed
    _, inf = gym.make(SPEED, preset="varied").reset(seed=11)
    assert inf["critical_speed_scale"] == ia["critical_speed_scale"][0]
    assert inf["support_damping_scale"] == ia["support_damping_scale"][0]


def test_new_ranges_leave_the_older_draws_as_they_were():
    """The critical-speed and damping numbers come after the others: the train preset with
    them added draws the same imbalance, phase, balls, drag and rolling resistance."""
    _, plain = gym.make(SPEED).reset(seed=4)
    _, more = gym.make(SPEED, randomize={"critical_speed_scale": [0.7, 1.3],
                                         "support_damping_scale": [0.5, 2.0]}).reset(seed=4)
    for key in ("imbalance", "imbalance_phase", "ball_drag_scale", "rolling_resistance_scale"):
        assert plain[key] == more[key], key
    assert np.array_equal(plain["initial_ball_angles"], more["initial_ball_angles"])
    assert plain["critical_speed_scale"] == 1.0 and more["critical_speed_scale"] != 1.0


def test_the_reward_scales_and_rest_position_are_the_episode_machines():
    """A_peak and A_op (the reward's scales) are those of this episode's machine with its
    balancer off; under gravity the rest position is this machine's sag."""
    env = vec(6, preset="varied")
    env.reset(seed=2)
    u = env.unwrapped
    for i in range(6):
        sc = u.episode_scene(i)
        peak, at_op = rotor.reference_amplitudes(sc, u.setup.operating_speed)
        assert u._bufs.st[i, S_AREF] == pytest.approx(peak, rel=1e-13)
        assert u._bufs.st[i, S_AOP] == pytest.approx(at_op, rel=1e-13)
    washer = gym.make(SPEED, scene="washer", preset="nominal",
                      randomize={"critical_speed_scale": [0.9, 1.1]})
    _, info = washer.reset(seed=0)
    sc = washer.unwrapped.episode_scene
    assert sc.total_mass != load_scene("washer").total_mass
    np.testing.assert_allclose(info["static_deflection"], rotor.static_deflection(sc),
                               rtol=1e-13)
    st = washer.unwrapped._bufs.st[0]
    assert (st[S_XS], st[S_YS]) == tuple(info["static_deflection"])


def test_reset_options_set_the_machine_and_are_checked_by_name():
    env = gym.make(SPEED, preset="varied")
    _, info = env.reset(seed=0, options={"critical_speed_scale": 1.2,
                                         "support_damping_scale": 0.5})
    assert info["critical_speed_scale"] == 1.2 and info["support_damping_scale"] == 0.5
    sc = env.unwrapped.episode_scene
    assert sc.critical_speed == pytest.approx(1.2 * load_scene("yoshida_odd").critical_speed,
                                              rel=1e-12)
    with pytest.raises(ValueError, match="'critical_speed_scale' must be > 0"):
        env.reset(options={"critical_speed_scale": 0.0})
    # a machine lighter than its balls does not exist
    with pytest.raises(ValueError, match="critical_speed_scale=8 .*no rotor mass left"):
        env.reset(options={"critical_speed_scale": 8.0})
    with pytest.raises(ValueError, match="'support_damping_scale' must be >= 0"):
        env.reset(options={"support_damping_scale": -1.0})


def test_preset_ranges_are_checked_at_their_corners():
    # no rotor mass left at the top of the range
    with pytest.raises(PresetError, match="'randomize.critical_speed_scale'.*no rotor mass left"):
        gym.make(SPEED, preset="varied", randomize={"critical_speed_scale": [0.7, 8.0]})
    # the washer, twice as heavy, sags onto its cabinet: refused, saying so
    with pytest.raises(PresetError, match="critical_speed_scale.*sags.*clearance"):
        gym.make(SPEED, scene="washer", preset="varied")
    with pytest.raises(PresetError, match="'randomize.critical_speed_scale' must be"):
        load_preset("varied", randomize={"critical_speed_scale": [1.3, 0.7]})
    with pytest.raises(PresetError, match="'randomize.support_damping_scale' must be"):
        load_preset("varied", randomize={"support_damping_scale": [-1.0, 2.0]})
    # the stiffness check still takes the corners, now of the machine's ranges too: a drag
    # range too stiff for RK4 is refused at make time and the message names the corner
    with pytest.raises(PresetError, match="critical_speed_scale=.*too stiff for integrator=.rk4."):
        gym.make(SPEED, preset="varied", randomize={"ball_drag_scale": [0.5, 1e3]})
    # ... and every corner's step is the one its machine gets at reset
    setup = gym.make(SPEED, preset="varied").unwrapped.setup
    rz = setup.config.randomize
    corners = np.array([(d, r, c, s) for d in rz.ball_drag_scale
                        for r in rz.rolling_resistance_scale
                        for c in rz.critical_speed_scale for s in rz.support_damping_scale])
    names = ("ball_drag_scale", "rolling_resistance_scale", "critical_speed_scale",
             "support_damping_scale")
    values = dict(zip(names, corners.T))
    p, b = variants.packed_variants(setup.scene, len(corners),
                                    imbalance=np.full(len(corners), setup.scene.imbalance),
                                    **values)
    values["fluid_temperature"] = np.full(len(corners), setup.scene.fluid_temperature)
    steps = episodes._rk4_steps(setup, p, b, values, "test", ValueError)
    for k, (d, r, c, s) in enumerate(corners):
        sc = variants.variant_scene(setup.scene, ball_drag_scale=d, rolling_resistance_scale=r,
                                    critical_speed_scale=c, support_damping_scale=s)
        assert steps[k] == default_step(sc, setup.max_speed, "rk4")


@pytest.mark.parametrize("scene", SCENES)
@pytest.mark.parametrize("preset", ["varied", "varied_test"])
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_check_env_with_the_varied_presets(env_id, scene, preset, strict_check_env):
    env = gym.make(env_id, scene=scene, preset=preset)
    strict_check_env(env)


def test_varied_preset_observes_the_sync_vibration():
    env = gym.make(SPEED, preset="varied")
    names = env.unwrapped.observation_names
    assert names[6:9] == ["sync_amplitude", "sync_cos", "sync_sin"]
    cfg = env.unwrapped.config
    assert cfg.sync_vibration.enabled and cfg.sync_vibration.noise > 0
    assert load_preset("varied_test").sync_vibration == cfg.sync_vibration
    # nothing about the machine is in the observation: the same observation at reset for two
    # machines differing only in critical speed and damping (noise aside)
    quiet = dict(preset="varied", sync_vibration={"noise": 0.0})
    a, _ = gym.make(SPEED, **quiet).reset(seed=0, options={"critical_speed_scale": 0.7})
    b, _ = gym.make(SPEED, **quiet).reset(seed=0, options={"critical_speed_scale": 1.3,
                                                           "support_damping_scale": 2.0})
    assert np.array_equal(a, b)
    assert math.isfinite(float(a.sum()))
