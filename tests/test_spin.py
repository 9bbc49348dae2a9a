"""abb_gym/SpinRedistribute-v0: the washer whose laundry redistributes when the drum tumbles
(:mod:`abb_gym.envs.spin`, :mod:`abb_gym.envs.redistribution`, :mod:`abb_gym.physics.laundry`),
its capacity, its open-loop floor, its oracle and its hand rules."""
from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import abb_gym  # noqa: F401
from abb_gym.baselines.families import build_family
from abb_gym.baselines.baseline_policy import ClosedLoopPolicy
from abb_gym.envs.tasks import SPIN_REDISTRIBUTE
from abb_gym.evaluation import evaluate as ev
from abb_gym.envs.layout import C_TUMBLE_SPEED
from abb_gym.physics import laundry, rotor
from abb_gym.physics import model as mdl
from abb_gym.physics.drives import SpeedProfile
from abb_gym.physics.scene import load_scene
from abb_gym.physics.simulate import simulate

SPIN = SPIN_REDISTRIBUTE.env_id


def test_check_env(strict_check_env):
    strict_check_env(gym.make(SPIN))


def test_tumble_speed_is_derived_from_the_detachment_angle():
    """Laundry on the wall leaves it where w^2 R = g sin(b); it falls across the drum from
    b <= 40 deg: w_tumble = sqrt(sin 40 deg g / R) = 0.80 sqrt(g / R)."""
    g, r = 9.81, 0.26
    assert laundry.tumble_speed(g, r) == pytest.approx(math.sqrt(g / r) * 0.8017, rel=1e-4)
    env = gym.make(SPIN)
    assert env.unwrapped.setup.cfg[C_TUMBLE_SPEED] == pytest.approx(laundry.tumble_speed(g, r))


def test_a_drum_kept_slow_redistributes_its_laundry_as_drawn():
    env = gym.make(SPIN, info_level="full")
    u = env.unwrapped
    obs, info = env.reset(seed=3)
    drawn = u.episode.redistributions
    assert drawn.shape == (4, 2)
    names = u.observation_names
    count = names.index("redistributions")
    tumble = u.config.redistribution.tumble_time
    dt = u.setup.control_interval
    steps = int(round(tumble / dt))
    for k in range(2):
        for _ in range(steps):
            obs, r, term, trunc, info = env.step(np.array([-1.0], np.float32))
        assert obs[count] == pytest.approx((k + 1) / 4)
        # the new laundry: the drawn imbalance, the balls at rest at the bottom of the race
        nq = u.state.shape[0] // 2
        p = u._bufs.p[0]
        assert p[mdl.P_U0] == drawn[k, 0]
        absolute = u.state[2] + u.state[3:nq]
        rest = np.zeros(u.scene.ball_count)
        laundry.resting_angles(p, u._bufs.b[0], rest, 0)
        assert np.allclose(np.remainder(absolute - rest + np.pi, 2 * np.pi) - np.pi, 0.0,
                           atol=1e-9)
    assert not (term or trunc)


def test_single_and_vector_agree_bit_for_bit_through_redistributions():
    env = gym.make(SPIN)
    venv = gym.make_vec(SPIN, num_envs=3, vectorization_mode="vector_entry_point")
    obs, _ = env.reset(seed=11)
    vobs, _ = venv.reset(seed=11)
    assert np.array_equal(obs, vobs[0])
    actions = [-1.0] * 20 + [1.0] * 20 + [-1.0] * 30 + [0.5] * 10
    for a in actions:
        act = np.array([a], np.float32)
        obs, r, term, trunc, _ = env.step(act)
        vobs, vr, vterm, vtrunc, _ = venv.step(np.repeat(act[None], 3, axis=0))
        assert np.array_equal(obs, vobs[0]) and r == vr[0]
        assert (term, trunc) == (vterm[0], vtrunc[0])
    assert obs[env.unwrapped.observation_names.index("redistributions")] > 0


def test_a_seeded_redistribution_sequence_reproduces():
    def run(seed):
        env = gym.make(SPIN, info_level="full")
        env.reset(seed=seed)
        out = []
        for _ in range(40):
            obs, *_ = env.step(np.array([-1.0], np.float32))
            out.append(obs.copy())
        return np.array(out), env.unwrapped.episode.redistributions
    a, da = run(5)
    b, db = run(5)
    c, dc = run(6)
    assert np.array_equal(a, b) and np.array_equal(da, db)
    assert not np.array_equal(da, dc)
    # the redistributions come from the episode's generator, after its other draws: a reset
    # option that fixes them leaves the episode's first laundry as it was
    env = gym.make(SPIN)
    _, info = env.reset(seed=5, options={"redistributions": [[0.01, 0.5]]})
    fixed = env.unwrapped.episode.redistributions
    assert fixed[0, 0] == 0.01 and np.array_equal(fixed[1:], da[1:])
    with pytest.raises(ValueError, match="redistributions"):
        env.reset(options={"redistributions": [[0.01]]})
    with pytest.raises(ValueError, match="redistribution.enabled"):
        gym.make("abb_gym/RunUpSpeed-v0", scene="washer").reset(
            options={"redistributions": [[0.01, 0.5]]})


def test_a_scene_without_gravity_is_refused():
    with pytest.raises(ValueError, match="horizontal-axis scene"):
        gym.make(SPIN, scene="yoshida_odd")
    with pytest.raises(ValueError, match="redistribution.enabled.*fixes"):
        gym.make(SPIN, redistribution={"enabled": False})


def test_effective_capacity_with_contact():
    """Beyond capacity the balls clump opposite the load, side by side: what is left is
    U - C_eff, with C_eff = |sum m_i R e^(i phi_i)| of touching balls (0.968 of sum m_i R on
    the washer).  Measured: the residual imbalance after a run-up to spin and a 30 s hold,
    with a load of 1.4 C, the balls starting at the bottom of the race.  Tolerance 1 %: the
    contact springs (5 kN/m) let the pressed clump close up a little."""
    sc = load_scene("washer")
    cap = sc.balancing_capacity
    c_eff = laundry.effective_capacity(sc)
    assert c_eff / cap == pytest.approx(0.968, abs=0.001)
    assert laundry.effective_capacity(sc.replace(contact_stiffness=0.0)) == cap
    u = 1.4 * cap
    loaded = sc.replace(rotor_eccentricity=u / sc.rotor_mass)
    w, alpha = sc.drive_operating_speed, sc.drive_max_acceleration
    p, b = mdl.pack_parameters(loaded)
    rest = np.zeros(sc.ball_count)
    laundry.resting_angles(p, b, rest, 0)
    profile = SpeedProfile(segments=((w / alpha, alpha), (30.0, 0.0)))
    tr = simulate(loaded, profile, w / alpha + 30.0, ball_angles0=rest,
                  x0=rotor.static_deflection(loaded), output_dt=0.05)
    residual = rotor.residual_imbalance(loaded, tr.ball_angles[-1])
    assert u - residual == pytest.approx(c_eff, rel=0.01)


def _laundry_episodes(policy: str, loads, redistributions=None, scene: str = "washer"):
    """One episode of the laundry preset per load (imbalance ratio; the phase, the oil and the
    rolling resistance from seeds 0, 1, ...; the nominal mass) under ``policy``, its
    redistributions (ratio, phase) fixed if given: the evaluation's rows."""
    cap = load_scene(scene).balancing_capacity
    options = [("imbalance_ratio", tuple(loads)), ("critical_speed_scale", 1.0)]
    if redistributions is not None:
        options.append(("redistributions", tuple((r * cap, ph) for r, ph in redistributions)))
    chunk = ev.Chunk(SPIN, scene, "laundry", policy, 0, tuple(range(len(loads))),
                     reset_options=tuple(options))
    return ev.run_chunk(chunk)[0]


def test_no_open_loop_profile_beats_the_floor():
    """A load beyond the effective capacity leaves the residual imbalance U - C_eff whatever
    the speed profile: its steady whirl at spin (the balancer-off machine's at U - C_eff) is a
    floor for every open-loop profile (a slow ramp and the knots profile here), within 3 %
    (what the balls still settle during the hold)."""
    sc = load_scene("washer")
    cap, c_eff = sc.balancing_capacity, laundry.effective_capacity(sc)
    loads = (1.3, 1.6)
    for policy in ("baseline:ramp", "baseline:knots"):
        for ratio, row in zip(loads, _laundry_episodes(policy, loads)):
            floor = rotor.reference_amplitudes(sc, sc.drive_operating_speed,
                                               ratio * cap - c_eff)[1] / 1e-3  # [mm]
            assert row["residual_after_hold"] >= 0.97 * floor, (policy, ratio)


def test_the_oracle_beats_the_open_loop_on_loads_beyond_capacity():
    loads = (1.3, 1.6)
    fits = [(0.5, 1.0), (0.6, -2.0)]
    ramp = _laundry_episodes("baseline:ramp", loads, fits)
    oracle = _laundry_episodes("baseline:laundry_oracle", loads, fits)
    for r, o in zip(ramp, oracle):
        assert o["residual_after_hold"] < 0.5 * r["residual_after_hold"]
        # the evaluation counts the retries: the ramp never tumbles, the oracle redistributes
        # the load it knows is too large until a drawn one fits (the first one here)
        assert (r["redistributions"], o["redistributions"]) == (0, 1)


def test_hand_rules_decide_on_constructed_cases():
    """redistribute_low stops the drum after its check at the distribution speed when the
    vibration there is above its threshold (a load of 1.6 C) and runs up when it is not
    (0.3 C); the thresholds are set here, between the two loads' readings."""
    env = gym.make_vec(SPIN, num_envs=2, vectorization_mode="vector_entry_point")
    rule = ClosedLoopPolicy("redistribute_low", build_family(
        "redistribute_low", distribution_speed=9.5, measure_time=3.0, threshold=0.3,
        max_redistributions=1))
    obs, info = env.reset(seed=0, options={"imbalance_ratio": np.array([1.6, 0.3]),
                                           "redistributions": [[0.3 * 0.088, 0.0]]})
    rule.reset(env, np.ones(2, bool))
    for _ in range(int(40 / env.unwrapped.setup.control_interval)):
        obs, r, term, trunc, info = env.step(rule.act(obs, info))
    # (the drum is below the tumble speed while it slows, rests and speeds up again: that can
    # be two tumble times, two redistributions)
    done = env.unwrapped.redistributions
    assert done[0] >= 1 and done[1] == 0
    # retry_at_spin stops the drum after its check at spin when the vibration there is above
    # its threshold (1.6 C leaves (U - C_eff) / M, about 1.4 mm) and holds the spin when it is
    # not (0.3 C: balanced)
    rule = ClosedLoopPolicy("retry_at_spin", build_family(
        "retry_at_spin", accel=5.0, check_time=2.0, threshold=0.1, max_retries=1))
    obs, info = env.reset(seed=0, options={"imbalance_ratio": np.array([1.6, 0.3]),
                                           "redistributions": [[0.3 * 0.088, 0.0]]})
    rule.reset(env, np.ones(2, bool))
    ended, peak = np.zeros(2, bool), 0.0
    for _ in range(int(40 / env.unwrapped.setup.control_interval)):
        obs, r, term, trunc, info = env.step(rule.act(obs, info))
        ended |= term | trunc
        peak = max(peak, float(obs[0, 0]))
    assert ended[1] and not ended[0]  # the balanced load settled at spin; the other dropped
    assert peak > 0.99 and obs[0, 0] < 0.8 * peak  # reached spin, on its way down to tumble


def test_the_open_loop_floor_of_a_test_set():
    """The floor of each episode is the balancer-off whirl at spin of the first load's excess
    over the effective capacity: zero for a load that fits, that whirl otherwise (the load
    read from the same seeded reset); a summary of a SpinRedistribute evaluation states it
    and a run-up task's has none."""
    from abb_gym.baselines.laundry import open_loop_floor
    from abb_gym.evaluation.report import residual_floor

    seeds = list(range(40))
    floor = open_loop_floor(SPIN, "washer_reduced", "laundry_test", seeds)
    env = gym.make_vec(SPIN, num_envs=len(seeds), vectorization_mode="vector_entry_point",
                       scene="washer_reduced", preset="laundry_test")
    env.reset(seed=seeds)
    loads, sc = env.unwrapped.imbalances, env.unwrapped.setup.scene
    c_eff = laundry.effective_capacity(sc)
    fits = loads <= c_eff
    assert fits.any() and (~fits).any()
    assert np.all(floor[fits] == 0.0)
    k = int(np.flatnonzero(~fits)[0])
    whirl = rotor.reference_amplitudes(sc, sc.drive_operating_speed, loads[k] - c_eff)[1]
    assert floor[k] == pytest.approx(whirl / 1e-3, rel=1e-12)  # mm
    result = ev.EvaluationResult("baseline:ramp", SPIN, "washer_reduced", "laundry_test", 0,
                                 episodes=[{"seed": s} for s in seeds])
    stat = residual_floor(result)
    assert stat["mean"] == pytest.approx(float(np.mean(floor)))
    assert stat["ci_low"] <= stat["mean"] <= stat["ci_high"] and "C_eff" in stat["definition"]
    other = ev.EvaluationResult("baseline:ramp", "abb_gym/RunUpSpeed-v0", "yoshida_odd",
                                "test", 0, episodes=[{"seed": 0}])
    assert residual_floor(other) is None
