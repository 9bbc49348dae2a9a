"""Ball-ball contact: the neighbour list of the kernels against every pair, bit for bit.

The right-hand side computes the contact of each ball with its two neighbours in index order
(:func:`abb_gym.physics.model._contacts`) where :func:`abb_gym.physics.contact.ring_holds`
says that index order is race order and that no other pair can touch, and every pair
otherwise.  Where the neighbour list is taken, the pairs it leaves out have no force, and each
ball's two terms are summed as the all-pairs loop sums them: the same bits."""
import math

import numpy as np
import pytest

from abb_gym._numba import njit
from abb_gym.physics import contact, load_scene
from abb_gym.physics import model as mdl


@njit
def _kernel_contacts(s, p, b, nb):
    """The kernel's contact pass: (forces, radial forces, ring flags) per ball and lane."""
    L = s.shape[1]
    nq = 3 + nb
    ds = np.zeros_like(s)
    work = np.zeros((nb, mdl.WORK_COLUMNS, L))
    mdl._contacts(s, p, b, ds, work, nb, nq, L)
    ring = np.zeros(L)
    for l in range(L):
        ring[l] = 1.0 if contact.ring_holds(s, l, nb, p[mdl.P_REACH, l]) else 0.0
    return ds[3:3 + nb].copy(), ds[nq + 3:nq + 3 + nb].copy(), ring


@njit
def _all_pairs(s, p, b, nb):
    L = s.shape[1]
    nq = 3 + nb
    out = np.zeros_like(s)
    for l in range(L):
        contact.ball_contacts_lane(s, l, nq, b, mdl.B_RADIUS, mdl.B_MEFF, p[mdl.P_R, l],
                                   p[mdl.P_KC, l], p[mdl.P_ZC, l], out, 3, nq + 3)
    return out[3:3 + nb].copy(), out[nq + 3:nq + 3 + nb].copy()


def _lanes(scene, angles, speeds):
    """A block of one lane per row of ``angles``/``speeds`` (ball angles [rad], speeds
    [rad/s])."""
    p1, b1 = mdl.pack_parameters(scene)
    n, nb = angles.shape
    s = np.zeros((2 * (3 + nb), n))
    s[3:3 + nb] = angles.T
    s[3 + 3 + nb:] = speeds.T
    return (s, np.repeat(p1[:, None], n, 1), np.repeat(b1[:, :, None], n, 2))


def _clustered(scene, rng, n_lanes, squeeze, widest=1.3):
    """Angles in race order, each gap the touching distance times a factor drawn from
    [1 - squeeze, widest] (overlaps up to ``squeeze`` of the reach), the cluster anywhere."""
    nb = scene.ball_count
    reach = 2.0 * math.asin(scene.ball_radius[0] / scene.race_radius)
    gaps = reach * rng.uniform(1.0 - squeeze, widest, (n_lanes, nb))
    angles = np.cumsum(gaps, axis=1) + rng.uniform(-20.0, 20.0, (n_lanes, 1))
    return angles, rng.normal(0.0, 5.0, (n_lanes, nb))


@pytest.mark.parametrize("name, count", [("yoshida_odd5", 5), ("washer", 12),
                                         ("yoshida_odd5", 4), ("washer", 8)])
def test_the_neighbour_list_gives_the_bits_of_every_pair(name, count):
    scene = load_scene(name)
    if count != scene.ball_count:
        scene = scene.replace(ball_count=count, ball_angles0=scene.ball_angles0[:count])
    rng = np.random.default_rng(count)
    angles, speeds = _clustered(scene, rng, 400, squeeze=0.3)
    s, p, b = _lanes(scene, angles, speeds)
    q, n, ring = _kernel_contacts(s, p, b, count)
    q_all, n_all = _all_pairs(s, p, b, count)
    assert ring.all()  # every lane took the neighbour list
    assert np.count_nonzero(q_all) > 0.3 * q_all.size  # and most balls touch
    assert np.array_equal(q, q_all) and np.array_equal(n, n_all)


@pytest.mark.parametrize("name", ["yoshida_odd5", "washer"])
def test_spread_lanes_skip_the_pair_force_and_give_the_bits_of_every_pair(name):
    """The kernel asks for a pair's force only in lanes where the two balls are within the
    reach angle (and skips a pair that no lane has within it): lanes of spread balls, of
    single touching pairs and of pairs a rounding error either side of the reach angle give
    the bits of every pair."""
    scene = load_scene(name)
    nb = scene.ball_count
    rng = np.random.default_rng(11)
    angles, speeds = _clustered(scene, rng, 300, squeeze=0.3, widest=3.0)
    # a third of the lanes spread over the whole race (no pair within reach in some of the
    # blocks' pairs), a third with pair (1, 2) at the reach angle less or more a few ulp
    angles[:100] = np.linspace(0.0, 2 * np.pi, nb, endpoint=False) + rng.uniform(
        -0.1, 0.1, (100, nb))
    reach_angle = contact.neighbour_reach_angle(scene.ball_radius, scene.race_radius)
    angles[100:200, 2] = angles[100:200, 1] + reach_angle * (1.0 + rng.uniform(-4e-16, 4e-16,
                                                                               100))
    s, p, b = _lanes(scene, angles, speeds)
    q, n, _ = _kernel_contacts(s, p, b, nb)
    q_all, n_all = _all_pairs(s, p, b, nb)
    assert np.array_equal(q, q_all) and np.array_equal(n, n_all)
    assert np.count_nonzero(q_all[:, 200:]) > 0.1 * q_all[:, 200:].size  # some balls touch
    # all spread: the force pass is skipped for every pair, every force is 0
    q, n, _ = _kernel_contacts(s[:, :100].copy(), p[:, :100].copy(), b[:, :, :100].copy(), nb)
    assert not q.any() and not n.any()


@pytest.mark.parametrize("ratio", [1e-4, 0.01, 0.3, 0.8, 0.84, 0.9, 1.0])
def test_no_pair_beyond_the_reach_angle_can_touch(ratio):
    """:func:`contact.may_touch` rules a pair out only where its force is zero: balls of
    radius up to ``ratio`` times the track radius, pairs at the reach angle less or more a
    relative 1e-5, approaching at any speed (the damper cannot make a force without
    penetration)."""
    rng = np.random.default_rng(int(ratio * 1e4))
    big_r = 0.2
    radii = big_r * ratio * rng.uniform(0.5, 1.0, 3)
    radii[0] = big_r * ratio
    reach_angle = contact.neighbour_reach_angle(radii, big_r)
    d = reach_angle * (1.0 + rng.uniform(-1e-5, 1e-5, 4000))
    d = np.concatenate([d, rng.uniform(-math.pi, math.pi, 4000)])
    ruled_out = 0
    for k, dk in enumerate(d):
        i, j = k % 3, (k + 1 + k // 3 % 2) % 3
        phi_i = rng.uniform(-30.0, 30.0)
        phi_j = phi_i + dk
        # (the difference as the kernel forms it)
        if contact.may_touch.py_func(contact.wrap_angle.py_func(phi_j - phi_i), reach_angle):
            continue
        ruled_out += 1
        on, q, radial = contact.pair_force.py_func(phi_i, phi_j, 50.0, -50.0, big_r,
                                                   radii[i] + radii[j], 1e-3, 2e-3, 1e4, 2.0)
        assert not on and q == 0.0 and radial == 0.0
    if reach_angle < contact.GUARD_LIMIT:
        assert ruled_out > 1000
    else:  # balls too large for the guard's margin: it rules nothing out
        assert ruled_out == 0


def test_lanes_out_of_race_order_or_squeezed_take_every_pair():
    scene = load_scene("washer")
    nb = scene.ball_count
    rng = np.random.default_rng(5)
    angles, speeds = _clustered(scene, rng, 60, squeeze=0.3)
    # a third of the lanes shuffled (index order is not race order), a third squeezed
    # (one ball pressed into its neighbours until the next-but-one pair touches)
    for l in range(20):
        angles[l] = rng.permutation(angles[l])
    reach = 2.0 * math.asin(scene.ball_radius[0] / scene.race_radius)
    for l in range(20, 40):
        angles[l, 6] = angles[l, 5] + 0.45 * reach
        angles[l, 7] = angles[l, 5] + 0.95 * reach
        speeds[l] = 0.0  # (so that no damping term cancels a penetration's force)
    s, p, b = _lanes(scene, angles, speeds)
    q, n, ring = _kernel_contacts(s, p, b, nb)
    q_all, n_all = _all_pairs(s, p, b, nb)
    assert not ring[:40].any() and ring[40:].all()
    assert np.array_equal(q, q_all) and np.array_equal(n, n_all)
    # the neighbours alone would be wrong there: the fall-back is what makes them agree
    nq = 3 + nb
    for l in range(40):
        nbr = np.zeros(nb)
        for k in range(nb):
            lo, hi = (0, nb - 1) if k == nb - 1 else (k, k + 1)
            _, qk, _ = contact.pair_force.py_func(
                s[3 + lo, l], s[3 + hi, l], s[nq + 3 + lo, l], s[nq + 3 + hi, l],
                p[mdl.P_R, l], b[lo, mdl.B_RADIUS, l] + b[hi, mdl.B_RADIUS, l],
                b[lo, mdl.B_MEFF, l], b[hi, mdl.B_MEFF, l], p[mdl.P_KC, l], p[mdl.P_ZC, l])
            nbr[hi] += qk
            nbr[lo] -= qk
        if l < 3 or 20 <= l < 23:
            assert not np.allclose(nbr, q_all[:, l], rtol=1e-6, atol=1e-12)


def test_two_and_three_balls_have_only_neighbour_pairs():
    scene = load_scene("yoshida_odd5")
    for count in (2, 3):
        sc = scene.replace(ball_count=count, ball_angles0=scene.ball_angles0[:count])
        rng = np.random.default_rng(count)
        angles, speeds = _clustered(sc, rng, 200, squeeze=0.3)
        angles[::2] = angles[::2, ::-1]  # any order: every pair is a neighbour pair
        s, p, b = _lanes(sc, angles, speeds)
        q, n, _ = _kernel_contacts(s, p, b, count)
        q_all, n_all = _all_pairs(s, p, b, count)
        assert np.array_equal(q, q_all) and np.array_equal(n, n_all)


def test_the_reach_angle_bounds_every_pair():
    # two balls that far apart cannot touch; a hair closer, the largest pair can
    radii = (1e-3, 2e-3, 1.5e-3)
    big_r = 0.01
    theta = contact.neighbour_reach_angle(radii, big_r)
    pen, _, _ = contact.pair_geometry.py_func(0.0, theta, big_r, 2 * max(radii))
    assert pen < 0.0
    pen, _, _ = contact.pair_geometry.py_func(0.0, theta * (1 - 1e-5), big_r, 2 * max(radii))
    assert pen > 0.0
    assert contact.neighbour_reach_angle((0.02,), big_r) == math.pi


@njit
def _rates(s, p, b, nb):
    L = s.shape[1]
    out = np.zeros((nb, L))
    for l in range(L):
        for i in range(nb):
            out[i, l] = contact.contact_rate_lane(s, l, i, b, mdl.B_RADIUS, mdl.B_MEFF,
                                                  p[mdl.P_R, l], p[mdl.P_KC, l],
                                                  p[mdl.P_ZC, l])
    return out


@njit
def _rates_of_the_lanes(s, p, b, start):
    L = s.shape[1]
    out = np.full((b.shape[0], L), start)
    for l in range(L):
        contact.add_contact_rates_lane(s, l, b, mdl.B_RADIUS, mdl.B_MEFF, p[mdl.P_R, l],
                                       p[mdl.P_KC, l], p[mdl.P_ZC, l], p[mdl.P_REACH, l],
                                       out, 0)
    return out


@pytest.mark.parametrize("seed", [9, 19])
def test_the_contact_rates_of_the_step_rule_ask_the_neighbours_for_the_same_bits(seed):
    """The drag-rate pass asks each neighbour pair once per lane (add_contact_rates_lane);
    every ball's rate is the bits of asking it alone over every pair, in race order, out of
    it and with every ball at one place (the step rule's state), and it is added to what the
    row held."""
    scene = load_scene("washer")
    rng = np.random.default_rng(seed)
    angles, speeds = _clustered(scene, rng, 200, squeeze=0.3)
    angles[:30] = np.sort(rng.uniform(-3, 3, (30, 12)))[:, ::-1]  # not in race order
    angles[30:40] = 0.0  # the step rule's state: every ball at one place
    s, p, b = _lanes(scene, angles, speeds)
    every = _rates(s, p, b, 12)
    assert np.count_nonzero(every[:, 40:]) > 0.5 * every[:, 40:].size
    assert np.array_equal(_rates_of_the_lanes(s, p, b, 0.0), every)
    assert np.array_equal(_rates_of_the_lanes(s, p, b, 3.5), every + 3.5)
