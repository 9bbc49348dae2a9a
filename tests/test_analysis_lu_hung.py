"""Lu & Hung (2008) closed forms: existence, ball ranges, worked positions, unbalanced branches.

Paper values are cited by seed line (S000 Lxxx); values marked [derived] come from the physics
note (lu_hung_2008_and_rezaee_fathi_2015.md), which computed them from the paper's equations.
"""
import math

import numpy as np
import pytest

from abb_gym.analysis import Groups, lu_hung, rotating_frame as rf


# ---------------------------------------------------------------- existence (P1)
@pytest.mark.parametrize("n", [2, 3, 4, 5])
def test_existence_threshold_is_n_eta_equal_one(n):
    """Paper (L188, L198): n balls balance iff n*eta >= 1.  Checked two ways: the closed form
    and, independently, whether the rotating-frame family solver finds any balanced member
    just above / below the threshold (1 % margin: far above round-off, small enough to pin
    the threshold to 1 %)."""
    lo, hi = 0.99 / n, 1.01 / n
    assert not lu_hung.balance_exists(n, lo)
    assert lu_hung.balance_exists(n, hi)
    assert lu_hung.balance_exists(n, 1.0 / n)
    for eta, expect in ((lo, False), (hi, True)):
        fam = rf.balanced_family(Groups(eta=eta, n_balls=n), 2.0, n_members=9)
        assert (len(fam) > 0) is expect


def test_range_bound_paper_values():
    """Paper L196: A(1/3) = -1, A(1/sqrt 3) = 0, A(1) = 1 (exact; tolerance round-off)."""
    assert lu_hung.range_bound(1 / 3) == pytest.approx(-1.0, abs=1e-14)
    assert lu_hung.range_bound(1 / math.sqrt(3)) == pytest.approx(0.0, abs=1e-14)
    assert lu_hung.range_bound(1.0) == pytest.approx(1.0, abs=1e-14)
    with pytest.raises(ValueError, match="eta"):
        lu_hung.allowed_ball_range(0.3)


# ---------------------------------------------------------------- worked positions (A4)
@pytest.mark.parametrize("eta,beta_star_deg", [(0.4, 130.54), (0.8, 54.90)])
def test_allowed_range_worked_numbers(eta, beta_star_deg):
    """[derived] note A4: beta* = 130.54 deg (eta 0.4), 54.90 deg (eta 0.8); printed to two
    decimals, so tolerance 0.005 deg."""
    lo, hi = lu_hung.allowed_ball_range(eta)
    assert math.degrees(lo) == pytest.approx(beta_star_deg, abs=0.005)
    assert math.degrees(hi) == pytest.approx(360 - beta_star_deg, abs=0.005)


@pytest.mark.parametrize("eta,expect", [(0.4, (138.59, 221.41)), (0.8, (97.18, 262.82))])
def test_three_ball_worked_positions(eta, expect):
    """[derived] note A4 with b3 = 180 deg (two-decimal print: tolerance 0.005 deg)."""
    b1, b2, b3 = lu_hung.three_ball_positions(eta, math.pi)
    assert math.degrees(b1) == pytest.approx(expect[0], abs=0.005)
    assert math.degrees(b2) == pytest.approx(expect[1], abs=0.005)


def test_one_third_puts_all_balls_opposite():
    """[derived] eta = 1/3: the only balanced set is all three balls at 180 deg."""
    b = lu_hung.three_ball_positions(1 / 3, math.pi)
    assert np.allclose(np.degrees(b), 180.0, atol=1e-5)
    lo, hi = lu_hung.allowed_ball_range(1 / 3)
    assert lo == pytest.approx(math.pi, abs=1e-6) and hi == pytest.approx(math.pi, abs=1e-6)


@pytest.mark.parametrize("eta,expect", [(0.6, (146.44, 213.56)), (1.2, (114.62, 245.38))])
def test_two_ball_worked_positions(eta, expect):
    """[derived] note A4, two-ball balancer (two-decimal print: tolerance 0.005 deg)."""
    b1, b2 = lu_hung.two_ball_positions(eta)
    assert (math.degrees(b1), math.degrees(b2)) == pytest.approx(expect, abs=0.005)
    with pytest.raises(ValueError, match="eta"):
        lu_hung.two_ball_positions(0.49)


@pytest.mark.parametrize("eta", [0.34, 0.4, 0.6, 0.8, 1.0, 1.5])
def test_eq34_members_satisfy_eqs_25_26(eta):
    """P2: b1, b2 from eq. (34) satisfy eqs. (25)-(26) to machine precision over the whole
    allowed range of b3, and every ball lies in the allowed range."""
    lo, hi = lu_hung.allowed_ball_range(eta)
    for b3 in np.linspace(lo, hi, 41)[1:-1]:
        b = np.array(lu_hung.three_ball_positions(eta, b3))
        assert np.sum(np.cos(b)) == pytest.approx(-1 / eta, abs=1e-12)
        assert np.sum(np.sin(b)) == pytest.approx(0.0, abs=1e-12)
        c = np.cos(b)
        assert np.all(c <= lu_hung.range_bound(eta) + 1e-9)
    if lo > 0:
        with pytest.raises(ValueError, match="outside the allowed range"):
            lu_hung.three_ball_positions(eta, 0.5 * lo)


# ---------------------------------------------------------------- unbalanced branches
@pytest.mark.parametrize("omega", [0.3, 0.8, 1.2, 2.0, 3.0])
@pytest.mark.parametrize("eta", [0.2, 0.4])
def test_closed_form_branches_match_rotating_frame(omega, eta):
    """Eqs. 14-24 (atan2 form) equal the general rotating-frame solution (a different
    derivation: quadratic in |p|), and each solves the static equations (10)-(12) to 1e-12."""
    g = Groups(eta=eta, mu=0.9, delta=20, zeta=0.1)
    closed = lu_hung.unbalanced_branches(omega, eta, 0.1, mu=0.9)
    general = rf.unbalanced_equilibria(g, omega, with_eigenvalues=False)
    assert len(closed) == len(general)
    key = lambda e: (e[0], round(e[1], 9))  # noqa: E731
    a = sorted(key((b.signed_count, b.r)) for b in closed)
    b = sorted(key((e.signed_count, e.radius)) for e in general)
    assert a == b
    for br in closed:
        q = np.concatenate([[br.r * math.cos(br.theta), br.r * math.sin(br.theta)],
                            br.ball_angles])
        assert np.max(np.abs(rf.residual(g, omega, q))) < 1e-12


@pytest.mark.parametrize("omega", np.linspace(0.2, 3.0, 15))
def test_eta_below_one_third_all_second_branches_negative(omega):
    """Paper L234 (P3): for eta < 1/3 (eta = 0.2) every r~_i2 is negative and r~_11 > 0."""
    br = lu_hung.unbalanced_branches(omega, 0.2, 0.1, mu=0.9, keep_negative=True)
    second = [b.r for b in br if b.branch == 2]
    assert second and all(r < 0 for r in second)
    r11 = [b.r for b in br if b.signed_count == 3 and b.branch == 1]
    assert r11 and r11[0] > 0


@pytest.mark.parametrize("zeta,expect", [(0.05, (0.9674, 1.0337)), (0.1, (0.9359, 1.0685)),
                                         (0.2, (0.8761, 1.1414))])
def test_r11_saddle_node_speeds(zeta, expect):
    """[derived] note A4: for eta = 0.4 the r11/r12 pair exists for Omega <= lo and >= hi
    (four-decimal print: tolerance 5e-5).  Independently, the rotating-frame solver finds a
    pair of all-balls-together states (|m| = 3, r > 0) just outside and none just inside the
    interval (above it the pair has the balls opposite the rotor deflection, case ii)."""
    lo, hi = lu_hung.saddle_node_speeds(zeta, 0.4, 3)
    assert (lo, hi) == pytest.approx(expect, abs=5e-5)
    g = Groups(eta=0.4, zeta=zeta)
    count = lambda om: sum(abs(e.signed_count) == 3 for e in  # noqa: E731
                           rf.unbalanced_equilibria(g, om, with_eigenvalues=False))
    assert count(lo * 0.999) == 2 and count(0.5 * (lo + hi)) == 0 and count(hi * 1.001) == 2


def test_r11_bell_shrinks_with_ball_damping():
    """Paper L241-249 (Fig. 4, eta = 0.2): r11 is unstable inside a bell in the zeta-Omega
    plane that shrinks as zeta_b grows; at a point A it is unstable for zeta_b = 0.1 and
    stable for 0.3.  [derived] note A8 (mu 0.9, delta 10): zeta = 0.05 is unstable on
    1.34-1.77 with zeta_b = 0.1 and stable everywhere with 0.3 - so Omega = 1.5 is such an A.
    Also [derived]: zeta = 0.1, zeta_b = 0.1 unstable on 1.49-1.61 (checked at both sides)."""
    def r11_stable(zeta, zeta_b, om):
        g = Groups(eta=0.2, mu=0.9, delta=10, zeta=zeta, zeta_b=zeta_b)
        (eq,) = [e for e in rf.unbalanced_equilibria(g, om)
                 if e.signed_count == 3 and e.branch == 1]
        return eq.stable
    assert not r11_stable(0.05, 0.1, 1.5)
    assert r11_stable(0.05, 0.3, 1.5)
    assert r11_stable(0.1, 0.1, 1.46) and not r11_stable(0.1, 0.1, 1.55)
    assert r11_stable(0.1, 0.1, 1.64)


def test_bad_input_messages():
    with pytest.raises(ValueError, match="Omega"):
        lu_hung.unbalanced_branches(0.0, 0.4, 0.1)
    with pytest.raises(ValueError, match="n_balls"):
        lu_hung.balance_exists(0, 0.4)
    with pytest.raises(ValueError, match="eta"):
        lu_hung.balance_exists(3, -1.0)
