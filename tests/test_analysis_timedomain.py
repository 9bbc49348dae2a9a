"""Time-domain agreement: abb_gym.simulate against the eigenvalue analysis.

The simulator integrates the fixed-frame equations of abb_gym.physics.model; the analysis uses
the rotating-frame equations of abb_gym.analysis.rotating_frame - different code paths.
"""
import math

import numpy as np
import pytest

from abb_gym import SpeedProfile, load_scene, simulate
from abb_gym.analysis import Groups, lu_hung, rotating_frame as rf, timedomain as td


def test_fig6_initial_conditions_balance_at_different_ball_sets():
    """Paper L251 (Fig. 6, eta = 0.4, Omega = 2): both ICs - x = y = 0, b = (0.01, 0.02,
    0.03) pi and (0.30, 0.32, 0.34) pi, velocities 0 - end perfectly balanced (r -> 0) with
    different final ball sets.  The lu_hung_odd3 scene carries the note's fitted groups.
    Checks: r < 1e-8 e after t* = 500; sum cos b = -1/eta (1e-6: the scene's rounded
    eccentricity); every ball in [beta*, 2 pi - beta*]; the sets differ by > 10 deg.
    [derived] note A8: IC1 -> (182.45, 219.71, 137.02), IC2 -> (205.67, 130.75, 198.93) deg;
    tolerance 0.5 deg because the final member of the neutral family depends on the whole
    transient (this RK4 run and the note's differ by ~0.15 deg)."""
    scene = load_scene("lu_hung_odd3")
    lo, hi = lu_hung.allowed_ball_range(0.4)
    finals = []
    for ic, note in (((0.01, 0.02, 0.03), (182.45, 219.71, 137.02)),
                     ((0.30, 0.32, 0.34), (205.67, 130.75, 198.93))):
        tr = simulate(scene, SpeedProfile.constant(200.0), 5.0,
                      ball_angles0=np.pi * np.array(ic), output_dt=0.01)
        b = np.mod(tr.ball_angles[-1], 2 * np.pi)
        assert tr.whirl_radius[-1] / 5e-4 < 1e-8
        assert np.sum(np.cos(b)) == pytest.approx(-2.5, abs=1e-6)
        assert np.sum(np.sin(b)) == pytest.approx(0.0, abs=1e-6)
        assert np.all((b > lo - 1e-3) & (b < hi + 1e-3))
        assert np.degrees(b) == pytest.approx(note, abs=0.5)
        finals.append(np.sort(b))
    assert np.max(np.abs(finals[0] - finals[1])) > math.radians(10)


@pytest.mark.parametrize("omega,expect_stable", [(2.0, True), (1.3, False)])
def test_balanced_member_converges_or_leaves_as_eigenvalues_say(omega, expect_stable):
    """Started 1e-3 from a balanced member of lu_hung_odd3: the run returns to the family where
    the eigenvalues say stable (Omega 2, max Re -0.08) and leaves where unstable (Omega 1.3,
    +0.046).  Decay/growth over t* = 300 is a factor e^(0.08*300) resp. e^(0.046*300); the
    thresholds 1e-2 / 10 leave orders of magnitude of margin."""
    scene = load_scene("lu_hung_odd3")
    g = Groups.from_scene(scene)
    fs = rf.family_stability(g, omega, 5)
    assert fs.all_stable is expect_stable and fs.union_stable is expect_stable
    q = np.concatenate([[0.0, 0.0], fs.members[2]])
    out = td.run_from_equilibrium(scene, omega, q, perturbation=1e-3, t_end=300.0)
    assert out["to_family"]
    if expect_stable:
        assert out["ratio"] < 1e-2
    else:
        assert out["ratio"] > 10


@pytest.mark.parametrize("signed_count,expect_stable", [(3, True), (1, False)])
def test_unbalanced_equilibria_converge_or_leave(signed_count, expect_stable):
    """Paper L251 (Fig. 5, eta = 0.4): below critical r11 (all balls together) is stable and
    r31 (two together, one opposite) unstable.  Eigenvalues and simulation agree at
    Omega = 0.5 (thresholds as above)."""
    scene = load_scene("lu_hung_odd3")
    g = Groups.from_scene(scene)
    (eq,) = [e for e in rf.unbalanced_equilibria(g, 0.5)
             if e.signed_count == signed_count and e.branch == 1]
    assert eq.stable is expect_stable
    out = td.run_from_equilibrium(scene, 0.5, eq.q, perturbation=1e-3, t_end=300.0)
    if expect_stable:
        assert out["ratio"] < 1e-2
    else:
        assert out["ratio"] > 10


# ---------------------------------------------------------------- Rezaee & Fathi conventional
REZAEE = Groups.from_rezaee_fathi(mbar=0.03, epsbar=0.01, zeta=0.1, beta=0.1)


@pytest.mark.parametrize("omega,balanced", [(1.4, False), (1.5, False), (1.6, True)])
def test_rezaee_conventional_points(omega, balanced):
    """Rezaee & Fathi Fig. 3/4 (L234, L284): conventional balancer, mbar = 0.03,
    epsbar = 0.01, zeta = beta = 0.1: not balanced at A (1.4) and B (1.5), balanced at C (1.6).
    Eigenvalues (union over the family) and a simulation from equally spaced balls (the
    springs' rest state, t* = 3000) agree.  [derived] note B9: union onset 1.575."""
    fs = rf.family_stability(REZAEE, omega)
    assert fs.union_stable is balanced
    run = td.settle(REZAEE, omega, 2 * np.pi * np.arange(3) / 3, t_end=3000.0)
    assert run.state == ("balanced" if balanced else "whirl")


def test_clumped_whirl_coexists_with_balanced_state():
    """Above the critical speed the clumped-ball whirl coexists with the balanced state
    (Rezaee conventional, Omega = 1.6): clumped balls (Lu & Hung IC1) whirl, spread balls
    balance.  [derived] note B9: whirl r in [0.244, 0.292] lambda = [24.4, 29.2] e, balls
    lagging at -0.70 w_n (inertial ~0.90 w_n); tolerance 2 % on r (three digits plus the
    tail window), 0.01 on the lag."""
    cw = td.clumped_whirl(REZAEE, 1.6, t_end=3000.0)
    assert cw.coexists, cw.report()
    assert cw.clumped.radius_min == pytest.approx(24.4, rel=0.02)
    assert cw.clumped.radius_max == pytest.approx(29.2, rel=0.02)
    assert cw.clumped.ball_speed == pytest.approx(-0.70, abs=0.01)
    assert cw.spread.radius_max < 1e-4
    assert "whirl" in cw.report()
