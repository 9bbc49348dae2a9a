"""The evaluation's confidence intervals against scipy.stats (the package computes them from
scipy.special's quantiles, to spare every evaluation the import of scipy.stats)."""
import numpy as np
import pytest
from scipy import stats

from abb_gym.evaluation.statistics import LEVEL, mean_ci, paired_difference_ci, share_ci


@pytest.mark.parametrize("n", [1, 2, 3, 7, 20, 100, 1000])
def test_share_ci_equals_scipy_wilson(n):
    """Every k of n: the Wilson interval of scipy.stats.binomtest to 1e-14 (the same formula;
    only the operation order may differ), inside [0, 1], around the share."""
    for k in range(n + 1) if n <= 100 else (0, 1, 17, 500, 999, 1000):
        p, low, high = share_ci(k, n)
        ref = stats.binomtest(k, n).proportion_ci(confidence_level=LEVEL, method="wilson")
        assert p == k / n
        assert low == pytest.approx(ref.low, abs=1e-14)
        assert high == pytest.approx(ref.high, abs=1e-14)
        assert 0.0 <= low <= p <= high <= 1.0


def test_share_ci_refuses_impossible_counts():
    with pytest.raises(ValueError, match=r"successes must be in \[0, n\]"):
        share_ci(11, 10)
    with pytest.raises(ValueError, match="successes"):
        share_ci(-1, 10)
    assert all(np.isnan(share_ci(0, 0)))


@pytest.mark.parametrize("size", [2, 3, 10, 200])
def test_mean_ci_equals_scipy_t_interval(size):
    """Student-t interval of scipy.stats.t.interval to 1e-12 relative."""
    rng = np.random.default_rng(size)
    v = rng.lognormal(size=size)
    mean, low, high, n = mean_ci(v)
    ref_low, ref_high = stats.t.interval(LEVEL, size - 1, loc=v.mean(), scale=stats.sem(v))
    assert n == size and mean == pytest.approx(v.mean(), rel=1e-15)
    assert low == pytest.approx(ref_low, rel=1e-12)
    assert high == pytest.approx(ref_high, rel=1e-12)
    d_mean, d_low, d_high, _ = paired_difference_ci(v, 0.5 * v)
    ref = stats.t.interval(LEVEL, size - 1, loc=(0.5 * v).mean(), scale=stats.sem(0.5 * v))
    assert (d_low, d_high) == pytest.approx(ref, rel=1e-12)
