"""pipeline/core/exact.py: CPython's ``math.hypot`` of three and ``math.fsum`` as kernels, bit for bit.

Algorithm 1's compiled tick forms its norms with :func:`hypot3` and re-sums its filter's window with :func:`fsum`;
the records it writes are the interpreted product's only if these are CPython's results to the last bit, at the
extremes too (zero of either sign, subnormals, huge values, infinities, NaN).  ``hypot3`` is CPython 3.11's
algorithm: on 3.12 and later ``math.hypot`` is another (the same accuracy, a different last bit on rare inputs), so
the comparison with it runs on 3.11, the product's CI interpreter; the compiled kernel and its ``py_func`` are held
to each other everywhere.
"""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from pipeline.core.exact import fsum, hypot3

ANY = st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True)
FINITE = st.floats(allow_nan=False, allow_infinity=False, allow_subnormal=True)
# values of every magnitude, the filter's window of forces among them
MAGNITUDES = st.one_of(FINITE, st.floats(-100.0, 100.0), st.floats(1e300, 1.7976931348623157e308),
                       st.floats(-1.7976931348623157e308, -1e300), st.floats(-1e-310, 1e-310))
ON_311 = pytest.mark.skipif(sys.version_info[:2] != (3, 11), reason="hypot3 is CPython 3.11's algorithm")


def _bits(x: float) -> int:
    """A float as its bits (0.0 differs from -0.0), every NaN as one."""
    return -1 if math.isnan(x) else int(np.float64(x).view(np.uint64))


@ON_311
@settings(max_examples=1500)
@given(x=ANY, y=ANY, z=ANY)
@example(5e-324, 5e-324, 5e-324)  # all subnormal: divided by the largest, not scaled
@example(1.53783614892744e-309, 1.53783614892744e-309, 1.53783614892744e-309)  # 3.12's rescaling would round up
@example(1.7976931348623157e308, 1.7976931348623157e308, 1.0)  # the sum of squares overflows, the norm too
@example(3.0, 4.0, 12.0)  # exact: 13
@example(-0.0, 0.0, -0.0)
@example(math.inf, math.nan, 1.0)  # an infinity wins over a NaN
def test_hypot3_is_math_hypot(x: float, y: float, z: float) -> None:
    assert _bits(hypot3(x, y, z)) == _bits(math.hypot(x, y, z))


@given(x=ANY, y=ANY, z=ANY)
def test_hypot3_compiled_is_its_python(x: float, y: float, z: float) -> None:
    assert _bits(hypot3(x, y, z)) == _bits(hypot3.py_func(x, y, z))


def _python_fsum(values: list[float]) -> float | str:
    """``math.fsum``, with :func:`pipeline.core.exact.fsum`'s fallback to the plain sum on an intermediate
    overflow ("VE" for its ValueError)."""
    try:
        return math.fsum(values)
    except OverflowError:
        return sum(values)
    except ValueError:
        return "VE"


@settings(max_examples=1000)
@given(values=st.one_of(st.lists(MAGNITUDES, max_size=24), st.lists(ANY, max_size=8)))
@example([1e-16, 1.0, 1e16])  # the half-even fix-up across partials rounds up
@example([1.7976931348623157e308, 1.7976931348623157e308, -1.7976931348623157e308])  # intermediate overflow
@example([math.inf, -math.inf])  # fsum's ValueError
@example([math.inf, 1.0, math.nan])
@example([])
def test_fsum_is_math_fsum(values: list[float]) -> None:
    want = _python_fsum(values)
    for f in (fsum, fsum.py_func):
        try:
            with np.errstate(all="ignore"):  # (the interpreted kernel's NumPy scalars warn of an inf - inf)
                got: float | str = f(np.array(values, dtype=np.float64))
        except ValueError:
            got = "VE"
        assert got == want if isinstance(want, str) else (isinstance(got, float) and _bits(got) == _bits(want))
