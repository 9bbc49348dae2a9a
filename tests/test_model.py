"""The equations of motion against independent derivations.

* The mass matrix and the full equations of motion are compared with a Lagrangian built from the
  kinematics alone (positions of the rotor mass centre and the balls, Spannan eq. 4.9, plus the
  spins), differentiated numerically.  That shares no formula with the kernel.
* Yoshida's equations (2-9)-(2-11) are written out literally and must agree with the kernel.
* Energy is conserved without damping when the rotor spins freely.
"""
import numpy as np
import pytest

import abb_gym
from abb_gym.benchmarks.numpy_reference import yoshida_accelerations
from abb_gym.physics import drive_law as dl
from abb_gym.physics import model as mdl
from abb_gym.physics.drives import MotorDrive, SpeedProfile
from abb_gym.physics.scene import load_scene
from abb_gym.physics.simulate import initial_state, simulate
from abb_gym.physics.steps import default_step


def random_scene(rng, n_balls, eccentric=True, orthotropic=True):
    base = load_scene("yoshida_odd")
    return base.replace(
        ball_count=n_balls,
        ball_mass=list(rng.uniform(0.5e-3, 3e-3, n_balls)),
        ball_radius=list(rng.uniform(0.5e-3, 2e-3, n_balls)),
        ball_inertia_factor=list(rng.uniform(0.0, 0.5, n_balls)),
        ball_drag=list(rng.uniform(0.1, 2.0, n_balls)),
        ball_rolling_resistance=0.0,
        ball_angles0=list(rng.uniform(-3, 3, n_balls)),
        race_eccentricity=rng.uniform(1e-4, 1e-3) if eccentric else 0.0,
        race_eccentricity_angle=rng.uniform(-3, 3),
        support_stiffness_x=1000.0,
        support_stiffness_y=1500.0 if orthotropic else 1000.0,
        support_damping_x=0.2,
        support_damping_y=0.35 if orthotropic else 0.2,
        bearing_drag=1e-6,
    )


class Kinematics:
    """Point masses and spins of the model, from positions only (no kernel formulas)."""

    def __init__(self, scene):
        self.s = scene
        a = scene.arrays()
        self.m = a["ball_mass"]
        self.r = a["ball_radius"]
        self.j = a["ball_inertia_factor"] * self.m * self.r ** 2
        self.n = scene.ball_count
        # rotor as a rigid body: mass centre offset e along the rotor angle, polar inertia J
        self.mr = scene.rotor_mass
        self.e = scene.rotor_eccentricity
        self.jc = scene.rotor_polar_inertia - self.mr * self.e ** 2

    def positions(self, q):
        x, y, th = q[0], q[1], q[2]
        big_r, big_e, gam = self.s.race_radius, self.s.race_eccentricity, \
            self.s.race_eccentricity_angle
        pts = [np.array([x + self.e * np.cos(th), y + self.e * np.sin(th)])]
        for i in range(self.n):
            ph = q[3 + i]
            pts.append(np.array([x + big_e * np.cos(th + gam) + big_r * np.cos(th + ph),
                                 y + big_e * np.sin(th + gam) + big_r * np.sin(th + ph)]))
        return pts

    def masses(self):
        return [self.mr] + list(self.m)

    def spin_rows(self):
        """(inertia, row of d(spin)/dq') for the rotor and each ball (kappa = th - R/r ph)."""
        nq = 3 + self.n
        rows = []
        row = np.zeros(nq)
        row[2] = 1.0
        rows.append((self.jc, row))
        for i in range(self.n):
            row = np.zeros(nq)
            row[2] = 1.0
            row[3 + i] = -self.s.race_radius / self.r[i]
            rows.append((self.j[i], row))
        return rows

    def jacobians(self, q, h=1e-6):
        nq = len(q)
        jacs = [np.zeros((2, nq)) for _ in self.masses()]
        for k in range(nq):
            dq = np.zeros(nq)
            dq[k] = h
            plus, minus = self.positions(q + dq), self.positions(q - dq)
            for jac, p, m in zip(jacs, plus, minus):
                jac[:, k] = (p - m) / (2 * h)
        return jacs

    def mass_matrix(self, q):
        mm = sum(m * jac.T @ jac for m, jac in zip(self.masses(), self.jacobians(q)))
        for inertia, row in self.spin_rows():
            mm = mm + inertia * np.outer(row, row)
        return mm

    def convective(self, q, v):
        """sum_k m_k J_k^T (d^2 p_k / dt^2 at q'' = 0), by central differences along v."""
        h = 1e-3 / np.abs(v).max()  # every angle moves 1 mrad at most: truncation ~1e-7
        plus, mid, minus = self.positions(q + h * v), self.positions(q), self.positions(q - h * v)
        acc = [(p - 2 * c + m) / h ** 2 for p, c, m in zip(plus, mid, minus)]
        return sum(m * jac.T @ a for m, jac, a in zip(self.masses(), self.jacobians(q), acc))


def random_state(rng, scene):
    nq = 3 + scene.ball_count
    q = np.concatenate([rng.uniform(-2e-3, 2e-3, 2), rng.uniform(-np.pi, np.pi, nq - 2)])
    v = np.concatenate([rng.uniform(-0.3, 0.3, 2), [rng.uniform(20, 150)],
                        rng.uniform(-20, 20, nq - 3)])
    return q, v


@pytest.mark.parametrize("n_balls", [1, 2, 3, 5])
def test_mass_matrix_symmetric_positive_definite_and_matches_kinematics(n_balls):
    rng = np.random.default_rng(n_balls)
    for _ in range(20):
        scene = random_scene(rng, n_balls)
        p, b = mdl.pack_parameters(scene)
        q, _ = random_state(rng, scene)
        mm = mdl.mass_matrix(q, p, b)
        assert np.array_equal(mm, mm.T)
        assert np.linalg.eigvalsh(mm).min() > 0
        # the equations read I_i and 1 / I_i from the packed columns (model.ball_inertias)
        assert np.array_equal(np.diag(mm)[3:], b[:, mdl.B_II])
        assert np.array_equal(b[:, mdl.B_INV], 1.0 / b[:, mdl.B_II])
        ref = Kinematics(scene).mass_matrix(q)
        np.testing.assert_allclose(mm, ref, rtol=1e-7, atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("n_balls,eccentric,orthotropic", [(1, True, True), (2, False, False),
                                                           (3, True, False), (4, True, True)])
def test_accelerations_match_lagrange_equations_from_kinematics(n_balls, eccentric, orthotropic):
    """M(q) q'' + conv(q, q') = Q - dV/dq, with M and conv derived from positions only."""
    rng = np.random.default_rng(10 + n_balls)
    for _ in range(10):
        scene = random_scene(rng, n_balls, eccentric, orthotropic)
        p, b = mdl.pack_parameters(scene)
        q, v = random_state(rng, scene)
        kin = Kinematics(scene)
        torque = 1e-3
        beta = scene.arrays()["ball_drag"] * scene.race_radius ** 2
        gen_force = np.concatenate([
            [-scene.support_damping_x * v[0] - scene.support_stiffness_x * q[0],
             -scene.support_damping_y * v[1] - scene.support_stiffness_y * q[1],
             torque - scene.bearing_drag * v[2]],
            -beta * v[3:]])
        ref = np.linalg.solve(kin.mass_matrix(q), gen_force - kin.convective(q, v))
        d = np.zeros(dl.N_DRIVE)
        d[dl.D_MODE] = dl.MODE_MOTOR
        d[dl.D_TORQUE] = torque
        d[dl.D_TLIM] = 1.0
        qdd = np.empty(len(q))
        mdl.accelerations(0.0, np.concatenate([q, v]), p, b, d, qdd, mdl.make_work(n_balls))
        np.testing.assert_allclose(qdd, ref, rtol=2e-5, atol=2e-6 * np.abs(ref).max())


def test_yoshida_equations_are_a_special_case():
    # a tiny regularisation speed turns tanh back into Yoshida's sign() for these ball speeds
    scene = load_scene("yoshida_odd", rolling_regularization_speed=1e-9,
                       ball_rolling_resistance=2e-5)
    p, b = mdl.pack_parameters(scene)
    rng = np.random.default_rng(3)
    for _ in range(50):
        q = np.concatenate([rng.uniform(-5e-3, 5e-3, 2), [0.0], rng.uniform(-7, 7, 2)])
        v = np.concatenate([rng.uniform(-0.5, 0.5, 2), [0.0],
                            rng.choice([-1, 1], 2) * rng.uniform(0.5, 30, 2)])
        psi, dpsi, ddpsi = rng.uniform(0, 50), rng.uniform(0, 250), rng.uniform(-40, 40)
        d = np.zeros(dl.N_DRIVE)
        d[dl.D_TH0], d[dl.D_W0], d[dl.D_ALPHA] = psi, dpsi, ddpsi
        qdd = np.empty(5)
        mdl.accelerations(0.0, np.concatenate([q, v]), p, b, d, qdd, mdl.make_work(2))
        ref = yoshida_accelerations(scene, q, v, psi, dpsi, ddpsi)
        np.testing.assert_allclose(qdd, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())


def test_energy_conserved_without_damping_free_rotor():
    """Free-spinning rotor, no damping, no drive: the total energy is a constant of motion."""
    rng = np.random.default_rng(7)
    scene = random_scene(rng, 3).replace(
        support_damping_x=0.0, support_damping_y=0.0, ball_drag=0.0, bearing_drag=0.0)
    p, b = mdl.pack_parameters(scene)
    drive = MotorDrive(torque=0.0, initial_speed=80.0)
    kwargs = dict(ball_angles0=[0.3, 2.0, -1.0], ball_speeds0=[5.0, -3.0, 1.0],
                  x0=(1e-3, -5e-4), v0=(0.02, 0.0), output_dt=0.01)
    ref = simulate(scene, drive, 1.0, method="DOP853", rtol=1e-12, **kwargs)
    energy = np.array([mdl.total_energy(s, p, b) for s in ref.states])
    assert np.ptp(energy) / energy[0] < 1e-9
    # the fixed-step path drifts less as the step shrinks (fourth order: about 16x per halving)
    drift = []
    for dt in (2e-3, 1e-3, 5e-4):
        tr = simulate(scene, drive, 1.0, dt=dt, **kwargs)
        e = np.array([mdl.total_energy(s, p, b) for s in tr.states])
        drift.append(np.max(np.abs(e - e[0])) / e[0])
    assert drift[0] < 1e-3
    assert drift[1] < drift[0] / 8 and drift[2] < drift[1] / 8


def test_prescribed_and_motor_paths_agree_when_the_motor_follows_the_profile():
    """A fast speed loop (time constant J/gain = 0.1 ms) holding a constant speed reproduces
    the prescribed-speed run: the two drive paths share the ball and rotor equations."""
    scene = load_scene("yoshida_odd")
    w = 150.0
    gain = scene.rotor_polar_inertia / 1e-4
    pres = simulate(scene, SpeedProfile.constant(w), 0.5, output_dt=0.01)
    motor = simulate(scene, MotorDrive(speed_gain=gain, target=w, torque_limit=1.0,
                                       initial_speed=w), 0.5, output_dt=0.01, dt=2e-5)
    assert np.max(np.abs(motor.rotor_speed - w)) < 1e-3
    assert np.max(np.abs(motor.motor_torque)) < 1.0  # never saturated
    np.testing.assert_allclose(motor.whirl_radius, pres.whirl_radius, rtol=0,
                               atol=2e-3 * pres.whirl_radius.max())
    np.testing.assert_allclose(motor.ball_angles, pres.ball_angles, atol=1e-3)


# --------------------------------------------------------------------------- extended physics
def test_virtual_mass_adds_to_the_relative_inertia_only():
    """Eq. 5.23 with u_rel = R ph': kinetic energy c_vm rho V R^2 ph'^2 / 2, i.e. the
    kinematic mass matrix plus that term on the ball diagonal and nothing else."""
    rng = np.random.default_rng(21)
    for n_balls in (1, 3):
        scene = random_scene(rng, n_balls).replace(fluid_preset="S50", fluid_virtual_mass=2.0)
        p, b = mdl.pack_parameters(scene)
        q, _ = random_state(rng, scene)
        added = 2.0 * 960.0 * 4 / 3 * np.pi * np.array(scene.ball_radius) ** 3 \
            * scene.race_radius ** 2
        ref = Kinematics(scene).mass_matrix(q)
        ref[3:, 3:] += np.diag(added)
        mm = mdl.mass_matrix(q, p, b)
        assert np.array_equal(mm, mm.T)
        np.testing.assert_allclose(mm, ref, rtol=1e-7, atol=1e-12 * np.abs(ref).max())


def test_gravity_matches_lagrange_equations_from_kinematics():
    """Gravity as the generalised force sum_k m_k J_k^T g of the kinematic positions, on top of
    the support, drive and drag forces (tilted g, eccentric race, virtual mass, motor)."""
    rng = np.random.default_rng(33)
    for n_balls in (1, 2, 4):
        scene = random_scene(rng, n_balls).replace(
            gravity_acceleration=9.81, gravity_angle=rng.uniform(-3, 3), fluid_preset="S20",
            fluid_virtual_mass=1.5)
        p, b = mdl.pack_parameters(scene)
        kin = Kinematics(scene)
        g = 9.81 * np.array([np.cos(scene.gravity_angle), np.sin(scene.gravity_angle)])
        added = 1.5 * 955.0 * 4 / 3 * np.pi * np.array(scene.ball_radius) ** 3 \
            * scene.race_radius ** 2
        for _ in range(5):
            q, v = random_state(rng, scene)
            torque = 1e-3
            beta = scene.arrays()["ball_drag"] * scene.race_radius ** 2
            gen_force = np.concatenate([
                [-scene.support_damping_x * v[0] - scene.support_stiffness_x * q[0],
                 -scene.support_damping_y * v[1] - scene.support_stiffness_y * q[1],
                 torque - scene.bearing_drag * v[2]], -beta * v[3:]])
            gen_force += sum(m * jac.T @ g for m, jac in zip(kin.masses(), kin.jacobians(q)))
            mm = kin.mass_matrix(q)
            mm[3:, 3:] += np.diag(added)
            ref = np.linalg.solve(mm, gen_force - kin.convective(q, v))
            d = np.zeros(dl.N_DRIVE)
            d[dl.D_MODE], d[dl.D_TORQUE], d[dl.D_TLIM] = dl.MODE_MOTOR, torque, 1.0
            qdd = np.empty(len(q))
            mdl.accelerations(0.0, np.concatenate([q, v]), p, b, d, qdd, mdl.make_work(n_balls))
            np.testing.assert_allclose(qdd, ref, rtol=2e-5, atol=2e-6 * np.abs(ref).max())
            # the potential the energy check uses is the one these forces derive from
            h = 1e-6
            for k in range(len(q)):
                dq = np.zeros(len(q))
                dq[k] = h
                dv = (mdl.gravity_energy(q + dq, p, b) - mdl.gravity_energy(q - dq, p, b)) / (2 * h)
                grav = sum(m * jac.T @ g for m, jac in zip(kin.masses(), kin.jacobians(q)))
                assert -dv == pytest.approx(grav[k], rel=1e-6, abs=1e-9)


def test_energy_conserved_with_virtual_mass_gravity_and_elastic_contact():
    """Free rotor, no damping anywhere, balls colliding through an undamped penalty, virtual
    mass on, horizontal axis: kinetic + spring + gravity + contact energy is constant."""
    scene = load_scene("yoshida_odd5", support_damping=0.0, bearing_drag=0.0, ball_drag=0.0,
                       ball_rolling_resistance=0.0, contact_damping_ratio=0.0,
                       gravity_acceleration=9.81, fluid_preset="S50", fluid_virtual_mass=2.0,
                       ball_angles0=[0.0, 0.5, 1.0, 1.5, 2.0], race_eccentricity=2e-4)
    p, b = mdl.pack_parameters(scene)
    drive = MotorDrive(torque=0.0, initial_speed=150.0)
    tr = simulate(scene, drive, 0.3, method="DOP853", rtol=1e-11, output_dt=1e-3,
                  ball_speeds0=[15.0, -15.0, 15.0, -15.0, 15.0], x0=(1e-4, -2e-4))
    energy = np.array([mdl.total_energy(s, p, b) for s in tr.states])
    assert np.ptp(energy) / energy[0] < 1e-8
    # the balls did collide, and the penalty energy they stored dwarfs the drift
    from abb_gym.physics.contact import contact_energy
    touch = [contact_energy(s[:8], b, mdl.B_RADIUS, scene.race_radius,
                            scene.contact_stiffness) for s in tr.states]
    assert max(touch) > 100 * np.ptp(energy)


def _run_case(name, motor):
    scene = load_scene(name)
    drive = (MotorDrive.limited_power(0.05, scene.drive_operating_speed) if motor
             else SpeedProfile.dwell(0.5 * scene.drive_max_acceleration, scene.critical_speed,
                                     0.3, 0.0, scene.drive_operating_speed))
    p, b = mdl.pack_parameters(scene)
    s0 = initial_state(scene, drive, np.linspace(0.3, 2.0, scene.ball_count))
    t_out = np.linspace(0.0, 1.0, 101)
    seg_t, seg_d = drive.segment_table(1.0, scene)
    h = default_step(scene, scene.drive_operating_speed)
    return scene, p, b, s0, t_out, seg_t, seg_d, h


ALL_BITS = (mdl.SPEC_EXT | mdl.SPEC_ECC | mdl.SPEC_ROLL | mdl.SPEC_CONTACT | mdl.SPEC_DRAG
            | mdl.SPEC_FRICTION | mdl.SPEC_GRAVITY)


@pytest.mark.parametrize("name", abb_gym.list_scenes())
@pytest.mark.parametrize("motor", [False, True])
def test_terms_of_effects_a_scene_lacks_are_exactly_zero(name, motor):
    """The kernel is compiled per effect set (``SPEC_*``), and a batch of scenes runs the union
    of their sets: every term of an effect a scene does not have must then add exactly zero.
    Forcing every effect bit on (and the motor envelope) must leave each shipped scene's
    trajectory and drag rates unchanged bit for bit."""
    from abb_gym.physics import integrators as integ
    scene, p, b, s0, t_out, seg_t, seg_d, h = _run_case(name, motor)
    spec = mdl.spec_of(p, seg_d)
    every = spec | ALL_BITS | (mdl.SPEC_ENVELOPE if motor else 0)
    runs, lams = [], []
    for bits in (spec, every):
        out = np.empty((t_out.size, s0.size))
        status = integ.run.generic(integ.METHOD_RK4, s0, t_out, seg_t, seg_d, p, b, h, 0.0,
                                   np.zeros(1), out, scene.ball_count, bits)
        assert status[0] == integ.STATUS_OK
        runs.append(out)
        lam = np.empty(s0.size)
        mdl.drag_rates(0.3, out[30], p, b, seg_d[0], lam, bits)
        lams.append(lam)
    assert np.array_equal(runs[0], runs[1])
    assert np.array_equal(lams[0], lams[1])


@pytest.mark.parametrize("name,motor", [("yoshida_odd", False), ("yoshida_odd5", True)])
def test_specialised_kernel_equals_the_general_one(name, motor):
    """A kernel compiled for one ball count and effect set (the vectorised one) does the same
    arithmetic as the general kernel: the same trajectory bit for bit (two effect sets: each
    specialisation takes a while to compile)."""
    from abb_gym.physics import integrators as integ
    scene, p, b, s0, t_out, seg_t, seg_d, h = _run_case(name, motor)
    spec = mdl.spec_of(p, seg_d)
    runs = []
    for call in (integ.run, integ.run.generic):
        out = np.empty((t_out.size, s0.size))
        status = call(integ.METHOD_RK4, s0, t_out, seg_t, seg_d, p, b, h, 0.0, np.zeros(1), out,
                      scene.ball_count, spec)
        assert status[0] == integ.STATUS_OK
        runs.append(out)
    assert np.array_equal(runs[0], runs[1])


def test_simulate_with_the_specialised_kernel_gives_the_same_trajectory():
    scene = load_scene("yoshida_odd")
    prof = SpeedProfile.dwell(40.0, scene.critical_speed, 0.3)
    general = simulate(scene, prof, 1.0, output_dt=0.01)
    special = simulate(scene, prof, 1.0, output_dt=0.01, kernel="specialised")
    assert np.array_equal(general.states, special.states)
    with pytest.raises(ValueError, match="kernel must be one of"):
        simulate(scene, prof, 1.0, kernel="fast")


def test_drive_classes_evaluate_the_kernel_drive_law():
    """SpeedProfile and MotorDrive evaluate speeds and torques with the kernel's own drive law
    (one implementation), and that law is the documented one."""
    prof = SpeedProfile.dwell(40.0, 100.0, 0.5, -10.0, 236.0)
    seg_t, rows = prof.segment_table(100.0)
    t = np.array([0.0, 1.0, 2.5, 2.7, 3.0, 9.0])
    th, w, alpha = dl.prescribed_profile(t, rows)
    assert np.array_equal(prof.speed(t), w) and np.array_equal(prof.angle(t), th)
    assert np.array_equal(prof.acceleration(t), alpha)
    assert prof.speed(2.7) == pytest.approx(100.0 - 10.0 * 0.2)
    scene = load_scene("yoshida_odd")
    motor = MotorDrive.linear_characteristic(1e-2, 300.0, power_limit=0.5)
    seg_t, rows = motor.segment_table(10.0, scene)
    speeds = np.array([0.0, 50.0, 100.0, 200.0, 320.0])
    times = np.zeros(5)
    # T = stall (1 - w / w_0), clipped to +-min(stall, P / |w|): it brakes above w_0
    limits = [min(1e-2, 0.5 / v if v else np.inf) for v in speeds]
    want = [np.clip(1e-2 / 300.0 * (300.0 - v), -e, e) for v, e in zip(speeds, limits)]
    assert np.allclose(motor.torque_at(times, speeds, scene), want, rtol=1e-12, atol=1e-15)
    assert np.array_equal(motor.torque_at(times, speeds, scene),
                          dl.motor_torques(times, speeds, rows))


def _lanes_case(name, motor, lanes=7):
    """Right-hand-side inputs of ``lanes`` lanes of states spread around the run's start."""
    scene, p, b, s0, t_out, seg_t, seg_d, h = _run_case(name, motor)
    rng = np.random.default_rng(3)
    s = s0[:, None] + rng.normal(0.0, 1.0, (s0.size, lanes)) * np.where(
        np.arange(s0.size) < s0.size // 2, 0.05, 2.0)[:, None]
    s[:2] = rng.normal(0.0, 1e-4, (2, lanes))  # rotor x, y [m]
    args = (np.linspace(0.0, 0.3, lanes), s, np.repeat(p[:, None], lanes, 1),
            np.repeat(b[:, :, None], lanes, 2), np.repeat(seg_d[0][:, None], lanes, 1))
    return args, scene.ball_count, mdl.spec_of(p, seg_d)


@pytest.fixture(scope="module")
def sums_in_one_loop():
    """The right-hand side compiled anew with :data:`~abb_gym.physics.model.SUMMED_BALLS` out
    of reach, so that one lane loop adds every ball to the rotor's sums (numba reads the
    global when it compiles: once here, for the argument types every case shares)."""
    from numba import njit
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(mdl, "SUMMED_BALLS", 10 ** 6)
        rhs = njit(error_model="numpy", noalias=True)(mdl.accelerations_block.py_func)
        args, nb, spec = _lanes_case("yoshida_odd5", True, lanes=1)
        rhs(*args, np.zeros_like(args[1]), mdl.make_work(nb, 1), nb, spec)
    return rhs


@pytest.mark.parametrize("name,motor", [("washer", True), ("washer", False),
                                        ("yoshida_odd5", True)])
def test_the_sums_ball_by_ball_are_the_sums_in_one_lane_loop(sums_in_one_loop, name, motor):
    """From :data:`~abb_gym.physics.model.SUMMED_BALLS` balls the split passes add each ball to
    the rotor's sums in a lane loop of its own (``_sum_pass``, which vectorises); below it one
    lane loop adds every ball.  Both add the same terms in the same order, so the derivatives
    agree bit for bit: the shipped right-hand side against one compiled with the threshold
    out of reach, on 7 lanes of states spread around the run's start (washer: contact, fluid
    drag, friction and gravity on)."""
    args, nb, spec = _lanes_case(name, motor)
    assert nb >= mdl.SUMMED_BALLS
    shipped = np.zeros_like(args[1])
    mdl.accelerations_block(*args, shipped, mdl.make_work(nb, 7), nb, spec)
    rows = np.zeros_like(args[1])
    sums_in_one_loop(*args, rows, mdl.make_work(nb, 7), nb, spec)
    assert len(sums_in_one_loop.signatures) == 1  # compiled once, with the threshold patched
    assert np.all(np.isfinite(shipped))
    assert np.array_equal(shipped, rows)
