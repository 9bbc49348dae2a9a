"""Rotor facts (abb_gym.physics.rotor): one implementation, used by every layer."""
from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import abb_gym
from abb_gym import SpeedProfile, load_scene, simulate
from abb_gym.evaluation.metrics import trajectory_metrics
from abb_gym.physics import model as mdl
from abb_gym.physics import rotor


def test_residual_imbalance_and_the_two_ball_cancelling_angles():
    scene = load_scene("yoshida_odd")
    u, cap = scene.imbalance, scene.balancing_capacity
    assert rotor.residual_imbalance(scene, [0.0, 0.0]) == pytest.approx(u + cap)
    # two balls cancel U0 exactly at pi +- arccos(U0 / (2 m R)) (physics note A5)
    half = math.acos(u / cap)
    assert rotor.residual_imbalance(scene, [math.pi - half, math.pi + half]) == \
        pytest.approx(0.0, abs=1e-12 * u)
    assert rotor.best_residual(scene) == 0.0
    angles = np.array([[0.0, 0.0], [math.pi, math.pi]])
    assert np.allclose(rotor.residual_imbalance(scene, angles), [u + cap, cap - u])


def test_best_residual_with_unequal_balls_and_an_eccentric_race():
    """The balls' own imbalance ranges over [2 max m R - sum m R, sum m R]; the race
    eccentricity adds the fixed imbalance sum m E e^{i gam}."""
    sc = load_scene("yoshida_odd", ball_mass=[1e-3, 3e-3], race_eccentricity=10e-6,
                    race_eccentricity_angle=0.5, rotor_eccentricity=1e-6)
    big_r = sc.race_radius
    lo = 2 * 3e-3 * big_r - 4e-3 * big_r  # the light ball cannot cancel the heavy one
    fixed = abs(sc.imbalance + 4e-3 * 10e-6 * np.exp(0.5j))
    assert fixed < lo
    assert rotor.best_residual(sc) == pytest.approx(lo - fixed, rel=1e-12)
    # the angles that reach it: both balls opposite the fixed imbalance's direction
    phase = np.angle(sc.imbalance + 4e-3 * 10e-6 * np.exp(0.5j))
    best_angles = [phase, phase + math.pi]  # light ball along, heavy ball against
    assert rotor.residual_imbalance(sc, best_angles) == pytest.approx(lo - fixed, rel=1e-9)


def test_environment_info_and_trajectory_metrics_agree_on_unequal_balls_and_an_eccentric_race():
    """The environment's info["balanced"] and the metrics of simulate() call the same rotor
    facts: on a machine with 1 g and 3 g balls and a 10 um race eccentricity they give the
    same residual and the same verdict (the first wave gave 19.4 U0 against 0.0)."""
    sc = load_scene("yoshida_odd", ball_mass=[1e-3, 3e-3], race_eccentricity=10e-6)
    profile = SpeedProfile.ramp(40.0, sc.drive_operating_speed)
    env = gym.make("abb_gym/RunUpSpeed-v0", scene=sc, preset="nominal")
    env.reset(seed=0)
    setup = env.unwrapped.setup
    info = {}
    for k in range(setup.max_steps):
        t = k * setup.control_interval
        a = (float(profile.speed(t + setup.control_interval)) - float(profile.speed(t))) \
            / setup.control_interval / setup.max_acceleration
        _, _, term, trunc, info = env.step(np.array([a], dtype=np.float32))
        if term or trunc:
            break
    tr = simulate(sc, profile, info["time"], output_dt=setup.control_interval)
    m = trajectory_metrics(tr, balance_tol=setup.config.balance_tolerance)
    assert np.allclose(tr.ball_angles[-1], info["ball_angles"], rtol=0, atol=1e-9)
    assert m["residual_imbalance"] == pytest.approx(info["residual_imbalance_ratio"], rel=1e-9)
    assert m["balanced"] == info["balanced"]
    # and both equal the rotor fact itself
    res = rotor.residual_imbalance(sc, info["ball_angles"]) / rotor.imbalance_scale(sc)
    assert res == pytest.approx(info["residual_imbalance_ratio"], rel=1e-12)


def test_reference_amplitudes_are_the_jeffcott_response_of_the_total_mass():
    sc = load_scene("yoshida_odd")
    peak, at_op = rotor.reference_amplitudes(sc, 240.0)
    w = np.linspace(1.0, 240.0, 200001)
    a = [rotor.jeffcott_amplitude(sc.imbalance, sc.total_mass, 1000.0, 0.2, v) for v in w]
    assert peak == pytest.approx(max(a), rel=1e-6)
    # the peak sits at the scene's critical speed sqrt(k / M), within the damping shift
    assert w[int(np.argmax(a))] == pytest.approx(sc.critical_speed, rel=1e-3)
    undamped = sc.imbalance * 240.0 ** 2 / abs(1000.0 - sc.total_mass * 240.0 ** 2)
    assert at_op == pytest.approx(undamped, rel=1e-3)
    low = rotor.reference_amplitudes(sc, 50.0)
    assert low[0] == low[1]  # below the critical speed the peak is the operating-speed value
    ortho = load_scene("spannan_discoidal")
    peak_x = rotor.reference_amplitudes(ortho.replace(support_stiffness_y=ortho.support_stiffness_x,
                                                      support_damping_y=ortho.support_damping_x),
                                        ortho.drive_operating_speed)[0]
    assert rotor.reference_amplitudes(ortho, ortho.drive_operating_speed)[0] >= peak_x


def test_spinning_inertia_is_the_mass_matrix_rotor_entry_averaged_over_ball_angles():
    sc = load_scene("spannan_cfrp", race_eccentricity=1e-4)
    p, b = mdl.pack_parameters(sc)
    nq = 3 + sc.ball_count
    entries = []
    for ang in np.linspace(0.0, 2 * math.pi, 64, endpoint=False):
        q = np.zeros(nq)
        q[3:] = ang
        entries.append(mdl.mass_matrix(q, p, b)[2, 2])
    assert rotor.spinning_inertia(sc) == pytest.approx(np.mean(entries), rel=1e-12)


def test_static_deflection_is_the_sag_of_the_total_mass():
    sc = load_scene("washer")
    x, y = rotor.static_deflection(sc)
    assert x == pytest.approx(0.0, abs=1e-15)
    assert y == pytest.approx(-sc.total_mass * sc.gravity_acceleration / sc.support_stiffness_y)
    assert rotor.static_deflection(load_scene("yoshida_odd")) == (0.0, 0.0)
