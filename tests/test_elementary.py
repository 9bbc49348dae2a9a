"""The branch-free elementary functions of the compiled kernels against the C library.

The module docstring of :mod:`abb_gym.physics.elementary` states the accuracy; these tests
measure it on dense samples (uniform, logarithmic down to subnormals, near the zeros of sin
and cos, up to the stated argument limit).  The reference is glibc through numpy, itself
within 1 ulp, so each bound allows the stated error plus that 1 ulp.
"""
from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from abb_gym.physics import elementary as el


@njit(cache=False)
def _sincos_all(x):
    s = np.empty_like(x)
    c = np.empty_like(x)
    for i in range(x.size):
        s[i], c[i] = el.sincos(x[i])
    return s, c


def _over_array(fn):
    """A compiled loop applying the scalar compiled function ``fn`` to every entry."""
    @njit(cache=False)
    def apply(x):
        out = np.empty_like(x)
        for i in range(x.size):
            out[i] = fn(x[i])
        return out
    return apply


_exp_all = _over_array(el.exp_bounded)
_tanh_all = _over_array(el.tanh)
_log_all = _over_array(el.log_positive)
_pow2_all = _over_array(el._pow2)


def _ulps(got, ref):
    """|got - ref| in units of the last place of ref."""
    return np.abs(got - ref) / np.spacing(np.abs(ref))


def _arguments(limit: float) -> np.ndarray:
    rng = np.random.default_rng(7)
    near_zeros = (np.arange(-2000, 2000) * (np.pi / 2))[:, None] + \
        rng.normal(scale=1e-9, size=(4000, 5))
    parts = [rng.uniform(-10.0, 10.0, 200_000),
             rng.uniform(-limit, limit, 200_000),
             np.sign(rng.normal(size=50_000)) * 10.0 ** rng.uniform(-310, np.log10(limit), 50_000),
             near_zeros.ravel(), np.array([0.0, -0.0, 5e-324, np.pi, limit, -limit])]
    return np.concatenate(parts)


def test_sincos_within_2_ulp_of_the_result_or_of_one_near_zeros():
    x = _arguments(el.SINCOS_LIMIT)
    s, c = _sincos_all(x)
    # stated: 2 ulp of the result, or of 1 where the function is near a zero; +1 ulp for the
    # reference
    assert np.all((_ulps(s, np.sin(x)) <= 3.0) | (np.abs(s - np.sin(x)) <= 3 * np.spacing(1.0)))
    assert np.all((_ulps(c, np.cos(x)) <= 3.0) | (np.abs(c - np.cos(x)) <= 3 * np.spacing(1.0)))
    # sin(-x) = -sin(x) and cos(-x) = cos(x) exactly: the reduction is symmetric
    s_neg, c_neg = _sincos_all(-x)
    assert np.array_equal(s_neg, -s) and np.array_equal(c_neg, c)


def test_exp_bounded_within_2_ulp_on_its_range():
    rng = np.random.default_rng(3)
    y = np.concatenate([rng.uniform(-708.0, 709.0, 200_000), rng.uniform(-1.0, 1.0, 100_000),
                        np.array([-708.0, 0.0, 709.0, 1e-300, -1e-300])])
    assert _ulps(_exp_all(y), np.exp(y)).max() <= 3.0


def test_log_positive_within_1_ulp_on_normal_numbers():
    """Stated: 1 ulp over every positive normal double; +1 ulp for the reference.  Samples:
    log-uniform over the whole range, dense on [0.5, 2] and around 1 (where log is near its
    zero: there the bound is 2 ulp of the spacing at the result, not of 1), and the ends."""
    rng = np.random.default_rng(11)
    x = np.concatenate([10.0 ** rng.uniform(np.log10(el.LOG_MIN), 308.0, 200_000),
                        rng.uniform(0.5, 2.0, 200_000), 1.0 + rng.normal(scale=1e-9, size=20_000),
                        np.array([el.LOG_MIN, 0.5, 1.0, np.sqrt(2.0), 2.0, 10.0, 1.7e308])])
    got = _log_all(x)
    ref = np.log(x)
    assert np.all((_ulps(got, ref) <= 2.0) | (got == ref))
    assert got[x == 1.0][0] == 0.0


@pytest.mark.parametrize("scale", [1e-300, 1e-8, 1.0, 30.0])
def test_tanh_within_6_ulp_relative_everywhere(scale):
    rng = np.random.default_rng(int(-np.log10(scale)) + 400)
    x = rng.normal(scale=scale, size=200_000)
    got = _tanh_all(x)
    assert _ulps(got, np.tanh(x)).max() <= 7.0
    assert np.array_equal(_tanh_all(-x), -got)
    assert np.all(np.abs(got) <= 1.0)


def test_pow2_from_the_exponent_bits_is_exact_on_its_range():
    """The power of two that scales exp and tanh, built from its exponent bits, is exactly
    2^n for every whole n the exponential can need (normal doubles)."""
    n = np.arange(-1022, 1024, dtype=np.float64)
    np.testing.assert_array_equal(_pow2_all(n), np.ldexp(1.0, n.astype(np.int64)))


# ------------------------------------------------------------------ no-alias kernels
def _argument_attributes(fn, sig) -> str:
    """The LLVM ``define`` line of ``fn`` compiled for ``sig`` (its argument attributes)."""
    fn.compile(sig)
    ir = fn.inspect_llvm(fn.signatures[-1])
    # the function itself (numba's calling convention: return pointer first), not its wrappers
    return next(line for line in ir.splitlines()
                if line.startswith("define") and "%retptr" in line)


def test_noalias_reaches_the_compiler_only_when_asked():
    """``njit(noalias=True)`` of abb_gym._numba marks the array data pointers ``noalias`` in
    the compiled function (the promise that spares the lane loops their overlap checks); a
    plain ``njit`` does not."""
    from abb_gym._numba import NOALIAS, njit
    if not NOALIAS:
        pytest.skip("this numba has no noalias compiler flag")

    def axpy(x, y):
        for i in range(x.shape[0]):
            y[i] += 2.0 * x[i]

    sig = "void(float64[::1], float64[::1])"
    marked = _argument_attributes(njit(noalias=True)(axpy), sig)
    plain = _argument_attributes(njit(axpy), sig)
    # numba marks its return and exception pointers noalias in both; the arrays add theirs
    assert marked.count("noalias") >= plain.count("noalias") + 2, (marked, plain)


def test_the_lane_loops_are_compiled_without_alias_checks():
    """The right-hand side, the drag rates and the RK4/ETDRK4 steps carry the option (their
    callers never pass overlapping arrays; the single, vector and simulate paths that run
    them agree bit for bit in tests/test_envs_batch.py)."""
    from abb_gym._numba import NOALIAS
    from abb_gym.physics import integrators as integ
    from abb_gym.physics import model as mdl
    for fn in (mdl.accelerations_block, mdl.drag_rates_block, integ._rk4_step,
               integ._etdrk4_step):
        assert fn.targetoptions.get("noalias", False) is NOALIAS, fn.py_func.__name__
