"""Elementary functions that the compiler can vectorise: sin, cos, exp, log, tanh without calls.

The equations of motion need sin and cos of the rotor and ball angles and tanh of the smoothed
rolling resistance at every right-hand side, and with extended effects the sine and cosine of
each touching pair's half gap and the log and power of the fluid drag's c_d(Re) law.  Calls
into the C library block LLVM's loop vectoriser, so the compiled kernels evaluate them with
the branch-free polynomials below (argument reduction plus the fdlibm minimax polynomials),
which vectorise across environments and give the same result in every path (single
environment, vector environment, ``simulate``).
The power of two that scales the exponential is built from its exponent bits (a bit
reinterpretation, :func:`_to_bits` / :func:`_from_bits`, which vectorises) rather than by ten
comparisons, and the exponential's series is evaluated partly by Estrin's scheme: a shorter
chain of dependent operations.  Together they cut one right-hand side of ``yoshida_odd`` (two
tanh per call) from 41 to 33 ns per lane at 64 lanes, at the same measured accuracy
(``python -m abb_gym.benchmarks.rhs_cost``).

Accuracy against the C library (``tests/test_elementary.py`` measures it):

=====================  ============================  ==========================================
function               arguments                     error
=====================  ============================  ==========================================
:func:`sincos`         ``|x| <= 1.6e6`` rad          <= 2 ulp of the result, or 2 ulp of 1 near
                                                     a zero of the function (absolute 4.5e-16)
:func:`exp_bounded`    ``[-708, 709]``               <= 2 ulp
:func:`log_positive`   positive normal finite        <= 1 ulp
:func:`tanh`           all finite                    <= 6 ulp relative
=====================  ============================  ==========================================

**Vectorisation needs two LLVM options**, set here when the module loads (they are process
wide: numba code compiled afterwards in the same process sees them too):

* ``-unroll-threshold=2000`` so that the ball loops of the kernels, whose length is a
  compile-time constant, are unrolled whole, which leaves the loop over environments straight
  enough to vectorise;
* ``-force-vector-interleave=2``: each pass of a vectorised lane loop computes two vectors of
  lanes (16 float64 lanes with AVX-512) instead of one.  One lane's right-hand side is a single
  chain of some hundreds of dependent operations, too long for the processor to start the
  next pass's chain before this one ends, so one vector at a time leaves the arithmetic units
  waiting on latencies; LLVM's own choice for a loop body this large is one.  The lanes' results
  are the same bits (each lane does the same operations; no loop here sums across lanes).
  The vector environment gains with it in float64 and float32, although the right-hand side
  alone is slower in float32 (a pass holds 32 float32 lanes, and more of them spill);
  ``python -m abb_gym.benchmarks.rhs_cost`` and ``abb-gym bench speed`` measure both.
  In one-lane code the loop over the ten state rows is the one that vectorises, and two
  vectors of 8 rows do not fit in 10: the step functions give one-lane blocks a constant row
  count (:func:`abb_gym.physics.model.rows_of`), which LLVM unrolls instead.

The lane loops read and write many arrays; they are compiled with the
promise that those do not overlap (``noalias``: :mod:`abb_gym._numba`), so LLVM needs no
run-time overlap checks, whose default budget is too small for the equations of motion.

Beyond ``|x| = 1.6e6`` rad (a rotor angle after 1.6e6 rad: 85 h at 5 rad/s, 11 min at
2400 rad/s) the three-part reduction of pi/2 loses digits; the environments and ``simulate``
integrate runs far shorter than that.
"""
from __future__ import annotations

import llvmlite.binding as _llvm
import numpy as np
from llvmlite import ir as _ir
from numba.core import types
from numba.extending import intrinsic, overload

from .._numba import njit

_llvm.set_option("abb_gym", "-unroll-threshold=2000")
_llvm.set_option("abb_gym", "-force-vector-interleave=2")

__all__ = ["sincos", "exp_bounded", "log_positive", "tanh", "SINCOS_LIMIT", "SINCOS_LIMIT_F32",
           "like", "is_single"]

SINCOS_LIMIT = 1.6e6
SINCOS_LIMIT_F32 = 1.0e3


# ------------------------------------------------------------------ precision
def like(x, value):
    """``value`` in the precision of ``x`` (a float32 or float64 scalar or array), in compiled
    code only.  Kernels written once for both precisions spell every constant so
    (``like(w, 2.0) * w``) and cast every value a float64 helper returns: numba types a bare
    ``0.5`` as float64, float32 times float64 is float64, and a variable has one type in the
    whole function, so one bare constant (or one ``x = 0.0`` that a branch later assigns a
    float32) would turn a float32 kernel's arithmetic into float64.  In float64
    ``like(x, c)`` is ``c`` itself: the float64 kernels are unchanged bit for bit."""
    raise TypeError("like() is for compiled code")


def _float_of(x):
    ty = x.dtype if isinstance(x, types.Array) else x
    if isinstance(ty, types.Float):
        return ty
    return None


@overload(like, inline="always")
def _like(x, value):
    ty = _float_of(x)
    if ty is None:
        return None
    cast = np.float32 if ty.bitwidth == 32 else np.float64

    def impl(x, value):
        return cast(value)
    return impl


def is_single(x):
    """Whether ``x`` (a float scalar or array) is float32: a compile-time constant of compiled
    code (the branch it guards is compiled away in the other precision)."""
    raise TypeError("is_single() is for compiled code")


@overload(is_single, inline="always")
def _is_single(x):
    ty = _float_of(x)
    if ty is None:
        return None
    single = ty.bitwidth == 32

    def impl(x):
        return single
    return impl


_TWO_OVER_PI = 6.36619772367581382433e-01
# pi/2 in three 33-bit parts (fdlibm): j * part is exact for |j| < 2^20
_PIO2_1 = 1.57079632673412561417e+00
_PIO2_2 = 6.07710050630396597660e-11
_PIO2_3 = 2.02226624871116645580e-21
_PIO2_3T = 8.47842766036889956997e-32
# fdlibm __kernel_sin / __kernel_cos on [-pi/4, pi/4]
_S1 = -1.66666666666666324348e-01
_S2 = 8.33333333332248946124e-03
_S3 = -1.98412698298579493134e-04
_S4 = 2.75573137070700676789e-06
_S5 = -2.50507602534068634195e-08
_S6 = 1.58969099521155010221e-10
_C1 = 4.16666666666666019037e-02
_C2 = -1.38888888888741095749e-03
_C3 = 2.48015872894767294178e-05
_C4 = -2.75573143513906633035e-07
_C5 = 2.08757232129817482790e-09
_C6 = -1.13596475577881948265e-11
# exp: ln 2 in two parts (fdlibm) and the Taylor coefficients 1/k! on |r| <= ln2 / 2
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_INV_LN2 = 1.44269504088896338700e+00
# 1.5 2^52: x + this rounds x to a whole number and leaves it in the low mantissa bits
_ROUND_SHIFT = 6755399441055744.0
_ROUND_SHIFT_BITS = 0x4338000000000000


@njit(cache=True, inline="always")
def _in_quadrant(j, s, c):
    """(sin x, cos x) from s = sin r, c = cos r of the reduced r = x - j pi/2, either precision."""
    # quadrant q = j mod 4, in floating point: swap for odd q, sin negative for q = 2, 3, cos
    # for q = 1, 2 (selects on float comparisons: no switch, no integers)
    q = j - like(j, 4.0) * np.floor(like(j, 0.25) * j)
    one, two = like(j, 1.0), like(j, 2.0)
    swap = (q == one) | (q == like(j, 3.0))
    sin_x = c if swap else s
    cos_x = s if swap else c
    sin_x = -sin_x if q >= two else sin_x
    cos_x = -cos_x if (q == one) | (q == two) else cos_x
    return sin_x, cos_x


@njit(cache=True, inline="always")
def _sincos64(x):
    """(sin x, cos x) of a float64 without library calls (module docstring for the accuracy)."""
    # np.floor (a float), not int() or math.floor (integers): AVX2 has no vector conversion
    # between doubles and 64-bit integers, and a scalar one stops LLVM from vectorising
    j = np.floor(x * _TWO_OVER_PI + 0.5)
    w = j * _PIO2_3
    r = ((x - j * _PIO2_1) - j * _PIO2_2) - w
    tail = ((x - j * _PIO2_1) - j * _PIO2_2 - r) - w  # what the last subtraction rounded off
    tail -= j * _PIO2_3T
    z = r * r
    v = z * r
    ps = _S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))
    s = r - ((z * (0.5 * tail - v * ps) - tail) - v * _S1)
    pc = z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))
    hz = 0.5 * z
    one_minus = 1.0 - hz
    c = one_minus + (((1.0 - one_minus) - hz) + (z * pc - r * tail))
    return _in_quadrant(j, s, c)


@intrinsic
def _to_bits(typingctx, x):
    """The IEEE bits of a float32 or float64 as a signed integer of its width (a
    reinterpretation, free in vector code)."""
    if not isinstance(x, types.Float):
        return None
    width = x.bitwidth

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], _ir.IntType(width))
    return types.Integer.from_bitwidth(width)(x), codegen


@intrinsic
def _from_bits(typingctx, i, like_x):
    """The float of ``like_x``'s type whose IEEE bits are the low bits of the integer ``i``
    (inverse of :func:`_to_bits`; wider integers come from integer promotion, which keeps the
    low bits)."""
    if not (isinstance(i, types.Integer) and isinstance(like_x, types.Float)
            and i.bitwidth >= like_x.bitwidth):
        return None
    width = like_x.bitwidth

    def codegen(context, builder, signature, args):
        v = args[0]
        if i.bitwidth != width:
            v = builder.trunc(v, _ir.IntType(width))
        return builder.bitcast(v, _ir.DoubleType() if width == 64 else _ir.FloatType())
    return like_x(i, like_x), codegen


@njit(cache=True, inline="always")
def _pow2(n):
    """2^n, exactly, for a whole number n in [-1022, 1023] given as a float, built from its
    exponent bits with vector integer operations only (AVX2 has no conversion from double to
    int64: adding 1.5 2^52 leaves n in the low bits of the sum instead)."""
    k = _to_bits(n + _ROUND_SHIFT) - _ROUND_SHIFT_BITS
    return _from_bits((k + 1023) << 52, n)


@njit(cache=True, inline="always")
def _expm1_reduced(y):
    """(2^n, e^r - 1) with y = n ln 2 + r, |r| <= ln 2 / 2: e^y - 1 = 2^n (e^r - 1) + 2^n - 1."""
    n = np.floor(y * _INV_LN2 + 0.5)
    r = (y - n * _LN2_HI) - n * _LN2_LO
    # Taylor series of e^r - 1 = r (1 + r/2! + ... + r^11/12!), truncation below 2e-17
    # relative on |r| <= 0.347.  The leading terms by Horner's rule (their roundings decide
    # the result's), the tail from r^4/5! by Estrin's scheme: its rounding is 1e-3 of the
    # result's, and the lane loops wait on a chain of 14 dependent operations instead of 22
    r2 = r * r
    r4 = r2 * r2
    tail = (((1.0 / 24 + r * (1.0 / 120)) + r2 * (1.0 / 720 + r * (1.0 / 5040)))
            + r4 * ((1.0 / 40320 + r * (1.0 / 362880)) + r2 * (1.0 / 3628800 + r * (
                1.0 / 39916800)) + r4 * (1.0 / 479001600)))
    p = r * (1.0 + r * (1.0 / 2 + r * (1.0 / 6 + r * tail)))
    return _pow2(n), p


@njit(cache=True, inline="always")
def exp_bounded(y):
    """e^y for y in [-708, 709] without library calls (<= 2 ulp)."""
    scale, p = _expm1_reduced(y)
    return scale + scale * p


# log: the fdlibm minimax coefficients of (log(1+f) - 2s) / s^3 in s^2, s = f / (2 + f)
_LG1 = 6.666666666666735130e-01
_LG2 = 3.999999999940941908e-01
_LG3 = 2.857142874366239149e-01
_LG4 = 2.222219843214978396e-01
_LG5 = 1.818357216161805012e-01
_LG6 = 1.531383769920937332e-01
_LG7 = 1.479819860511658591e-01
_SQRT2 = 1.41421356237309514547e+00
# 2^52 + 1023 and its bits: the biased exponent e, placed in the low mantissa bits of 2^52,
# reads back as 2^52 + e (the exponent as a float without an int64-to-double conversion)
_TWO52 = 4503599627370496.0
_TWO52_BITS = 0x4330000000000000
_MANTISSA = 0x000FFFFFFFFFFFFF
_ONE_BITS = 0x3FF0000000000000
LOG_MIN = 2.2250738585072014e-308


@njit(cache=True, inline="always")
def log_positive(x):
    """Natural logarithm of a positive, normal, finite float64 (``LOG_MIN <= x < inf``)
    without library calls (<= 1 ulp; fdlibm's ``e_log.c`` without its special cases, which
    only save work).  Outside that range the result is meaningless, not NaN: callers keep
    their arguments in it."""
    bits = _to_bits(x)
    e = _from_bits(_TWO52_BITS | (bits >> 52), x) - (_TWO52 + 1023.0)
    m = _from_bits((bits & _MANTISSA) | _ONE_BITS, x)  # x = 2^e m, m in [1, 2)
    big = m > _SQRT2
    m = 0.5 * m if big else m  # exact; m in [sqrt(2)/2, sqrt(2)], |f| <= 0.414
    e = e + 1.0 if big else e
    f = m - 1.0
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    r = z * (_LG1 + w * (_LG3 + w * (_LG5 + w * _LG7))) + w * (_LG2 + w * (_LG4 + w * _LG6))
    hfsq = 0.5 * f * f
    return e * _LN2_HI - ((hfsq - (s * (hfsq + r) + e * _LN2_LO)) - f)


@njit(cache=True, inline="always")
def _tanh64(x):
    """tanh x of a float64 without library calls: ``u / (u + 2)`` with ``u = e^(2|x|) - 1``
    evaluated without cancellation, so the relative error stays a few ulp down to the smallest
    x."""
    a = min(abs(x), 20.0)  # tanh(20) = 1 - 8e-18: 1 in double precision
    scale, p = _expm1_reduced(2.0 * a)
    u = scale * p + (scale - 1.0)
    t = u / (u + 2.0)
    return t if x >= 0.0 else -t


# ------------------------------------------------------------------ float32
# pi/2 in three parts whose products with a whole j < 2^11 are exact in float32 (the
# Cody-Waite split of Cephes' sinf, doubled); a float32 block holds the rotor angle within a
# turn of [0, 2 pi) (:mod:`abb_gym.physics.batch`, "Precision"), so the arguments stay small
_PIO2_1F = 1.5703125
_PIO2_2F = 4.837512969970703125e-4
_PIO2_3F = 7.54978995489188216e-8
# Cephes sinf / cosf minimax polynomials on [-pi/4, pi/4]
_S1F = -1.6666654611e-1
_S2F = 8.3321608736e-3
_S3F = -1.9515295891e-4
_C1F = 4.166664568298827e-2
_C2F = -1.388731625493765e-3
_C3F = 2.443315711809948e-5
# ln 2 in two parts (Cephes expf), 1.5 2^23 and its bits (float32 rounding to whole numbers)
_LN2_HI_F = 0.693359375
_LN2_LO_F = -2.12194440e-4
_ROUND_SHIFT_F = 12582912.0
_ROUND_SHIFT_BITS_F = 0x4B400000


@njit(cache=True, inline="always")
def _sincos32(x):
    """(sin x, cos x) of a float32, ``|x| <= SINCOS_LIMIT_F32`` (module docstring)."""
    f = np.float32
    j = np.floor(x * f(_TWO_OVER_PI) + f(0.5))
    r = ((x - j * f(_PIO2_1F)) - j * f(_PIO2_2F)) - j * f(_PIO2_3F)
    z = r * r
    s = r + r * z * (f(_S1F) + z * (f(_S2F) + z * f(_S3F)))
    c = (f(1.0) - f(0.5) * z) + z * z * (f(_C1F) + z * (f(_C2F) + z * f(_C3F)))
    return _in_quadrant(j, s, c)


@njit(cache=True, inline="always")
def _tanh32(x):
    """tanh x of a float32 (module docstring): ``u / (u + 2)``, ``u = e^(2|x|) - 1``."""
    f = np.float32
    a = min(abs(x), f(9.0))  # tanh(9) = 1 - 3e-8: 1 in float32
    y = f(2.0) * a
    n = np.floor(y * f(_INV_LN2) + f(0.5))
    r = (y - n * f(_LN2_HI_F)) - n * f(_LN2_LO_F)
    # Taylor series of e^r - 1 to r^7/7!: truncation below 2e-8 relative on |r| <= 0.347
    p = r * (f(1.0) + r * (f(0.5) + r * (f(1.0 / 6) + r * (f(1.0 / 24) + r * (
        f(1.0 / 120) + r * (f(1.0 / 720) + r * f(1.0 / 5040)))))))
    k = _to_bits(n + f(_ROUND_SHIFT_F)) - _ROUND_SHIFT_BITS_F
    scale = _from_bits((k + 127) << 23, n)
    u = scale * p + (scale - f(1.0))
    t = u / (u + f(2.0))
    return t if x >= f(0.0) else -t


# ------------------------------------------------------------------ by precision
def _by_precision(f64, f32):
    """A stub whose compiled calls go to ``f64`` or ``f32`` by the argument's type."""
    def stub(x):
        raise TypeError("compiled code only")

    @overload(stub)
    def _pick(x):
        if isinstance(x, types.Float):
            chosen = f32 if x.bitwidth == 32 else f64

            def impl(x):
                return chosen(x)
            return impl
        return None
    return stub


_sincos_any = _by_precision(_sincos64, _sincos32)
_tanh_any = _by_precision(_tanh64, _tanh32)


@njit(cache=True, inline="always")
def sincos(x):
    """(sin x, cos x) without library calls, in the precision of ``x`` (float64 or float32;
    the module docstring states the accuracy and the argument range of each)."""
    return _sincos_any(x)


@njit(cache=True, inline="always")
def tanh(x):
    """tanh x without library calls, in the precision of ``x`` (float64 or float32)."""
    return _tanh_any(x)
