"""Episodes are drawn one environment at a time and written many rows at once
(:mod:`abb_gym.envs.episodes`); the vectorised write must equal packing each episode's Scene."""
from __future__ import annotations

import math

import numpy as np
import pytest

import abb_gym
from abb_gym.envs import episodes
from abb_gym.envs.setup import EnvSetup
from abb_gym.envs.layout import S_AOP, S_AREF
from abb_gym.physics import model as mdl
from abb_gym.physics import rotor
from abb_gym.physics import variants
from abb_gym.physics.steps import default_step, stiff_rates


def test_one_random_call_gives_the_numbers_of_uniform_one_by_one():
    """draw() takes all of an episode's numbers with one rng.random call; they must be the
    numbers (and the bits) of the rng.uniform calls it replaced, so seeded episodes stay."""
    ranges = [(0.2, 0.9), (-np.pi, np.pi), (0.5, 1.5)]
    a = np.random.default_rng(11)
    b = np.random.default_rng(11)
    one_by_one = [a.uniform(lo, hi) for lo, hi in ranges] + list(a.uniform(-3.0, 3.0, size=4))
    u = b.random(len(ranges) + 4)
    batched = ([episodes._uniform(r, u[k]) for k, r in enumerate(ranges)]
               + list(episodes._uniform((-3.0, 3.0), u[3:])))
    assert np.array_equal(one_by_one, batched)
    # and draw() itself: the train preset's values in its documented order, as rng.uniform
    # would give them one by one
    setup = EnvSetup("abb_gym/RunUpSpeed-v0", "yoshida_odd", "train")
    rz = setup.config.randomize
    a = np.random.default_rng(5)
    ratio = a.uniform(*rz.imbalance_ratio)
    phase = a.uniform(*rz.imbalance_phase)
    angles = a.uniform(*rz.ball_angles, size=setup.scene.ball_count)
    drag = a.uniform(*rz.ball_drag_scale)
    roll = a.uniform(*rz.rolling_resistance_scale)
    got = episodes.draw(setup, np.random.default_rng(5), None)
    assert got["imbalance"] == ratio * setup.scene.balancing_capacity
    assert got["imbalance_phase"] == episodes.reduce_angle(phase)
    assert np.array_equal(got["ball_angles"], episodes.reduce_angle(angles))
    assert (got["ball_drag_scale"], got["rolling_resistance_scale"]) == (drag, roll)


@pytest.mark.parametrize("scene", ["yoshida_odd", "washer", "yoshida_odd5"])
def test_rows_written_at_once_equal_each_episode_scene_packed(scene):
    setup = EnvSetup("abb_gym/RunUpSpeed-v0", scene, "train")
    sc = setup.scene
    rng = np.random.default_rng(3)
    n = 7
    imbalance = rng.uniform(0.1, 0.9, n) * sc.balancing_capacity
    imbalance[2] = sc.imbalance  # the nominal imbalance keeps the nominal eccentricity
    drag = rng.uniform(0.5, 1.5, n)
    drag[3] = 1.0
    roll = rng.uniform(0.0, 2.0, n)
    roll[4] = 0.0  # no rolling resistance at all: the effect goes away
    roll[5] = 1.0
    p, b = variants.packed_variants(sc, n, imbalance=imbalance, ball_drag_scale=drag,
                                    rolling_resistance_scale=roll)
    for r in range(n):
        ep_scene = variants.variant_scene(sc, imbalance=imbalance[r], ball_drag_scale=drag[r],
                                          rolling_resistance_scale=roll[r])
        p_ref, b_ref = mdl.pack_parameters(ep_scene)
        assert np.array_equal(p[r], p_ref), r
        assert np.array_equal(b[r], b_ref), r
        assert ep_scene.reference_length == variants.references(
            sc, p[r:r + 1], setup.operating_speed, imbalance=imbalance[r:r + 1],
            ball_drag_scale=drag[r:r + 1], rolling_resistance_scale=roll[r:r + 1]
        ).reference_length[0]
    rates = stiff_rates(p, b, setup.max_speed)
    steps = default_step(sc, setup.max_speed, "rk4", rate=rates)
    for r in range(n):
        ep_scene = variants.variant_scene(sc, imbalance=imbalance[r], ball_drag_scale=drag[r],
                                          rolling_resistance_scale=roll[r])
        assert steps[r] == default_step(ep_scene, setup.max_speed, "rk4")
    # machines of another load (critical speed), support damping and, where the scene's oil
    # has a temperature law, fluid temperature: the same, bit for bit, and what a reset
    # writes (step, reference length, reward scales, rest position)
    crit = rng.uniform(0.9, 1.1, n)
    crit[2] = 1.0  # the nominal mass and imbalance: the nominal eccentricity
    crit[6] = 1.0
    damp = rng.uniform(0.5, 2.0, n)
    damp[0] = 1.0
    temp = np.full(n, sc.fluid_temperature)
    if sc.fluid_preset:
        temp = rng.uniform(293.15, 333.15, n)
        temp[1] = sc.fluid_temperature
    values = {"imbalance": imbalance, "ball_drag_scale": drag, "rolling_resistance_scale": roll,
              "critical_speed_scale": crit, "support_damping_scale": damp,
              "fluid_temperature": temp}
    p, b = variants.packed_variants(sc, n, **values)
    table = episodes.EpisodeTable(setup.scene, n, setup.redistribution_events)
    pending = episodes.prepare(setup, table, np.arange(n), {
        **values, "imbalance_phase": np.zeros(n), "ball_angles": np.zeros((n, sc.ball_count))})
    for r in range(n):
        ep_scene = variants.variant_scene(sc, **{k: v[r] for k, v in values.items()})
        p_ref, b_ref = mdl.pack_parameters(ep_scene)
        assert np.array_equal(p[r], p_ref), r
        assert np.array_equal(b[r], b_ref), r
        assert np.array_equal(pending.p[r], p_ref), r
        assert np.array_equal(pending.b[r], b_ref), r
        assert pending.step[r] == default_step(ep_scene, setup.max_speed, "rk4"), r
        assert pending.reference_length[r] == ep_scene.reference_length, r
        assert tuple(pending.static_deflection[r]) == rotor.static_deflection(ep_scene), r
        scale = rotor.imbalance_scale(ep_scene)
        assert (pending.st[r, S_AREF], pending.st[r, S_AOP]) == rotor.reference_amplitudes(
            ep_scene, setup.operating_speed, scale), r


def test_reset_options_are_checked_by_name():
    setup = EnvSetup("abb_gym/RunUpSpeed-v0", "yoshida_odd", "train")
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="unknown reset option"):
        episodes.draw(setup, rng, {"imbalence": 1.0})
    with pytest.raises(ValueError, match="'ball_drag_scale' must be > 0"):
        episodes.draw(setup, rng, {"ball_drag_scale": 0.0})
    with pytest.raises(ValueError, match="'ball_angles' must be 2 finite"):
        episodes.draw(setup, rng, {"ball_angles": [0.0, np.nan]})
    with pytest.raises(ValueError, match="'critical_speed_scale' must be > 0"):
        episodes.draw(setup, rng, {"critical_speed_scale": -1.0})
    with pytest.raises(ValueError, match="'support_damping_scale' must be a number"):
        episodes.draw(setup, rng, {"support_damping_scale": "high"})


@pytest.mark.parametrize("scene, preset", [("yoshida_odd", "train"), ("yoshida_odd", "test"),
                                           ("yoshida_odd", "varied"),
                                           ("spannan_cfrp", "varied_test"),
                                           ("yoshida_odd5", "nominal"),
                                           ("lu_hung_odd3", "train")])
def test_rows_drawn_at_once_are_each_rows_draw_bit_for_bit(scene, preset):
    """The autoreset draws all resetting rows at once (draw_rows); every value must be the one
    draw() gives row by row from the same generator, bit for bit, and the generators must end
    in the same state: seeded episodes do not change."""
    setup = EnvSetup("abb_gym/RunUpSpeed-v0", scene, preset)
    seeds = [3, 14, 15, 92, 65]
    one = [np.random.default_rng(s) for s in seeds]
    many = [np.random.default_rng(s) for s in seeds]
    for _ in range(3):  # later draws too: the generators advance alike
        want = [episodes.draw(setup, rng, None) for rng in one]
        got = episodes.draw_rows(setup, many, [None, {}, None, {}, None])
        assert list(got) == list(want[0])
        for k in got:
            column = np.array([w[k] for w in want])
            assert got[k].dtype == column.dtype, k
            assert np.array_equal(got[k], column), (k, got[k], column)
            assert np.array_equal(np.signbit(got[k]), np.signbit(column)), k
    assert [r.bit_generator.state for r in one] == [r.bit_generator.state for r in many]


def test_rows_with_reset_options_are_drawn_row_by_row():
    setup = EnvSetup("abb_gym/RunUpSpeed-v0", "yoshida_odd", "varied")
    opts = [None, {"imbalance_ratio": 0.5, "critical_speed_scale": 1.1}]
    got = episodes.draw_rows(setup, [np.random.default_rng(1), np.random.default_rng(2)], opts)
    want = [episodes.draw(setup, np.random.default_rng(s), o) for s, o in zip((1, 2), opts)]
    for k in got:
        assert np.array_equal(got[k], np.array([w[k] for w in want])), k
    assert got["critical_speed_scale"][1] == 1.1
    with pytest.raises(ValueError, match="options must be a dict"):
        episodes.draw_rows(setup, [np.random.default_rng(1)], [[]])


def test_angles_reduce_exactly_whether_in_range_or_not():
    a = np.array([0.0, -0.0, np.pi, -np.pi, 3.5, -7.0, 1e6, np.nan, 2 * np.pi])
    got = episodes.reduce_angle(a)
    want = [math.remainder(v, episodes.TWO_PI) for v in a]
    assert np.array_equal(got, want, equal_nan=True)
    assert np.array_equal(np.signbit(got), np.signbit(want))
    assert got.shape == a.shape and episodes.reduce_angle(a.reshape(3, 3)).shape == (3, 3)
