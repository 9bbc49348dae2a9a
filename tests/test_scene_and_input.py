"""Scenes load, override and reject bad input with errors naming the field and range."""
import math

import numpy as np
import pytest

import abb_gym
from abb_gym import SceneError, SimulationError, SpeedProfile, load_scene, simulate
from abb_gym.physics.drives import MotorDrive
from abb_gym.physics.trajectory import state_names


@pytest.mark.parametrize("name", abb_gym.list_scenes())
def test_every_shipped_scene_loads_and_runs(name):
    scene = load_scene(name)
    assert scene.name == name
    tr = simulate(scene, SpeedProfile.constant(1.2 * scene.critical_speed), 0.2, output_dt=0.01)
    assert np.all(np.isfinite(tr.states))


def test_shipped_scene_values():
    y = load_scene("yoshida_odd")
    assert y.total_mass == pytest.approx(0.1)
    assert y.critical_speed == pytest.approx(100.0)
    assert y.imbalance == pytest.approx(0.098 * 1e-4)
    assert y.effects == {"rolling_resistance"}
    lh = load_scene("lu_hung_odd3")
    # Lu & Hung groups: eta = m_b d / (m_d e) = 0.4, zeta = 0.1, zeta_B = 0.1
    assert lh.ball_mass[0] * lh.race_radius / lh.imbalance == pytest.approx(0.4)
    assert lh.support_damping_x / (2 * lh.total_mass * lh.critical_speed) == pytest.approx(0.1)
    assert lh.ball_drag[0] / (2 * lh.ball_mass[0] * lh.critical_speed) == pytest.approx(0.1)
    d = load_scene("spannan_discoidal")
    assert d.critical_speeds[0] == pytest.approx(60.29, abs=0.01)  # 9.6 Hz measured mode


def test_overrides_by_keyword_and_scene_copy():
    s = load_scene("yoshida_odd", ball_mass=2e-3, support_stiffness=2000.0)
    assert s.ball_mass == (2e-3, 2e-3)
    assert s.support_stiffness_x == s.support_stiffness_y == 2000.0
    assert s.total_mass == pytest.approx(0.102)
    three = s.replace(ball_count=3, ball_angles0=[0, 1, 2])
    assert three.ball_count == 3 and three.ball_mass == (2e-3,) * 3
    assert load_scene(s) is s


def test_scene_loads_from_path(tmp_path):
    src = abb_gym.physics.scene.scenes_dir() / "yoshida_odd.yaml"
    p = tmp_path / "mine.yaml"
    p.write_text(src.read_text().replace("name: yoshida_odd", "name: mine"))
    assert load_scene(p).name == "mine"
    assert load_scene(str(p), ball_count=1, ball_angles0=0.5).ball_count == 1


@pytest.mark.parametrize("overrides, field", [
    ({"ball_mass": -1e-3}, "ball_mass"),
    ({"ball_mass": 0.0}, "ball_mass"),
    ({"rotor_mass": 0.0}, "rotor_mass"),
    ({"support_stiffness_x": -5.0}, "support_stiffness_x"),
    ({"race_radius": 0.0}, "race_radius"),
    ({"ball_radius": float("nan")}, "ball_radius"),
    ({"support_damping_y": float("inf")}, "support_damping_y"),
    ({"ball_count": 0}, "ball_count"),
    ({"ball_count": 2.5}, "ball_count"),
    ({"ball_radius": 0.02}, "ball_radius"),
    ({"ball_mass": [1e-3, 1e-3, 1e-3]}, "ball_mass"),
    ({"ball_inertia_factor": 1.5}, "ball_inertia_factor"),
    ({"race_eccentricity": 0.5}, "race_eccentricity"),
    ({"ball_drag": "lots"}, "ball_drag"),
    ({"colour": "red"}, "colour"),
])
def test_bad_scene_values_raise_value_error_naming_the_field(overrides, field):
    with pytest.raises(ValueError, match=field) as info:
        load_scene("yoshida_odd", **overrides)
    assert isinstance(info.value, SceneError)


def test_error_message_states_allowed_range():
    with pytest.raises(SceneError, match=r"'ball_mass' must be in \[1e-07, 1000\] \[kg\] \(got -1"):
        load_scene("yoshida_odd", ball_mass=-1.0)
    with pytest.raises(SceneError, match=r"'ball_radius' must be < race_radius"):
        load_scene("yoshida_odd", ball_radius=0.011)


def test_unknown_scene_malformed_yaml_and_missing_fields(tmp_path):
    with pytest.raises(SceneError, match="unknown scene 'nope'.*yoshida_odd"):
        load_scene("nope")
    bad = tmp_path / "bad.yaml"
    bad.write_text("rotor: {mass: 1.0\nballs: [")
    with pytest.raises(SceneError, match="not valid YAML"):
        load_scene(bad)
    missing = tmp_path / "missing.yaml"
    missing.write_text("name: missing\nrotor: {mass: 1.0}\n")
    with pytest.raises(SceneError, match="missing field.*race_radius"):
        load_scene(missing)
    unknown = tmp_path / "unknown.yaml"
    src = (abb_gym.physics.scene.scenes_dir() / "yoshida_odd.yaml").read_text()
    unknown.write_text(src + "rotor_colour: red\n")
    with pytest.raises(SceneError, match="unknown field.*rotor_colour"):
        load_scene(unknown)
    with pytest.raises(SceneError, match="does not exist"):
        load_scene(tmp_path / "absent.yaml")


@pytest.mark.parametrize("make, match", [
    (lambda: SpeedProfile(segments=((-1.0, 40.0),)), "duration must be >= 0"),
    (lambda: SpeedProfile.dwell(accel=40, dwell_speed=100, dwell_time=-0.5), "dwell_time"),
    (lambda: SpeedProfile.ramp(accel=float("nan")), "accel"),
    (lambda: SpeedProfile.ramp(accel=-40.0), "accel"),
    (lambda: SpeedProfile.dwell(accel=40, dwell_speed=100, dwell_time=10, dwell_accel=-20),
     "speed negative"),
    (lambda: SpeedProfile.dwell(accel=40, dwell_speed=100, dwell_time=0.5,
                                operating_speed=50.0), "operating_speed"),
    (lambda: MotorDrive(speed_gain=-1.0), "speed_gain"),
    (lambda: MotorDrive(torque_limit=0.0), "torque_limit"),
])
def test_bad_drives_raise(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_bad_simulate_arguments():
    scene = load_scene("yoshida_odd")
    drive = SpeedProfile.ramp(40.0)
    with pytest.raises(ValueError, match="t_end"):
        simulate(scene, drive, -1.0)
    with pytest.raises(ValueError, match="ball_angles0"):
        simulate(scene, drive, 1.0, ball_angles0=[0.0])
    with pytest.raises(ValueError, match="ball_angles0"):
        simulate(scene, drive, 1.0, ball_angles0=[0.0, math.nan])
    with pytest.raises(ValueError, match="method"):
        simulate(scene, drive, 1.0, method="euler")
    with pytest.raises(ValueError, match="dt"):
        simulate(scene, drive, 1.0, dt=0.0)


def test_non_finite_state_stops_with_time_and_variable():
    """Beyond RK4's stability limit (h * c_b/(1.4 m) = 3.6 > 2.79) the run must stop with an
    error naming the time and the variable, never return NaN."""
    scene = load_scene("yoshida_odd")
    with pytest.raises(SimulationError) as info:
        simulate(scene, SpeedProfile.ramp(40.0), 6.0, dt=5e-3, output_dt=0.01)
    err = info.value
    assert 0 < err.time <= 6.0
    assert err.variable in str(err) and f"t = {err.time:.6g} s" in str(err)
    assert err.variable in state_names(2)
