"""Elementary functions written so that LLVM vectorises the loops that call them (numba compiles a call to the C
library's ``exp`` or ``log`` as a scalar call per element, which was most of the time of the kernels that use them).
Each is within 2 ulp of numpy's value on its stated domain (tests/tracking/test_vecmath.py); the kernels inline them.
Without numba they are plain Python (the same arithmetic)."""
from __future__ import annotations

import numpy as np

try:
    import numba
except ImportError:                 # plain Python (only the tests call them so)
    numba = None

from .._numba import jit

_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01    # fdlibm's split of ln 2: k * _LN2_HI is exact for |k| < 2^11
_LN2_LO = 1.90821492927058770002e-10
_MAGIC = 6755399441055744.0         # 1.5 * 2^52: adding it rounds to an integer held in the low mantissa bits
_TWO_M64 = 5.421010862427522e-20    # 2^-64
_TWO52 = 4503599627370496.0         # 2^52
# fdlibm's (musl's) Remez coefficients of log(1 + f) in s = f / (2 + f)
_LG1, _LG2, _LG3, _LG4 = 6.666666666666735130e-01, 3.999999999940941908e-01, 2.857142874366239149e-01, \
    2.222219843214978396e-01
_LG5, _LG6, _LG7 = 1.818357216161805012e-01, 1.531383769920937332e-01, 1.479819860511658591e-01


def _jit_contract(fn):
    """``fn`` compiled with fused multiply-adds allowed (``contract``: one rounding instead of two)."""
    return jit(fn, contract=True)


if numba is not None:
    from llvmlite import ir
    from numba.core import types
    from numba.extending import intrinsic

    @intrinsic
    def _bits(typingctx, x):
        """The IEEE-754 bits of a float64 as an int64 (a bitcast)."""
        if not isinstance(x, types.Float):
            return None

        def codegen(context, builder, signature, args):
            return builder.bitcast(args[0], ir.IntType(64))
        return types.int64(types.float64), codegen

    @intrinsic
    def _from_bits(typingctx, b):
        """The float64 whose IEEE-754 bits are the int64 ``b`` (a bitcast)."""
        if not isinstance(b, types.Integer):
            return None

        def codegen(context, builder, signature, args):
            return builder.bitcast(args[0], ir.DoubleType())
        return types.float64(types.int64), codegen
else:                               # plain Python
    def _bits(x):
        return int(np.float64(x).view(np.int64))

    def _from_bits(b):
        return float(np.int64(b).view(np.float64))


@_jit_contract
def _exp_nonpositive(x):
    """``exp(x)`` for ``x <= 0`` (``-inf`` allowed; not NaN): ``x = k ln2 + r``, ``|r| <= ln2 / 2`` (Cody-Waite,
    fdlibm's split of ln 2), ``exp(r)`` by its Taylor polynomial to degree 13 (remainder below 5e-18 relative),
    times ``2^k`` built from its bits (``2^(k+64)``, always normal, then ``2^-64``: one rounding for a subnormal
    result). Below -746 the result is 0, as ``exp``'s. Within 2 ulp of the correctly rounded value."""
    if x < -746.0:
        x = -746.0
    kd = x * _LOG2E + _MAGIC
    k = kd - _MAGIC
    r = (x - k * _LN2_HI) - k * _LN2_LO
    p = 1.0 / 6227020800.0
    p = p * r + 1.0 / 479001600.0
    p = p * r + 1.0 / 39916800.0
    p = p * r + 1.0 / 3628800.0
    p = p * r + 1.0 / 362880.0
    p = p * r + 1.0 / 40320.0
    p = p * r + 1.0 / 5040.0
    p = p * r + 1.0 / 720.0
    p = p * r + 1.0 / 120.0
    p = p * r + 1.0 / 24.0
    p = p * r + 1.0 / 6.0
    p = p * r + 0.5
    p = p * r + 1.0
    p = p * r + 1.0
    ki = _bits(kd) - _bits(_MAGIC)
    return p * _from_bits((ki + 1087) << 52) * _TWO_M64


@jit
def _log1p_parts(f):
    """musl's ``log(1 + f)`` for ``1 + f`` in ``[sqrt(2)/2, sqrt(2))`` (after FreeBSD's e_log.c), in its parts:
    ``(s, hfsq, r)`` with ``s = f / (2 + f)``, ``hfsq = f^2 / 2`` and ``r`` the Remez polynomial in ``s``, so that
    ``log(1 + f) = f - hfsq + s (hfsq + r)`` (the callers add the terms in the order that keeps their precision)."""
    hfsq = 0.5 * f * f
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    t1 = w * (_LG2 + w * (_LG4 + w * _LG6))
    t2 = z * (_LG1 + w * (_LG3 + w * (_LG5 + w * _LG7)))
    return s, hfsq, t2 + t1


@jit
def _log_positive(x):
    """``log(x)`` for positive, normal, finite ``x`` (the caller checks; zero, subnormals, infinities and NaN are out
    of its domain): musl's ``log``, ``x = 2^k (1 + f)`` with ``1 + f`` in ``[sqrt(2)/2, sqrt(2))`` taken from the
    bits, ``log(1 + f)`` by :func:`_log1p_parts`, plus ``k ln 2`` in two parts; ``k`` turned into a double through
    the bits (``2^52 + k + 1023``), which vectorises where an integer conversion would not. Within 1 ulp of the
    correct value (2 of numpy's)."""
    ix = _bits(x)
    hx = (ix >> 32) + (0x3ff00000 - 0x3fe6a09e)
    dk = (_from_bits((hx >> 20) | 0x4330000000000000) - _TWO52) - 1023.0
    f = _from_bits((((hx & 0x000fffff) + 0x3fe6a09e) << 32) | (ix & 0xffffffff)) - 1.0
    s, hfsq, r = _log1p_parts(f)
    return s * (hfsq + r) + dk * _LN2_LO - hfsq + f + dk * _LN2_HI


# musl's log10 (after FreeBSD's e_log10.c): log(1 + f) by the Remez polynomial of s = f / (2 + f), then the
# product with 1/ln 10 and the k log10(2) term in two parts; within 1 ulp of the correct value (glibc's, numpy's log10
# is also within 1 ulp: the two differ by at most 2 ulp). Written on integer views so that LLVM vectorises it.
_IVLN10HI, _IVLN10LO = 4.34294481878168880939e-01, 2.50829467116452752298e-11
_LOG10_2HI, _LOG10_2LO = 3.01029995663611771306e-01, 3.69423907715893078616e-13
_TINY = 2.2250738585072014e-308                 # the smallest normal double


@jit
def _log10_block(x, out, work, n):
    """``out[:n] = log10(x[:n])`` (musl's algorithm above) for positive normal finite ``x``; any other value goes to
    ``np.log10`` (zero, subnormal, infinite). ``work``: a scratch array of the same length."""
    xb = x.view(np.uint64)
    ob = out.view(np.uint64)
    wb = work.view(np.uint64)
    for i in range(n):                          # x = 2^k (1 + f), 1 + f in [sqrt(2)/2, sqrt(2))
        ix = xb[i]
        hx = (ix >> np.uint64(32)) + np.uint64(0x3ff00000 - 0x3fe6a09e)
        ob[i] = (hx >> np.uint64(20)) | np.uint64(0x4330000000000000)        # k + 1023 as the double 2^52 + (k+1023)
        wb[i] = (((hx & np.uint64(0x000fffff)) + np.uint64(0x3fe6a09e)) << np.uint64(32)) | (ix & np.uint64(0xffffffff))
    for i in range(n):
        dk = (out[i] - _TWO52) - 1023.0
        f = work[i] - 1.0
        s, hfsq, r = _log1p_parts(f)
        work[i] = f - hfsq
        wb[i] = wb[i] & np.uint64(0xffffffff00000000)                     # hi: the top 21 bits of f - hfsq
        hi = work[i]
        lo = f - hi - hfsq + s * (hfsq + r)
        val_hi = hi * _IVLN10HI
        y = dk * _LOG10_2HI
        val_lo = dk * _LOG10_2LO + (lo + hi) * _IVLN10LO + lo * _IVLN10HI
        top = y + val_hi
        val_lo += (y - top) + val_hi
        out[i] = val_lo + top
    odd = 0                                     # an integer reduction vectorises; the guarded call would not
    for i in range(n):
        odd |= not (x[i] >= _TINY and x[i] < np.inf)
    if odd:
        for i in range(n):
            if not (x[i] >= _TINY and x[i] < np.inf):
                out[i] = np.log10(x[i])
