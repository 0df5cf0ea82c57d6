"""Paired ON-vs-OFF statistics: Wilcoxon signed-rank, Hodges–Lehmann, Holm, correlation.

Everything here works on *paired* data: one OFF value and one ON value per
participant (or per trial for trial-level analyses). The paired difference is
always

    d_i = ON_i − OFF_i

so a positive effect size, Hodges–Lehmann shift or ``z`` means "larger with
haptic feedback ON" (for errors and times: ON is *worse*; for success: ON is
better).

The signed-rank test reproduces :func:`scipy.stats.wilcoxon` (SciPy 1.17.1)
exactly — statistic, p-value and the choice of method under ``method="auto"`` —
but is computed here from first principles so that the report states what was
done and does not change silently with the SciPy version:

* ``"exact"`` -- the null distribution of W⁺ for *n* untied, non-zero
  differences (all 2ⁿ sign patterns equally likely), counted with integers, so
  a p-value is an exact multiple of 2⁻ⁿ (n = 10, W = 0 → p = 2/1024 = 0.001953125).
* ``"permutation"`` -- the exact sign-flip distribution of W⁺ given the
  observed mid-ranks (the conditional test that stays exact with ties and
  zeros), obtained by convolution rather than by enumerating 2ⁿ patterns.
* ``"approx"`` -- the normal approximation with the tie and zero corrections
  (SciPy's ``"asymptotic"``), optional continuity correction.

``method="auto"`` follows SciPy 1.17: with more than 50 pairs → approx;
otherwise no ties and no zeros → exact; otherwise at most 13 pairs →
permutation; otherwise → approx. "Pairs" counts zero differences too.

Hodges–Lehmann estimates use an exact order-statistic selection over the
n(n+1)/2 Walsh averages that never materializes them, so n = 10 000 pairs take
milliseconds rather than 50 million floats.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd
from scipy import special
from scipy import stats as sps

__all__ = [
    "ALTERNATIVES",
    "CorrelationResult",
    "DEFAULT_DECIMALS",
    "EXACT_MAX_N",
    "HL_EXACT_MAX_N",
    "METHODS",
    "PERMUTATION_AUTO_MAX_N",
    "PERMUTATION_MAX_N",
    "WilcoxonResult",
    "ZERO_METHODS",
    "correlation",
    "hodges_lehmann",
    "holm",
    "methods_text",
    "paired_wilcoxon",
    "results_frame",
    "signed_rank_null_counts",
]

ZERO_METHODS = ("wilcox", "pratt", "zsplit")
ALTERNATIVES = ("two-sided", "less", "greater")
#: Accepted ``method`` values (``"asymptotic"`` is accepted as SciPy's name for ``"approx"``).
METHODS = ("auto", "exact", "permutation", "approx", "asymptotic")
#: SciPy's ``auto`` rule: more pairs than this → normal approximation.
EXACT_MAX_N = 50
#: SciPy's ``auto`` rule: with ties or zeros, at most this many pairs → permutation test.
PERMUTATION_AUTO_MAX_N = 13
#: Largest n for an explicitly requested exact or permutation test (the
#: convolution grows as n³; beyond this the normal approximation is exact enough).
PERMUTATION_MAX_N = 400
#: Largest n for which the Hodges–Lehmann interval uses exact signed-rank critical values.
HL_EXACT_MAX_N = 50
#: Differences are rounded to this many decimals before testing (see :func:`paired_wilcoxon`).
DEFAULT_DECIMALS = 10

# Exact integer counts fit in int64 up to n = 62 (total 2⁶² patterns).
_INT_COUNTS_MAX_N = 62
_SCIPY_NAME = {"exact": "exact", "permutation": "permutation", "approx": "asymptotic"}


# ------------------------------------------------------------------------------------------------
# Result types
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class WilcoxonResult:
    """One paired Wilcoxon signed-rank test of ON vs OFF for one metric.

    Attributes
    ----------
    metric : str
        Name of the metric, with its unit (``"rmse_n"``, ``"tct_s"``).
    n_pairs : int
        Complete pairs: pairs given minus those where either side was NaN.
    n_dropped_nan : int
        Pairs dropped because a side was NaN (e.g. TCT undefined: no successes in a mode).
    n_used : int
        Pairs that enter the ranking: ``n_pairs − n_zero`` under ``zero_method="wilcox"``,
        ``n_pairs`` under ``"pratt"`` and ``"zsplit"``.
    n_zero : int
        Pairs with a zero difference (after rounding, see ``decimals``).
    n_ties : int
        Number of groups of equal ``|d|`` of size > 1 among the non-zero differences.
    method : str
        Method actually used: ``"exact"``, ``"permutation"`` or ``"approx"``; empty when not computable.
    zero_method : str
        ``"wilcox"`` (zeros discarded), ``"pratt"`` (zeros ranked, their ranks dropped)
        or ``"zsplit"`` (zero ranks split half to W⁺, half to W⁻).
    statistic : float
        As :func:`scipy.stats.wilcoxon` reports it: ``min(W⁺, W⁻)`` for a two-sided test,
        ``W⁺`` (sum of ranks of ON > OFF pairs) for a one-sided one.
    p_value : float
        p-value of the method used.
    z : float
        Normal-approximation z = (W⁺ − E W⁺)/SD W⁺ with the tie and zero
        corrections and *without* continuity correction; computed whatever the
        method, for the effect size. Positive when ON > OFF dominates.
    rank_biserial : float
        Matched-pairs rank-biserial correlation (Kerby 2014) ``(W⁺ − W⁻)/(W⁺ + W⁻)``,
        in [−1, 1]; +1 when every ranked pair has ON > OFF. Uses the W⁺, W⁻ of
        ``zero_method`` (under ``"zsplit"`` the split zero ranks enlarge the denominator).
    r : float
        ``z / sqrt(n_used)`` (Rosenthal's r, signed like ``z``; N is the number of
        ranked pairs, not 2N).
    median_off, median_on : float
        Medians of the OFF and ON values over the complete pairs.
    hl_estimate : float
        Hodges–Lehmann shift: median of the Walsh averages (d_i + d_j)/2, i ≤ j,
        of all complete differences *including zeros*.
    hl_ci_low, hl_ci_high : float
        Distribution-free confidence interval for the shift from the signed-rank
        distribution (see :func:`hodges_lehmann`).
    ci_level : float
        Confidence the interval actually achieves (≥ the requested level unless
        n is too small to reach it, in which case the interval is [min d, max d]).
    computable : bool
        False when no test is possible (see ``note``); test fields are then NaN.
    note : str
        Empty, or in plain words why the test is not computable or which
        degenerate case occurred.
    alternative : str
        ``"two-sided"``, ``"greater"`` (ON > OFF) or ``"less"`` (ON < OFF).
    w_plus, w_minus : float
        Rank sums of the ON > OFF and ON < OFF pairs (including split zero ranks under ``"zsplit"``).
    n_positive, n_negative : int
        Pairs with ON > OFF and ON < OFF.
    """

    metric: str
    n_pairs: int
    n_dropped_nan: int
    n_used: int
    n_zero: int
    n_ties: int
    method: str
    zero_method: str
    statistic: float
    p_value: float
    z: float
    rank_biserial: float
    r: float
    median_off: float
    median_on: float
    hl_estimate: float
    hl_ci_low: float
    hl_ci_high: float
    ci_level: float
    computable: bool
    note: str
    alternative: str = "two-sided"
    w_plus: float = math.nan
    w_minus: float = math.nan
    n_positive: int = 0
    n_negative: int = 0


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


# ------------------------------------------------------------------------------------------------
# Null distributions
# ------------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=128)
def _exact_counts(n: int) -> np.ndarray:
    """Number of the 2ⁿ sign patterns giving W⁺ = 0 … n(n+1)/2 (ranks 1…n), int64, n ≤ 62."""
    c = np.zeros(n * (n + 1) // 2 + 1, dtype=np.int64)
    c[0] = 1
    top = 0
    for k in range(1, n + 1):
        # rank k positive or not: c'[w] = c[w] + c[w − k]
        c[k : top + k + 1] += c[: top + 1].copy()
        top += k
    c.flags.writeable = False
    return c


def signed_rank_null_counts(n: int) -> np.ndarray:
    """Exact null distribution of the signed-rank statistic W⁺ for n untied, non-zero differences.

    Parameters
    ----------
    n : int
        Number of ranked differences, 0 ≤ n ≤ 62.

    Returns
    -------
    numpy.ndarray
        ``counts[w]`` = number of the 2ⁿ equally likely sign patterns with
        W⁺ = w, w = 0 … n(n+1)/2 (int64, read-only). P(W⁺ = w) = counts[w] / 2ⁿ.
    """
    if not 0 <= n <= _INT_COUNTS_MAX_N:
        raise ValueError(f"n = {n}: exact integer counts are available for 0 ≤ n ≤ {_INT_COUNTS_MAX_N}")
    return _exact_counts(int(n))


def _sign_flip_distribution(units: np.ndarray) -> tuple[np.ndarray, float]:
    """Distribution of Σ s_i·u_i (s_i ∈ {0, 1} fair coins) for non-negative integer ``units``.

    Returns ``(weights, total)`` with P(S = s) = weights[s] / total. Integer and
    exact while 2ⁿ fits int64; beyond, probabilities in float64 (total = 1).
    """
    size = int(units.sum()) + 1
    exact = units.size <= _INT_COUNTS_MAX_N
    w = np.zeros(size, dtype=np.int64 if exact else np.float64)
    w[0] = 1
    top = 0
    for u in units.tolist():
        if exact:
            w[u : top + u + 1] += w[: top + 1].copy()
        else:
            prev = w[: top + 1].copy()
            w[: top + 1] *= 0.5
            w[u : top + u + 1] += 0.5 * prev
        top += u
    return w, (float(2**units.size) if exact else 1.0)


def _tail_p(weights: np.ndarray, total: float, obs_lo: int, obs_hi: int, alternative: str) -> float:
    """p-value from a discrete null: P(S ≤ obs_lo) ('less'), P(S ≥ obs_hi) ('greater'), or twice the smaller."""
    obs_lo = min(max(obs_lo, -1), weights.size - 1)
    obs_hi = min(max(obs_hi, 0), weights.size)
    p_less = float(weights[: obs_lo + 1].sum()) / total
    p_greater = float(weights[obs_hi:].sum()) / total
    if alternative == "less":
        return min(p_less, 1.0)
    if alternative == "greater":
        return min(p_greater, 1.0)
    return min(2.0 * min(p_less, p_greater), 1.0)


# ------------------------------------------------------------------------------------------------
# Hodges–Lehmann via exact selection over Walsh averages
# ------------------------------------------------------------------------------------------------
_EPS = float(np.finfo(np.float64).eps)
_TINY = float(np.finfo(np.float64).smallest_subnormal)


def _row_bounds(half: np.ndarray, v: float, lo: np.ndarray, hi: np.ndarray, strict: bool) -> np.ndarray:
    """Per row i, the first column j in [lo_i, hi_i] whose Walsh average is ≥ v (strict) or > v.

    Row i holds w(i, j) = half[i] + half[j], j = i … n−1, non-decreasing in j
    (``half`` = 0.5·sorted d). ``searchsorted`` of v − half[i] ± δ brackets the
    boundary (δ, a few ulps, covers the rounding of the subtraction and of the
    sum), then a binary search on the exact float sums, vectorized over the
    rows whose bracket is not yet a single point, makes it exact.
    """
    a = lo.copy()
    b = hi.copy()
    rows = np.nonzero(a < b)[0]  # rows without candidates keep a = lo = hi
    hr = half[rows]
    with np.errstate(over="ignore", invalid="ignore"):
        t = v - hr
        c = 8.0 * _EPS
        delta = c * abs(v) + c * np.abs(hr) + c * np.abs(t) + 8.0 * _TINY
        t_lo, t_hi = t - delta, t + delta
    # where v − half overflows (|d| near the float maximum) the bracket is the whole candidate range
    sure = np.isfinite(t_lo) & np.isfinite(t_hi)
    a[rows] = np.where(sure, np.clip(np.searchsorted(half, t_lo, side="left"), lo[rows], hi[rows]), lo[rows])
    b[rows] = np.where(sure, np.clip(np.searchsorted(half, t_hi, side="right"), lo[rows], hi[rows]), hi[rows])
    last = half.size - 1
    act = rows[a[rows] < b[rows]]
    while act.size:
        aa, bb = a[act], b[act]
        mid = (aa + bb) // 2
        w = half[act] + half[np.minimum(mid, last)]
        below = (w < v) if strict else (w <= v)
        a[act] = np.where(below, mid + 1, aa)
        b[act] = np.where(below, bb, mid)
        act = act[a[act] < b[act]]
    return a


def _walsh_select(
    ds: np.ndarray, k: int, *, enumerate_at: int | None = None, sample: int = 16384, seed: int = 0x5EED
) -> float:
    """The k-th smallest (1-based) Walsh average ``0.5·ds[i] + 0.5·ds[j]``, i ≤ j, of sorted ``ds``.

    Selection on the implicit matrix whose rows are sorted (Floyd–Rivest style):
    draw ``sample`` of the still-active Walsh averages, take the two sample
    quantiles that bracket rank k with high probability as pivots, and count
    the averages below each pivot exactly with a vectorized binary search per
    row (O(n log n)); each count narrows the per-row active column ranges to
    the side holding rank k, whether or not the bracket guess was right. Once
    at most ``enumerate_at`` candidates remain they are materialized and
    partitioned. The result is exactly the brute-force order statistic (same
    float formula). Halving before adding cannot overflow and is monotone.
    """
    n = ds.size
    m_total = n * (n + 1) // 2
    if not 1 <= k <= m_total:
        raise ValueError(f"k = {k} outside 1 … {m_total}")
    if enumerate_at is None:
        enumerate_at = max(4 * n, 8192)
    half = 0.5 * ds
    rows = np.arange(n)
    lo = rows.copy()  # row i: columns [lo_i, hi_i) are the candidates; those before lo_i rank below
    hi = np.full(n, n, dtype=rows.dtype)
    rng = np.random.default_rng(seed)
    while True:
        sizes = hi - lo
        total = int(sizes.sum())
        before = int((lo - rows).sum())
        kk = k - before  # rank of the answer among the candidates, 1-based
        if total <= enumerate_at:
            starts = np.cumsum(sizes) - sizes
            r_idx = np.repeat(rows, sizes)
            c_idx = np.repeat(lo, sizes) + (np.arange(total) - np.repeat(starts, sizes))
            return float(np.partition(half[r_idx] + half[c_idx], kk - 1)[kk - 1])
        ends = np.cumsum(sizes)
        s_size = min(sample, max(64, total))  # a sample larger than the candidates buys nothing
        picks = rng.integers(total, size=s_size)
        prow = np.searchsorted(ends, picks, side="right")
        pcol = lo[prow] + picks - (ends[prow] - sizes[prow])
        vals = np.sort(half[prow] + half[pcol])
        q = kk / total
        spread = 3.0 * math.sqrt(s_size * q * (1.0 - q)) + 2.0
        pivots = (vals[max(0, math.floor(q * s_size - spread))],
                  vals[min(s_size - 1, math.ceil(q * s_size + spread))])
        for v in pivots:
            lt = _row_bounds(half, v, lo, hi, strict=True)
            if int((lt - rows).sum()) >= k:
                hi = lt
                break  # the answer is below v, so below the second pivot too
            le = _row_bounds(half, v, lt, hi, strict=False)
            if int((le - rows).sum()) >= k:
                return float(v)
            lo = le


def _walsh_next(ds: np.ndarray, k: int, v: float) -> float:
    """The (k+1)-th smallest Walsh average given that the k-th is ``v`` (one counting pass)."""
    half = 0.5 * ds
    n = ds.size
    rows = np.arange(n)
    le = _row_bounds(half, v, rows, np.full(n, n, dtype=rows.dtype), strict=False)
    if int((le - rows).sum()) >= k + 1:
        return v
    has = le < n
    return float(np.min(half[rows[has]] + half[le[has]]))


def _hl_rank(n: int, confidence: float) -> tuple[int, float]:
    """Order-statistic index k (1-based) of the lower bound and the achieved confidence.

    Exact (n ≤ HL_EXACT_MAX_N): the largest k ≥ 1 with P(W⁺ ≤ k−1) ≤ α/2, level
    1 − 2·P(W⁺ ≤ k−1). Normal (n larger): k = ⌊n(n+1)/4 + ½ − z_{1−α/2}·σ⌋,
    σ² = n(n+1)(2n+1)/24, level 1 − 2Φ((k − ½ − n(n+1)/4)/σ). When even k = 1
    misses the requested level, k = 1 is returned with its (lower) level.
    """
    alpha = 1.0 - confidence
    if n <= HL_EXACT_MAX_N:
        cdf = np.cumsum(signed_rank_null_counts(n))  # cdf[w] = #patterns with W⁺ ≤ w
        total = 2**n
        # cdf[k-1]/total ≤ α/2  ⇔  2·cdf[k-1] ≤ α·total, evaluated on exact integers where possible
        ok = np.nonzero(cdf / total <= alpha / 2.0)[0]
        k = int(ok[-1]) + 1 if ok.size else 1
        k = min(k, (n * (n + 1) // 2 + 1) // 2)
        return k, 1.0 - 2.0 * float(cdf[k - 1]) / total
    mean = n * (n + 1) / 4.0
    sd = math.sqrt(n * (n + 1) * (2 * n + 1) / 24.0)
    zq = float(special.ndtri(1.0 - alpha / 2.0))
    k = max(1, math.floor(mean + 0.5 - zq * sd))
    return k, 1.0 - 2.0 * float(special.ndtr((k - 0.5 - mean) / sd))


def _midpoint(a: float, b: float) -> float:
    """(a + b)/2 rounded once, as the median of an even count is (and NumPy's); never overflows.

    ``0.5·a + 0.5·b`` would round twice when the halves are subnormal.  The
    sum is exact whenever its half is subnormal, and halving a normal number
    is exact, so ``(a + b)·0.5`` rounds once; only a sum beyond DBL_MAX takes
    the halves, which are then exact.
    """
    s = a + b
    return s * 0.5 if math.isfinite(s) else 0.5 * a + 0.5 * b


def hodges_lehmann(d: npt.ArrayLike, confidence: float = 0.95) -> tuple[float, float, float, float]:
    """Hodges–Lehmann shift estimate of paired differences and its signed-rank confidence interval.

    Parameters
    ----------
    d : array_like
        Paired differences (ON − OFF), finite, 1-D, at least one. Zeros are data
        and are kept (zero handling concerns only the test).
    confidence : float
        Requested two-sided confidence level in (0, 1).

    Returns
    -------
    estimate, low, high, level : float
        ``estimate`` is the median of the M = n(n+1)/2 Walsh averages
        (d_i + d_j)/2, i ≤ j (the mean of the two middle ones when M is even).
        ``[low, high] = [W_(k), W_(M+1−k)]`` (order statistics of the Walsh
        averages) is the set of shifts θ that a two-sided signed-rank test of
        d − θ does not reject. ``k`` comes from the exact null distribution of
        W⁺ for n ≤ 50 (largest k with P(W⁺ ≤ k−1) ≤ α/2, so the achieved
        ``level`` = 1 − 2·P(W⁺ ≤ k−1) ≥ ``confidence``) and from the normal
        approximation with continuity correction for larger n (``level`` is
        then the approximation's value). Ties in d do not change this
        construction: equal d_i have equal signs of d_i − θ, so W⁺(θ) is the
        number of Walsh averages above θ whatever the tie breaking; with
        discrete data the closed interval is, if anything, conservative.
        When n is too small to reach ``confidence`` (n ≤ 5 at 95 %), the
        interval is [min d, max d] and ``level`` = 1 − 2⁽¹⁻ⁿ⁾ is below the
        request; for n = 1 the interval and level are NaN.

    Notes
    -----
    The order statistics are found by an exact selection over the implicit,
    row-sorted matrix of Walsh averages (randomized pivot, counting by a
    vectorized binary search per row), O(n log n) memory-free per step, so
    n = 10 000 (5·10⁷ averages) costs milliseconds. Walsh averages are
    computed as 0.5·d_i + 0.5·d_j, which cannot overflow.
    """
    arr = np.asarray(d, dtype=np.float64)
    if arr.ndim != 1:
        raise ValueError(f"d must be 1-D, got shape {arr.shape}")
    if arr.size == 0:
        raise ValueError("d is empty: the Hodges–Lehmann estimate needs at least one difference")
    if not np.isfinite(arr).all():
        bad = int(np.nonzero(~np.isfinite(arr))[0][0])
        raise ValueError(f"d[{bad}] = {arr[bad]}: differences must be finite")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence = {confidence}: allowed is 0 < confidence < 1")
    ds = np.sort(arr)
    n = ds.size
    m = n * (n + 1) // 2
    if m % 2:
        est = _walsh_select(ds, (m + 1) // 2)
    else:
        below = _walsh_select(ds, m // 2)
        est = _midpoint(below, _walsh_next(ds, m // 2, below))
    if n == 1:
        return est, math.nan, math.nan, math.nan
    k, level = _hl_rank(n, confidence)
    return est, _walsh_select(ds, k), _walsh_select(ds, m + 1 - k), level


# ------------------------------------------------------------------------------------------------
# The signed-rank test
# ------------------------------------------------------------------------------------------------
def _normalize_method(method: str) -> str:
    m = str(method).lower()
    if m not in METHODS:
        raise ValueError(f"method = {method!r}: allowed are {', '.join(METHODS)}")
    return "approx" if m == "asymptotic" else m


def _auto_method(n_total: int, n_zero: int, n_ties: int) -> str:
    """SciPy 1.17's ``method='auto'`` rule (``scipy/stats/_wilcoxon.py``); n_total counts zeros."""
    if n_total > EXACT_MAX_N:
        return "approx"
    if n_ties == 0 and n_zero == 0:
        return "exact"
    if n_total <= PERMUTATION_AUTO_MAX_N:
        return "permutation"
    return "approx"


def _not_computable(base: dict[str, Any], note: str) -> WilcoxonResult:
    nan = math.nan
    fill: dict[str, Any] = dict(
        method="", statistic=nan, p_value=nan, z=nan, rank_biserial=nan, r=nan,
        median_off=nan, median_on=nan, hl_estimate=nan, hl_ci_low=nan, hl_ci_high=nan, ci_level=nan,
    )
    fill.update(base)
    fill.update(computable=False, note=note)
    return WilcoxonResult(**fill)


def paired_wilcoxon(
    off: npt.ArrayLike,
    on: npt.ArrayLike,
    *,
    metric: str = "",
    zero_method: str = "wilcox",
    alternative: str = "two-sided",
    method: str = "auto",
    confidence: float = 0.95,
    correction: bool = False,
    decimals: int | None = DEFAULT_DECIMALS,
) -> WilcoxonResult:
    """Paired Wilcoxon signed-rank test of ON against OFF, with effect sizes and a Hodges–Lehmann interval.

    Parameters
    ----------
    off, on : array_like
        One value per participant (or trial) in each mode, same length, paired
        by position. A pair with NaN on either side is dropped and counted
        (``n_dropped_nan``), e.g. TCT undefined because a participant had no
        success in one mode.
    metric : str
        Name of the metric, carried into the result (``"rmse_n"``).
    zero_method : {"wilcox", "pratt", "zsplit"}
        Zero differences: discarded (Wilcoxon), ranked with their ranks then
        dropped (Pratt; Cureton's normal correction), or ranked and split half
        to W⁺ and half to W⁻ (zsplit). As in SciPy.
    alternative : {"two-sided", "greater", "less"}
        "greater": ON tends to exceed OFF (d = ON − OFF > 0).
    method : {"auto", "exact", "permutation", "approx"}
        ``"auto"`` applies SciPy 1.17's rule (module docstring); the result's
        ``method`` says what was used. ``"exact"`` uses the untied null
        distribution of n = ``n_used`` ranks and, with ties or zeros, rounds a
        fractional W⁺ conservatively (up for the lower tail, down for the upper
        tail), exactly as SciPy does. ``"permutation"`` is the exact sign-flip
        distribution of the observed mid-ranks (equal to SciPy's
        ``PermutationMethod()`` whenever SciPy enumerates all 2ⁿ patterns,
        i.e. n ≤ 13). ``"asymptotic"`` is accepted for ``"approx"``.
    confidence : float
        Requested level of the Hodges–Lehmann interval (see :func:`hodges_lehmann`).
    correction : bool
        Continuity correction of the normal approximation (SciPy's default, False).
    decimals : int or None
        Round the differences to this many decimals before anything else, so
        that differences equal in exact arithmetic are equal in floating point
        (0.7 − 0.6 and 0.8 − 0.7 differ in the 17th digit; SciPy's
        documentation gives the same advice). The default 10 is far below any
        measurement resolution here (N, s, fractions). ``None`` keeps
        ``on − off`` bit for bit, which is what :func:`scipy.stats.wilcoxon`
        sees when given ``on, off``.

    Returns
    -------
    WilcoxonResult
        See its attributes. Never raises on data: empty, single-pair, all-zero
        and non-finite inputs give ``computable=False`` with a ``note`` and NaN
        test fields (descriptive fields stay filled where they are defined).

    Raises
    ------
    ValueError
        On malformed arguments: unequal lengths, non-1-D input, an unknown
        ``zero_method``/``alternative``/``method``, a confidence outside (0, 1),
        or an explicit exact/permutation test with more than ``PERMUTATION_MAX_N`` pairs.
    """
    zero_method = str(zero_method).lower()
    if zero_method not in ZERO_METHODS:
        raise ValueError(f"zero_method = {zero_method!r}: allowed are {', '.join(ZERO_METHODS)}")
    alternative = str(alternative).lower()
    if alternative not in ALTERNATIVES:
        raise ValueError(f"alternative = {alternative!r}: allowed are {', '.join(ALTERNATIVES)}")
    requested = _normalize_method(method)
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence = {confidence}: allowed is 0 < confidence < 1")
    x_off = np.asarray(off, dtype=np.float64)
    x_on = np.asarray(on, dtype=np.float64)
    if x_off.ndim != 1 or x_on.ndim != 1:
        raise ValueError(f"off and on must be 1-D, got shapes {x_off.shape} and {x_on.shape}")
    if x_off.size != x_on.size:
        raise ValueError(f"off has {x_off.size} values and on has {x_on.size}: pairs need equal lengths")

    keep = ~(np.isnan(x_off) | np.isnan(x_on))
    n_dropped = int(x_off.size - keep.sum())
    base: dict[str, Any] = dict(
        metric=metric, n_pairs=int(keep.sum()), n_dropped_nan=n_dropped, n_used=0, n_zero=0, n_ties=0,
        zero_method=zero_method, alternative=alternative,
    )
    dropped_note = (
        f"{n_dropped} of {x_off.size} pairs dropped because a side was NaN (e.g. undefined in one mode)"
        if n_dropped else ""
    )

    def joined(*parts: str) -> str:
        return "; ".join(p for p in (dropped_note, *parts) if p)

    for name, arr in (("off", x_off), ("on", x_on)):
        inf_at = np.nonzero(np.isinf(arr))[0]
        if inf_at.size:
            i = int(inf_at[0])
            return _not_computable(base, joined(
                f"{name}[{i}] is {arr[i]}: values must be finite, so no test or estimate is computed"))

    a_off = x_off[keep]
    a_on = x_on[keep]
    n_pairs = a_off.size
    if n_pairs == 0:
        return _not_computable(base, joined("no complete pairs: nothing to test"))
    with np.errstate(over="ignore"):  # an overflow is reported below, in words
        d = a_on - a_off
    if decimals is not None:
        d = np.round(d, decimals)
    if not np.isfinite(d).all():  # finite inputs whose difference overflows
        return _not_computable(base, joined("ON − OFF overflows to infinity: values too large to compare"))

    is_zero = d == 0
    n_zero = int(is_zero.sum())
    nz = d[~is_zero]
    _, tie_sizes = np.unique(np.abs(nz), return_counts=True)
    n_ties = int((tie_sizes > 1).sum())
    n_used = n_pairs - n_zero if zero_method == "wilcox" else n_pairs
    base.update(n_used=n_used, n_zero=n_zero, n_ties=n_ties,
                n_positive=int((d > 0).sum()), n_negative=int((d < 0).sum()),
                median_off=float(np.median(a_off)), median_on=float(np.median(a_on)))

    hl_est, hl_lo, hl_hi, level = hodges_lehmann(d, confidence)
    base.update(hl_estimate=hl_est, hl_ci_low=hl_lo, hl_ci_high=hl_hi, ci_level=level)

    if n_pairs == 1:
        return _not_computable(base, joined("a single pair (one participant): a paired test needs at least two"))
    if n_zero == n_pairs:
        return _not_computable(base, joined(
            f"all {n_pairs} differences are zero (ON equals OFF for every pair): nothing to rank"))

    # Ranks of |d| as the chosen zero method defines them.
    if zero_method == "wilcox":
        ranked = nz
    else:
        ranked = d
    ranks = sps.rankdata(np.abs(ranked), method="average")
    w_plus = float(ranks[ranked > 0].sum())
    w_minus = float(ranks[ranked < 0].sum())
    zero_rank_sum = float(ranks[ranked == 0].sum())
    if zero_method == "zsplit":
        w_plus += zero_rank_sum / 2.0
        w_minus += zero_rank_sum / 2.0

    # Normal approximation, arithmetic in SciPy's order so that z is bit-identical.
    count = float(ranked.size)
    mn = count * (count + 1.0) * 0.25
    se2 = count * (count + 1.0) * (2.0 * count + 1.0)
    _, groups = np.unique(np.abs(ranked), return_counts=True)
    if zero_method == "pratt" and n_zero:
        nzf = float(n_zero)
        mn -= nzf * (nzf + 1.0) * 0.25
        se2 -= nzf * (nzf + 1.0) * (2.0 * nzf + 1.0)
        groups = groups[1:]  # the zero group is not a tie (Cureton)
    tie_correct = float(np.sum(groups.astype(np.float64) ** 3 - groups))
    se = math.sqrt((se2 - tie_correct / 2.0) / 24.0)
    z = (w_plus - mn) / se

    used = _auto_method(n_pairs, n_zero, n_ties) if requested == "auto" else requested
    if used in ("exact", "permutation") and ranked.size > PERMUTATION_MAX_N:
        raise ValueError(
            f"method = {used!r} with {ranked.size} pairs: allowed up to {PERMUTATION_MAX_N}; use 'auto' or 'approx'")

    if used == "approx":
        zc = z
        if correction:
            sign = 1.0 if alternative == "greater" else -1.0 if alternative == "less" else float(np.sign(z))
            zc = z - sign * 0.5 / se
        if alternative == "less":
            p = float(special.ndtr(zc))
        elif alternative == "greater":
            p = float(special.ndtr(-zc))
        else:
            p = float(2.0 * special.ndtr(-abs(zc)))
    elif used == "exact":
        nn = ranked.size
        if nn <= _INT_COUNTS_MAX_N:
            weights, total = signed_rank_null_counts(nn), float(2**nn)
        else:
            weights, total = _sign_flip_distribution(np.arange(1, nn + 1)), 1.0
        p = _tail_p(weights, total, math.ceil(w_plus), math.floor(w_plus), alternative)
    else:  # permutation: exact sign flips of the observed mid-ranks (zero ranks carry no sign)
        flip = ranks[ranked != 0]
        units = np.rint(2.0 * flip).astype(np.int64)  # mid-ranks are multiples of ½
        weights, total = _sign_flip_distribution(units)
        obs = int(round(2.0 * float(flip[ranked[ranked != 0] > 0].sum())))
        p = _tail_p(weights, total, obs, obs, alternative)
    p = min(max(p, 0.0), 1.0)

    statistic = min(w_plus, w_minus) if alternative == "two-sided" else w_plus
    denom = w_plus + w_minus
    notes: list[str] = []
    if n_used < 6 and used != "approx":
        notes.append(f"only {n_used} ranked pairs: a two-sided p cannot be below {2.0 / 2**n_used:g}")
    if np.ptp(d) == 0:
        notes.append(f"all differences are equal (d = {d[0]:g}): the Hodges–Lehmann interval has zero width")
    if n_pairs > 1 and level < confidence:
        notes.append(
            f"n = {n_pairs} is too small for a {confidence:.0%} interval: [min d, max d] shown at {level:.1%}")
    return WilcoxonResult(
        method=used, statistic=statistic, p_value=p, z=z,
        rank_biserial=(w_plus - w_minus) / denom, r=z / math.sqrt(n_used),
        computable=True, note=joined(*notes), w_plus=w_plus, w_minus=w_minus, **base,
    )


# ------------------------------------------------------------------------------------------------
# Multiple comparisons, correlation, tables, methods text
# ------------------------------------------------------------------------------------------------
def holm(p_values: npt.ArrayLike, *, axis: int | None = None) -> np.ndarray:
    """Holm (1979) step-down adjusted p-values.

    Parameters
    ----------
    p_values : array_like
        p-values in [0, 1]; NaN entries (untested metrics) stay NaN and do not
        count towards the family size m.
    axis : int or None
        None (default): the whole array is one family.  An axis: every slice
        along it is a family of its own, all adjusted at once (e.g. the four
        metrics of each of thousands of resampled studies, ``axis=-1``).

    Returns
    -------
    numpy.ndarray
        Same shape. With the m finite p-values of a family sorted, p₍₁₎ ≤ … ≤ p₍ₘ₎,
        ``p̃₍ᵢ₎ = min(1, max_{j ≤ i} (m − j + 1)·p₍ⱼ₎)`` — monotone in p and capped
        at 1, as ``statsmodels.stats.multitest.multipletests(method="holm")``.

    Raises
    ------
    ValueError
        If a p-value is outside [0, 1] or infinite.
    """
    p = np.asarray(p_values, dtype=np.float64)
    flat = p.ravel()
    ok = ~np.isnan(flat)
    bad = ok & ~((flat >= 0.0) & (flat <= 1.0))
    if bad.any():
        i = int(np.nonzero(bad)[0][0])
        raise ValueError(f"p_values[{i}] = {flat[i]}: p-values must lie in [0, 1] (or be NaN)")
    if axis is None:
        return _holm_rows(flat.reshape(1, -1)).reshape(p.shape)
    moved = np.moveaxis(p, axis, -1)
    rows = _holm_rows(moved.reshape(-1, moved.shape[-1]))
    return np.moveaxis(rows.reshape(moved.shape), -1, axis)


def _holm_rows(q: np.ndarray) -> np.ndarray:
    """Holm's adjustment of every row of a 2-D array, each row a family (NaN: not in the family)."""
    missing = np.isnan(q)
    m = (~missing).sum(axis=1, keepdims=True)
    # NaN sorts last, so the first m sorted entries of a row are its family, in ascending order
    order = np.argsort(np.where(missing, np.inf, q), axis=1, kind="stable")
    ranked = np.take_along_axis(q, order, axis=1)
    with np.errstate(invalid="ignore"):
        adj = np.minimum(1.0, np.maximum.accumulate((m - np.arange(q.shape[1])) * ranked, axis=1))
    out = np.empty_like(q)
    np.put_along_axis(out, order, adj, axis=1)
    out[missing] = np.nan
    return out


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
    if meth == "spearman":
        res = sps.spearmanr(xa, ya)
        r, p = float(res.statistic), float(res.pvalue)
    else:
        res = sps.pearsonr(xa, ya)
        r, p = float(res.statistic), float(res.pvalue)
    notes = [f"{dropped} pairs dropped because a value was NaN"] if dropped else []
    lo = hi = nan
    if n >= 4:
        se = math.sqrt((1.0 + r * r / 2.0) / (n - 3)) if meth == "spearman" else 1.0 / math.sqrt(n - 3)
        zq = float(special.ndtri(0.5 + confidence / 2.0))
        rc = min(max(r, -1.0), 1.0)
        with np.errstate(divide="ignore"):
            zr = float(np.arctanh(rc))
        lo, hi = math.tanh(zr - zq * se), math.tanh(zr + zq * se)
    else:
        notes.append("n = 3: no Fisher-z interval (needs n ≥ 4)")
    return CorrelationResult(meth, n, dropped, r, min(max(p, 0.0), 1.0), lo, hi, confidence, True, "; ".join(notes))


#: Column order of :func:`results_frame`.
RESULT_COLUMNS: tuple[str, ...] = tuple(f.name for f in fields(WilcoxonResult)) + ("p_holm",)


def results_frame(results: Sequence[WilcoxonResult]) -> pd.DataFrame:
    """One tidy row per metric with every field of :class:`WilcoxonResult` plus ``p_holm``.

    Parameters
    ----------
    results : sequence of WilcoxonResult
        One test per metric (the Holm family).

    Returns
    -------
    pandas.DataFrame
        Columns are the snake_case field names in declaration order, then
        ``p_holm``: Holm-adjusted p across the *computable* rows of this table
        (a non-computable row has NaN and does not count in m).
    """
    rows = [asdict(r) for r in results]
    frame = pd.DataFrame(rows, columns=list(RESULT_COLUMNS[:-1]))
    p = frame["p_value"].to_numpy(dtype=np.float64)
    p = np.where(frame["computable"].to_numpy(dtype=bool), p, np.nan)
    frame["p_holm"] = holm(p)
    return frame


def methods_text(zero_method: str = "wilcox", confidence: float = 0.95) -> str:
    """One plain-English paragraph stating the statistical choices, for the report's methods section.

    Parameters
    ----------
    zero_method : {"wilcox", "pratt", "zsplit"}
        The zero handling used for the tests.
    confidence : float
        The requested Hodges–Lehmann confidence level.

    Returns
    -------
    str
        The paragraph (no trailing newline).
    """
    zm = str(zero_method).lower()
    if zm not in ZERO_METHODS:
        raise ValueError(f"zero_method = {zero_method!r}: allowed are {', '.join(ZERO_METHODS)}")
    zeros = {
        "wilcox": "zero differences were discarded before ranking (Wilcoxon's method), so n can be smaller "
                  "than the number of participants",
        "pratt": "zero differences were ranked and their ranks then dropped (Pratt's method, with Cureton's "
                 "correction of the normal approximation)",
        "zsplit": "zero differences were ranked and their ranks split equally between the positive and "
                  "negative rank sums (the zero-split method)",
    }[zm]
    return (
        "For every metric, each participant's ON and OFF values formed a pair and the difference d = ON − OFF "
        f"(rounded to {DEFAULT_DECIMALS} decimals so that equal values tie exactly) was tested with a two-sided "
        f"Wilcoxon signed-rank test; pairs missing a value in either mode were excluded and counted, and {zeros}. "
        "Tied absolute differences received average ranks. The p-value method followed SciPy 1.17's automatic "
        f"rule and is reported per metric: the exact null distribution when there were at most {EXACT_MAX_N} "
        f"pairs and no ties or zeros; otherwise, with at most {PERMUTATION_AUTO_MAX_N} pairs, an exact "
        "permutation test over all sign flips of the observed ranks; otherwise the normal approximation with "
        "tie (and zero) corrections and no continuity correction. The statistic is the smaller of the two rank "
        "sums. Effect sizes are the matched-pairs rank-biserial correlation (W⁺ − W⁻)/(W⁺ + W⁻) and "
        "r = z/√n, where n is the number of ranked pairs and z the tie-corrected normal statistic; both are "
        "positive when ON exceeds OFF. The shift ON − OFF was estimated by the Hodges–Lehmann estimator (the "
        "median of all pairwise Walsh averages of the differences, zeros included) with a "
        f"{confidence:.0%} confidence interval from the signed-rank distribution (exact critical values up to "
        f"{HL_EXACT_MAX_N} pairs, normal approximation beyond; the achieved level is reported). p-values were "
        "adjusted across the metrics with Holm's step-down method, reported alongside the unadjusted values."
    )
