"""Bad input to the plain simulation API: the answer is a result, or a ValueError (SceneError)
or SimulationError whose message names the field; never another exception type, a hang, or a
silently non-finite result.

First one regression test per class of bad input found by fuzzing (issue 15: wrong types,
paths, step sizes and horizons, values the physics cannot use, default steps that miss the
stated accuracy), then property-based tests (hypothesis) over ``load_scene`` overrides,
``simulate`` keyword arguments, ``SpeedProfile`` and ``MotorDrive``.  The property runs are kept
small (t_end <= 0.05 s, ``max_steps`` <= 2000) so that the whole file takes about a minute;
``ABB_GYM_FUZZ_SCALE=20`` runs 20 times the examples with a fresh seed.
"""
import math
import os
import threading
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from abb_gym import MotorDrive, SceneError, SpeedProfile, load_scene, simulate
from abb_gym.configuration import specs
from abb_gym.physics.fluids import FLUIDS
from abb_gym.physics.scene import ANGLE_LIMIT, Scene
from abb_gym.physics.simulate import METHODS, SimulationError
from abb_gym.physics.steps import default_step

RAMP = SpeedProfile.ramp(40.0)


@pytest.fixture(scope="module")
def yoshida():
    return load_scene("yoshida_odd")


# ================================================================== regression, class by class
# ---------------------------------------------------------------------------- wrong types
@pytest.mark.parametrize("kwargs, field", [
    ({"dt": "a"}, "dt"),
    ({"dt": [1e-3]}, "dt"),
    ({"dt": True}, "dt"),
    ({"output_dt": "a"}, "output_dt"),
    ({"rtol": "a", "method": "dopri5"}, "rtol"),
    ({"rtol": None, "atol": "a", "method": "dopri5"}, "atol"),
    ({"atol": [1e-6, 1e-6], "method": "dopri5"}, "atol"),
    ({"x0": "ab"}, "x0"),
    ({"v0": [None, 0.0]}, "v0"),
    ({"ball_angles0": "ab"}, "ball_angles0"),
    ({"ball_angles0": [None, 1.0]}, "ball_angles0"),
    ({"ball_speeds0": [True, False]}, "ball_speeds0"),
    ({"energy_tolerance": "a"}, "energy_tolerance"),
    ({"method": ["rk4"]}, "method"),
    ({"method": np.array(["rk4", "ros2"])}, "method"),
    ({"kernel": 3}, "kernel"),
    ({"max_steps": 1.5}, "max_steps"),
])
def test_simulate_arguments_of_the_wrong_type_name_the_argument(yoshida, kwargs, field):
    with pytest.raises(ValueError, match=field):
        simulate(yoshida, RAMP, 0.02, **kwargs)


@pytest.mark.parametrize("t_end", ["a", None, [1.0], True])
def test_t_end_of_the_wrong_type_names_t_end(yoshida, t_end):
    with pytest.raises(ValueError, match="t_end"):
        simulate(yoshida, RAMP, t_end)


@pytest.mark.parametrize("make, field", [
    (lambda: SpeedProfile(segments=None), "segments"),
    (lambda: SpeedProfile(segments=3), "segments"),
    (lambda: SpeedProfile(segments=[1.0, 2.0]), "segments"),  # flat, not pairs
    (lambda: SpeedProfile(segments="ab"), "segments"),
    (lambda: SpeedProfile(segments=[("a", 40.0)]), "duration"),
    (lambda: SpeedProfile(segments=[(1.0, None)]), "acceleration"),
    (lambda: SpeedProfile(segments=[(True, 40.0)]), "duration"),
    (lambda: SpeedProfile(segments=(), initial_speed="a"), "initial_speed"),
    (lambda: SpeedProfile.ramp(None), "accel"),
    (lambda: SpeedProfile.ramp("40"), "accel"),
    (lambda: SpeedProfile.ramp(40.0, "a"), "operating_speed"),
    (lambda: SpeedProfile.dwell(40.0, None, 0.5), "dwell_speed"),
    (lambda: SpeedProfile.dwell(40.0, 100.0, "x"), "dwell_time"),
    (lambda: SpeedProfile.constant(None), "speed"),
    (lambda: MotorDrive(torque=None), "torque"),
    (lambda: MotorDrive(torque=True), "torque"),
    (lambda: MotorDrive(target="a"), "target"),
    (lambda: MotorDrive(target=[1.0]), "target"),
    (lambda: MotorDrive(torque_limit="a"), "torque_limit"),
    (lambda: MotorDrive.limited_power(None, 100.0), "gain"),
    (lambda: MotorDrive.linear_characteristic("a", 100.0), "stall_torque"),
    (lambda: MotorDrive.linear_characteristic(1.0, 100.0, initial_speed="a"), "initial_speed"),
])
def test_drive_arguments_of_the_wrong_type_name_the_argument(make, field):
    with pytest.raises(ValueError, match=field):
        make()


def test_booleans_are_not_numbers_in_a_scene(tmp_path):
    """``true`` used to become 1.0 (numpy's bool everywhere, YAML's for per-ball fields)."""
    with pytest.raises(SceneError, match="contact_stiffness"):
        load_scene("yoshida_odd", contact_stiffness=np.True_)
    with pytest.raises(SceneError, match="ball_count"):
        load_scene("yoshida_odd", ball_count=np.True_)
    path = tmp_path / "bool.yaml"
    text = (load_scene("yoshida_odd").to_dict())
    import yaml
    text["contact_stiffness"] = True
    path.write_text(yaml.safe_dump(text))
    with pytest.raises(SceneError, match="contact_stiffness"):
        load_scene(path)


def test_scene_values_of_odd_types_name_the_field(tmp_path):
    # a choice compared with an array used to raise numpy's "truth value ... is ambiguous"
    with pytest.raises(SceneError, match="fluid_drag_law"):
        load_scene("yoshida_odd", fluid_drag_law=np.array(["linear", "stokes"]))
    # a 0-d array is one value (list() of it used to raise TypeError)
    assert load_scene("yoshida_odd", ball_mass=np.array(2e-3)).ball_mass == (2e-3, 2e-3)
    with pytest.raises(SceneError, match="rotor_mass"):
        load_scene("yoshida_odd", rotor_mass=np.array([1.0]))
    with pytest.raises(SceneError, match="rotor_mass"):
        load_scene("yoshida_odd", rotor_mass=b"1.0")
    # nested per-ball lists with a new ball count used to raise "unhashable type: 'list'"
    import yaml
    data = load_scene("yoshida_odd").to_dict()
    data["ball_mass"] = [[1e-3], [1e-3]]
    path = tmp_path / "nested.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(SceneError, match="ball_mass"):
        load_scene(path, ball_count=3)
    # unknown keys of mixed types used to make sorted() raise TypeError
    path.write_text(path.read_text().replace("ball_mass:", "1: 2\nfoo: 3\nball_mass:"))
    with pytest.raises(SceneError, match="unknown field"):
        load_scene(path)


# ---------------------------------------------------------------------------- paths
def test_paths_that_are_not_scene_files_give_one_line_naming_the_path(tmp_path):
    with pytest.raises(SceneError, match="is a directory"):
        load_scene(tmp_path)
    folder = tmp_path / "folder.yaml"
    folder.mkdir()
    with pytest.raises(SceneError, match="folder.yaml.*is a directory"):
        load_scene(folder)
    binary = tmp_path / "binary.yaml"
    binary.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xfe")
    with pytest.raises(SceneError, match="binary.yaml.*not UTF-8"):
        load_scene(binary)
    latin1 = tmp_path / "latin1.yaml"
    latin1.write_bytes("name: caf\u00e9\n".encode("latin-1"))
    with pytest.raises(SceneError, match="latin1.yaml.*not UTF-8"):
        load_scene(latin1)
    huge = tmp_path / "huge.yaml"
    huge.write_bytes(b"#" * (5 * 1024 * 1024))
    with pytest.raises(SceneError, match="huge.yaml.*bytes"):
        load_scene(huge)


@pytest.mark.parametrize("name", ["", "   ", "."])
def test_an_empty_scene_name_never_reads_the_current_folder(name):
    with pytest.raises(SceneError, match="must be a name or a path|unknown scene"):
        load_scene(name)


def test_a_name_the_system_refuses_is_a_scene_error():
    """A 5000-character name used to raise OSError (file name too long); the message is cut."""
    for name in ("x" * 5000, "x" * 5000 + ".yaml", "a/" * 3000 + "b.yaml", "a\x00b.yaml"):
        with pytest.raises(SceneError) as info:
            load_scene(name)
        assert len(str(info.value)) < 600


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
def test_a_pipe_is_refused_not_read(tmp_path):
    """A named pipe (or /dev/zero) used to block for ever; a writer opens it after 3 s so that
    a regression fails instead of hanging."""
    pipe = tmp_path / "pipe.yaml"
    os.mkfifo(pipe)

    def unblock():
        time.sleep(3.0)
        try:
            fd = os.open(pipe, os.O_WRONLY | os.O_NONBLOCK)
        except OSError:  # nobody reading: the test has passed
            return
        os.write(fd, b"rotor: [")
        os.close(fd)

    threading.Thread(target=unblock, daemon=True).start()
    with pytest.raises(SceneError, match="not a regular file"):
        load_scene(pipe)


# ---------------------------------------------------------------------------- steps, horizons
@pytest.mark.parametrize("kwargs, t_end, field", [
    ({"dt": 1e-30}, 0.1, "dt"),        # the step count overflowed: 1 ms steps, silently
    ({"dt": 1e-15}, 0.1, "dt"),        # hung
    ({"output_dt": 1e-15}, 0.1, "output_dt"),  # MemoryError
    ({}, 1e7, "t_end"),                # hung (and ran out of memory)
    ({"method": "dopri5"}, 1e7, "t_end"),
    ({"method": "DOP853"}, 1e5, "t_end"),
    ({}, 1e300, "t_end"),
    ({"method": "dopri5"}, 1e300, "t_end"),  # ZeroDivisionError in the estimate
    ({"ball_speeds0": [1e12, 0.0]}, 1.0, "t_end"),
])
def test_the_work_is_bounded_before_it_starts(yoshida, kwargs, t_end, field):
    default_step(yoshida, 1.0)  # load the compiled stiff-rate function before timing
    start = time.perf_counter()
    with pytest.raises(ValueError, match=field) as info:
        simulate(yoshida, RAMP, t_end, **kwargs)
    assert time.perf_counter() - start < 2.0
    message = str(info.value)
    assert "max_steps" in message or "samples" in message  # the limit, and how to proceed
    assert "shorter t_end" in message


@pytest.mark.parametrize("method", ["rk4", "Radau"])
def test_a_subnormal_horizon_is_refused(yoshida, method):
    """t_end = 5e-324 s made solve_ivp fail with "array must not contain infs or NaNs"."""
    with pytest.raises(ValueError, match="t_end must be >= 1e-09 s"):
        simulate(yoshida, RAMP, 5e-324, method=method)


def test_a_free_spin_up_is_stepped_at_its_top_speed(yoshida):
    """A torque command spins the rotor far beyond its initial speed and target (0): the
    default step used to turn the final 500 rad/s by 1.7 rad a step instead of 0.4."""
    tr = simulate(yoshida, MotorDrive(torque=0.02, torque_limit=0.02), 1.0, output_dt=0.01)
    assert tr.rotor_speed.max() > 400.0
    assert tr.step * tr.rotor_speed.max() <= 0.4 + 1e-9


def test_max_steps_sets_the_bound(yoshida):
    with pytest.raises(ValueError, match="max_steps = 10 "):
        simulate(yoshida, RAMP, 0.1, dt=1e-3, max_steps=10)
    tr = simulate(yoshida, RAMP, 0.1, dt=1e-3, max_steps=200)
    assert tr.work == 100


def test_the_default_step_explains_what_bounds_it(yoshida):
    stiff = yoshida.replace(ball_mass=1e-7, ball_drag=1e6)
    with pytest.raises(ValueError, match="stiff ball drag.*'etdrk4' or 'ros2'"):
        simulate(stiff, RAMP, 0.05)
    assert np.isfinite(simulate(stiff, RAMP, 0.05, method="etdrk4").states).all()


@pytest.mark.parametrize("method", ["rk4", "etdrk4", "dopri5"])
def test_heavy_support_damping_bounds_the_explicit_steps(yoshida, method):
    """Support damping of 1e9 N s/m on a 0.1 kg rotor (rate 1e10 1/s) was invisible to the
    step rules: dopri5 ran for three minutes on a 0.02 s run, rk4 and etdrk4 went unstable."""
    damped = yoshida.replace(support_damping=1e9)
    start = time.perf_counter()
    with pytest.raises(ValueError, match="max_steps.*'ros2'"):
        simulate(damped, RAMP, 0.02, method=method)
    assert time.perf_counter() - start < 2.0
    assert np.isfinite(simulate(damped, RAMP, 0.02, method="ros2").states).all()


def test_a_stiff_motor_bounds_the_explicit_steps(yoshida):
    drive = MotorDrive.limited_power(gain=1e3, target=100.0)  # gain / J = 2.5e7 1/s
    with pytest.raises(ValueError, match="motor drive"):
        simulate(yoshida, drive, 5.0)


def test_solve_ivp_stops_at_its_work_bound(yoshida):
    """solve_ivp has no bound of its own: a Radau run on a stiff scene took 5 minutes."""
    with pytest.raises(SimulationError, match="right-hand side") as info:
        simulate(yoshida, RAMP, 0.05, method="Radau", output_dt=0.05, max_steps=5)
    assert info.value.variable == "work"


# ---------------------------------------------------------------------------- physics
@pytest.mark.parametrize("overrides, field", [
    ({"ball_radius": 1e-30}, "ball_radius"),
    ({"ball_rolling_resistance": 1e30}, "ball_rolling_resistance"),
    ({"race_radius": 1e-30}, "race_radius"),
    ({"ball_mass": 1e-300}, "ball_mass"),
])
def test_values_the_physics_cannot_use_are_refused_by_the_scene(overrides, field):
    with pytest.raises(SceneError, match=field):
        load_scene("yoshida_odd", **overrides)


@pytest.mark.parametrize("overrides, field", [
    ({"rotor_eccentricity": 5e-324}, "rotor_eccentricity"),  # W_r/e was inf
    ({"race_eccentricity": 1e-20}, "race_eccentricity"),
    ({"ball_rolling_resistance": 2e-3}, "ball_rolling_resistance"),  # lever arm > radius
    ({"drive_max_acceleration": 5e-324}, "drive_max_acceleration"),  # run-up time inf
    ({"drive_operating_speed": 1e-300}, "drive_operating_speed"),
    ({"rotor_polar_inertia": 1e-300}, "rotor_polar_inertia"),
    ({"housing_clearance": 5e-324}, "housing_clearance"),
    ({"drive_torque_limit": 5e-324}, "drive_torque_limit"),
])
def test_subnormal_and_unphysical_values_are_refused(overrides, field):
    with pytest.raises(SceneError, match=field):
        load_scene("yoshida_odd", **overrides)


def test_the_smallest_accepted_eccentricity_gives_a_finite_whirl_ratio():
    scene = load_scene("yoshida_odd", rotor_eccentricity=1e-12)
    tr = simulate(scene, RAMP, 0.05, output_dt=0.01)
    assert np.all(np.isfinite(tr.whirl_ratio))
    assert load_scene("yoshida_odd", rotor_eccentricity=0.0).rotor_eccentricity == 0.0


@pytest.mark.parametrize("make, field", [
    (lambda: SpeedProfile(segments=((1.0, 40.0),), initial_speed=-5.0), "initial_speed"),
    (lambda: MotorDrive(initial_speed=-5.0), "initial_speed"),
    (lambda: MotorDrive(speed_gain=1e-3, target=-100.0), "target"),
    (lambda: SpeedProfile(segments=(), initial_angle=1e16), "initial_angle"),
    (lambda: MotorDrive(initial_angle=-1e16), "initial_angle"),
    (lambda: SpeedProfile(segments=((1e200, 1e200), (1.0, 0.0))), "segments"),
    (lambda: SpeedProfile.dwell(40.0, 100.0, 10.0, dwell_accel=-20.0), "dwell_accel"),
])
def test_negative_speeds_and_far_angles_are_refused(make, field):
    with pytest.raises(ValueError, match=field):
        make()


def test_negative_atol_and_far_ball_angles_are_refused(yoshida):
    with pytest.raises(ValueError, match="atol"):
        simulate(yoshida, RAMP, 0.02, method="dopri5", atol=-1e-9)
    with pytest.raises(ValueError, match="atol"):
        simulate(yoshida, RAMP, 0.02, method="dopri5", atol=[1e-9] * 9 + [-1e-9])
    with pytest.raises(ValueError, match="ball_angles0"):
        simulate(yoshida, RAMP, 0.02, ball_angles0=[1e16, 0.0])
    with pytest.raises(ValueError, match="rtol"):
        simulate(yoshida, RAMP, 0.02, method="dopri5", rtol=1e-20)


# ---------------------------------------------------------------------------- default steps
CASES = {
    "yoshida_odd ramp": ("yoshida_odd", SpeedProfile.ramp(40.0), 6.0),
    "spannan_cfrp ramp": ("spannan_cfrp", SpeedProfile.ramp(2.0, 50.0), 30.0),
}
_REFERENCES: dict = {}


def _reference(case):
    if case not in _REFERENCES:
        name, drive, t_end = CASES[case]
        _REFERENCES[case] = simulate(load_scene(name), drive, t_end, method="DOP853",
                                     rtol=1e-12, output_dt=0.01)
    return _REFERENCES[case]


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("method", ["rk4", "etdrk4", "ros2", "dopri5"])
def test_every_default_step_meets_the_stated_accuracy(case, method):
    """The stated 1 % of the peak whirl and 1 deg of the final ball angles against DOP853
    (rtol 1e-12), at the 10 ms output interval (which leaves the default step uncapped).  ROS2
    at its old default (0.4 rad a step) was 28 % off the Yoshida peak."""
    name, drive, t_end = CASES[case]
    ref = _reference(case)
    tr = simulate(load_scene(name), drive, t_end, method=method, output_dt=0.01)
    peak_err = abs(tr.whirl_ratio.max() / ref.whirl_ratio.max() - 1)
    angle_err = np.degrees(np.max(np.abs(tr.ball_angles[-1] - ref.ball_angles[-1])))
    assert peak_err < 0.01 and angle_err < 1.0, (peak_err, angle_err)


_MANY_BALLS = {
    # 5 balls, no contact; a ramp through the critical speed, as yoshida_odd's case above
    "yoshida_odd5 ramp": ("yoshida_odd5", SpeedProfile.ramp(40.0), 6.0),
    # 12 balls with contact, oil drag and gravity; 5 rad/s^2 through the tub's resonance to
    # 60 rad/s.  DOP853 at rtol 1e-10 and 1e-12 agree to 1e-13 on the peak and 0.08 deg on
    # the angles here, so the reference resolves the stated 1 deg
    "washer ramp": ("washer", SpeedProfile.ramp(5.0, 125.66), 12.0),
}
_ANGLES_OFF = ("the default step does not keep the stated 1 deg of the final ball angles on "
               "the washer: the error grows once the clumped balls collide at speed (0.3 deg "
               "at 6 s, 1 deg at 8 s), 2.7 deg (rk4) and 3.0 deg (etdrk4) at 12 s")
# DOP853 moves the final angles by 0.07 deg when every start angle moves by 1e-9 rad: the
# case is not chaotic at the stated 1 deg.  dopri5 at its default tolerance
# is 0.65-4.3 deg off over start angles shifted by 0, 1e-9, 2e-9 and 1e-8 rad, so which side of
# 1 deg this one case falls on is chance (simulate(scene.replace(ball_angles0=angles + shift),
# ...) against DOP853 from the same start)
_DOPRI5_ANGLES = ("dopri5's default tolerance does not keep 1 deg of the washer's final ball "
                  "angles reliably: 0.65-4.3 deg over start angles shifted by up to 1e-8 rad, "
                  "4.3 deg on this case")


@pytest.mark.parametrize("case, method", [
    ("yoshida_odd5 ramp", "rk4"), ("yoshida_odd5 ramp", "etdrk4"),
    ("yoshida_odd5 ramp", "dopri5"),
    pytest.param("yoshida_odd5 ramp", "ros2", marks=pytest.mark.xfail(
        strict=True, reason="ros2's default step: 5 % off the peak whirl, 2.1 deg")),
    pytest.param("washer ramp", "rk4", marks=pytest.mark.xfail(strict=True, reason=_ANGLES_OFF)),
    pytest.param("washer ramp", "etdrk4",
                 marks=pytest.mark.xfail(strict=True, reason=_ANGLES_OFF)),
    pytest.param("washer ramp", "dopri5",
                 marks=pytest.mark.xfail(strict=True, reason=_DOPRI5_ANGLES)),
])
def test_the_stated_accuracy_with_many_balls(case, method):
    """The stated 1 % of the peak whirl and 1 deg of the final ball angles against DOP853 on
    the many-ball scenes the environments integrate (issue "Many balls and small batches").
    The peak holds on both scenes for every method here (within 1e-5 on the washer); where
    the angles do not, the case is an expected failure that says by how much."""
    name, drive, t_end = _MANY_BALLS[case]
    scene = load_scene(name)
    if case not in _REFERENCES:
        _REFERENCES[case] = simulate(scene, drive, t_end, method="DOP853", rtol=1e-10,
                                     output_dt=0.01, max_steps=400_000)
    ref = _REFERENCES[case]
    tr = simulate(scene, drive, t_end, method=method, output_dt=0.01)
    peak_err = abs(tr.whirl_ratio.max() / ref.whirl_ratio.max() - 1)
    angle_err = np.degrees(np.max(np.abs(tr.ball_angles[-1] - ref.ball_angles[-1])))
    assert peak_err < 0.01 and angle_err < 1.0, (peak_err, angle_err)


def test_ros2_default_step_is_its_own():
    scene = load_scene("yoshida_odd")
    assert default_step(scene, 240.0, "ros2") == pytest.approx(0.05 / 240.0)
    assert default_step(scene, 240.0, "ros2") < default_step(scene, 240.0, "rk4") / 4


# ================================================================== property-based
# Deterministic by default, random with ABB_GYM_FUZZ_SCALE > 1 (tests/conftest.py's hypothesis
# profile); SCALE multiplies the examples.
SCALE = max(1, int(os.environ.get("ABB_GYM_FUZZ_SCALE", "1")))
PROPERTY = settings(deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                           HealthCheck.filter_too_much])

SPECS = specs(Scene)
FIELDS = sorted(n for n in SPECS if n != "name")
SHORTCUTS = ["support_stiffness", "support_damping"]

junk = st.one_of(
    st.none(), st.booleans(), st.text(max_size=4), st.binary(max_size=3),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-10**30, max_value=10**30),
    st.lists(st.one_of(st.floats(), st.text(max_size=2), st.none()), max_size=3),
    st.dictionaries(st.text(max_size=2), st.integers(), max_size=2),
    st.sampled_from([np.True_, np.float64(np.nan), np.array(1.0), np.array([1.0, 2.0]),
                     np.array(["a"]), np.int64(3), complex(1.0, 1.0), object(),
                     float("1e-320"), -0.0, [[1.0, 2.0]], (1.0,)]),
)


def _in_range(spec):
    """Values inside a numeric field's declared range, the bounds included."""
    lo = spec.ge if spec.ge is not None else spec.gt
    hi = spec.le if spec.le is not None else spec.lt
    if spec.kind == "integer":
        return st.integers(int(lo), min(int(hi), 6))
    inner = st.floats(lo, hi, exclude_min=spec.gt is not None, exclude_max=spec.lt is not None)
    ends = [v for v, ok in ((lo, spec.gt is None), (hi, spec.lt is None)) if ok]
    if lo is not None and lo >= 0 and hi is not None and hi > 0:
        # log-uniform as well: most of a range of 1e-9..1e12 is otherwise never reached
        low = max(lo, hi * 1e-15, 1e-300)
        logs = st.floats(math.log10(low), math.log10(hi)).map(lambda e: min(hi, 10.0 ** e))
        inner = st.one_of(inner, logs.filter(lambda v: v > lo or spec.gt is None))
    return st.one_of(st.sampled_from(ends), inner) if ends else inner


def _good_value(name):
    spec = SPECS[name]
    if name == "fluid_preset":
        return st.sampled_from(["", *FLUIDS])
    if spec.kind == "choice":
        return st.sampled_from(spec.choices)
    if spec.kind == "text":
        return st.text(max_size=8)
    one = _in_range(spec)
    if spec.per_ball:
        return st.one_of(one, st.lists(one, min_size=1, max_size=4))
    return one


@st.composite
def scene_overrides(draw, junk_share=0.3):
    keys = draw(st.lists(st.sampled_from(FIELDS + SHORTCUTS + ["bogus_field"]), max_size=4,
                         unique=True))
    out = {}
    for key in keys:
        name = {"support_stiffness": "support_stiffness_x",
                "support_damping": "support_damping_x"}.get(key, key)
        if name not in SPECS or draw(st.floats(0, 1)) < junk_share:
            out[key] = draw(junk)
        else:
            out[key] = draw(_good_value(name))
    return out


def _named(message, names):
    """True if ``message`` names one of ``names``."""
    return any(n in message for n in names)


def _checked_run(fn, names, what="run"):
    """``fn()``'s result, or None after an allowed error: a SimulationError naming its
    variable, or a ValueError naming one of ``names``.  Any other exception propagates."""
    try:
        result = fn()
    except SimulationError as err:
        assert err.variable in str(err), str(err)
        event(f"{what}: SimulationError")
    except ValueError as err:
        assert _named(str(err), names), str(err)
        event(f"{what}: ValueError")
    else:
        event(f"{what}: result")
        return result
    return None


def _check_trajectory(tr, t_end):
    assert np.all(np.isfinite(tr.states)), "silently non-finite states"
    assert tr.t[0] == 0.0 and tr.t[-1] == pytest.approx(t_end)
    assert np.all(np.diff(tr.t) > 0)
    if tr.motor_torque is not None:
        assert np.all(np.isfinite(tr.motor_torque))


SIM_NAMES = ["t_end", "dt", "output_dt", "max_steps", "method", "rtol", "atol", "ball_angles0",
             "ball_speeds0", "x0", "v0", "energy_tolerance", "kernel", "drive", "segments"]


@settings(PROPERTY, max_examples=300 * SCALE)
@given(base=st.sampled_from(["yoshida_odd", "lu_hung_odd3", "washer"]),
       overrides=scene_overrides())
def test_scene_overrides_give_a_scene_or_an_error_naming_the_field(base, overrides):
    try:
        scene = load_scene(base, **overrides)
    except SceneError as err:
        assert _named(str(err), FIELDS + SHORTCUTS + ["bogus_field"]), str(err)
        assert len(str(err)) < 2000
        return
    assert isinstance(scene, Scene)
    for name in FIELDS:  # every accepted value is of its declared kind, never a bool
        value = getattr(scene, name)
        for v in (value if SPECS[name].per_ball else (value,)):
            assert not isinstance(v, bool) and type(v) in (int, float, str), (name, v)
            if isinstance(v, float):
                assert math.isfinite(v)


@settings(PROPERTY, max_examples=60 * SCALE)
@given(base=st.sampled_from(["yoshida_odd", "lu_hung_odd3", "spannan_cfrp"]),
       overrides=scene_overrides(junk_share=0.0),
       method=st.sampled_from(["rk4", "etdrk4", "ros2", "dopri5"]))
def test_every_accepted_scene_simulates(base, overrides, method):
    """The physics can use every scene load_scene accepts: a short run is finite, or stops with
    a SimulationError, or is refused up front for its work (never ZeroDivisionError or NaN)."""
    try:
        scene = load_scene(base, **overrides)
    except SceneError:
        event("scene refused")
        return
    drive = SpeedProfile.ramp(scene.drive_max_acceleration, scene.drive_operating_speed)
    tr = _checked_run(lambda: simulate(scene, drive, 0.02, method=method, output_dt=0.01,
                                       max_steps=2000), ["max_steps"])
    if tr is not None:
        _check_trajectory(tr, 0.02)


def _maybe(good, junk_share=0.25):
    """``good`` values, with junk in about ``junk_share`` of the draws."""
    return st.floats(0.0, 1.0).flatmap(lambda u: junk if u < junk_share else good)


SIM_KWARGS = {
    "dt": _maybe(st.one_of(st.none(), st.floats(1e-30, 1e-2))),
    "output_dt": _maybe(st.one_of(st.none(), st.floats(1e-15, 0.1))),
    "method": _maybe(st.sampled_from(METHODS)),
    "rtol": _maybe(st.one_of(st.none(), st.floats(1e-16, 10.0))),
    "atol": _maybe(st.one_of(st.none(), st.floats(-1.0, 1.0),
                             st.lists(st.floats(-1e-3, 1e-3), min_size=9, max_size=11))),
    "ball_angles0": _maybe(st.lists(st.floats(-2e3, 2e3), min_size=1, max_size=3)),
    "ball_speeds0": _maybe(st.lists(st.floats(-1e3, 1e3), min_size=1, max_size=3)),
    "x0": _maybe(st.lists(st.floats(-1e-2, 1e-2), min_size=1, max_size=3)),
    "v0": _maybe(st.lists(st.floats(-1.0, 1.0), min_size=1, max_size=3)),
    "energy_tolerance": _maybe(st.floats(-1.0, 1.0)),
    "kernel": _maybe(st.sampled_from([None, "auto", "generic"])),
    "max_steps": _maybe(st.integers(-5, 2000)),
}


@st.composite
def simulate_kwargs(draw):
    keys = draw(st.lists(st.sampled_from(sorted(SIM_KWARGS)), max_size=5, unique=True))
    return {k: draw(SIM_KWARGS[k]) for k in keys}


@settings(PROPERTY, max_examples=200 * SCALE)
@given(t_end=_maybe(st.one_of(st.floats(1e-9, 0.05), st.sampled_from([1e7, 1e300, 5e-324]))),
       kwargs=simulate_kwargs())
def test_simulate_arguments_give_a_result_or_an_error_naming_them(yoshida, t_end, kwargs):
    kwargs.setdefault("max_steps", 2000)  # a bound per example: no run may take long
    tr = _checked_run(lambda: simulate(yoshida, RAMP, t_end, **kwargs), SIM_NAMES)
    if tr is not None:
        _check_trajectory(tr, t_end)


number = _maybe(st.one_of(st.floats(0.0, 1e3), st.floats(-1e3, 1e3),
                          st.floats(allow_nan=True, allow_infinity=True)), junk_share=0.15)
pair = st.one_of(st.tuples(number, number), st.lists(number, max_size=3), junk)
segments = st.one_of(st.lists(pair, max_size=4),
                     st.lists(st.tuples(st.floats(0.0, 0.05), st.floats(-100.0, 1000.0)),
                              max_size=4),
                     junk)


@st.composite
def speed_profiles(draw):
    """(constructor, arguments, names it may use in a message)."""
    kind = draw(st.sampled_from(["init", "ramp", "dwell", "constant"]))
    if kind == "init":
        kw = {"segments": draw(segments)}
        for name in ("initial_speed", "initial_angle"):
            if draw(st.booleans()):
                kw[name] = draw(number)
        return SpeedProfile, kw
    args = {"ramp": ("accel", "operating_speed"),
            "dwell": ("accel", "dwell_speed", "dwell_time", "dwell_accel", "operating_speed"),
            "constant": ("speed", "angle")}[kind]
    kw = {name: draw(number) for name in args if name in ("accel", "speed", "dwell_speed",
                                                          "dwell_time") or draw(st.booleans())}
    return getattr(SpeedProfile, kind), kw


PROFILE_NAMES = ["segments", "initial_speed", "initial_angle", "accel", "operating_speed",
                 "dwell_speed", "dwell_time", "dwell_accel", "speed", "angle"]


@settings(PROPERTY, max_examples=200 * SCALE)
@given(made=speed_profiles())
def test_speed_profiles_are_a_profile_or_an_error_naming_the_argument(yoshida, made):
    make, kw = made
    profile = _checked_run(lambda: make(**kw), PROFILE_NAMES, "profile")
    if profile is None:
        return
    assert profile.initial_speed >= 0 and abs(profile.initial_angle) <= ANGLE_LIMIT
    assert np.all(np.isfinite(profile.speed(profile.breakpoints)))
    tr = _checked_run(lambda: simulate(yoshida, profile, 0.02, output_dt=0.01, max_steps=2000),
                      ["max_steps", "t_end"])
    if tr is not None:
        _check_trajectory(tr, 0.02)


MOTOR_FIELDS = ("torque", "speed_gain", "target", "torque_limit", "initial_speed",
                "initial_angle", "no_load_speed", "power_limit")


@st.composite
def motor_drives(draw):
    kind = draw(st.sampled_from(["init", "constant_torque", "limited_power",
                                 "linear_characteristic"]))
    value = st.one_of(number, st.floats(0.0, 1e-2), st.just(None))
    if kind == "init":
        kw = {}
        for name in draw(st.lists(st.sampled_from(MOTOR_FIELDS), max_size=4, unique=True)):
            kw[name] = draw(st.one_of(value, st.just(RAMP)) if name == "target" else value)
        return MotorDrive, kw
    args = {"constant_torque": ("torque", "torque_limit"),
            "limited_power": ("gain", "target", "torque_limit"),
            "linear_characteristic": ("stall_torque", "no_load_speed", "power_limit",
                                      "initial_speed")}[kind]
    kw = {name: draw(value) for name in args}
    return getattr(MotorDrive, kind), kw


@settings(PROPERTY, max_examples=200 * SCALE)
@given(made=motor_drives())
def test_motor_drives_are_a_drive_or_an_error_naming_the_argument(yoshida, made):
    make, kw = made
    names = list(MOTOR_FIELDS) + ["gain", "stall_torque"]
    drive = _checked_run(lambda: make(**kw), names, "drive")
    if drive is None:
        return
    tr = _checked_run(lambda: simulate(yoshida, drive, 0.02, output_dt=0.01, max_steps=2000),
                      ["max_steps", "t_end"])
    if tr is not None:
        _check_trajectory(tr, 0.02)


def test_yaml_files_are_parsed_once_per_content_and_reread_when_changed(tmp_path, monkeypatch):
    """read_yaml parses a text once (an evaluation reads the same files per chunk), but every
    call reads and checks the file: a changed file gives its new content, a file turned bad
    gives the error, and what a caller changes in its copy does not reach the next caller."""
    from abb_gym import configuration
    from abb_gym.configuration import ConfigError, read_yaml
    calls = []
    real = configuration.strict_yaml_load
    monkeypatch.setattr(configuration, "strict_yaml_load",
                        lambda text: calls.append(text) or real(text))
    path = tmp_path / "x.yaml"
    path.write_text("a: {b: 1}\nunique: 7f3c\n")
    first = read_yaml(path, "test")
    first["a"]["b"] = 99
    second = read_yaml(path, "test")
    assert second["a"]["b"] == 1 and len(calls) == 1
    path.write_text("a: {b: 2}\nunique: 7f3c\n")   # same size: a new text all the same
    assert read_yaml(path, "test")["a"]["b"] == 2 and len(calls) == 2
    path.write_text("a: [1\n")
    with pytest.raises(ConfigError, match="is not valid YAML"):
        read_yaml(path, "test")
    path.unlink()
    with pytest.raises(ConfigError, match="does not exist"):
        read_yaml(path, "test")
