"""Confidence intervals of evaluation results (95 % unless stated).

* :func:`mean_ci` - mean with a Student-t interval over the finite values; for a metric that
  cannot be negative (``nonnegative=True``) the interval is clipped at 0, since a negative
  bound is no possible value.
* :func:`share_ci` - a share of successes with the Wilson score interval (Newcombe 1998, the
  formula of ``scipy.stats.binomtest(...).proportion_ci(method="wilson")``), which stays
  inside [0, 1] and behaves at 0 and at n successes, where the normal approximation
  collapses.
* :func:`paired_difference_ci` - mean and t-interval of per-episode differences of two
  policies on the same machines (paired: the machine-to-machine spread cancels).
"""
from __future__ import annotations

import math

import numpy as np
# the two quantile functions, not scipy.stats: importing scipy.stats took 0.85 s of every
# evaluation's start (scipy.special 0.25 s); tests/test_evaluation_statistics.py checks the
# intervals against scipy.stats
from scipy.special import ndtri, stdtrit

__all__ = ["mean_ci", "share_ci", "paired_difference_ci", "mean_interval", "paired_interval",
           "LEVEL"]

LEVEL = 0.95


def mean_ci(values, nonnegative: bool = False) -> tuple[float, float, float, int]:
    """(mean, low, high, n) over the finite ``values``; NaN bounds below two values."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return math.nan, math.nan, math.nan, 0
    mean = float(v.mean())
    if v.size < 2:
        return mean, math.nan, math.nan, int(v.size)
    half = float(stdtrit(v.size - 1, 0.5 + LEVEL / 2) * v.std(ddof=1) / math.sqrt(v.size))
    low = mean - half
    if nonnegative:
        low = max(0.0, low)
    return mean, low, mean + half, int(v.size)


def share_ci(successes: int, n: int) -> tuple[float, float, float]:
    """(share, low, high) of ``successes`` out of ``n`` (Wilson score interval)."""
    if n == 0:
        return math.nan, math.nan, math.nan
    k, n = int(successes), int(n)
    if not 0 <= k <= n:
        raise ValueError(f"successes must be in [0, n] = [0, {n}] (got {k})")
    p = k / n
    z = float(ndtri(0.5 + 0.5 * LEVEL))
    denom = 2 * (n + z * z)
    center = (2 * n * p + z * z) / denom
    delta = z / denom * math.sqrt(4 * n * p * (1 - p) + z * z)
    low = 0.0 if k == 0 else center - delta
    high = 1.0 if k == n else center + delta
    return p, low, high


def paired_difference_ci(a, b) -> tuple[float, float, float, int]:
    """(mean, low, high, n) of ``a - b`` over the pairs where both are finite."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape != b.shape:
        raise ValueError(f"paired values need the same episodes (shapes {a.shape} and {b.shape})")
    return mean_ci(a - b)


def _as_dict(mean: float, low: float, high: float, n: int) -> dict[str, float]:
    return {"mean": mean, "ci_low": low, "ci_high": high, "n": n}


def mean_interval(values, nonnegative: bool = False) -> dict[str, float]:
    """:func:`mean_ci` as ``{"mean", "ci_low", "ci_high", "n"}`` (the reports' form)."""
    return _as_dict(*mean_ci(values, nonnegative=nonnegative))


def paired_interval(a, b) -> dict[str, float]:
    """:func:`paired_difference_ci` of ``a - b`` in the form of :func:`mean_interval`."""
    return _as_dict(*paired_difference_ci(a, b))
