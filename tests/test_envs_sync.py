"""The synchronous (1x) vibration observation (:mod:`abb_gym.physics.sensors`) and the frame
stack: what a drive with a once-per-revolution reference measures, and memory for policies.

The steady-state tests hold the balls at known angles (a race drag a million times the
scene's, integrated exactly by ETDRK4: over the 20 s run the balls creep by about 2e-5 rad)
and run the rotor at constant speed below and above its critical speed.  The rotor is then a
Jeffcott rotor of the total mass carrying the residual imbalance (sensors module docstring), so

    measured phase = imbalance_phase + chi - lambda,   measured amplitude = A,

chi the residual's direction from the primary imbalance, lambda = atan2(c W, k - M W^2) the
support's lag and A the Jeffcott amplitude.  Tolerance 1e-3 rad and 1e-3 relative, from the
error sources: the start transient decays as exp(-zeta w_n t) = exp(-15) = 3e-7 by the end of
the 15 s settling window (yoshida_odd: zeta w_n = c / (2 M) = 1 /s); the balls' creep moves chi
by < 1e-4 rad; ETDRK4 at a 1 ms step (0.24 rad per step at 240 rad/s) errs by ~1e-5 (measured:
1e-6 deg and 6e-6 relative); the float32 observation rounds at 6e-8.  The larger error a
tolerance could hide is the support's lag itself: 0.76 deg = 0.013 rad below resonance,
13 x the tolerance.
"""
from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import abb_gym  # noqa: F401  (registers the ids)
from abb_gym.envs import PresetError, load_preset
from abb_gym.physics import rotor, sensors

SPEED = "abb_gym/RunUpSpeed-v0"
TOL = 1e-3


def held_balls_run(speed, ball_angles, imbalance_ratio=None, lag=0.2, phase=0.7):
    """Run yoshida_odd up to ``speed`` [rad/s] and hold it for 15 s with the balls held at
    ``ball_angles``; return (observation, info, env)."""
    env = gym.make(SPEED, scene="yoshida_odd", preset="nominal", operating_speed=speed,
                   integrator="etdrk4", integration_step=1e-3, episode_length=20.0,
                   settle_time=15.0, control_interval=0.05,
                   sync_vibration={"enabled": True, "lag": lag})
    options = {"imbalance_phase": phase, "ball_angles": ball_angles, "ball_drag_scale": 1e6}
    if imbalance_ratio is not None:
        options["imbalance_ratio"] = imbalance_ratio
    env.reset(seed=0, options=options)
    while True:
        obs, _, terminated, truncated, info = env.step(np.array([1.0], np.float32))
        if terminated or truncated:
            assert terminated and info["settled"]
            return obs, info, env


@pytest.mark.parametrize("speed", [50.0, 200.0])  # half and twice the critical speed 100 rad/s
@pytest.mark.parametrize("balls, ratio", [([0.5, 1.0], None),          # the scene's imbalance
                                          ([math.pi, math.pi], 0.5)])  # balls opposite
def test_sync_phase_is_the_residual_imbalance_from_the_mark_minus_the_support_lag(
        speed, balls, ratio):
    obs, info, env = held_balls_run(speed, balls, ratio)
    sc = env.unwrapped.episode_scene
    names = env.unwrapped.observation_names
    k = names.index("sync_amplitude")
    assert names[k + 1:k + 3] == ["sync_cos", "sync_sin"]
    # the balls stayed where they were put
    np.testing.assert_allclose(info["ball_angles"], balls, atol=1e-4)
    residual = sc.imbalance + sum(m * sc.race_radius * np.exp(1j * a)
                                  for m, a in zip(sc.ball_mass, info["ball_angles"]))
    amplitude, lag = rotor.jeffcott_response(abs(residual), sc.total_mass,
                                             sc.support_stiffness_x, sc.support_damping_x, speed)
    # the support's lag: about 0 below the critical speed, about 180 deg above
    if speed < sc.critical_speed:
        assert lag < 0.02
    else:
        assert lag > math.pi - 0.02
    expected = 0.7 + np.angle(residual) - lag
    measured = math.atan2(obs[k + 2], obs[k + 1])
    assert abs(math.remainder(measured - expected, 2 * math.pi)) < TOL
    assert obs[k + 1] ** 2 + obs[k + 2] ** 2 == pytest.approx(1.0, abs=1e-6)
    # the amplitude is the steady whirl radius: the Jeffcott amplitude, and what the rotor does
    measured_amplitude = obs[k] * env.unwrapped.setup.vibration_scale
    assert measured_amplitude == pytest.approx(amplitude, rel=TOL)
    assert measured_amplitude == pytest.approx(info["vibration_radius"], rel=TOL)
    if ratio is not None:
        # balls opposite the imbalance: the residual points away from the imbalance
        assert abs(math.remainder(np.angle(residual) - math.pi, 2 * math.pi)) < 1e-4


def test_sync_without_lag_reads_the_demodulated_sample():
    """lag = 0: the output is the demodulated vibration at the end of the interval, which at
    steady state is the same constant."""
    obs, info, env = held_balls_run(200.0, [0.5, 1.0], lag=0.0)
    k = env.unwrapped.observation_names.index("sync_amplitude")
    assert obs[k] * env.unwrapped.setup.vibration_scale == pytest.approx(
        info["vibration_radius"], rel=1e-6)


def test_sync_filter_follows_a_first_order_lag():
    """The filter's step response: the gain over a step h is 1 - exp(-h / lag), so n steps
    leave exp(-n h / lag) of a jump, whatever the steps (the exact response of lag Z' + Z = u
    to u held over each step)."""
    gain = sensors.filter_gain
    assert gain(1e-3, 0.1) == pytest.approx(1.0 - math.exp(-0.01), rel=1e-14)
    assert gain(1e-3, 0.0) == 1.0
    z = 0.0
    for _ in range(100):
        z += gain(1e-3, 0.1) * (1.0 - z)
    assert 1.0 - z == pytest.approx(math.exp(-1.0), rel=1e-12)


def test_demodulator_rotates_into_the_mark_frame():
    dx, dy = 2.0 * math.cos(1.3), 2.0 * math.sin(1.3)
    ux, uy = sensors.demodulate(dx, dy, 0.4)
    assert math.hypot(ux, uy) == pytest.approx(2.0, rel=1e-15)
    assert math.atan2(uy, ux) == pytest.approx(0.9, rel=1e-14)


def test_noise_numbers_are_standard_normal_and_a_pure_function_of_key_and_step():
    n = np.array([sensors.gaussian_pair(12345, k) for k in range(20000)])
    assert abs(n.mean()) < 0.03
    np.testing.assert_allclose(n.std(axis=0), 1.0, atol=0.03)
    assert abs(np.corrcoef(n[:, 0], n[:, 1])[0, 1]) < 0.03
    assert abs(np.corrcoef(n[:-1, 0], n[1:, 0])[0, 1]) < 0.03
    assert sensors.gaussian_pair(12345, 7) == sensors.gaussian_pair(12345, 7)
    assert sensors.gaussian_pair(12345, 7) != sensors.gaussian_pair(12346, 7)


def test_noisy_sync_observation_is_seeded():
    """At reset the filter is 0: the reading is the noise alone, sigma = noise * A_v per
    component, so sync_amplitude = noise |n| (Rayleigh, mean noise sqrt(pi / 2)); the same seed
    gives the same reading, other seeds others."""
    env = gym.make(SPEED, sync_vibration={"enabled": True, "noise": 0.01})
    k = env.unwrapped.observation_names.index("sync_amplitude")
    amps = [env.reset(seed=s)[0][k] for s in range(400)]
    assert np.mean(amps) == pytest.approx(0.01 * math.sqrt(math.pi / 2), rel=0.1)
    a, _ = env.reset(seed=3)
    b, _ = env.reset(seed=3)
    assert np.array_equal(a, b)
    # the noise key is drawn after every randomised value: the episode is that of the
    # noiseless preset with the same seed
    quiet = gym.make(SPEED, sync_vibration={"enabled": True})
    _, info_quiet = quiet.reset(seed=3)
    _, info = env.reset(seed=3)
    assert info["imbalance"] == info_quiet["imbalance"]
    assert np.array_equal(info["initial_ball_angles"], info_quiet["initial_ball_angles"])


def test_sync_off_keeps_the_observation_layout():
    env = gym.make(SPEED)
    assert env.observation_space.shape == (6,)
    assert "sync_amplitude" not in env.unwrapped.observation_names
    on = gym.make(SPEED, sync_vibration={"enabled": True}, observe_balls=True)
    assert on.unwrapped.observation_names == [
        "rotor_speed", "vibration_x", "vibration_y", "vibration_amplitude", "time_fraction",
        "last_action[0]", "sync_amplitude", "sync_cos", "sync_sin", "cos(ball_angle[0])",
        "sin(ball_angle[0])", "cos(ball_angle[1])", "sin(ball_angle[1])"]
    obs, _ = on.reset(seed=0, options={"ball_angles": [0.5, -1.0]})
    np.testing.assert_allclose(obs[9:], np.float32([math.cos(0.5), math.sin(0.5),
                                                    math.cos(-1.0), math.sin(-1.0)]))
    assert np.array_equal(obs[6:9], [0.0, 0.0, 0.0])  # nothing vibrates yet, no noise


def test_sync_settings_are_checked_by_name():
    with pytest.raises(PresetError, match="'sync_vibration.lag' must be in"):
        load_preset("train", sync_vibration={"lag": -1.0})
    with pytest.raises(PresetError, match="'sync_vibration.noise' must be in"):
        load_preset("train", sync_vibration={"noise": float("nan")})
    with pytest.raises(PresetError, match="'sync_vibration.enabled' must be true or false"):
        load_preset("train", sync_vibration={"enabled": 1})
    with pytest.raises(PresetError, match="unknown key.*'lags'"):
        load_preset("train", sync_vibration={"lags": 0.1})
    with pytest.raises(PresetError, match="'frame_stack' must be an integer"):
        load_preset("train", frame_stack=2.5)
    with pytest.raises(PresetError, match="'frame_stack' must be"):
        load_preset("train", frame_stack=0)


# ------------------------------------------------------------------------ frame stack
def test_frame_stack_holds_the_last_k_observations_oldest_first():
    k = 3
    plain = gym.make(SPEED, sync_vibration={"enabled": True, "noise": 0.01})
    stacked = gym.make(SPEED, sync_vibration={"enabled": True, "noise": 0.01}, frame_stack=k)
    d = plain.observation_space.shape[0]
    assert stacked.observation_space.shape == (k * d,)
    names = stacked.unwrapped.observation_names
    assert names[:2] == ["rotor_speed@t-2", "vibration_x@t-2"]
    assert names[-d:] == plain.unwrapped.observation_names
    rng = np.random.default_rng(0)
    history = []
    for episode in range(2):
        o, _ = plain.reset(seed=episode)
        s, _ = stacked.reset(seed=episode)
        history = [o] * k  # at reset the first observation fills every frame
        assert np.array_equal(s, np.concatenate(history))
        for _ in range(6):
            a = rng.uniform(0, 1, 1).astype(np.float32)
            o = plain.step(a)[0]
            s = stacked.step(a)[0]
            history = history[1:] + [o]
            assert np.array_equal(s, np.concatenate(history))
            assert s in stacked.observation_space


# ------------------------------------------------------------------------ API conformance
@pytest.mark.parametrize("env_id", ["abb_gym/RunUpTorque-v0", SPEED, "abb_gym/DwellProfile-v0"])
def test_check_env_with_sync_observation_and_frame_stack(env_id, strict_check_env):
    env = gym.make(env_id, sync_vibration={"enabled": True, "noise": 0.01}, frame_stack=2,
                   observe_balls=True)
    strict_check_env(env)


def test_sync_and_frame_stack_survive_pickling():
    import pickle
    env = gym.make(SPEED, preset="varied", frame_stack=3)
    env.reset(seed=1)
    for _ in range(5):
        env.step(np.array([0.8], np.float32))
    clone = pickle.loads(pickle.dumps(env))
    for _ in range(5):
        a = env.step(np.array([0.8], np.float32))
        b = clone.step(np.array([0.8], np.float32))
        assert np.array_equal(a[0], b[0]) and a[1] == b[1]
