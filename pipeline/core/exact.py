"""Python's exactly rounded sum and its three-dimensional norm, as kernels: ``math.fsum`` and ``math.hypot(x, y, z)``.

Algorithm 1's compiled tick (:mod:`pipeline.force.framework`) forms a norm several times a tick and re-sums its
filter's window exactly once a window.  It must give the bits the interpreted product gave (a seeded study's
records are byte-identical across the change, and a recording made by either replays through the other), so these
are CPython's own algorithms, operation for operation, not NumPy's or the C library's (``np.hypot`` and a square root
of the sum of squares round differently in the last bit):

* :func:`hypot3` is ``vector_norm`` of CPython 3.11's ``Modules/mathmodule.c`` for three coordinates: lossless
  scaling by a power of two, Veltkamp--Dekker splitting of each square, a compensated (Neumaier) sum with ``1.0``
  as its guard, and one differential correction of the square root; a vector whose largest component is below
  2⁻¹⁰²⁴ (``frexp``'s exponent below −1023, where the scale would overflow) is divided by the largest instead,
  with a plain compensated sum.  Faithfully rounded, almost always correctly rounded.  CPython 3.12 rewrote the
  same steps with two accumulators, which can differ in the last bit on rare inputs: the product's records are
  this kernel's on any interpreter (the replay forms them with it too), and the test that holds it to
  ``math.hypot`` bit for bit runs on 3.11 (``tests/pipeline/test_exact.py``).
* :func:`fsum` is ``math_fsum``'s Shewchuk partials with its half-even fix-up across partials, the same on every
  CPython since 2.6; where ``fsum`` raises on intermediate overflow it gives the plain left-to-right sum (±inf or
  NaN: a filter's window of finite samples near DBL_MAX may sum beyond it, and the filter must not raise at 1 kHz;
  its next re-sum repairs the running sum).
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.core.compiled import State, kernel

__all__ = ["fsum", "hypot3"]

_SPLIT = 134217729.0  # 2**27 + 1: Veltkamp's constant for splitting a double into two 26-bit halves


@kernel
def _norm_scaled(x: float, y: float, z: float, mx: float) -> float:
    """``vector_norm`` of finite non-negative ``x, y, z`` with ``mx`` their largest, at least 2⁻¹⁰²⁴."""
    _, max_e = math.frexp(mx)
    scale = math.ldexp(1.0, -max_e)
    csum = 1.0
    frac = 0.0
    for i in range(3):
        v = x if i == 0 else (y if i == 1 else z)
        v *= scale  # lossless scaling
        t = v * _SPLIT
        hi = t - (t - v)
        lo = v - hi
        v = hi * hi
        oldcsum = csum
        csum += v
        frac += (oldcsum - csum) + v
        v = 2.0 * hi * lo
        oldcsum = csum
        csum += v
        frac += (oldcsum - csum) + v
        frac += lo * lo
    h = math.sqrt(csum - 1.0 + frac)
    t = h * _SPLIT
    hi = t - (t - h)
    lo = h - hi
    v = -hi * hi
    oldcsum = csum
    csum += v
    frac += (oldcsum - csum) + v
    v = -2.0 * hi * lo
    oldcsum = csum
    csum += v
    frac += (oldcsum - csum) + v
    v = -lo * lo
    oldcsum = csum
    csum += v
    frac += (oldcsum - csum) + v
    v = csum - 1.0 + frac
    return (h + v / (2.0 * h)) / scale


@kernel
def hypot3(x: float, y: float, z: float) -> float:
    """``math.hypot(x, y, z)`` of CPython 3.11, bit for bit (see the module's docstring)."""
    x = abs(x)
    y = abs(y)
    z = abs(z)
    found_nan = x != x or y != y or z != z
    mx = 0.0
    if x > mx:
        mx = x
    if y > mx:
        mx = y
    if z > mx:
        mx = z
    if mx == math.inf:
        return mx
    if found_nan:
        return math.nan
    if mx == 0.0:
        return mx
    _, max_e = math.frexp(mx)
    if max_e >= -1023:
        return _norm_scaled(x, y, z, mx)
    # the largest below 2**-1024: ldexp(1, -max_e) would overflow, so 3.11 divides by it instead of scaling, with a
    # plain compensated sum (3.12 rescales by DBL_MIN and recurses: another last bit on some such inputs)
    csum = 1.0
    frac = 0.0
    for i in range(3):
        v = x if i == 0 else (y if i == 1 else z)
        v /= mx
        v = v * v
        oldcsum = csum
        csum += v
        frac += (oldcsum - csum) + v
    return mx * math.sqrt(csum - 1.0 + frac)


@kernel
def fsum(values: State) -> float:
    """``math.fsum(values)`` (a 1-D array); the plain left-to-right sum where ``fsum`` would raise on intermediate
    overflow (see the module's docstring).  ``-inf + inf`` raises ValueError, as ``fsum`` does."""
    p = np.empty(len(values) + 1)  # the partials: never more than the values summed
    n = 0
    special_sum = 0.0
    inf_sum = 0.0
    lo = 0.0
    for k in range(len(values)):
        x = values[k]
        xsave = x
        i = 0
        for j in range(n):
            y = p[j]
            if abs(x) < abs(y):
                x, y = y, x
            hi = x + y
            yr = hi - x
            lo = y - yr
            if lo != 0.0:
                p[i] = lo
                i += 1
            x = hi
        n = i
        if x != 0.0:
            if x - x != 0.0:  # non-finite: an overflow of finite values, or an inf or a NaN among them
                if xsave - xsave == 0.0:
                    total = 0.0  # fsum raises "intermediate overflow": the plain sum instead
                    for v in values:
                        total += v
                    return total
                if xsave == math.inf or xsave == -math.inf:
                    inf_sum += xsave
                special_sum += xsave
                n = 0
            else:
                p[n] = x
                n += 1
    if special_sum != 0.0:
        if inf_sum != inf_sum:
            raise ValueError("-inf + inf in fsum")
        return special_sum
    hi = 0.0
    if n > 0:
        n -= 1
        hi = p[n]
        lo = 0.0
        while n > 0:  # sum_exact from the top, stopping when the sum becomes inexact
            x = hi
            n -= 1
            y = p[n]
            hi = x + y
            yr = hi - x
            lo = y - yr
            if lo != 0.0:
                break
        # half-even rounding across partials (fsum([1e-16, 1, 1e16]) rounds up)
        if n > 0 and ((lo < 0.0 and p[n - 1] < 0.0) or (lo > 0.0 and p[n - 1] > 0.0)):
            y = lo * 2.0
            x = hi + y
            yr = x - hi
            if y == yr:
                hi = x
    return float(hi)
