"""The batched RK4 (:mod:`abb_gym.physics.batch`) is the production RK4, bit for bit."""
from __future__ import annotations

import numpy as np
import pytest

import abb_gym
from abb_gym.physics import batch, drive_law as dl, model as mdl
from abb_gym.physics import integrators as integ
from abb_gym.physics.integrators import rk4_run
from abb_gym.physics.simulate import default_step, initial_state


@pytest.mark.parametrize("scene_name", ["yoshida_odd", "lu_hung_odd3", "spannan_discoidal"])
def test_run_batch_equals_rk4_run(scene_name):
    base = abb_gym.load_scene(scene_name)
    w = base.drive_operating_speed
    a = base.drive_max_acceleration
    crit = base.critical_speed
    cases = [
        (base, abb_gym.SpeedProfile.dwell(a / 2, crit, 0.3, 0.0, w)),
        (base.replace(ball_drag=[1.3 * v for v in base.ball_drag]),
         abb_gym.SpeedProfile.ramp(a, w)),
        (base.replace(rotor_eccentricity=2 * base.rotor_eccentricity),
         abb_gym.MotorDrive.constant_torque(0.5 * base.drive_torque_limit)),
        (base, abb_gym.MotorDrive.limited_power(1e-3, abb_gym.SpeedProfile.ramp(a / 2, w))),
    ]
    t_end = 1.2 * crit / (a / 2)
    t_out = np.linspace(0.0, t_end, 61)
    h = default_step(base, w)
    n = len(cases)
    nb = base.ball_count
    ns = 2 * (3 + nb)
    s0 = np.zeros((n, ns))
    seg_d = np.zeros((n, 5, dl.N_DRIVE))
    nseg = np.zeros(n, dtype=np.int64)
    p = np.zeros((n, mdl.N_PARAMS))
    b = np.zeros((n, nb, mdl.N_BALL_PARAMS))
    refs = []
    for i, (sc, drive) in enumerate(cases):
        s0[i] = initial_state(sc, drive, ball_angles0=np.linspace(0.2, 2.0, nb) * (i + 1))
        seg_t, rows = drive.segment_table(t_end, sc)
        seg_d[i, :len(rows)] = rows
        nseg[i] = len(rows)
        p[i], b[i] = mdl.pack_parameters(sc)
        out = np.empty((len(t_out), ns))
        status = rk4_run(s0[i], t_out, seg_t, rows, p[i], b[i], h, out)
        refs.append((out, status))
    out = np.empty((n, len(t_out), ns))
    status = np.zeros((n, 4))
    ws, work = batch.make_workspace(n, nb)
    batch.run_batch(s0, t_out, seg_d, nseg, p, b, h, out, status, ws, work)
    for i, (ref, st) in enumerate(refs):
        assert status[i, 0] == st[0] == 0
        assert status[i, 3] == st[3]
        assert np.array_equal(out[i], ref), f"case {i} differs"


def test_advance_reports_nonfinite_and_whirl():
    sc = abb_gym.load_scene("yoshida_odd")
    drive = abb_gym.SpeedProfile.ramp(40.0, 240.0)
    s = initial_state(sc, drive)
    _, rows = drive.segment_table(10.0)
    p, b = mdl.pack_parameters(sc)
    ws, work = batch.make_workspace(1, 2)
    whirl = np.zeros(5)  # integral, max, rest position (0, 0), max from rest
    st, j, t_fail, bad, steps = batch.advance(s, 0.0, 2.6, rows, len(rows), 0, p, b, 1e-3,
                                              ws[0], work[0], whirl, integ.METHOD_RK4)
    assert st == 0 and steps == 2600 and whirl[1] > 0 and 0 < whirl[0] < 2.6 * whirl[1]
    assert whirl[4] == whirl[1]  # no gravity: the rest position is the bearing axis
    s[4] = np.nan
    st, *_ = batch.advance(s, 2.6, 2.7, rows, len(rows), j, p, b, 1e-3, ws[0], work[0], whirl,
                           integ.METHOD_RK4)
    assert st == 1
