"""The report's Wilcoxon test on thousands of resampled studies at once, for the power analysis.

Calling :func:`analysis.stats.wilcoxon.paired_wilcoxon` R times per n and metric costs
about a millisecond a call; here the R tests of one metric run at once.  The
tie groups of every resample come from one sort of the whole R × n block of
codes; the exact null distribution of each n and the sign-flip distribution of
each tie structure (:mod:`analysis.stats.signed_rank`) are computed once and cached;
the normal approximation is vectorised.  The method of each study is the one
the report's ``method="auto"`` chooses (:func:`analysis.stats.signed_rank.report_method`: SciPy's rule, but exact
wherever at most 13 differences are non-zero, as ``paired_wilcoxon`` names it).  The p-values are bit-for-bit those of
:func:`~analysis.stats.wilcoxon.paired_wilcoxon`, that is of :func:`scipy.stats.wilcoxon`
(tests/analysis/test_power.py proves it on random samples with ties, zeros and
missing values).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import special

from analysis.stats.signed_rank import report_method, sign_flip_distribution, signed_rank_null_counts
from analysis.stats.wilcoxon import DEFAULT_DECIMALS, check_zero_method

__all__ = ["METHOD_NAMES", "PreparedMetric", "prepare_metric", "resampled_p_values", "study_tests"]

#: Method codes of :func:`resampled_p_values` (0: no test possible).
METHOD_NAMES = ("", "exact", "permutation", "approx")
_METHOD_CODE = {name: code for code, name in enumerate(METHOD_NAMES)}


@functools.cache
def _exact_p(n: int) -> np.ndarray:
    """Two-sided exact p-value of every W⁺ = 0 … n(n+1)/2 for n untied, non-zero differences."""
    return _two_sided_p(signed_rank_null_counts(n), float(2**n))


def _two_sided_p(weights: np.ndarray, total: float) -> np.ndarray:
    """min(1, 2·min(P(S ≤ s), P(S ≥ s))) of a discrete null for every s at once, as SciPy computes it.

    P(S ≥ s) is counted on the integer weights (exact), then divided by the total, as in SciPy's exact test.
    """
    cdf = np.cumsum(weights)
    p_less = cdf / total
    p_greater = (cdf[-1] - cdf + weights) / total  # integer counts of S ≥ s
    p: np.ndarray = np.minimum(2.0 * np.minimum(p_less, p_greater), 1.0)
    p.flags.writeable = False
    return p


_PERM_CACHE: dict[int, np.ndarray] = {}
_PERM_CACHE_MAX = 200_000


@dataclass(frozen=True, slots=True)
class PreparedMetric:
    """One metric's pool, coded for resampling.

    ``rank`` orders the pool by |d| (ties in pool order), complete pairs
    first and pairs with a missing value last; ``by_rank`` is its inverse, so
    sorting a resample's ranks sorts its members by |d|.
    """

    rank: np.ndarray      # pool member → position in the |d| order
    by_rank: np.ndarray   # position → pool member
    code: np.ndarray      # pool member → index of its |d| among the distinct values; missing pairs after all
    positive: np.ndarray
    zero: np.ndarray
    missing: np.ndarray   # NaN on a side: the pair is dropped and counted
    bad: np.ndarray       # infinite value or overflowing difference: the whole test is not computable
    any_bad: bool


def prepare_metric(off: npt.ArrayLike, on: npt.ArrayLike) -> PreparedMetric:
    """One metric's pool, coded for :func:`study_tests`.

    Parameters
    ----------
    off, on : array_like
        One value per pool member, same length; NaN where undefined.

    Returns
    -------
    PreparedMetric
        The members ordered by |d| (rounded as ``paired_wilcoxon`` rounds it), their signs and what is missing.
    """
    x_off = np.asarray(off, dtype=np.float64)
    x_on = np.asarray(on, dtype=np.float64)
    missing = np.isnan(x_off) | np.isnan(x_on)
    with np.errstate(over="ignore", invalid="ignore"):
        d = np.round(x_on - x_off, DEFAULT_DECIMALS)  # elementwise, as paired_wilcoxon computes it
    bad = np.isinf(x_off) | np.isinf(x_on) | (~missing & ~np.isfinite(d))
    unusable = missing | bad
    absd = np.abs(d[~unusable])
    values = np.unique(absd)
    code = np.full(d.size, values.size, dtype=np.int64)
    code[~unusable] = np.searchsorted(values, absd)
    by_rank = np.argsort(code, kind="stable")
    rank = np.empty_like(by_rank)
    rank[by_rank] = np.arange(by_rank.size)
    # small ranks sort by radix (kind="stable" on ≤ 16-bit integers), the bulk of the cost otherwise
    rank = rank.astype(np.int16 if by_rank.size <= np.iinfo(np.int16).max else np.int64)
    return PreparedMetric(rank, by_rank, code, ~unusable & (d > 0), ~unusable & (d == 0), unusable, bad,
                          bool(bad.any()))


def _permutation_p(key: int, units: np.ndarray) -> np.ndarray:
    """Two-sided p of every doubled W⁺ under the sign-flip distribution of these doubled mid-ranks (cached by key)."""
    table = _PERM_CACHE.get(key)
    if table is None:
        if len(_PERM_CACHE) >= _PERM_CACHE_MAX:
            _PERM_CACHE.clear()
        table = _PERM_CACHE[key] = _two_sided_p(*sign_flip_distribution(units))
    return table


@dataclass(frozen=True, slots=True)
class _Rows:
    """The ranking of every resampled study (one row each), members sorted by |d|, missing pairs last."""

    pos: np.ndarray         # column index, broadcast to (R, n)
    new: np.ndarray         # a tie group begins here
    size: np.ndarray        # size of the tie group of this position
    units: np.ndarray       # doubled mid-rank of this position (integers)
    nonzero: np.ndarray
    ranked: np.ndarray      # positions that take a rank under the zero method
    tie_groups: np.ndarray  # non-zero positions in a tie group of size > 1
    n_pairs: np.ndarray
    n_zero: np.ndarray
    count: np.ndarray       # ranked pairs per study
    w2: np.ndarray          # 2·W⁺ without the zero ranks
    side: np.ndarray


def _rank_rows(pm: PreparedMetric, idx: np.ndarray, zero_method: str) -> _Rows:
    r, n = idx.shape
    pick = pm.by_rank[np.sort(pm.rank[idx], axis=1, kind="stable")]  # members sorted by |d|, missing last
    code = pm.code[pick]
    # tie groups of the sorted rows: where each group starts and how long it is
    pos = np.broadcast_to(np.arange(n), (r, n))
    new = np.ones((r, n), dtype=bool)
    new[:, 1:] = code[:, 1:] != code[:, :-1]
    start = np.maximum.accumulate(np.where(new, pos, 0), axis=1)
    last = np.ones((r, n), dtype=bool)
    last[:, :-1] = new[:, 1:]
    end = np.minimum.accumulate(np.where(last, pos, n)[:, ::-1], axis=1)[:, ::-1]
    size = end - start + 1
    missing = pm.missing[pick]
    zero = pm.zero[pick]
    nonzero = ~missing & ~zero
    n_zero = zero.sum(axis=1)
    if zero_method == "wilcox":
        ranked, offset = nonzero, n_zero[:, None]  # zeros (sorted first) are dropped before ranking
    else:
        ranked, offset = ~missing, np.zeros((r, 1), dtype=np.int64)
    units = 2 * (start - offset) + size + 1  # doubled mid-ranks: integers
    w2 = np.where(pm.positive[pick], units, 0).sum(axis=1)
    # W⁺ against its null mean, half the non-zero pairs' rank sum: 2·w2 vs Σ units, all integers (zeros cancel)
    side = np.sign(2 * w2 - np.where(nonzero, units, 0).sum(axis=1)).astype(np.int8)
    return _Rows(pos, new, size, units, nonzero, ranked, nonzero & (size > 1), n - missing.sum(axis=1), n_zero,
                 ranked.sum(axis=1), w2, side)


def _methods(rows: _Rows, pm: PreparedMetric, idx: np.ndarray) -> np.ndarray:
    """The report's automatic choice per study (0 where no test is possible), asked once per distinct case."""
    computable = (rows.n_pairs >= 2) & (rows.n_zero < rows.n_pairs)
    if pm.any_bad:
        computable &= ~pm.bad[idx].any(axis=1)
    # the method depends on the pairs, the zeros among them (how many: the non-zero ones a permutation flips) and
    # whether |d| ties
    keys = (rows.n_pairs.astype(np.int64) * (idx.shape[1] + 1) + rows.n_zero) * 2 + rows.tie_groups.any(axis=1)
    uniq, inverse = np.unique(keys, return_inverse=True)
    width = idx.shape[1] + 1
    chosen = np.array([_METHOD_CODE[report_method(int(k) // 2 // width, int(k) // 2 % width, int(k) % 2)]
                       for k in uniq], dtype=np.int8)
    return np.where(computable, chosen[inverse.ravel()], 0).astype(np.int8)


def _exact_rows(rows: _Rows, sel: np.ndarray, _zero_method: str, p: np.ndarray) -> None:
    # no zeros and no ties in these rows, so the zero method does not matter
    for nn in np.unique(rows.count[sel]):
        at = sel[rows.count[sel] == nn]
        p[at] = _exact_p(int(nn))[rows.w2[at] // 2]


def _permutation_rows(rows: _Rows, sel: np.ndarray, zero_method: str, p: np.ndarray) -> None:
    # The sign-flip distribution depends on the doubled mid-ranks of the non-zero pairs only: their
    # number, where tie groups begin among them (≤ 13 bits) and the ranks zeros take below them.
    n_zero = rows.n_zero[sel]
    nz = rows.nonzero[sel]
    begins = nz & rows.new[sel]
    bit = np.left_shift(np.int64(1), np.clip(rows.pos[sel] - n_zero[:, None], 0, 62))
    shape = np.where(begins, bit, 0).sum(axis=1)
    below = n_zero if zero_method != "wilcox" else np.zeros(sel.size, dtype=np.int64)
    # (the zeros below can be many now that a study of any size with at most 13 non-zero differences is permuted)
    key = (shape * (1 << 24) + below) * 64 + rows.count[sel] - (n_zero if zero_method != "wilcox" else 0)
    kinds, first, which = np.unique(key, return_index=True, return_inverse=True)
    tables = []
    for kk, i in zip(kinds.tolist(), first.tolist(), strict=True):
        t = _PERM_CACHE.get(kk)
        tables.append(t if t is not None else _permutation_p(kk, rows.units[sel[i]][nz[i]]))
    stacked = np.full((len(tables), max(t.size for t in tables)), np.nan)
    for k, t in enumerate(tables):
        stacked[k, : t.size] = t
    p[sel] = stacked[which.ravel(), rows.w2[sel]]


def _approx_rows(rows: _Rows, sel: np.ndarray, zero_method: str, p: np.ndarray) -> None:
    # SciPy's normal approximation with tie and zero corrections, in SciPy's order of operations
    n_zero = rows.n_zero[sel]
    cnt = rows.count[sel].astype(np.float64)
    nzf = n_zero.astype(np.float64)
    w_plus2 = rows.w2[sel].astype(np.float64)
    if zero_method == "zsplit":
        w_plus2 += n_zero * (n_zero + 1) // 2  # half the zero ranks go to W⁺
    tie_set = rows.tie_groups[sel] if zero_method != "zsplit" else (rows.ranked & (rows.size > 1))[sel]
    tie_correct = np.where(tie_set, rows.size[sel] ** 2 - 1, 0).sum(axis=1).astype(np.float64)  # Σ (t³ − t)
    mn = cnt * (cnt + 1.0) * 0.25
    se2 = cnt * (cnt + 1.0) * (2.0 * cnt + 1.0)
    if zero_method == "pratt":
        mn -= nzf * (nzf + 1.0) * 0.25
        se2 -= nzf * (nzf + 1.0) * (2.0 * nzf + 1.0)
    se = np.sqrt((se2 - tie_correct / 2.0) / 24.0)
    z = (w_plus2 / 2.0 - mn) / se
    p[sel] = 2.0 * special.ndtr(-np.abs(z))


def study_tests(pm: PreparedMetric, idx: np.ndarray,
                zero_method: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """p-value (NaN: not computable), method code, complete pairs and side of every resampled study (rows of idx).

    The side is the direction of the study's effect as the signed-rank test
    sees it: +1 when W⁺ (the rank sum of the ON > OFF pairs) lies above its
    null mean, -1 below, 0 on it -- the side on which the two-sided test rejects.

    Parameters
    ----------
    pm : PreparedMetric
        The metric's pool (:func:`prepare_metric`).
    idx : numpy.ndarray
        Shape (R, n), int: the pool members of each of R studies.
    zero_method : {"wilcox", "pratt", "zsplit"}
        As in :func:`analysis.stats.wilcoxon.paired_wilcoxon` (lower case).

    Returns
    -------
    p, method, n_pairs, side : numpy.ndarray
        Each of shape (R,); ``method`` indexes :data:`METHOD_NAMES`.
    """
    rows = _rank_rows(pm, idx, zero_method)
    method = _methods(rows, pm, idx)
    p = np.full(idx.shape[0], np.nan)
    for name, fill in (("exact", _exact_rows), ("permutation", _permutation_rows), ("approx", _approx_rows)):
        sel = np.nonzero(method == _METHOD_CODE[name])[0]
        if sel.size:
            fill(rows, sel, zero_method, p)
    return np.minimum(np.maximum(p, 0.0), 1.0), method, rows.n_pairs, rows.side


def resampled_p_values(
    off: npt.ArrayLike, on: npt.ArrayLike, idx: npt.ArrayLike, *, zero_method: str = "wilcox", sides: bool = False
) -> tuple[np.ndarray, ...]:
    """p-values of the report's Wilcoxon test on many resampled studies at once.

    Row r of ``idx`` is a study made of the pairs ``(off[idx[r]], on[idx[r]])``;
    its p-value is exactly ``paired_wilcoxon(off[idx[r]], on[idx[r]],
    zero_method=zero_method).p_value`` (two-sided, ``method="auto"``,
    differences rounded to :data:`analysis.stats.wilcoxon.DEFAULT_DECIMALS` decimals).

    Parameters
    ----------
    off, on : array_like
        One value per pool member, same length; NaN where undefined.
    idx : array_like of int
        Shape (R, n): the pool members of each of R studies of n participants.
    zero_method : {"wilcox", "pratt", "zsplit"}
        As in :func:`analysis.stats.wilcoxon.paired_wilcoxon`.
    sides : bool
        Also return each study's side.

    Returns
    -------
    p, method[, side]
        ``p`` (R,): NaN where ``paired_wilcoxon`` reports the test not
        computable (fewer than two complete pairs, all differences zero, an
        infinite value); ``method`` (R,): index into :data:`METHOD_NAMES`;
        ``side`` (R,): +1 when the signed-rank statistic W⁺ lies above its
        null mean (ON > OFF carries more rank weight), -1 below, 0 on it.
    """
    zm = check_zero_method(zero_method)
    pm = prepare_metric(off, on)
    ix = np.asarray(idx, dtype=np.int64)
    if ix.ndim != 2:
        raise ValueError(f"idx must be 2-D (resamples × n), got shape {ix.shape}")
    if ix.size and (ix.min() < 0 or ix.max() >= pm.code.size):
        raise ValueError(f"idx holds values outside 0 … {pm.code.size - 1}")
    p, method, _, side = study_tests(pm, ix, zm)
    return (p, method, side) if sides else (p, method)

