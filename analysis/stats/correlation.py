"""Correlation of two paired variables (e.g. per-trial TCT against RMSE) with its test and Fisher-z interval."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import special
from scipy import stats as sps

__all__ = ["UNIT_R_TOLERANCE", "CorrelationResult", "correlation", "unit_snapped"]

#: A correlation this close to ±1 is ±1.  A perfect line's r is a ratio of dot products whose last bit depends on the
#: CPU's arithmetic (the BLAS kernel: AVX-512 gives -0.9999999999999999 where Haswell gives -1.0), and a product
#: that treats ±1 apart (its p is 0, its interval a point) must do so on every CPU: 1e-12 is far above that rounding
#: (a few ulps, 2.2e-16 each) and far below any correlation a study reports to four decimals.
UNIT_R_TOLERANCE = 1e-12


def unit_snapped(r: float) -> float:
    """``r`` made ±1 when it is within :data:`UNIT_R_TOLERANCE` of it (and so never beyond ±1 by rounding)."""
    return math.copysign(1.0, r) if abs(r) >= 1.0 - UNIT_R_TOLERANCE else r


@dataclass(frozen=True, slots=True)
class CorrelationResult:
    """A correlation between two paired variables and its test.

    Attributes
    ----------
    method : str
        ``"spearman"`` or ``"pearson"``.
    n : int
        Complete pairs used.
    n_dropped_nan : int
        Pairs dropped because either value was NaN.
    r : float
        Spearman's ρ or Pearson's r.
    p_value : float
        Two-sided p-value of H0: no association (SciPy's ``spearmanr``: t with
        n − 2 df; ``pearsonr``: exact under bivariate normality).
    ci_low, ci_high : float
        Fisher-z confidence interval: ``tanh(atanh(r) ± z_{1−α/2}·SE)`` with
        SE = 1/√(n − 3) (Pearson) or the Bonett–Wright (2000) SE
        √((1 + ρ²/2)/(n − 3)) (Spearman). NaN when n < 4.
    ci_level : float
        Nominal level of the interval.
    computable : bool
        False when the correlation is undefined (n < 3, a constant variable, inf values).
    note : str
        Empty, or why not computable / which degenerate case occurred.
    """

    method: str
    n: int
    n_dropped_nan: int
    r: float
    p_value: float
    ci_low: float
    ci_high: float
    ci_level: float
    computable: bool
    note: str


def correlation(
    x: npt.ArrayLike, y: npt.ArrayLike, *, method: str = "spearman", confidence: float = 0.95
) -> CorrelationResult:
    """Correlation of paired observations (e.g. per-trial TCT against RMSE) with its test and CI.

    Parameters
    ----------
    x, y : array_like
        Paired values, same length, 1-D. Pairs with a NaN are dropped and counted.
    method : {"spearman", "pearson"}
        Spearman's rank correlation (default: robust to the skewed TCT) or Pearson's r.
    confidence : float
        Level of the Fisher-z interval.

    Returns
    -------
    CorrelationResult
        ``r`` and the two-sided ``p_value`` from :func:`scipy.stats.spearmanr` /
        :func:`scipy.stats.pearsonr`; the interval ``tanh(atanh r ± z·SE)`` with
        SE = 1/√(n−3) for Pearson and SE = √((1 + r²/2)/(n−3)) for Spearman
        (Bonett & Wright 2000, Psychometrika 65:23–28). Not computable (NaN
        fields and a note) when n < 3, a variable is constant, or a value is infinite.
    """
    meth = str(method).lower()
    if meth not in ("spearman", "pearson"):
        raise ValueError(f"method = {method!r}: allowed are spearman, pearson")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence = {confidence}: allowed is 0 < confidence < 1")
    xa = np.asarray(x, dtype=np.float64)
    ya = np.asarray(y, dtype=np.float64)
    if xa.ndim != 1 or ya.ndim != 1 or xa.size != ya.size:
        raise ValueError(f"x and y must be 1-D of equal length, got shapes {xa.shape} and {ya.shape}")
    keep = ~(np.isnan(xa) | np.isnan(ya))
    n = int(keep.sum())
    dropped = int(xa.size - n)
    xa, ya = xa[keep], ya[keep]
    nan = math.nan

    def fail(note: str) -> CorrelationResult:
        if dropped:
            note = f"{dropped} pairs dropped because a value was NaN; {note}"
        return CorrelationResult(meth, n, dropped, nan, nan, nan, nan, confidence, False, note)

    if not (np.isfinite(xa).all() and np.isfinite(ya).all()):
        return fail("a value is infinite: values must be finite")
    if n < 3:
        return fail(f"only {n} complete pairs: a correlation test needs at least 3")
    for name, arr in (("x", xa), ("y", ya)):
        if np.ptp(arr) == 0:
            return fail(f"{name} is constant ({arr[0]:g}): the correlation is undefined")
    res = sps.spearmanr(xa, ya) if meth == "spearman" else sps.pearsonr(xa, ya)
    # a perfect association is ±1 with p 0 on every CPU (UNIT_R_TOLERANCE), not ±0.9999999999999999 on some
    r = unit_snapped(float(res.statistic))
    p = 0.0 if abs(r) == 1.0 else float(res.pvalue)
    notes = [f"{dropped} pairs dropped because a value was NaN"] if dropped else []
    lo = hi = nan
    if n >= 4:
        se = math.sqrt((1.0 + r * r / 2.0) / (n - 3)) if meth == "spearman" else 1.0 / math.sqrt(n - 3)
        zq = float(special.ndtri(0.5 + confidence / 2.0))
        with np.errstate(divide="ignore"):
            zr = float(np.arctanh(r))  # ±inf at ±1 (snapped): the interval is the point ±1
        lo, hi = math.tanh(zr - zq * se), math.tanh(zr + zq * se)
    else:
        notes.append("n = 3: no Fisher-z interval (needs n ≥ 4)")
    # p clipped into [0, 1] (a doubled tail can round past 1)
    return CorrelationResult(meth, n, dropped, r, min(max(p, 0.0), 1.0), lo, hi, confidence, True, "; ".join(notes))
