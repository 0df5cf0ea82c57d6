"""Planning the next study: power and sample size by resampling participants.

G*Power and R's ``pwr`` need a parametric effect size (Cohen's d, a shift of
a normal distribution); the report's tests are paired Wilcoxon signed-rank
tests on success rates (multiples of 1/10), on TCT averaged over successful
trials (undefined for a participant without a success) and on force errors,
none of which has one.  What a lab does have is per-participant paired data:
a pilot study, or the simulated participant calibrated against the paper.

**Method.**  Each participant of the pilot contributes its OFF and ON value of
every metric, aggregated exactly as the report aggregates them
(:func:`analysis.aggregate.per_participant`, overall and per target).  A
planned study of n participants is imitated by drawing n pilot participants
with replacement, whole (all metrics and both targets together, so the
metrics keep their correlation), and applying the report's test to every
metric: :func:`analysis.stats.paired_wilcoxon` with its defaults (d = ON − OFF
rounded to 10 decimals, the chosen zero method, SciPy's automatic choice of
the exact, permutation or normal method, two-sided), significant when
p < α.

**Directional power.**  What a lab asks is the probability of detecting the
effect *in the direction the pilot shows* (feedback helps), not of a
significant result either way.  The direction of a study's effect is the side
of its signed-rank statistic: W⁺ (the rank sum of the ON > OFF pairs) above
or below its null mean, the side on which the two-sided test rejects.  The
pool's direction is that of the whole pool; ``power`` is the fraction of R
resampled studies that reject *and* lie on the pool's side (about α/2 when
there is no effect), ``power_two_sided`` the fraction that reject either way
(about α), each with a Clopper–Pearson interval for the Monte Carlo error.
The family-wise figures apply Holm's correction across the four metrics
within each resampled study, as the report does, and count a metric only
when its rejection is directional.

**Speed.**  Calling :func:`~analysis.stats.paired_wilcoxon` R times per n and
metric costs about a millisecond a call; here the R tests of one metric run
at once.  The tie groups of every resample come from one sort of the whole
R × n block of codes; the exact null distribution of each n and the sign-flip
distribution of each tie structure are computed once and cached; the normal
approximation is vectorised.  The p-values are bit-for-bit those of
:func:`~analysis.stats.paired_wilcoxon` (tests/analysis/test_power.py proves
it on random samples with ties, zeros and missing values).

**Edges.**  A pilot with fewer than :data:`MIN_PILOT` participants is refused
(:class:`PowerError`).  A participant whose metric is undefined (TCT without a
success in a mode) is left out of that metric's test in every resample, as in
the report, so a study of n has fewer TCT pairs; when every difference is zero
no resample can reject; when all the pool's differences have one sign (zeros
aside), every resample has that sign too and the power is overstated.  All
are stated in :attr:`PowerResult.notes`.  The
resamples of each n come from ``numpy.random.default_rng([seed, n])``: the
same seed gives the same numbers, whatever other n are asked for.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd
from scipy import special
from scipy import stats as sps

from analysis.aggregate import METRIC_LABELS, PRIMARY_METRICS, per_participant
from analysis.load import AnalysisError, Progress, load_study
from analysis.metrics import MetricOptions, compute_trials
from analysis.signed_rank import auto_method, sign_flip_distribution, signed_rank_null_counts
from analysis.stats import DEFAULT_DECIMALS, ZERO_METHODS, holm

__all__ = [
    "DEFAULT_N_VALUES",
    "DIRECTION_NAMES",
    "DIRECTION_TEXT",
    "FAMILY_ALL",
    "FAMILY_ANY",
    "MIN_PILOT",
    "POWER_CSV_COLUMNS",
    "PairedPool",
    "PowerError",
    "PowerResult",
    "ReportPower",
    "estimate_power",
    "load_pool",
    "monte_carlo_interval",
    "plan_table",
    "pool_from_trials",
    "report_section",
    "resample_indices",
    "resampled_p_values",
    "smallest_n",
    "summary_text",
    "write_power",
]

#: Planned study sizes tried by default.
DEFAULT_N_VALUES: tuple[int, ...] = (6, 8, 10, 12, 16, 20, 30)
#: A pilot needs at least this many participants with both modes to be resampled.
MIN_PILOT = 4
#: Pseudo-metrics of the family rows: Holm across the four metrics rejects all of them / at least one.
FAMILY_ALL = "all_four_holm"
FAMILY_ANY = "any_holm"
FAMILY_LABELS = {FAMILY_ALL: "all four (Holm)", FAMILY_ANY: "at least one (Holm)"}
#: power.csv: its columns, in this order.
POWER_CSV_COLUMNS = (
    "scope", "metric", "direction", "n", "resamples", "alpha", "rejections", "power", "ci_low", "ci_high",
    "rejections_two_sided", "power_two_sided", "two_sided_ci_low", "two_sided_ci_high",
    "rejections_holm", "power_holm", "holm_ci_low", "holm_ci_high", "mean_pairs", "not_computable",
    "exact", "permutation", "approx",
)
#: ``direction`` of power.csv: the pool's direction of effect per metric (the one a rejection must have).
DIRECTION_NAMES = {1: "on_higher", -1: "on_lower", 0: "none"}
#: The same directions in words, for people (the text summary and the report's table); family rows have none.
DIRECTION_TEXT = {"on_higher": "ON > OFF", "on_lower": "ON < OFF", "none": "no effect", "": ""}
#: Method codes of :func:`resampled_p_values` (0: no test possible).
METHOD_NAMES = ("", "exact", "permutation", "approx")
_METHOD_CODE = {name: code for code, name in enumerate(METHOD_NAMES)}


class PowerError(AnalysisError):
    """The data cannot be resampled or the request is malformed; the message says which and why."""


# ------------------------------------------------------------------------------------------------
# The pool: per-participant OFF/ON values, aggregated as the report aggregates them
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class PairedPool:
    """Per-participant OFF and ON values to resample from.

    Attributes
    ----------
    participants
        Participant codes, in the order of the last axis of ``off`` and ``on``.
    scopes
        ``"overall"``, then the target labels in order of target force.
    metrics
        The metrics (the Holm family): :data:`analysis.aggregate.PRIMARY_METRICS`.
    off, on
        Shape (scopes, metrics, participants); NaN where a value is undefined
        (TCT with no successful trial in that mode) or a participant lacks a mode.
    source
        Where the values come from, in words (for the outputs).
    options
        The aggregation choices (error window, TCT policy).
    """

    participants: tuple[str, ...]
    scopes: tuple[str, ...]
    metrics: tuple[str, ...]
    off: npt.NDArray[np.float64]
    on: npt.NDArray[np.float64]
    source: str
    options: MetricOptions = MetricOptions()

    @property
    def n_participants(self) -> int:
        """Participants in the pool."""
        return len(self.participants)


def _wide(per_part: pd.DataFrame, metric: str, codes: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    wide = per_part.pivot(index="participant_code", columns="haptic_mode", values=metric).reindex(list(codes))
    cols = [wide[m].to_numpy(dtype=float) if m in wide.columns else np.full(len(codes), np.nan) for m in ("off", "on")]
    return cols[0], cols[1]


def pool_from_trials(trials: pd.DataFrame, options: MetricOptions = MetricOptions(), *, source: str = "") -> PairedPool:
    """The resampling pool of an analysed trial table.

    Parameters
    ----------
    trials
        :attr:`analysis.metrics.TrialTable.trials` (or a table with its columns).
    options
        Error window and TCT policy, as in the report.
    source
        Where the trials come from, in words.

    Returns
    -------
    PairedPool
        Only participants with trials in both haptic modes are kept.
    """
    overall = per_participant(trials, options)
    modes = overall.groupby("participant_code")["haptic_mode"].nunique()
    codes = tuple(sorted(str(c) for c in modes[modes == 2].index))
    by_target = per_participant(trials, options, by_target=True)
    order = trials.drop_duplicates("target_label").sort_values("target_force_n")["target_label"].tolist()
    scopes = ("overall", *[str(t) for t in order])
    metrics = tuple(PRIMARY_METRICS)
    off = np.full((len(scopes), len(metrics), len(codes)), np.nan)
    on = off.copy()
    for s, scope in enumerate(scopes):
        part = overall if scope == "overall" else by_target[by_target["target_label"] == scope]
        for m, metric in enumerate(metrics):
            off[s, m], on[s, m] = _wide(part, metric, codes)
    return PairedPool(codes, scopes, metrics, off, on, source, options)


def load_pool(
    databases: Sequence[str | os.PathLike[str]],
    options: MetricOptions = MetricOptions(),
    *,
    source: str | None = None,
    progress: Progress | None = None,
    workers: int | None = None,
    participants: Sequence[str] | None = None,
) -> PairedPool:
    """Read study databases (read-only), recompute every trial as the report does, and build the pool.

    Parameters
    ----------
    databases
        Pilot study databases; they merge into one study, as in the report.
    options
        Error window and TCT policy.
    source
        Description for the outputs (default: the database names).
    progress, workers
        As in :func:`analysis.metrics.compute_trials`.
    participants
        Only these participant codes (the first N of a larger simulated pool); default: all.
    """
    study = load_study(databases)
    if participants is not None:
        import dataclasses

        keep = set(participants)
        study = dataclasses.replace(study, trials=study.trials[study.trials["participant_code"].isin(keep)],
                                    sessions=study.sessions[study.sessions["participant_code"].isin(keep)])
    trials = compute_trials(study, options, progress=progress, workers=workers).trials
    if source is None:
        source = "the pilot study " + ", ".join(os.path.basename(str(d)) for d in databases)
    return pool_from_trials(trials, options, source=source)


# ------------------------------------------------------------------------------------------------
# The report's Wilcoxon test, vectorised across resamples
# ------------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=None)
def _exact_p(n: int) -> np.ndarray:
    """Two-sided exact p-value of every W⁺ = 0 … n(n+1)/2 for n untied, non-zero differences."""
    return _two_sided_p(signed_rank_null_counts(n), float(2**n))


def _two_sided_p(weights: np.ndarray, total: float) -> np.ndarray:
    """``analysis.stats._tail_p(weights, total, s, s, "two-sided")`` for every s at once (same float operations)."""
    cdf = np.cumsum(weights)
    p_less = cdf / total
    p_greater = (cdf[-1] - cdf + weights) / total  # integer counts of S ≥ s, exact as in _tail_p
    p = np.minimum(2.0 * np.minimum(p_less, p_greater), 1.0)
    p.flags.writeable = False
    return p


_PERM_CACHE: dict[int, np.ndarray] = {}
_PERM_CACHE_MAX = 200_000


@dataclass(frozen=True, slots=True)
class _PreparedMetric:
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


def _prepare(off: npt.ArrayLike, on: npt.ArrayLike) -> _PreparedMetric:
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
    return _PreparedMetric(rank, by_rank, code, ~unusable & (d > 0), ~unusable & (d == 0), unusable, bad,
                           bool(bad.any()))


def _permutation_p(key: int, units: np.ndarray) -> np.ndarray:
    """Two-sided p of every doubled W⁺ under the sign-flip distribution of these doubled mid-ranks (cached by key)."""
    table = _PERM_CACHE.get(key)
    if table is None:
        if len(_PERM_CACHE) >= _PERM_CACHE_MAX:
            _PERM_CACHE.clear()
        table = _PERM_CACHE[key] = _two_sided_p(*sign_flip_distribution(units))
    return table


def _p_values(pm: _PreparedMetric, idx: np.ndarray,
              zero_method: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """p-value (NaN: not computable), method code, complete pairs and side of every resampled study (rows of idx).

    The side is the direction of the study's effect as the signed-rank test
    sees it: +1 when W⁺ (the rank sum of the ON > OFF pairs) lies above its
    null mean, -1 below, 0 on it -- the side on which the two-sided test rejects.
    """
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
    n_pairs = n - missing.sum(axis=1)
    n_zero = zero.sum(axis=1)
    if zero_method == "wilcox":
        ranked, offset = nonzero, n_zero[:, None]  # zeros (sorted first) are dropped before ranking
    else:
        ranked, offset = ~missing, np.zeros((r, 1), dtype=np.int64)
    units = 2 * (start - offset) + size + 1  # doubled mid-ranks: integers
    w2 = np.where(pm.positive[pick], units, 0).sum(axis=1)  # 2·W⁺ without the zero ranks
    # W⁺ against its null mean, half the non-zero pairs' rank sum: 2·w2 vs Σ units, all integers (zeros cancel)
    side = np.sign(2 * w2 - np.where(nonzero, units, 0).sum(axis=1)).astype(np.int8)
    count = ranked.sum(axis=1)
    tie_groups = nonzero & (size > 1)
    has_ties = tie_groups.any(axis=1)
    computable = (n_pairs >= 2) & (n_zero < n_pairs)
    if pm.any_bad:
        computable &= ~pm.bad[idx].any(axis=1)

    # SciPy's automatic choice, asked once per distinct (pairs, any zero, any tie)
    keys = 4 * n_pairs + 2 * (n_zero > 0) + has_ties
    uniq, inverse = np.unique(keys, return_inverse=True)
    chosen = np.array([_METHOD_CODE[auto_method(int(k) // 4, int(k) // 2 % 2, int(k) % 2)] for k in uniq],
                      dtype=np.int8)
    method = np.where(computable, chosen[inverse.ravel()], 0).astype(np.int8)

    p = np.full(r, np.nan)
    sel = np.nonzero(method == _METHOD_CODE["exact"])[0]
    for nn in np.unique(count[sel]):
        at = sel[count[sel] == nn]
        p[at] = _exact_p(int(nn))[w2[at] // 2]
    sel = np.nonzero(method == _METHOD_CODE["permutation"])[0]
    if sel.size:
        # The sign-flip distribution depends on the doubled mid-ranks of the non-zero pairs only: their
        # number, where tie groups begin among them (≤ 13 bits) and the ranks zeros take below them.
        nz = nonzero[sel]
        begins = nz & new[sel]
        bit = np.left_shift(np.int64(1), np.clip(pos[sel] - n_zero[sel][:, None], 0, 62))
        shape = np.where(begins, bit, 0).sum(axis=1)
        below = n_zero[sel] if zero_method != "wilcox" else np.zeros(sel.size, dtype=np.int64)
        key = (shape * 64 + below) * 64 + count[sel] - (n_zero[sel] if zero_method != "wilcox" else 0)
        kinds, first, which = np.unique(key, return_index=True, return_inverse=True)
        tables = []
        for kk, i in zip(kinds.tolist(), first.tolist()):
            t = _PERM_CACHE.get(kk)
            tables.append(t if t is not None else _permutation_p(kk, units[sel[i]][nz[i]]))
        stacked = np.full((len(tables), max(t.size for t in tables)), np.nan)
        for k, t in enumerate(tables):
            stacked[k, : t.size] = t
        p[sel] = stacked[which.ravel(), w2[sel]]
    sel = np.nonzero(method == _METHOD_CODE["approx"])[0]
    if sel.size:
        # SciPy's normal approximation with tie and zero corrections, in paired_wilcoxon's order of operations
        cnt = count[sel].astype(np.float64)
        nzf = n_zero[sel].astype(np.float64)
        w_plus2 = w2[sel].astype(np.float64)
        if zero_method == "zsplit":
            w_plus2 += n_zero[sel] * (n_zero[sel] + 1) // 2  # half the zero ranks go to W⁺
        tie_set = tie_groups[sel] if zero_method != "zsplit" else (ranked & (size > 1))[sel]
        tie_correct = np.where(tie_set, size[sel] ** 2 - 1, 0).sum(axis=1).astype(np.float64)  # Σ (t³ − t)
        mn = cnt * (cnt + 1.0) * 0.25
        se2 = cnt * (cnt + 1.0) * (2.0 * cnt + 1.0)
        if zero_method == "pratt":
            mn -= nzf * (nzf + 1.0) * 0.25
            se2 -= nzf * (nzf + 1.0) * (2.0 * nzf + 1.0)
        se = np.sqrt((se2 - tie_correct / 2.0) / 24.0)
        z = (w_plus2 / 2.0 - mn) / se
        p[sel] = 2.0 * special.ndtr(-np.abs(z))
    return np.minimum(np.maximum(p, 0.0), 1.0), method, n_pairs, side


def resampled_p_values(
    off: npt.ArrayLike, on: npt.ArrayLike, idx: npt.ArrayLike, *, zero_method: str = "wilcox", sides: bool = False
) -> tuple[np.ndarray, ...]:
    """p-values of the report's Wilcoxon test on many resampled studies at once.

    Row r of ``idx`` is a study made of the pairs ``(off[idx[r]], on[idx[r]])``;
    its p-value is exactly ``paired_wilcoxon(off[idx[r]], on[idx[r]],
    zero_method=zero_method).p_value`` (two-sided, ``method="auto"``,
    differences rounded to :data:`analysis.stats.DEFAULT_DECIMALS` decimals).

    Parameters
    ----------
    off, on : array_like
        One value per pool member, same length; NaN where undefined.
    idx : array_like of int
        Shape (R, n): the pool members of each of R studies of n participants.
    zero_method : {"wilcox", "pratt", "zsplit"}
        As in :func:`analysis.stats.paired_wilcoxon`.
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
    zm = str(zero_method).lower()
    if zm not in ZERO_METHODS:
        raise ValueError(f"zero_method = {zero_method!r}: allowed are {', '.join(ZERO_METHODS)}")
    pm = _prepare(off, on)
    ix = np.asarray(idx, dtype=np.int64)
    if ix.ndim != 2:
        raise ValueError(f"idx must be 2-D (resamples × n), got shape {ix.shape}")
    if ix.size and (ix.min() < 0 or ix.max() >= pm.code.size):
        raise ValueError(f"idx holds values outside 0 … {pm.code.size - 1}")
    p, method, _, side = _p_values(pm, ix, zm)
    return (p, method, side) if sides else (p, method)


# ------------------------------------------------------------------------------------------------
# Power
# ------------------------------------------------------------------------------------------------
def monte_carlo_interval(
    successes: npt.ArrayLike, trials: int, level: float = 0.95
) -> tuple[np.ndarray, np.ndarray]:
    """Clopper–Pearson interval of a proportion estimated from ``trials`` Monte Carlo draws.

    The exact binomial interval, equal to
    ``scipy.stats.binomtest(k, trials).proportion_ci(level)`` (the default,
    exact method) but vectorised: the bounds are the beta quantiles
    B(α/2; k, N − k + 1) and B(1 − α/2; k + 1, N − k), 0 at k = 0 and 1 at k = N.
    """
    k = np.asarray(successes, dtype=np.float64)
    a = (1.0 - level) / 2.0
    with np.errstate(invalid="ignore", divide="ignore"):
        lo = np.where(k > 0, sps.beta.ppf(a, np.maximum(k, 1), trials - k + 1), 0.0)
        hi = np.where(k < trials, sps.beta.isf(a, k + 1, np.maximum(trials - k, 1)), 1.0)
    return lo, hi


@dataclass(frozen=True, slots=True)
class PowerResult:
    """Estimated power of a planned study, per metric and size.

    Attributes
    ----------
    frame
        One row per scope × metric × n (columns :data:`POWER_CSV_COLUMNS`, then
        ``source``); ``metric`` is a metric name or :data:`FAMILY_ALL` /
        :data:`FAMILY_ANY` (their ``power`` is the Holm family-wise figure);
        ``power`` counts rejections in the pool's ``direction`` only,
        ``power_two_sided`` every rejection (empty on the family rows).
    notes
        Plain-words notes on the pool (undefined values, zero differences,
        a pool whose differences all have one sign, the smallest attainable p
        at small n).
    source, n_pool, resamples, alpha, seed, zero_method, options, n_values, interval_level
        What was resampled and how.
    """

    frame: pd.DataFrame
    notes: list[str]
    source: str
    n_pool: int
    resamples: int
    alpha: float
    seed: int
    zero_method: str
    options: MetricOptions
    n_values: tuple[int, ...] = field(default=DEFAULT_N_VALUES)
    interval_level: float = 0.95


def resample_indices(seed: int, n: int, resamples: int, pool_size: int) -> np.ndarray:
    """The pool members of ``resamples`` studies of ``n`` participants, drawn with replacement.

    From ``numpy.random.default_rng([seed, n])``: reproducible for a seed, and
    independent of which other study sizes are asked for.
    """
    return np.random.default_rng([int(seed), int(n)]).integers(0, pool_size, size=(int(resamples), int(n)))


def _check_request(n_values: Sequence[int], resamples: int, alpha: float, zero_method: str) -> tuple[int, ...]:
    ns = tuple(int(n) for n in n_values)
    if not ns:
        raise PowerError("n: give at least one study size")
    for n in ns:
        if not 2 <= n <= 10_000:
            raise PowerError(f"n = {n}: each study size must be a whole number from 2 to 10000")
    if not 1 <= int(resamples) <= 1_000_000:
        raise PowerError(f"resamples = {resamples}: must be a whole number from 1 to 1000000")
    if not 0.0 < float(alpha) < 1.0:
        raise PowerError(f"alpha = {alpha}: must be a number with 0 < alpha < 1")
    if zero_method not in ZERO_METHODS:
        raise PowerError(f"zero_method = {zero_method!r}: allowed are {', '.join(ZERO_METHODS)}")
    return tuple(sorted(set(ns)))


def _pool_notes(pool: PairedPool, prepared: list[list[_PreparedMetric]], direction: np.ndarray,
                n_values: tuple[int, ...], alpha: float) -> list[str]:
    notes = []
    one_sign: list[str] = []  # one note for all of them: it can hold for most measures of a small pilot
    P = pool.n_participants
    for s, scope in enumerate(pool.scopes):
        where = "" if scope == "overall" else f" ({scope})"
        for m, metric in enumerate(pool.metrics):
            pm = prepared[s][m]
            label = METRIC_LABELS.get(metric, metric)
            undefined = int(pm.missing.sum())
            if undefined == P:
                notes.append(f"{label}{where} is undefined for every participant: no study can test it, "
                             "its power is 0 at every n")
                continue
            if undefined and scope == "overall":
                why = (" (no successful trial in a mode)" if metric == "tct_s" and pool.options.tct_policy == "successful"
                       else "")
                notes.append(
                    f"{label} is undefined for {undefined} of {P} participants{why}: resampled studies leave "
                    f"those pairs out, as the report does, so a study of n participants has about "
                    f"{1 - undefined / P:.2f}·n {label.split(' (')[0]} pairs")
            if pm.zero[~pm.missing].all():
                notes.append(f"{label}{where}: every participant has ON = OFF, so no resampled study can "
                             "reject: its power is 0 at every n (the pool shows no effect)")
                continue
            if direction[s, m] == 0:
                notes.append(f"{label}{where}: the pool's signed-rank statistic lies exactly on its null mean, so "
                             "the pool shows no direction of effect; its (directional) power is 0 at every n "
                             "(power_two_sided in power.csv still counts every rejection)")
            used = ~pm.missing & ~pm.zero
            if used.any() and (pm.positive[used].all() or not pm.positive[used].any()):
                sign = "ON > OFF" if pm.positive[used].all() else "ON < OFF"
                one_sign.append(f"{label}{where} {sign}{' or =' if pm.zero[~pm.missing].any() else ''}")
    if one_sign:
        notes.append(
            f"every participant of the pool has the same sign of ON − OFF (zeros aside) for {'; '.join(one_sign)}: "
            "every resampled study then has that sign too, so the power of "
            f"{'this test' if len(one_sign) == 1 else 'these tests'} comes out high; a real study will also meet "
            "participants the other way round, so it overstates the power (more so the smaller the pool)")
    if max(n_values) > P:
        notes.append(
            f"n up to {max(n_values)} from {P} participants: larger studies repeat pool members, so their power "
            f"treats the pool as the whole population; its own sampling error (of {P} participants) is not in "
            "the intervals")
    small = [n for n in n_values if 2.0 / 2**n >= alpha]
    if small:
        notes.append(
            f"with n ≤ {max(small)} the exact test cannot reach p < {alpha:g} (smallest two-sided p = 2/2ⁿ = "
            f"{2.0 / 2 ** max(small):.3g} at n = {max(small)}): power there is 0 by construction")
    return notes


def estimate_power(
    pool: PairedPool,
    n_values: Sequence[int] = DEFAULT_N_VALUES,
    *,
    resamples: int = 2000,
    alpha: float = 0.05,
    seed: int = 0,
    zero_method: str = "wilcox",
    interval_level: float = 0.95,
) -> PowerResult:
    """Power of the report's ON-vs-OFF tests for studies of each size in ``n_values``.

    Parameters
    ----------
    pool
        Per-participant values to resample (:func:`load_pool`, :func:`pool_from_trials`).
    n_values
        Planned numbers of participants (each ≥ 2).
    resamples
        Resampled studies per n.
    alpha
        Significance level: a test rejects when p < alpha (the report's marks use p < 0.05).
    seed
        Resampling seed; the studies of size n are drawn from ``default_rng([seed, n])``.
    zero_method
        Wilcoxon zero handling, as the report's ``--zero-method``.
    interval_level
        Level of the Clopper–Pearson Monte Carlo intervals.

    Returns
    -------
    PowerResult

    Raises
    ------
    PowerError
        Fewer than :data:`MIN_PILOT` participants in the pool, or a malformed request.
    """
    ns = _check_request(n_values, resamples, alpha, zero_method)
    P = pool.n_participants
    if P < MIN_PILOT:
        raise PowerError(
            f"{pool.source or 'the pool'} has {P} participant{'s' if P != 1 else ''} with both haptic modes: at "
            f"least {MIN_PILOT} are needed to resample planned studies from (with fewer, every resampled study "
            "repeats the same few people)")
    R = int(resamples)
    prepared = [[_prepare(pool.off[s, m], pool.on[s, m]) for m in range(len(pool.metrics))]
                for s in range(len(pool.scopes))]
    # the pool's own direction of effect, per scope and metric: the side its own test statistic lies on
    whole = np.arange(P)[None, :]
    direction = np.array([[int(_p_values(pm, whole, zero_method)[3][0]) for pm in row] for row in prepared])
    rows: list[dict[str, object]] = []
    for n in ns:
        idx = resample_indices(seed, n, R, P)
        for s, scope in enumerate(pool.scopes):
            pvals = np.empty((R, len(pool.metrics)))
            agree = np.empty((R, len(pool.metrics)), dtype=bool)
            per_metric = []
            for m in range(len(pool.metrics)):
                p, method, n_pairs, side = _p_values(prepared[s][m], idx, zero_method)
                pvals[:, m] = p
                agree[:, m] = (side == direction[s, m]) & (direction[s, m] != 0)
                per_metric.append((method, n_pairs))
            with np.errstate(invalid="ignore"):
                reject_two = pvals < alpha
                reject_holm = (holm(pvals, axis=1) < alpha) & agree
            reject = reject_two & agree
            for m, metric in enumerate(pool.metrics):
                method, n_pairs = per_metric[m]
                counts = np.bincount(method, minlength=len(METHOD_NAMES))
                rows.append(dict(scope=scope, metric=metric, direction=DIRECTION_NAMES[int(direction[s, m])], n=n,
                                 rejections=int(reject[:, m].sum()), rejections_two_sided=int(reject_two[:, m].sum()),
                                 rejections_holm=int(reject_holm[:, m].sum()), mean_pairs=float(n_pairs.mean()),
                                 not_computable=int(counts[0]), exact=int(counts[1]), permutation=int(counts[2]),
                                 approx=int(counts[3])))
            for fam, hits in ((FAMILY_ALL, reject_holm.all(axis=1)), (FAMILY_ANY, reject_holm.any(axis=1))):
                k = int(hits.sum())
                rows.append(dict(scope=scope, metric=fam, direction="", n=n, rejections=k,
                                 rejections_two_sided=np.nan, rejections_holm=k, mean_pairs=np.nan,
                                 not_computable=0, exact=0, permutation=0, approx=0))
    frame = pd.DataFrame(rows)
    frame["resamples"] = R
    frame["alpha"] = float(alpha)
    frame["rejections_two_sided"] = frame["rejections_two_sided"].astype("Int64")  # empty on the family rows
    for prefix, col, power_col in (("", "rejections", "power"),
                                   ("two_sided_", "rejections_two_sided", "power_two_sided"),
                                   ("holm_", "rejections_holm", "power_holm")):
        k = frame[col].to_numpy(dtype=float, na_value=np.nan)
        frame[power_col] = k / R
        lo, hi = monte_carlo_interval(np.nan_to_num(k), R, interval_level)
        frame[f"{prefix}ci_low"] = np.where(np.isnan(k), np.nan, lo)
        frame[f"{prefix}ci_high"] = np.where(np.isnan(k), np.nan, hi)
    frame = frame[list(POWER_CSV_COLUMNS)]
    frame["source"] = pool.source
    return PowerResult(frame, _pool_notes(pool, prepared, direction, ns, float(alpha)), pool.source, P, R,
                       float(alpha), int(seed), zero_method, pool.options, ns, float(interval_level))


# ------------------------------------------------------------------------------------------------
# In words, and on disk
# ------------------------------------------------------------------------------------------------
def smallest_n(frame: pd.DataFrame, scope: str, metric: str, target: float, *, holm_adjusted: bool = False) -> int | None:
    """The smallest n tried from which on every larger n tried reaches ``target`` power (None: not reached).

    "From which on" rather than "the first n that reaches it": the discrete
    Wilcoxon test can make power dip between neighbouring n, and a plan needs
    an n that is not followed by a shortfall.
    """
    sel = frame[(frame["scope"] == scope) & (frame["metric"] == metric)].sort_values("n")
    col = "power_holm" if holm_adjusted else "power"
    ok = (sel[col].to_numpy() >= target)
    ns = sel["n"].to_numpy()
    best = None
    for i in range(len(ns) - 1, -1, -1):
        if not ok[i]:
            break
        best = int(ns[i])
    return best


def _label(metric: str) -> str:
    return FAMILY_LABELS.get(metric, METRIC_LABELS.get(metric, metric))


def _reach(frame: pd.DataFrame, scope: str, metric: str, target: float, holm_adjusted: bool) -> str:
    n = smallest_n(frame, scope, metric, target, holm_adjusted=holm_adjusted)
    if n is not None:
        return f"n = {n}"
    last = frame[(frame["scope"] == scope) & (frame["metric"] == metric)].sort_values("n").iloc[-1]
    return f"> {int(last['n'])} ({last['power_holm' if holm_adjusted else 'power']:.0%})"


def summary_text(result: PowerResult) -> str:
    """The plan in words: per metric, the smallest n reaching 80 % and 90 % power, and the notes."""
    f = result.frame
    tct = "over successful trials" if result.options.tct_policy == "successful" else "failures counted at the trial cap"
    lines = [
        f"Source: {result.source}; {result.n_pool} participants with both haptic modes, resampled with replacement "
        f"({result.resamples} studies per n, seed {result.seed}).",
        f"Test: the report's paired Wilcoxon signed-rank test ON vs OFF per metric, two-sided, significant at "
        f"p < {result.alpha:g}; TCT {tct}; RMSE and Max AE from the "
        f"{'cue' if result.options.error_window == 'cue' else 'first contact'}; zero differences: {result.zero_method}.",
        "Power: the probability that a study detects the effect in the direction this pool shows (a rejection "
        "counts only when the resampled study's effect lies on the pool's side); the two-sided rejection rate, "
        "which also counts significant effects the other way, is power_two_sided.",
        f"Intervals ({result.interval_level:.0%}, in power.csv and the figure) are the Monte Carlo error of the "
        f"resampling only, not the uncertainty of the {result.n_pool} participants' own effects: a plan from a "
        "small pilot is itself uncertain.",
        f"Participants needed: the smallest n of {', '.join(str(n) for n in result.n_values)} from which on power "
        "stays at or above the target, for the test alone and with Holm across the four metrics (as the report's "
        "significance marks); '> N (x %)': not reached, x = power at the largest n tried.",
        f"  {'':<21s}{'80 % power':<28s}90 % power",
        f"  {'':<21s}{'test':<14s}{'with Holm':<14s}{'test':<14s}with Holm",
    ]
    for scope in dict.fromkeys(f["scope"]):
        if scope != "overall":
            lines.append(f"  within {scope}:")
        for metric in dict.fromkeys(f["metric"]):
            family = metric in FAMILY_LABELS
            cells = []
            for target in (0.8, 0.9):
                cells.append("" if family else _reach(f, scope, metric, target, False))
                cells.append(_reach(f, scope, metric, target, True))
            name = _label(metric) if scope == "overall" else f"  {_label(metric)}"
            lines.append(f"  {name:<21s}" + "".join(f"{c:<14s}" for c in cells).rstrip())
    lines.append("Power at each n (overall; the two-sided rejection rate in brackets):")
    ns = list(result.n_values)
    lines.append(f"  {'':<21s}{'pool shows':<12s}" + "".join(f"{'n = ' + str(n):<14s}" for n in ns).rstrip())
    overall = f[f["scope"] == "overall"]
    for metric in dict.fromkeys(overall["metric"]):
        if metric in FAMILY_LABELS:
            continue
        sel = overall[overall["metric"] == metric].set_index("n")
        direction = DIRECTION_TEXT[str(sel["direction"].iloc[0])]
        cells = [f"{sel.at[n, 'power']:.0%} ({sel.at[n, 'power_two_sided']:.0%})" for n in ns]
        lines.append(f"  {_label(metric):<21s}{direction:<12s}" + "".join(f"{c:<14s}" for c in cells).rstrip())
    last = max(result.n_values)
    under = [_label(m) for m in dict.fromkeys(f["metric"])
             if m not in FAMILY_LABELS and smallest_n(f, "overall", m, 0.8) is None]
    if under:
        lines.append(f"Under-powered: {', '.join(under)} do{'es' if len(under) == 1 else ''} not reach 80 % power "
                     f"by n = {last}: a study testing {'it' if len(under) == 1 else 'them'} needs more participants "
                     "(try a larger --n) or a more sensitive definition.")
    if result.notes:
        lines.append("Notes:")
        lines.extend(f"  - {n}" for n in result.notes)
    return "\n".join(lines)


def write_power(result: PowerResult, folder: str | os.PathLike[str]) -> list[str]:
    """Write ``power.csv``, ``power.txt`` (:func:`summary_text`) and ``power.png/.pdf/.svg`` into ``folder``.

    ``haptic-study power`` gives it the temporary folder of
    :func:`analysis.outdir.write_output_folder`, which moves the files into
    ``--out`` under the output-folder policy (marker, ``--force``, the pool kept).

    Returns
    -------
    list of str
        The file names written.
    """
    from analysis.power_figures import power_curves

    out = Path(folder)
    result.frame.to_csv(out / "power.csv", index=False)
    (out / "power.txt").write_text(summary_text(result) + "\n", encoding="utf-8")
    fig = power_curves(result)
    names = ["power.csv", "power.txt"]
    for ext in ("png", "pdf", "svg"):
        meta = {"Date": None} if ext == "svg" else {"CreationDate": None} if ext == "pdf" else {}
        fig.savefig(out / f"power.{ext}", format=ext, dpi=150, metadata=meta)
        names.append(f"power.{ext}")
    return names


@dataclass(frozen=True, slots=True)
class ReportPower:
    """The "what n would a study need?" section of ``report --power``.

    Attributes
    ----------
    result
        The estimate (None when it could not be made).
    notice
        Why it could not be made, in words ("" when it was).
    png
        The power-curve figure (None when not made).
    """

    result: PowerResult | None
    notice: str
    png: bytes | None


def plan_table(result: PowerResult) -> pd.DataFrame:
    """The plan as a table, one row per scope × metric (family rows included), for the report's page.

    Columns: ``scope``, ``metric``, ``direction``, ``n80``, ``n90``,
    ``n80_holm``, ``n90_holm`` (text: ``"12"``, ``"> 30 (64%)"`` when not
    reached, ``""`` where it does not apply) and ``power_n{n}`` per n tried
    (directional power, a fraction; NaN where it does not apply).
    """
    f = result.frame
    rows = []
    for scope in dict.fromkeys(f["scope"]):
        for metric in dict.fromkeys(f[f["scope"] == scope]["metric"]):
            family = metric in FAMILY_LABELS
            sel = f[(f["scope"] == scope) & (f["metric"] == metric)].set_index("n")
            row: dict[str, object] = {"scope": scope, "metric": metric, "direction": str(sel["direction"].iloc[0])}
            for target in (0.8, 0.9):
                key = f"n{round(target * 100)}"
                row[key] = "" if family else _reach(f, scope, metric, target, False).removeprefix("n = ")
                row[f"{key}_holm"] = _reach(f, scope, metric, target, True).removeprefix("n = ")
            for n in result.n_values:
                row[f"power_n{n}"] = float(sel.at[n, "power_holm" if family else "power"])
            rows.append(row)
    return pd.DataFrame(rows)


def report_section(trials: pd.DataFrame, options: MetricOptions, zero_method: str,
                   out_dir: str | os.PathLike[str]) -> ReportPower:
    """``report --power``: what n a study would need, resampling the reported study's own participants.

    Writes ``power.csv`` and ``figures/power.png`` / ``.svg`` into ``out_dir``
    with the defaults of ``haptic-study power`` (n = 6 … 30, 2000 resamples,
    α = 0.05, seed 0).

    Returns
    -------
    ReportPower
        The estimate and the figure; when the study cannot be resampled
        (fewer than :data:`MIN_PILOT` participants with both modes, ...), no
        estimate and the reason in words, for the page to show.
    """
    from analysis.figures import save
    from analysis.power_figures import power_curves

    pool = pool_from_trials(trials, options, source="this study")
    try:
        result = estimate_power(pool, zero_method=zero_method)
    except PowerError as exc:
        return ReportPower(None, f"Not estimated: {exc}.", None)
    out = Path(out_dir)
    result.frame.to_csv(out / "power.csv", index=False)
    return ReportPower(result, "", save(power_curves(result), out / "figures", "power"))
