"""Speed profiles are exact piecewise quadratics, and simulate follows them exactly."""
import numpy as np
import pytest

from abb_gym import SpeedProfile, load_scene, simulate


def test_dwell_profile_pieces():
    p = SpeedProfile.dwell(accel=40.0, dwell_speed=100.0, dwell_time=0.5, dwell_accel=20.0,
                           operating_speed=240.0)
    np.testing.assert_allclose(p.breakpoints, [0.0, 2.5, 3.0, 3.0 + 130.0 / 40.0])
    assert p.speed(2.5) == pytest.approx(100.0)
    assert p.speed(3.0) == pytest.approx(110.0)
    assert p.acceleration(2.7) == 20.0 and p.acceleration(1.0) == 40.0
    assert p.speed(100.0) == pytest.approx(240.0) and p.acceleration(100.0) == 0.0
    # the angle is the integral of the speed
    t = np.linspace(0, 8, 80001)
    angle = np.concatenate([[0], np.cumsum(0.5 * (p.speed(t[1:]) + p.speed(t[:-1])) * np.diff(t))])
    np.testing.assert_allclose(p.angle(t), angle, atol=1e-6)


def test_ramp_and_constant():
    r = SpeedProfile.ramp(40.0)
    assert r.speed(6.0) == pytest.approx(240.0)
    assert r.angle(6.0) == pytest.approx(0.5 * 40 * 36)
    c = SpeedProfile.constant(100.0)
    assert c.speed(3.0) == 100.0 and c.angle(3.0) == pytest.approx(300.0)
    assert c.max_speed(5.0) == 100.0


@pytest.mark.parametrize("method", ["rk4", "DOP853"])
def test_simulate_follows_the_profile_exactly(method):
    p = SpeedProfile.dwell(accel=40.0, dwell_speed=90.0, dwell_time=0.37, dwell_accel=-10.0)
    tr = simulate(load_scene("yoshida_odd"), p, 4.0, method=method, output_dt=0.01)
    np.testing.assert_allclose(tr.rotor_speed, p.speed(tr.t), rtol=1e-13, atol=1e-10)
    np.testing.assert_allclose(tr.rotor_angle, p.angle(tr.t), rtol=1e-13, atol=1e-10)
