"""Direction-preserving tanh scaling of the haptic force (the paper, eq. H_scaled).

``f_scaled = f / |f| · tanh(|f| / f_scale) · f_max``

The paper's form divides by ``|f|`` and is undefined at zero; written naively it
also overflows (``sqrt(x²+y²+z²)`` above ~1.3e154), underflows (below ~1e-162)
and passes NaN straight to the motors (docs/science.md §7).  This module is the
one definition of the law used everywhere (pipeline, simulated participant,
figures); it is exact to about an ulp on every finite input and never returns
a non-finite value or a magnitude above ``f_max_n``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from fractions import Fraction
from numbers import Real

from pipeline.core import exact
from pipeline.core.compiled import fingerprint, kernel
from pipeline.force.config import LIMIT_RANGE_N
from pipeline.force.frames import Vec3

__all__ = ["LIMIT_RANGE_N", "clamp3", "clamp_norm", "scale_components", "scale_force", "scale_kernel",
           "scale_magnitude", "small_signal_gain"]

# Below t = |f|/f_scale = 1e-4 the series tanh(t)/t = 1 - t²/3 + 2t⁴/15 is exact
# to rounding (the next term, 17t⁶/315, is < 1e-25); above it math.tanh is.
_SERIES_T = 1e-4
# tanh(17) = 1 - 3.4e-15: below this, |out| ≤ f_max·tanh(t)·(1 + 4 ulp) < f_max.
_SATURATED_T = 17.0
_INF = math.inf
_HYPOT = math.hypot
_TINY = 2.0**-600  # an exact power of two that brings an overflowing norm's components back in range


def small_signal_gain(f_max_n: float = 3.0, f_scale_n: float = 7.0) -> float:
    """Slope of the law at zero, ``f_max / f_scale`` (3/7 ≈ 0.4286 for the paper)."""
    return f_max_n / f_scale_n


def scale_magnitude(force_n: float, f_max_n: float = 3.0, f_scale_n: float = 7.0) -> float:
    """Scalar form of the law: ``f_max · tanh(F / f_scale)``, odd in ``F``.

    Used where only the magnitude matters (the simulated participant's percept,
    the figures).  Non-finite input gives 0, like :func:`scale_force`.
    """
    return scale_force((force_n, 0.0, 0.0), f_max_n, f_scale_n)[0]


def scale_force(f: Sequence[float], f_max_n: float = 3.0, f_scale_n: float = 7.0) -> Vec3:
    """Scale a haptic-frame force by eq. (H_scaled) of the paper.

    Parameters
    ----------
    f
        Force ``(fx, fy, fz)`` in the haptic frame, N.  Any real numbers,
        including integers or Fractions beyond the double range.
    f_max_n
        Saturation magnitude, N (the paper: 3 N).  Must be finite and > 0.
    f_scale_n
        Scale of the transition from linear to saturated, N (the paper: 7 N).
        Must be finite and > 0.

    Returns
    -------
    tuple of float
        The scaled force, N: parallel to ``f``, magnitude
        ``f_max · tanh(|f| / f_scale) ≤ f_max``.  Zero for ``|f| = 0`` and for
        any non-finite component (the loop's watchdog raises the fault; this
        function only guarantees nothing non-finite reaches a device).

    Notes
    -----
    Near zero the law is linear with gain ``f_max/f_scale``; the series for
    ``tanh(t)/t`` keeps it within about an ulp of that line down to subnormals.
    ``math.hypot`` keeps the norm exact over the whole double range; inputs
    whose norm overflows are rescaled by a power of two first.
    """
    check_limits(f_max_n, f_scale_n)
    try:
        fx, fy, fz = f
    except (TypeError, ValueError):
        raise ValueError(f"f = {f!r}: expected three force components (fx, fy, fz)") from None
    if not (type(fx) is float and type(fy) is float and type(fz) is float):
        conv = _to_floats(fx, fy, fz)
        if conv is None:  # finite values beyond the double range: saturate along their direction
            return _saturate_huge(fx, fy, fz, f_max_n)
        fx, fy, fz = conv
    return scale_components(fx, fy, fz, f_max_n, f_scale_n)




def check_limits(f_max_n: float, f_scale_n: float) -> None:
    """Raise ValueError unless both parameters are real numbers in :data:`LIMIT_RANGE_N`."""
    lo, hi = LIMIT_RANGE_N
    for name, v in (("f_max_n", f_max_n), ("f_scale_n", f_scale_n)):
        if isinstance(v, bool) or not isinstance(v, Real) or not (lo <= v <= hi):
            raise ValueError(f"{name} = {v!r}: must be a number of newtons from {lo:g} to {hi:g}")


def _compile_clamp(callees: int) -> Callable[..., tuple[float, float, float]]:
    """:func:`clamp3` closed over the :func:`pipeline.core.compiled.fingerprint` of :mod:`pipeline.core.exact` (numba
    keys its cache on a kernel's own file and closure: a closure must hold plain values only, never another kernel,
    whose pickled form differs from process to process)."""

    @kernel
    def clamp3(x: float, y: float, z: float, limit: float) -> tuple[float, float, float]:
        """``(x, y, z)`` shrunk (by as few ulps as needed) so that ``hypot(x, y, z) ≤ limit`` (:func:`clamp_norm`)."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        m = exact.hypot3(x, y, z)
        while m > limit:
            k = (limit / m) * (1.0 - 2.0**-52)
            x, y, z = x * k, y * k, z * k
            m = exact.hypot3(x, y, z)
        return (x, y, z)

    return clamp3


def _compile_scale(callees: int) -> Callable[..., tuple[float, float, float]]:
    """:func:`scale_kernel` closed over the same fingerprint (it calls :func:`clamp3`, a global of this module)."""

    @kernel
    def scale_kernel(fx: float, fy: float, fz: float, f_max_n: float, f_scale_n: float) -> tuple[float, float,
                                                                                                  float]:
        """:func:`scale_components`, compiled."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        # x - x is 0.0 for finite x and NaN for ±inf/NaN: one cheap test for all three.
        if (fx - fx) + (fy - fy) + (fz - fz) != 0.0:
            return (0.0, 0.0, 0.0)
        n = exact.hypot3(fx, fy, fz)
        if n == 0.0:
            return (0.0, 0.0, 0.0)
        if n == _INF:
            # finite components whose norm overflows: an exact power-of-two rescale
            s = _TINY
            fx, fy, fz = fx * s, fy * s, fz * s
            n = exact.hypot3(fx, fy, fz)
            return clamp3(fx / n * f_max_n, fy / n * f_max_n, fz / n * f_max_n, f_max_n)
        t = n / f_scale_n
        if t < _SERIES_T:
            t2 = t * t
            k = (f_max_n / f_scale_n) * (1.0 - t2 / 3.0 + 2.0 * t2 * t2 / 15.0)
            return (fx * k, fy * k, fz * k)
        k = f_max_n * math.tanh(t) / n
        if t > _SATURATED_T:
            # tanh(t) is within 15 ulps of 1: the few roundings in k·f_i could
            # leave |out| an ulp above f_max, so clamp explicitly.
            return clamp3(fx * k, fy * k, fz * k, f_max_n)
        return (fx * k, fy * k, fz * k)

    return scale_kernel


#: :func:`scale_components`, compiled (Algorithm 1's compiled tick calls it), and :func:`clamp_norm`, compiled.
clamp3 = _compile_clamp(fingerprint(exact))
scale_kernel = _compile_scale(fingerprint(exact))


def scale_components(fx: float, fy: float, fz: float, f_max_n: float, f_scale_n: float) -> Vec3:
    """Kernel of :func:`scale_force` for float components and pre-validated limits.

    The 1 kHz loop validates ``f_max_n``/``f_scale_n`` once at configuration and
    calls this directly; everything else should call :func:`scale_force`.  The arithmetic is :func:`scale_kernel`'s.
    """
    return scale_kernel(float(fx), float(fy), float(fz), float(f_max_n),
                        float(f_scale_n))


def clamp_norm(v: Vec3, limit: float) -> Vec3:
    """Return ``v`` shrunk (by as few ulps as needed) so that ``hypot(*v) ≤ limit`` (:func:`clamp3`)."""
    return clamp3(float(v[0]), float(v[1]), float(v[2]), float(limit))


def _to_floats(fx: object, fy: object, fz: object) -> tuple[float, float, float] | None:
    """Convert real numbers to floats.

    Returns None if a component is finite but beyond the double range (and
    none is NaN or infinite); a NaN or infinite component wins and yields
    floats that :func:`scale_components` turns into zero.
    """
    out = []
    overflow = False
    for c in (fx, fy, fz):
        if isinstance(c, bool) or not isinstance(c, Real):
            raise ValueError(f"force component {c!r} is not a real number; expected three numbers (fx, fy, fz)")
        try:
            out.append(float(c))
        except OverflowError:
            overflow = True
            out.append(0.0)
    if any(v - v != 0.0 for v in out):
        return (math.nan, math.nan, math.nan)
    if overflow:
        return None
    return out[0], out[1], out[2]


def _saturate_huge(fx: object, fy: object, fz: object, f_max_n: float) -> Vec3:
    """Direction of a force whose components exceed DBL_MAX, at magnitude f_max (tanh(∞) = 1)."""
    # any Real that _to_floats let through (a huge int, a Decimal, ...); typeshed has no Fraction(Real) overload
    comps = [Fraction(c) for c in (fx, fy, fz)]  # type: ignore[call-overload]  # see above
    big = max(abs(c) for c in comps)
    ux, uy, uz = (float(c / big) for c in comps)  # each in [-1, 1], exact to rounding
    n = _HYPOT(ux, uy, uz)
    return clamp_norm((ux / n * f_max_n, uy / n * f_max_n, uz / n * f_max_n), f_max_n)
