"""Integrators where they work and where they fail: accuracy against DOP853, the explicit step
limits set by the ball drag and by the rotor speed, and failure detection."""
import numpy as np
import pytest

from abb_gym import MotorDrive, SimulationError, SpeedProfile, load_scene, simulate
from abb_gym.physics import integrators as integ
from abb_gym.physics import model as mdl
from abb_gym.physics.steps import stiff_rate

RK4_REAL_LIMIT = 2.785  # |h lambda| on the negative real axis where RK4 stops being stable
DWELL = SpeedProfile.dwell(accel=40.0, dwell_speed=100.0, dwell_time=0.5)


def errors(tr, ref):
    """(relative peak-whirl error, largest ball-angle error [deg])."""
    return (abs(tr.whirl_ratio.max() / ref.whirl_ratio.max() - 1),
            float(np.degrees(np.abs(tr.ball_angles - ref.ball_angles).max())))


@pytest.fixture(scope="module")
def yoshida():
    return load_scene("yoshida_odd")


@pytest.fixture(scope="module")
def reference(yoshida):
    return simulate(yoshida, DWELL, 6.0, method="DOP853", rtol=1e-12, output_dt=0.01)


@pytest.mark.parametrize("method, kw, peak_tol, angle_tol", [
    ("rk4", {"dt": 2e-3}, 1e-3, 0.1),
    ("etdrk4", {"dt": 2e-3}, 1e-3, 0.1),
    ("dopri5", {"rtol": 1e-6}, 1e-6, 1e-3),
    ("ros2", {"dt": 2.5e-4}, 1e-2, 5.0),
    ("Radau", {"rtol": 1e-8}, 1e-6, 1e-3),
])
def test_every_integrator_converges_to_the_reference(yoshida, reference, method, kw,
                                                     peak_tol, angle_tol):
    """Tolerances are what each method delivers at the stated step/tolerance on the Yoshida
    run-up (second-order ros2 is far behind the fourth-order methods at equal step)."""
    tr = simulate(yoshida, DWELL, 6.0, method=method, output_dt=0.01, **kw)
    peak, angle = errors(tr, reference)
    assert peak < peak_tol and angle < angle_tol


@pytest.mark.parametrize("method", ["etdrk4", "ros2"])
def test_fixed_step_methods_converge_at_their_order(yoshida, method):
    kw = dict(ball_angles0=[0.3, -0.4], output_dt=0.05)
    ref = simulate(yoshida, DWELL, 3.5, method="DOP853", rtol=1e-12, **kw)
    errs = [np.max(np.abs(simulate(yoshida, DWELL, 3.5, method=method, dt=h, **kw).states
                          - ref.states) / np.abs(ref.states).max(0))
            for h in (1e-3, 5e-4, 2.5e-4)]
    order = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    expected = {"etdrk4": 4, "ros2": 2}[method]
    assert np.all(np.abs(order - expected) < 0.6), (errs, order)


def test_etd_coefficients_are_continuous_and_reduce_to_rk4():
    for z in (0.0, -1e-8):
        e2, e, q, f1, f2, f3 = integ.etd_coefficients(z)
        assert q == pytest.approx(0.5)
        assert f1 == pytest.approx(1 / 6) and f2 == pytest.approx(1 / 6)
        assert f3 == pytest.approx(1 / 6)
    below, above = integ.etd_coefficients(-0.2 + 1e-12), integ.etd_coefficients(-0.2 - 1e-12)
    np.testing.assert_allclose(below, above, rtol=1e-10)
    below, above = integ.etd_coefficients(0.2 - 1e-12), integ.etd_coefficients(0.2 + 1e-12)
    np.testing.assert_allclose(below, above, rtol=1e-10)


def test_lu_solver_matches_numpy():
    rng = np.random.default_rng(0)
    for n in (3, 7, 12):
        a = rng.normal(size=(n, n))
        x = rng.normal(size=n)
        lu, piv = a.copy(), np.empty(n, dtype=np.int64)
        integ._lu_factor(lu, piv)
        y = x.copy()
        integ._lu_solve(lu, piv, y)
        np.testing.assert_allclose(y, np.linalg.solve(a, x), rtol=1e-10)


def test_drag_sets_the_rk4_step_limit_where_predicted():
    """Yoshida's heavier drag (c_b = 4 N s/m) with a 0.5 g ball: rate = c_b/(1.4 m) plus the
    rolling slope.  RK4 runs at 0.85x the predicted limit 2.785/rate and fails at 1.15x;
    the exponential and Rosenbrock methods run at 8x the limit."""
    scene = load_scene("yoshida_odd", ball_drag=4.0, ball_mass=0.5e-3)
    limit = RK4_REAL_LIMIT / stiff_rate(scene, 240.0)
    ok = simulate(scene, DWELL, 6.0, dt=0.85 * limit, output_dt=0.01)
    assert np.all(np.isfinite(ok.states))
    with pytest.raises(SimulationError, match="non-finite"):
        simulate(scene, DWELL, 6.0, dt=1.15 * limit, output_dt=0.01)
    ref = simulate(scene, DWELL, 6.0, method="Radau", rtol=1e-9, output_dt=0.01)
    etd = simulate(scene, DWELL, 6.0, method="etdrk4", dt=8 * limit, output_dt=0.01)
    peak, angle = errors(etd, ref)
    assert peak < 5e-3 and angle < 0.1  # stable and still accurate at 8x the RK4 limit
    ros = simulate(scene, DWELL, 6.0, method="ros2", dt=8 * limit, output_dt=0.01)
    assert np.all(np.isfinite(ros.states))


def test_rotor_speed_sets_the_rk4_step_limit_through_rolling_resistance():
    """The smoothed rolling resistance adds a damping slope that grows with Omega^2.  At a
    fixed 2 ms step h * rate = 2.3 at 250 rad/s (inside RK4's limit) and 6.6 at 600 rad/s.
    Beyond the limit RK4 does not diverge: the slope only exists for |R ph'| < u*, so the ball
    speeds chatter in that band instead, and the ball-speed error jumps; ETDRK4, which
    integrates that slope exactly, keeps it 3x smaller.  (The default step stays inside.)"""
    scene = load_scene("yoshida_odd")
    h = 2e-3
    assert h * stiff_rate(scene, 250.0) < RK4_REAL_LIMIT < h * stiff_rate(scene, 600.0)
    speed_error = {}
    for omega in (250.0, 600.0):
        drive = SpeedProfile.constant(omega)
        ref = simulate(scene, drive, 1.0, method="Radau", rtol=1e-9, output_dt=h)
        for method in ("rk4", "etdrk4"):
            tr = simulate(scene, drive, 1.0, method=method, dt=h, output_dt=h)
            speed_error[method, omega] = np.abs(tr.ball_speeds - ref.ball_speeds).max() \
                / np.abs(ref.ball_speeds).max()
    assert speed_error["rk4", 250.0] < 0.03
    assert speed_error["rk4", 600.0] > 0.25
    assert speed_error["etdrk4", 600.0] < speed_error["rk4", 600.0] / 3


def test_energy_growth_in_an_undamped_run_is_detected():
    """Undamped, free rotor: DOPRI5 at a loose tolerance (rtol = 1e-2) returns a finite but
    wrong solution that gains energy (about 170 % over 20 s); simulate raises instead.  At
    rtol = 1e-6 the same run passes."""
    scene = load_scene("yoshida_odd", support_damping=0.0, ball_drag=0.0,
                       ball_rolling_resistance=0.0, bearing_drag=0.0)
    drive = MotorDrive(torque=0.0, initial_speed=150.0)
    kw = dict(ball_speeds0=[3.0, -2.0], x0=(1e-3, 0.0), output_dt=0.05, method="dopri5")
    simulate(scene, drive, 20.0, rtol=1e-6, **kw)
    with pytest.raises(SimulationError, match="gained") as info:
        simulate(scene, drive, 20.0, rtol=1e-2, **kw)
    assert info.value.variable == "energy" and 0 < info.value.time <= 20.0


def test_long_undamped_energy_drift_is_small_for_the_fourth_order_methods():
    scene = load_scene("yoshida_odd", support_damping=0.0, ball_drag=0.0,
                       ball_rolling_resistance=0.0, bearing_drag=0.0)
    p, b = mdl.pack_parameters(scene)
    drive = MotorDrive(torque=0.0, initial_speed=150.0)
    kw = dict(ball_speeds0=[3.0, -2.0], x0=(1e-3, 0.0), output_dt=0.1)
    for method in ("rk4", "etdrk4", "dopri5"):
        tr = simulate(scene, drive, 20.0, method=method, dt=1e-3, rtol=1e-8, **kw)
        e = np.array([mdl.total_energy(s, p, b) for s in tr.states])
        assert np.max(np.abs(e - e[0])) / e[0] < 1e-4, method


def test_adaptive_step_respects_breakpoints_and_outputs(yoshida):
    tr = simulate(yoshida, DWELL, 4.0, method="dopri5", rtol=1e-9, output_dt=0.5)
    np.testing.assert_allclose(tr.rotor_speed, DWELL.speed(tr.t), rtol=1e-13)
    ref = simulate(yoshida, DWELL, 4.0, method="DOP853", rtol=1e-12, output_dt=0.5)
    np.testing.assert_allclose(tr.states, ref.states, rtol=1e-6,
                               atol=1e-7 * np.abs(ref.states).max())
