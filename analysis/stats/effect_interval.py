"""An interval for the rank-biserial correlation, the effect size of the paired Wilcoxon test.

The matched-pairs rank-biserial correlation r = (W⁺ − W⁻)/(W⁺ + W⁻) (Kerby 2014) has no distribution-free interval
of its own; the report gives the bootstrap one: the participants (their differences ON − OFF) resampled with
replacement, r recomputed on each resample exactly as the test ranks (zeros dropped, or ranked, as the zero method
says), and the bias-corrected and accelerated (BCa) interval of :func:`scipy.stats.bootstrap` -- with a fixed seed, so
the same data give the same interval.  Where every resample gives the same r (every difference of one sign: r = ±1)
BCa is undefined and the percentile interval is given, [r, r].  With 10 participants the interval is wide: that is
what 10 participants say about an effect size.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import numpy.typing as npt
from scipy import stats as sps

__all__ = ["BOOTSTRAP_RESAMPLES", "BOOTSTRAP_SEED", "rank_biserial", "rank_biserial_interval"]

#: Resamples of the bootstrap, and its seed.
BOOTSTRAP_RESAMPLES = 9999
BOOTSTRAP_SEED = 20260406


def rank_biserial(d: npt.ArrayLike, zero_method: str = "wilcox", axis: int = -1) -> np.ndarray:
    """(W⁺ − W⁻)/(W⁺ + W⁻) of the differences along ``axis`` (vectorised: one value per row of a resample).

    ``wilcox``: zeros are dropped before ranking; ``pratt``: ranked with the others, their ranks then dropped;
    ``zsplit``: ranked, their rank sum split half to each side (so it counts in the denominator).  NaN where no
    difference is ranked.
    """
    x = np.moveaxis(np.asarray(d, dtype=np.float64), axis, -1)
    ranks = sps.rankdata(np.abs(x), axis=-1)  # zeros, the smallest |d|, take the lowest ranks
    zeros = x == 0
    if zero_method == "wilcox":  # the ranks among the non-zero differences: less the zeros below them
        ranks = ranks - zeros.sum(axis=-1, keepdims=True)
    w_plus = np.where(x > 0, ranks, 0.0).sum(axis=-1)
    w_minus = np.where(x < 0, ranks, 0.0).sum(axis=-1)
    total = w_plus + w_minus
    if zero_method == "zsplit":
        total = total + np.where(zeros, ranks, 0.0).sum(axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        out: np.ndarray = (w_plus - w_minus) / total
    return out


def rank_biserial_interval(d: npt.ArrayLike, zero_method: str = "wilcox", confidence: float = 0.95, *,
                           resamples: int = BOOTSTRAP_RESAMPLES, seed: int = BOOTSTRAP_SEED,
                           ) -> tuple[float, float, str]:
    """The bootstrap interval of the rank-biserial correlation of ``d`` (module docstring): (low, high, method).

    ``method`` is ``BCa`` or ``percentile`` (every resample the same r); (NaN, NaN, "") for fewer than 2 differences
    or none ranked.
    """
    x = np.asarray(d, dtype=np.float64)
    x = x[np.isfinite(x)]
    ranked = x != 0 if zero_method == "wilcox" else np.ones(x.size, dtype=bool)
    if x.size < 2 or not ranked.any() or not x.any():
        return math.nan, math.nan, ""

    def stat(sample: np.ndarray, axis: int = -1) -> np.ndarray:
        return rank_biserial(sample, zero_method, axis=axis)

    for method in ("BCa", "percentile"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a degenerate BCa: NaN, and the percentile interval instead
            res = sps.bootstrap((x,), stat, n_resamples=resamples, confidence_level=confidence, method=method,
                                rng=np.random.default_rng(seed), vectorized=True)
        lo, hi = float(res.confidence_interval.low), float(res.confidence_interval.high)
        if math.isfinite(lo) and math.isfinite(hi):
            return lo, hi, method
    return math.nan, math.nan, ""
