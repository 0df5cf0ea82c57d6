"""Paired ON-vs-OFF statistics: the Wilcoxon signed-rank test with its effect sizes and Hodges–Lehmann shift
(Holm's correction across a family of them: :mod:`analysis.stats.holm`).

Everything here works on *paired* data: one OFF value and one ON value per
participant (or per trial for trial-level analyses). The paired difference is
always

    d_i = ON_i − OFF_i

so a positive effect size, Hodges–Lehmann shift or ``z`` means "larger with
haptic feedback ON" (for errors and times: ON is *worse*; for success: ON is
better).

The signed-rank test is :func:`scipy.stats.wilcoxon`; around it,
:func:`paired_wilcoxon` adds what a report needs and SciPy does not give:
the pairs dropped for NaN and why a test is not computable, in words; the
method SciPy's ``method="auto"`` chooses, named (:func:`analysis.stats.signed_rank.auto_method`:
with more than 50 pairs → the normal approximation; otherwise no ties and no
zeros → the exact distribution; otherwise at most 13 pairs → the permutation
test over all 2ⁿ sign flips; otherwise → the normal approximation; "pairs"
counts zero differences too -- the rule of SciPy 1.15 – 1.17, the range
``pyproject.toml`` pins; the report departs from it in one place, exactly:
where SciPy would approximate though at most 13 differences are non-zero it
enumerates their sign flips, :func:`analysis.stats.signed_rank.report_method`);
both rank sums, the rank-biserial correlation and
r = z/√n; and the Hodges–Lehmann shift with its interval
(:mod:`analysis.stats.hodges_lehmann`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import scipy
from scipy import stats as sps

from analysis.reading.codebook_columns import DIFFERENCE_DECIMALS
from analysis.stats.hodges_lehmann import HL_EXACT_MAX_N, hodges_lehmann
from analysis.stats.signed_rank import EXACT_MAX_N, PERMUTATION_AUTO_MAX_N, SCIPY_AUTO_RANGE, report_method

__all__ = [
    "ALTERNATIVES",
    "DEFAULT_DECIMALS",
    "EXPLICIT_EXACT_MAX_N",
    "METHODS",
    "ZERO_METHODS",
    "WilcoxonResult",
    "check_zero_method",
    "methods_text",
    "paired_wilcoxon",
]

ZERO_METHODS = ("wilcox", "pratt", "zsplit")
ALTERNATIVES = ("two-sided", "less", "greater")
#: Accepted ``method`` values (``"asymptotic"`` is accepted as SciPy's name for ``"approx"``).
METHODS = ("auto", "exact", "permutation", "approx", "asymptotic")
#: Largest n for an explicitly requested exact test (beyond, the normal approximation is exact enough).
EXPLICIT_EXACT_MAX_N = 400
#: Differences are rounded to this many decimals before testing (see :func:`paired_wilcoxon`; participants_wide.csv
#: writes its differences so: one definition, in the codebook).
DEFAULT_DECIMALS = DIFFERENCE_DECIMALS

_SCIPY_NAME = {"exact": "exact", "approx": "asymptotic"}


# ------------------------------------------------------------------------------------------------
# Result type
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


# ------------------------------------------------------------------------------------------------
# The signed-rank test, on scipy.stats.wilcoxon
# ------------------------------------------------------------------------------------------------
def check_zero_method(zero_method: str) -> str:
    """The zero method, lower-cased, checked against :data:`ZERO_METHODS`.

    Parameters
    ----------
    zero_method : str
        ``"wilcox"``, ``"pratt"`` or ``"zsplit"``, in any case.

    Returns
    -------
    str
        The name in lower case.

    Raises
    ------
    ValueError
        Naming the value given and what is allowed.
    """
    zm = str(zero_method).lower()
    if zm not in ZERO_METHODS:
        raise ValueError(f"zero_method = {zero_method!r}: allowed are {', '.join(ZERO_METHODS)}")
    return zm


def _check_arguments(zero_method: str, alternative: str, method: str, confidence: float) -> tuple[str, str, str]:
    """Lower-cased ``zero_method``, ``alternative`` and method (``"asymptotic"`` → ``"approx"``), or ValueError."""
    zm = check_zero_method(zero_method)
    alt = str(alternative).lower()
    if alt not in ALTERNATIVES:
        raise ValueError(f"alternative = {alt!r}: allowed are {', '.join(ALTERNATIVES)}")
    m = str(method).lower()
    if m not in METHODS:
        raise ValueError(f"method = {method!r}: allowed are {', '.join(METHODS)}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence = {confidence}: allowed is 0 < confidence < 1")
    return zm, alt, "approx" if m == "asymptotic" else m


def _not_computable(base: dict[str, Any], note: str) -> WilcoxonResult:
    nan = math.nan
    fill: dict[str, Any] = dict(
        method="", statistic=nan, p_value=nan, z=nan, rank_biserial=nan, r=nan,
        median_off=nan, median_on=nan, hl_estimate=nan, hl_ci_low=nan, hl_ci_high=nan, ci_level=nan,
    )
    fill.update(base)
    fill.update(computable=False, note=note)
    return WilcoxonResult(**fill)


def _rank_sums(d: np.ndarray, zero_method: str) -> tuple[float, float]:
    """W⁺ and W⁻ as ``zero_method`` defines them (under ``"zsplit"`` each takes half the zero ranks).

    SciPy reports only ``min(W⁺, W⁻)`` (two-sided) or W⁺; the rank-biserial
    correlation needs both, so they are summed here from SciPy's average ranks.
    """
    ranked = d[d != 0] if zero_method == "wilcox" else d
    ranks = sps.rankdata(np.abs(ranked), method="average")
    w_plus = float(ranks[ranked > 0].sum())
    w_minus = float(ranks[ranked < 0].sum())
    if zero_method == "zsplit":
        zero_rank_sum = float(ranks[ranked == 0].sum())
        w_plus += zero_rank_sum / 2.0
        w_minus += zero_rank_sum / 2.0
    return w_plus, w_minus


def _permutation_p(d: np.ndarray, zero_method: str, alternative: str) -> float:
    """The p-value of ``scipy.stats.wilcoxon(d, method=PermutationMethod())``, hundreds of times faster.

    SciPy's wilcoxon hands :func:`scipy.stats.permutation_test` a statistic
    that is not vectorised, so the 2ⁿ sign flips run as a Python loop (0.24 s
    at n = 10, 1.7 s at n = 13 with SciPy 1.17.1), where the report and the
    power tests run it thousands of times.  Here the same ``permutation_test``
    (same sign flips, same p-value arithmetic) gets W⁺ vectorised: flipping
    signs leaves |d| and so the ranks unchanged, and W⁺ is the rank sum of the
    positive flips (plus half the zero ranks under "zsplit"), the very values
    SciPy's statistic takes.  tests/analysis/test_stats.py checks the p-values equal.
    """
    # A zero's sign flip changes no statistic (its rank, where it has one, is dropped or split whatever its sign):
    # the 2ⁿ flips of the non-zero differences are enumerated, each of SciPy's 2ⁿ⁺ᶻ flips' values once per zero
    # pattern, so the same p-value -- and exact up to 13 non-zero differences wherever the zeros are.
    # (SciPy's permutation_test needs two values: with one non-zero difference one zero stays, changing nothing.)
    nonzero = d != 0
    ranked = nonzero if zero_method == "wilcox" else np.ones(d.size, dtype=bool)
    all_ranks = np.zeros(d.size)
    all_ranks[ranked] = sps.rankdata(np.abs(d[ranked]), method="average")
    half_zero = float(all_ranks[~nonzero].sum()) / 2.0 if zero_method == "zsplit" else 0.0
    flipped = nonzero.copy()
    if np.count_nonzero(nonzero) < 2:
        flipped[np.flatnonzero(~nonzero)[:1]] = True
    ranks, d = all_ranks[flipped], d[flipped]

    def w_plus(x: np.ndarray, axis: int) -> np.ndarray:
        w: np.ndarray = np.sum((x > 0) * ranks, axis=axis) + half_zero
        return w

    res = sps.permutation_test((d,), w_plus, permutation_type="samples", vectorized=True,
                               alternative=alternative, axis=-1)
    return float(res.pvalue)


def _scipy_test(d: np.ndarray, zero_method: str, alternative: str, method: str,
                correction: bool) -> tuple[float, float, float]:
    """Statistic and p-value of :func:`scipy.stats.wilcoxon` with ``method``, and the signed z.

    The method is passed explicitly (the one :func:`analysis.stats.signed_rank.auto_method`
    named under ``"auto"``), so the method the report names is the method that ran;
    the permutation test runs through :func:`_permutation_p`.
    z is SciPy's normal statistic of the one-sided test ("greater"), which is
    (W⁺ − E W⁺)/SD W⁺ with the tie and zero corrections, signed, and without
    continuity correction: SciPy's two-sided z is −|z|.
    """
    signed = sps.wilcoxon(d, zero_method=zero_method, alternative="greater", method="asymptotic", correction=False)
    if method == "permutation":
        # the statistic does not depend on the method; SciPy reports it whichever is asked for
        statistic = sps.wilcoxon(d, zero_method=zero_method, alternative=alternative, method="asymptotic").statistic
        p = _permutation_p(d, zero_method, alternative)
    else:
        res = sps.wilcoxon(d, zero_method=zero_method, alternative=alternative, method=_SCIPY_NAME[method],
                           correction=correction)
        statistic, p = res.statistic, res.pvalue
    # p clipped into [0, 1]: an exact tail sum doubled for two sides can round a hair above 1
    return float(statistic), min(max(float(p), 0.0), 1.0), float(signed.zstatistic)


def _check_size(method: str, n_pairs: int) -> None:
    """An explicit exact or permutation test refused where SciPy would not compute it exactly."""
    limit = {"exact": EXPLICIT_EXACT_MAX_N, "permutation": PERMUTATION_AUTO_MAX_N}.get(method)
    if limit is not None and n_pairs > limit:
        raise ValueError(f"method = {method!r} with {n_pairs} pairs: allowed up to {limit}; use 'auto' or 'approx'")


def _complete_pairs(off: npt.ArrayLike, on: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """OFF and ON as 1-D float arrays of equal length, and the mask of pairs with no NaN."""
    x_off = np.asarray(off, dtype=np.float64)
    x_on = np.asarray(on, dtype=np.float64)
    if x_off.ndim != 1 or x_on.ndim != 1:
        raise ValueError(f"off and on must be 1-D, got shapes {x_off.shape} and {x_on.shape}")
    if x_off.size != x_on.size:
        raise ValueError(f"off has {x_off.size} values and on has {x_on.size}: pairs need equal lengths")
    return x_off, x_on, ~(np.isnan(x_off) | np.isnan(x_on))


def _differences(x_off: np.ndarray, x_on: np.ndarray, keep: np.ndarray,
                 decimals: int | None) -> tuple[np.ndarray | None, str]:
    """d = ON − OFF over the complete pairs, rounded; or None and why no test or estimate is possible."""
    for name, arr in (("off", x_off), ("on", x_on)):
        inf_at = np.nonzero(np.isinf(arr))[0]
        if inf_at.size:
            i = int(inf_at[0])
            return None, f"{name}[{i}] is {arr[i]}: values must be finite, so no test or estimate is computed"
    if not keep.any():
        return None, "no complete pairs: nothing to test"
    with np.errstate(over="ignore"):  # an overflow is reported below, in words
        d = x_on[keep] - x_off[keep]
    if decimals is not None:
        d = np.round(d, decimals)
    if not np.isfinite(d).all():  # finite inputs whose difference overflows
        return None, "ON − OFF overflows to infinity: values too large to compare"
    return d, ""


def _notes(d: np.ndarray, n_used: int, method: str, level: float, confidence: float) -> list[str]:
    """The degenerate cases of a computable test, in words."""
    notes: list[str] = []
    if n_used < 6 and method != "approx":
        notes.append(f"only {n_used} ranked pairs: a two-sided p cannot be below {2.0 / 2**n_used:g}")
    if np.ptp(d) == 0:
        notes.append(f"all differences are equal (d = {d[0]:g}): the Hodges–Lehmann interval has zero width")
    if d.size > 1 and level < confidence:
        zeros = int((d == 0).sum())
        which = f"{d.size} differences ({zeros} of them zero)" if zeros else f"{d.size} differences"
        notes.append(f"{which} are too few for a {confidence:.0%} Hodges–Lehmann interval: [min d, max d] shown, "
                     f"at {level:.1%}")
    return notes


def _untestable(d: np.ndarray) -> str:
    """Why complete, finite differences cannot be tested, in words ("" when they can)."""
    if d.size == 1:
        return "a single pair (one participant): a paired test needs at least two"
    if not d.any():
        return f"all {d.size} differences are zero (ON equals OFF for every pair): nothing to rank"
    return ""


def _descriptives(d: np.ndarray, a_off: np.ndarray, a_on: np.ndarray, zero_method: str,
                  confidence: float) -> dict[str, Any]:
    """Counts, medians and the Hodges–Lehmann shift: defined whether or not a test can run."""
    n_zero = int((d == 0).sum())
    _, tie_sizes = np.unique(np.abs(d[d != 0]), return_counts=True)
    hl_est, hl_lo, hl_hi, level = hodges_lehmann(d, confidence)
    return dict(
        n_used=d.size - n_zero if zero_method == "wilcox" else d.size, n_zero=n_zero,
        n_ties=int((tie_sizes > 1).sum()), n_positive=int((d > 0).sum()), n_negative=int((d < 0).sum()),
        median_off=float(np.median(a_off)), median_on=float(np.median(a_on)),
        hl_estimate=hl_est, hl_ci_low=hl_lo, hl_ci_high=hl_hi, ci_level=level,
    )


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
        One value per participant (or trial) in each mode, same length, paired by position. A pair with
        NaN on either side is dropped and counted (``n_dropped_nan``), e.g. TCT undefined because a
        participant had no success in one mode.
    metric : str
        Name of the metric, carried into the result (``"rmse_n"``).
    zero_method : {"wilcox", "pratt", "zsplit"}
        Zero differences: discarded (Wilcoxon), ranked with their ranks then dropped (Pratt; Cureton's
        normal correction), or ranked and split half to W⁺ and half to W⁻ (zsplit). As in SciPy.
    alternative : {"two-sided", "greater", "less"}
        "greater": ON tends to exceed OFF (d = ON − OFF > 0).
    method : {"auto", "exact", "permutation", "approx"}
        ``"auto"`` applies the report's rule (:func:`analysis.stats.signed_rank.report_method`: SciPy's, but an exact
        permutation test wherever at most 13 differences are non-zero); the result's ``method``
        says what was used. ``"exact"``: SciPy's untied null distribution of ``n_used`` ranks (with ties or
        zeros it rounds a fractional W⁺ conservatively); ``"permutation"``: SciPy's ``PermutationMethod()``,
        all 2ⁿ sign flips of the non-zero differences, up to 13 of them; ``"asymptotic"`` is accepted for ``"approx"``.
    confidence : float
        Requested level of the Hodges–Lehmann interval (see :func:`hodges_lehmann`).
    correction : bool
        Continuity correction of the normal approximation (SciPy's default, False).
    decimals : int or None
        Round the differences to this many decimals first, so that differences equal in exact arithmetic
        are equal in floating point (0.7 − 0.6 and 0.8 − 0.7 differ in the 17th digit; SciPy's
        documentation gives the same advice); 10 is far below any measurement resolution here. ``None``
        keeps ``on − off`` bit for bit, what :func:`scipy.stats.wilcoxon` sees when given ``on, off``.

    Returns
    -------
    WilcoxonResult
        Statistic and p-value from :func:`scipy.stats.wilcoxon`; see the attributes. Never raises on data:
        empty, single-pair, all-zero and non-finite inputs give ``computable=False`` with a ``note`` and
        NaN test fields (descriptive fields stay filled where they are defined).

    Raises
    ------
    ValueError
        On malformed arguments: unequal lengths, non-1-D input, an unknown ``zero_method``/``alternative``/
        ``method``, a confidence outside (0, 1), an explicit exact test with more than
        ``EXPLICIT_EXACT_MAX_N`` pairs or an explicit permutation test with more than 13 non-zero differences.
    """
    zero_method, alternative, requested = _check_arguments(zero_method, alternative, method, confidence)
    x_off, x_on, keep = _complete_pairs(off, on)
    base, lead = _pairs_counted(x_off, keep, metric, zero_method, alternative)
    d, why = _differences(x_off, x_on, keep, decimals)
    if d is not None:
        base.update(_descriptives(d, x_off[keep], x_on[keep], zero_method, confidence))
        why = _untestable(d)
    if d is None or why:
        return _not_computable(base, "; ".join([*lead, why]))
    used = report_method(d.size, base["n_zero"], base["n_ties"]) if requested == "auto" else requested
    # a permutation test enumerates the signs of the non-zero differences (:func:`_permutation_p`)
    _check_size(used, base["n_used"] if used == "exact" else d.size - base["n_zero"])
    notes = _notes(d, base["n_used"], used, base["ci_level"], confidence)
    return WilcoxonResult(method=used, computable=True, note="; ".join([*lead, *notes]),
                          **_tested(d, zero_method, alternative, used, correction, base["n_used"]), **base)


def _pairs_counted(x_off: np.ndarray, keep: np.ndarray, metric: str, zero_method: str,
                   alternative: str) -> tuple[dict[str, Any], list[str]]:
    """The result's fields so far (the pairs kept and dropped, the choices) and the note on the pairs dropped."""
    base: dict[str, Any] = dict(
        metric=metric, n_pairs=int(keep.sum()), n_dropped_nan=int(x_off.size - keep.sum()), n_used=0, n_zero=0,
        n_ties=0, zero_method=zero_method, alternative=alternative,
    )
    dropped = base["n_dropped_nan"]
    lead = [f"{dropped} of {x_off.size} pairs dropped because a side was NaN (e.g. undefined in one mode)"
            ] if dropped else []
    return base, lead


def _tested(d: np.ndarray, zero_method: str, alternative: str, used: str, correction: bool,
            n_used: int) -> dict[str, Any]:
    """The test of differences ``d`` by method ``used`` and its effect sizes, as the result's fields: the statistic,
    p, z, both rank sums, the rank-biserial correlation and r = z/√n."""
    statistic, p, z = _scipy_test(d, zero_method, alternative, used, correction)
    w_plus, w_minus = _rank_sums(d, zero_method)
    return {"statistic": statistic, "p_value": p, "z": z, "rank_biserial": (w_plus - w_minus) / (w_plus + w_minus),
            "r": z / math.sqrt(n_used), "w_plus": w_plus, "w_minus": w_minus}


# ------------------------------------------------------------------------------------------------
# Methods text
# ------------------------------------------------------------------------------------------------
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
        The paragraph (no trailing newline); it names the SciPy version that computed the tests.
    """
    zm = check_zero_method(zero_method)
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
        "Tied absolute differences received average ranks. The test was computed with scipy.stats.wilcoxon "
        f"(SciPy {scipy.__version__}), its p-value method chosen by SciPy's automatic rule (the same in SciPy "
        f"{SCIPY_AUTO_RANGE[0]} – {SCIPY_AUTO_RANGE[1]}) and reported per metric: the exact null distribution "
        f"when there were at most {EXACT_MAX_N} pairs (zero differences counted) and no ties or zeros; "
        f"otherwise, with at most {PERMUTATION_AUTO_MAX_N} pairs, an exact permutation test over all 2ⁿ sign "
        f"flips of the observed ranks -- also where SciPy's rule, which counts zero differences, would approximate "
        f"though at most {PERMUTATION_AUTO_MAX_N} pairs are ranked; otherwise the normal approximation with "
        "tie (and zero) corrections and no continuity correction. The statistic is the smaller of the two rank "
        "sums. Effect sizes are the matched-pairs rank-biserial correlation (W⁺ − W⁻)/(W⁺ + W⁻) and "
        "r = z/√n, where n is the number of ranked pairs and z the tie-corrected normal statistic; both are "
        "positive when ON exceeds OFF; the rank-biserial correlation has a bootstrap interval (participants "
        "resampled, BCa, scipy.stats.bootstrap, a fixed seed). The shift ON − OFF was estimated by the "
        "Hodges–Lehmann estimator (the "
        "median of all pairwise Walsh averages of the differences, zeros included) with a "
        f"{confidence:.0%} confidence interval from the signed-rank distribution (exact critical values up to "
        f"{HL_EXACT_MAX_N} pairs, normal approximation beyond; the achieved level is reported). p-values were "
        "adjusted across the metrics with Holm's step-down method, reported alongside the unadjusted values."
    )
