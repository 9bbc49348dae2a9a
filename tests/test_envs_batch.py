"""The batched RK4 (:mod:`abb_gym.physics.batch`) is the production RK4, bit for bit."""
from __future__ import annotations

import numpy as np
import pytest

import abb_gym
from abb_gym.physics import batch, drive_law as dl, model as mdl
from abb_gym.physics import integrators as integ
from abb_gym.physics.integrators import rk4_run
from abb_gym.physics.simulate import initial_state
from abb_gym.physics.steps import default_step


def drive_cases(base):
    """Four (scene, drive) cases around ``base``: a dwell and a ramp (prescribed rotor, the
    second with more ball drag), constant torque (twice the eccentricity) and limited power."""
    w = base.drive_operating_speed
    a = base.drive_max_acceleration
    crit = base.critical_speed
    return [
        (base, abb_gym.SpeedProfile.dwell(a / 2, crit, 0.3, 0.0, w)),
        (base.replace(ball_drag=[1.3 * v for v in base.ball_drag]),
         abb_gym.SpeedProfile.ramp(a, w)),
        (base.replace(rotor_eccentricity=2 * base.rotor_eccentricity),
         abb_gym.MotorDrive.constant_torque(0.5 * base.drive_torque_limit)),
        (base, abb_gym.MotorDrive.limited_power(1e-3, abb_gym.SpeedProfile.ramp(a / 2, w))),
    ]


def rk4_references(cases, t_end, t_out, h):
    """The batch inputs for ``cases`` [(scene, drive)] of one ball count, each with its own
    ball start, and each case's single-run RK4 answer [(out, status)] at ``t_out``, step ``h``."""
    n, nb = len(cases), cases[0][0].ball_count
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
    return s0, seg_d, nseg, p, b, refs


@pytest.mark.parametrize("scene_name, kernel", [
    ("yoshida_odd", "generic"), ("lu_hung_odd3", "generic"), ("spannan_discoidal", "generic"),
    # one vectorised case: each specialisation compiles for about a minute
    ("yoshida_odd", "specialised")])
def test_run_batch_equals_rk4_run(scene_name, kernel):
    base = abb_gym.load_scene(scene_name)
    cases = drive_cases(base)
    if kernel == "specialised":
        cases = cases[:2]  # the prescribed-rotor group only: one specialisation to compile
    t_end = 1.2 * base.critical_speed / (base.drive_max_acceleration / 2)
    t_out = np.linspace(0.0, t_end, 61)
    h = default_step(base, base.drive_operating_speed)
    n = len(cases)
    s0, seg_d, nseg, p, b, refs = rk4_references(cases, t_end, t_out, h)
    out = np.empty((n,) + refs[0][0].shape)
    status = np.zeros((n, 4))
    batch.run_batch(s0, t_out, seg_d, nseg, p, b, h, out, status, kernel=kernel)
    for i, (ref, st) in enumerate(refs):
        assert status[i, 0] == st[0] == 0
        assert status[i, 3] == st[3]
        assert np.array_equal(out[i], ref), f"case {i} differs"


def test_advance_block_reports_nonfinite_and_whirl():
    sc = abb_gym.load_scene("yoshida_odd")
    drive = abb_gym.SpeedProfile.ramp(40.0, 240.0)
    _, rows = drive.segment_table(10.0)
    p, b = mdl.pack_parameters(sc)
    blocks = batch.Blocks(2, 2, lanes=2)
    s, pb, bb, d, k, tmp, lam, coef, work, f, g, act = (a[0] for a in blocks.arrays())
    for lane in range(2):
        s[:, lane] = initial_state(sc, drive)
        pb[:, lane] = p
        bb[:, :, lane] = b
    seg_d = np.stack([rows, rows])
    g[batch.G_ON] = 1
    g[batch.G_ROW] = [0, 1]
    g[batch.G_NSEG] = len(rows)
    f[batch.F_T1] = [2.6, 1.3]  # lanes with their own intervals and steps
    f[batch.F_HMAX] = [1e-3, 0.5e-3]
    spec = mdl.spec_of(p, rows)
    batch.advance_block(s, pb, bb, d, k, tmp, lam, coef, work, f, g, act, seg_d,
                        integ.METHOD_RK4, 2, spec)
    assert list(g[batch.G_STATUS]) == [0, 0] and list(g[batch.G_STEPS]) == [2600, 2600]
    assert f[batch.W_MAX, 0] > 0 and 0 < f[batch.W_INT, 0] < 2.6 * f[batch.W_MAX, 0]
    assert f[batch.W_DMAX, 0] == f[batch.W_MAX, 0]  # no gravity: the rest position is the axis
    ref = np.empty((2, len(s)))
    integ.run(integ.METHOD_RK4, initial_state(sc, drive), np.array([0.0, 1.3]), rows[:, 0].copy(),
              rows, p, b, 0.5e-3, 0.0, np.zeros(1), ref, 2, spec)
    assert np.array_equal(s[:, 1], ref[1])  # the lane that stopped early kept its state
    s[4, 0] = np.nan
    f[batch.F_T0] = f[batch.F_T1]
    f[batch.F_T1] += 0.1
    batch.advance_block(s, pb, bb, d, k, tmp, lam, coef, work, f, g, act, seg_d,
                        integ.METHOD_RK4, 2, spec)
    assert list(g[batch.G_STATUS]) == [integ.STATUS_NONFINITE, 0]
    assert g[batch.G_BAD, 0] >= 0 and abs(f[batch.F_TFAIL, 0] - 2.6 - 1e-3) < 1e-12


@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_run_batch_does_not_depend_on_the_block_size(precision):
    """A run's states are the same bits in blocks of ``batch.MAX_LANES`` lanes (the default
    here), half that and 8 lanes: the lane count per block is a speed setting, not part of the
    arithmetic.  300 runs
    with their own ball drag and start (so their steps differ and the last block is part
    full), in the order of the step size and in a shuffled order."""
    base = abb_gym.load_scene("yoshida_odd")
    rng = np.random.default_rng(3)
    scales = rng.uniform(0.5, 2.0, 300)
    scenes = [base.replace(ball_drag=[k * v for v in base.ball_drag],
                           ball_angles0=list(rng.uniform(-3.0, 3.0, base.ball_count)))
              for k in scales]
    drive = abb_gym.SpeedProfile.ramp(base.drive_max_acceleration, base.drive_operating_speed)
    t_out = np.linspace(0.0, 1.5, 7)
    s0, seg_d, nseg, p, b, h = batch.run_inputs(scenes, drive, t_out[-1],
                                                base.drive_operating_speed)
    assert np.unique(h).size > 10  # the runs take different steps
    full = batch.MAX_LANES
    assert batch.lanes_per_block(len(scenes)) == full
    results = []
    for lanes, order in [(full, None), (full // 2, None), (8, None),
                         (full, rng.permutation(300))]:
        out = np.empty((len(scenes), len(t_out), s0.shape[1]))
        status = np.zeros((len(scenes), 4))
        batch.run_batch(s0, t_out, seg_d, nseg, p, b, h, out, status, order=order,
                        lanes=lanes, kernel="specialised", precision=precision)
        assert np.all(status[:, 0] == 0) and np.all(np.isfinite(out))
        results.append(out)
    for out in results[1:]:
        assert np.array_equal(out, results[0])


@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_block_arrays_start_apart_modulo_4096(precision):
    # rows of whole kilobytes and arrays at one address modulo 4096 made the right-hand
    # side's loads wait on its stores (4K aliasing: batch.staggered_zeros)
    blocks = batch.Blocks(1024, 2, precision=precision)
    arrays = blocks.arrays()
    starts = [a.ctypes.data % 4096 for a in arrays]
    for i in range(len(starts)):
        for j in range(i + 1, len(starts)):
            gap = (starts[i] - starts[j]) % 4096
            assert 64 <= gap <= 4096 - 64, (i, j, starts)
    dtype = np.dtype(precision)
    assert [a.dtype for a in arrays[:9]] == [dtype] * 9
    assert (arrays[9].dtype, arrays[10].dtype, arrays[11].dtype) == (np.float64, np.int64,
                                                                     np.uint8)
    assert all(a.flags.c_contiguous and a.shape[0] == 1024 // blocks.lanes and not a.any()
               for a in arrays)
    assert blocks.s.shape == (1024 // blocks.lanes, 10, blocks.lanes)


def test_staggered_zeros_places_the_start_and_keeps_the_shape():
    for slot in range(12):
        a = batch.staggered_zeros((3, 5, 7), np.float32, slot)
        assert a.shape == (3, 5, 7) and a.dtype == np.float32 and a.flags.c_contiguous
        assert a.ctypes.data % 4096 == (slot * batch.STAGGER) % 4096
        assert not a.any()


def _check_lane_order(step_sizes, lanes, parts):
    order = batch.lane_order(step_sizes, lanes, parts)
    n = len(step_sizes)
    assert order.dtype == np.int64 and np.array_equal(np.sort(order), np.arange(n))
    n_blocks = -(-n // lanes)
    runs = max(1, min(parts, n_blocks))
    edges = [min(k * n_blocks // runs * lanes, n) for k in range(runs)] + [n]
    for lo, hi in zip(edges[:-1], edges[1:]):
        # each thread's run of blocks holds its own contiguous rows, stably sorted by step
        assert np.array_equal(np.sort(order[lo:hi]), np.arange(lo, hi))
        expected = lo + np.argsort(np.asarray(step_sizes)[lo:hi], kind="stable")
        assert np.array_equal(order[lo:hi], expected)
    return order


def test_lane_order_sorts_each_threads_run_of_blocks():
    # the vector environment at 1024 on two threads: 8 blocks of 128, two runs of four
    rng = np.random.default_rng(5)
    h = rng.uniform(1.0e-3, 1.67e-3, 1024)
    whole = batch.lane_order(h)
    assert np.array_equal(whole, np.argsort(h, kind="stable"))
    order = _check_lane_order(h, 128, 2)
    substeps = np.ceil(0.01 / h[order] - 1e-9).reshape(8, 128).max(axis=1)
    by_run = substeps[:4].sum(), substeps[4:].sum()
    sorted_whole = np.ceil(0.01 / h[whole] - 1e-9).reshape(8, 128).max(axis=1)
    # the point of the runs: the two threads' work is closer than with one sort
    assert abs(by_run[0] - by_run[1]) < abs(sorted_whole[:4].sum() - sorted_whole[4:].sum())


def test_lane_order_property():
    from hypothesis import given, settings
    from hypothesis import strategies as st

    @settings(max_examples=200, deadline=None)
    @given(st.lists(st.sampled_from([1e-3, 1.1e-3, 1.25e-3, 2e-3]), min_size=1, max_size=300),
           st.integers(1, 130), st.integers(1, 9))
    def check(step_sizes, lanes, parts):
        _check_lane_order(step_sizes, lanes, parts)

    check()


def test_vector_env_sorts_per_thread_and_keeps_its_results():
    # two threads: each run of blocks sorts its own rows; one thread: one sort.  The order only
    # decides which lanes share a block, so the steps give the same bits either way.
    numba = pytest.importorskip("numba")
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs two numba threads")
    import gymnasium as gym
    from abb_gym.envs.layout import S_DTMAX

    def run(threads):
        before = numba.get_num_threads()
        numba.set_num_threads(threads)
        try:
            env = gym.make_vec("abb_gym/RunUpSpeed-v0", num_envs=300,
                               vectorization_mode="vector_entry_point", scene="yoshida_odd",
                               preset="train", control_interval=0.01)
            env.reset(seed=11)
            bufs = env.unwrapped._bufs
            h = bufs.st[:, S_DTMAX].copy()
            order = bufs.order.copy()
            rng = np.random.default_rng(2)
            outs = [env.step(rng.uniform(-1, 1, (300, 1)).astype(np.float32))[:2]
                    for _ in range(15)]
            env.close()
            return h, order, bufs.blocks.lanes, outs
        finally:
            numba.set_num_threads(before)

    h1, order1, lanes, outs1 = run(1)
    h2, order2, lanes2, outs2 = run(2)
    assert lanes == lanes2 and np.array_equal(h1, h2)
    assert np.array_equal(order1, np.argsort(h1, kind="stable"))
    assert -(-300 // lanes) >= 2  # two runs of blocks, or the test would show nothing
    _check_lane_order(h2, lanes, 2)
    assert not np.array_equal(order1, order2)
    for (obs1, rew1), (obs2, rew2) in zip(outs1, outs2):
        assert np.array_equal(obs1, obs2) and np.array_equal(rew1, rew2)
