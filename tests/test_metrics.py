"""Metrics on hand-made time histories with known answers, and the baseline profiles."""
import math

import numpy as np
import pytest

from abb_gym import load_scene, simulate
from abb_gym.baselines import profiles
from abb_gym.evaluation.metrics import nonsynchronous_whirl, runup_metrics


@pytest.fixture(scope="module")
def scene():
    return load_scene("yoshida_odd")


def test_metrics_on_a_hand_made_run(scene):
    """A ramp reaching w_op = 240 rad/s at t = 6 s, then holding it; whirl 10 t e up to 3 s,
    then 2 e; the balls slide to the balanced split and stop at t = 7 s."""
    t = np.linspace(0.0, 10.0, 1001)
    speed = np.minimum(40.0 * t, 240.0)            # in the 0.2 % band from t = 5.99 s
    e = scene.reference_length
    whirl = e * np.where(t < 3.0, 10.0 * t, 2.0)    # peak 29.9 e before 3 s, then 2 e
    target = np.array([math.pi - 1.0, math.pi + 1.0])
    frac = np.clip(t / 7.0, 0.0, 1.0)[:, None]
    angles = frac * target
    torque = np.full_like(t, 1e-3)
    m = runup_metrics(scene, t, speed, whirl, np.zeros_like(t), angles, torque=torque)
    # 40 t >= 240 (1 - 0.002) from t = 5.988 s: the first sample in the band is 5.99 s
    assert m["first_at_speed"] == m["run_up_time"] == pytest.approx(5.99)
    assert m["at_speed"]
    assert m["peak_whirl"] == pytest.approx(29.9, abs=1e-9)
    assert m["residual_vibration"] == pytest.approx(2.0)
    assert m["peak_speed"] == 1.0 and m["time_above_band"] == 0.0
    # within 2 deg of the final value from t = 7 (1 - (2 deg) / (pi + 1))
    t_in = 7.0 * (1 - math.radians(2.0) / (math.pi + 1.0))
    assert m["ball_settling_time"] == pytest.approx(t_in - 5.99, abs=0.011)
    expected_energy = 1e-3 * (0.5 * 40 * 6.0 ** 2 + 240.0 * 4.0)
    assert m["drive_energy"] == pytest.approx(expected_energy, rel=1e-3)
    assert not m["nonsynchronous_whirl"]


def test_the_residual_counts_only_the_settling_window_in_the_band(scene):
    """Parking at 0.99 w_op never completes the run-up, however small the whirl there; a run
    that leaves the band starts a new stay, and only the final stay's window counts."""
    t = np.linspace(0.0, 10.0, 1001)
    e = scene.reference_length
    parked = np.minimum(40.0 * t, 0.99 * 240.0)
    m = runup_metrics(scene, t, parked, 0.1 * e + 0 * t, 0 * t, np.zeros((1001, 2)))
    assert not m["at_speed"] and math.isnan(m["residual_vibration"])
    assert m["run_up_time"] == 10.0 and math.isnan(m["first_at_speed"])
    # in the band from 5.99 s, out at 6.5-7.5 s (a dip), back from 7.5 s: settled entry 7.5 s,
    # and the residual is the whirl of the second after it (3 e), not the earlier 1 e
    w = np.where((t >= 6.5) & (t < 7.5), 200.0, np.minimum(40.0 * t, 240.0))
    whirl = e * np.where(t < 7.5, 1.0, np.where(t <= 8.5 + 1e-9, 3.0, 5.0))
    m = runup_metrics(scene, t, w, whirl, 0 * t, np.zeros((1001, 2)), settle_time=1.0)
    assert m["first_at_speed"] == pytest.approx(5.99) and m["run_up_time"] == pytest.approx(7.5)
    assert m["at_speed"] and m["residual_vibration"] == pytest.approx(3.0)
    # overspeed: above the band for 0.5 s
    over = np.where((t > 6.0) & (t <= 6.5), 250.0, np.minimum(40.0 * t, 240.0))
    m = runup_metrics(scene, t, over, 0 * t, 0 * t, np.zeros((1001, 2)))
    assert m["time_above_band"] == pytest.approx(0.5) and m["peak_speed"] == pytest.approx(250 / 240)


def test_balanced_flag_of_the_metrics(scene):
    u, cap = scene.imbalance, scene.balancing_capacity
    half = math.acos(u / cap)
    t = np.linspace(0, 1, 11)
    m = runup_metrics(scene, t, np.full(11, 240.0), np.zeros(11), np.zeros(11),
                      np.tile([math.pi - half, math.pi + half], (11, 1)))
    assert m["balanced"]
    m = runup_metrics(scene, t, np.full(11, 240.0), np.zeros(11), np.zeros(11),
                      np.zeros((11, 2)))
    assert not m["balanced"]


def test_environment_and_trajectory_metrics_are_one_implementation():
    """RunUpSpeed driven with a profile (Yoshida's default dwell: every breakpoint on a control
    instant) and simulate() with that profile, sampled at the environment's RK4 step, feed the
    same accumulator: the metrics agree to rounding (the environment integrates the vibration
    over its RK4 steps with the right-endpoint rule, which is what the trajectory's samples
    give at that spacing)."""
    import gymnasium as gym
    from abb_gym.baselines.baseline_policy import make_baseline
    from abb_gym.evaluation.evaluate import Chunk, run_chunk
    from abb_gym.evaluation.metrics import trajectory_metrics
    scene = load_scene("yoshida_odd")
    policy = make_baseline("speed_dwell", scene, use_tuned=False)
    chunk = Chunk("abb_gym/RunUpSpeed-v0", "yoshida_odd", "nominal", "x", 0, (0,))
    ep = run_chunk(chunk, policy)[0][0]
    env = gym.make("abb_gym/RunUpSpeed-v0", scene="yoshida_odd", preset="nominal")
    _, info = env.reset(seed=0)
    dt = env.unwrapped.setup.control_interval
    h = dt / math.ceil(dt / info["integration_step"] - 1e-9)  # the environment's RK4 step
    prof = profiles.build("speed_dwell", scene)
    tr = simulate(scene, prof, ep["run_up_time"] + 2.0, output_dt=h)
    m = trajectory_metrics(tr, interval=dt)
    for key in ("run_up_time", "first_at_speed", "peak_speed"):
        assert m[key] == pytest.approx(ep[key], abs=1e-9), key
    assert m["at_speed"] and ep["at_speed"]
    assert m["residual_vibration"] == pytest.approx(ep["residual_vibration"], rel=1e-9)
    assert m["peak_whirl"] == pytest.approx(ep["peak_whirl"], rel=1e-9)


def test_nonsynchronous_whirl_detects_a_circulating_ball(scene):
    t = np.linspace(0.0, 5.0, 501)
    speed = np.full_like(t, 150.0)
    lagging = np.stack([-50.0 * t, np.full_like(t, math.pi)], axis=1)  # 50 rad/s behind
    settled = np.stack([-1.0 * t, np.full_like(t, math.pi)], axis=1)
    assert nonsynchronous_whirl(scene, t, speed, lagging)
    assert nonsynchronous_whirl(scene, t, speed, lagging, window=1.0)  # 50 rad in 1 s
    assert not nonsynchronous_whirl(scene, t, speed, 0.2 * lagging, window=0.5)  # 5 rad in 0.5 s
    assert not nonsynchronous_whirl(scene, t, speed, settled)
    assert not nonsynchronous_whirl(scene, t, np.full_like(t, 50.0), lagging)  # below critical


@pytest.mark.parametrize("name", list(profiles.FAMILIES))
def test_every_baseline_profile_reaches_and_holds_the_operating_speed(scene, name):
    prof = profiles.build(name, scene)
    end = profiles.duration(prof)
    assert prof.speed(end + 1.0) == pytest.approx(scene.drive_operating_speed)
    assert prof.acceleration(end + 1.0) == 0.0
    t = np.linspace(0, end, 2000)
    assert np.all(prof.speed(t) >= -1e-9)
    assert np.all(prof.speed(t) <= scene.drive_operating_speed + 1e-9)


def test_yoshida_default_dwell_is_the_thesis_profile(scene):
    """Scaling rule at the reference scene: dwell at omega_c = 100 rad/s for 0.5 s at 40 rad/s^2."""
    prof = profiles.build("speed_dwell", scene)
    np.testing.assert_allclose(prof.breakpoints[:3], [0.0, 2.5, 3.0])
    tr = simulate(scene, prof, 6.0)
    assert tr.whirl_ratio.max() == pytest.approx(62.5, abs=0.5)  # Fig. 4.7 as in test_validation


def test_speed_reduction_drops_to_the_plateau(scene):
    prof = profiles.build("speed_reduction", scene, plateau_speed=130.0, plateau_time=0.4)
    bp = prof.breakpoints
    assert prof.speed(bp[3] + 0.2) == pytest.approx(130.0)
    assert prof.speed(bp[2]) == pytest.approx(scene.drive_operating_speed)


def test_bad_baseline_parameters(scene):
    with pytest.raises(ValueError, match="unknown baseline"):
        profiles.build("magic", scene)
    with pytest.raises(ValueError, match="dwell_speed"):
        profiles.build("speed_dwell", scene, dwell_speed=1e4)
    with pytest.raises(ValueError, match="dwell_accel"):
        profiles.build("decel_dwell", scene, dwell_accel=5.0)


@pytest.mark.parametrize("name", ["accel_dwell", "decel_dwell"])
@pytest.mark.parametrize("scene_name", ["yoshida_odd", "spannan_cfrp", "spannan_discoidal"])
def test_dwell_defaults_scale_with_the_scene(name, scene_name):
    """Yoshida's 20 of 40 rad/s^2 becomes half the scene's run-up rate, so a slow centrifuge
    drive never reverses (a fixed -20 rad/s^2 would)."""
    scene = load_scene(scene_name)
    prof = profiles.build(name, scene)
    t = np.linspace(0, profiles.duration(prof), 5000)
    assert np.all(prof.speed(t) >= -1e-9)
    assert abs(prof.segments[1][1]) == pytest.approx(0.5 * profiles.default_accel(scene))
    cut = profiles.build("decel_dwell", scene, dwell_time=1e4)  # cut at standstill
    assert cut.speed(profiles.duration(cut) - 1e-9) >= 0
