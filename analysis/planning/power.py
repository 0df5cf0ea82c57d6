"""Planning the next study: power and sample size by resampling participants.

G*Power and R's ``pwr`` need a parametric effect size (Cohen's d, a shift of
a normal distribution); the report's tests are paired Wilcoxon signed-rank
tests on success rates (multiples of 1/10), on TCT averaged over successful
trials (undefined for a participant without a success) and on force errors,
none of which has one.  What a lab does have is per-participant paired data:
a pilot study, or the simulated participant calibrated against the paper.

**Method.**  Each participant of the pilot contributes its OFF and ON value of
every metric, aggregated exactly as the report aggregates them
(:func:`analysis.stats.aggregate.per_participant`, overall and per target).  A
planned study of n participants is imitated by drawing n pilot participants
with replacement, whole (all metrics and both targets together, so the
metrics keep their correlation), and applying the report's test to every
metric: :func:`analysis.stats.wilcoxon.paired_wilcoxon` with its defaults (d = ON − OFF
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
The family-wise figures apply Holm's correction across the primary metrics
(the report's family) within each resampled study, as the report does, and count a metric only
when its rejection is directional; a secondary metric has its own power and none with Holm.

**Speed.**  The R tests of one metric run at once
(:mod:`analysis.stats.resampled_wilcoxon`), bit for bit those of
:func:`~analysis.stats.wilcoxon.paired_wilcoxon`; the pool is built in
:mod:`analysis.planning.paired_pool`.

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

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
import pandas as pd
from scipy import stats as sps

from analysis.planning.paired_pool import PairedPool
from analysis.reading.load import AnalysisError
from analysis.reading.metrics import MetricOptions
from analysis.stats.aggregate import METRIC_LABELS, PRIMARY_METRICS
from analysis.stats.holm import holm
from analysis.stats.resampled_wilcoxon import METHOD_NAMES, PreparedMetric, prepare_metric, study_tests
from analysis.stats.wilcoxon import ZERO_METHODS
from protocol.metrics import by_participant_name, family_word

__all__ = [
    "DEFAULT_N_VALUES",
    "DIRECTION_NAMES",
    "DIRECTION_TEXT",
    "FAMILY_ANY",
    "MIN_PILOT",
    "POWER_CSV_COLUMNS",
    "PowerError",
    "PowerResult",
    "estimate_power",
    "family_all",
    "holm_applies",
    "is_family_row",
    "metric_label",
    "monte_carlo_interval",
    "resample_indices",
]

#: Planned study sizes tried by default.
DEFAULT_N_VALUES: tuple[int, ...] = (6, 8, 10, 12, 16, 20, 30)
#: A pilot needs at least this many participants with both modes to be resampled.
MIN_PILOT = 4
#: Pseudo-metric of a family row: Holm across the primary metrics rejects at least one (the other family row, all
#: of them, is named by their number: :func:`family_all`).
FAMILY_ANY = "any_holm"


def family_all(family: Sequence[str]) -> str:
    """The family row whose Holm correction across these primary metrics (per-participant columns; the study's, its
    tasks': the paper's four for force regulation) rejects all of them: ``all_four_holm``."""
    return f"all_{family_word([m for name in family if (m := by_participant_name(name)) is not None])}_holm"


def is_family_row(metric: str) -> bool:
    """Whether a row of power.csv is a family row (:func:`family_all`, :data:`FAMILY_ANY`), not a metric's."""
    return metric == FAMILY_ANY or (metric.startswith("all_") and metric.endswith("_holm"))
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


class PowerError(AnalysisError):
    """The data cannot be resampled or the request is malformed; the message says which and why."""


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
        ``source``); ``metric`` is a metric name or a family row, :func:`family_all` /
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
    if zero_method not in ZERO_METHODS:  # exactly these names: estimate_power passes it on as given
        raise PowerError(f"zero_method = {zero_method!r}: allowed are {', '.join(ZERO_METHODS)}")
    return tuple(sorted(set(ns)))


def _pool_notes(pool: PairedPool, prepared: list[list[PreparedMetric]], direction: np.ndarray,
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
                known = by_participant_name(metric)
                successful_only = known is not None and known.success_only and pool.options.tct_policy == "successful"
                why = " (no successful trial in a mode)" if successful_only else ""
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


@dataclass
class _Counts:
    """Rejection counts of one scope and study size, summed over the chunks of resampled studies."""

    metrics: int
    family: np.ndarray  # which metrics Holm's correction runs across (the report's primary measures)
    reject: np.ndarray = field(init=False)
    two_sided: np.ndarray = field(init=False)
    holm: np.ndarray = field(init=False)
    pairs: np.ndarray = field(init=False)
    methods: np.ndarray = field(init=False)
    family_rows: np.ndarray = field(init=False)  # all of the family (Holm), at least one (Holm)

    def __post_init__(self) -> None:
        m = self.metrics
        self.reject, self.two_sided, self.holm, self.pairs = (np.zeros(m, dtype=np.int64) for _ in range(4))
        self.methods = np.zeros((m, len(METHOD_NAMES)), dtype=np.int64)
        self.family_rows = np.zeros(2, dtype=np.int64)

    def add(self, prepared: list[PreparedMetric], direction: np.ndarray, idx: np.ndarray, zero_method: str,
            alpha: float) -> None:
        """Test the studies of ``idx`` (rows) and add their counts."""
        R = idx.shape[0]
        pvals = np.empty((R, self.metrics))
        agree = np.empty((R, self.metrics), dtype=bool)
        for m in range(self.metrics):
            p, method, n_pairs, side = study_tests(prepared[m], idx, zero_method)
            pvals[:, m] = p
            agree[:, m] = (side == direction[m]) & (direction[m] != 0)
            self.methods[m] += np.bincount(method, minlength=len(METHOD_NAMES))
            self.pairs[m] += int(n_pairs.sum())
        family = self.family
        with np.errstate(invalid="ignore"):
            reject_two = pvals < alpha
            reject_holm = (holm(pvals[:, family], axis=1) < alpha) & agree[:, family]
        self.reject += (reject_two & agree).sum(axis=0)
        self.two_sided += reject_two.sum(axis=0)
        self.holm[family] += reject_holm.sum(axis=0)
        self.family_rows += (int(reject_holm.all(axis=1).sum()), int(reject_holm.any(axis=1).sum()))

    def rows(self, metrics: Sequence[str], direction: np.ndarray, scope: str, n: int,
             R: int) -> list[dict[str, object]]:
        """power.csv's rejection counts: one row per metric, then the family rows."""
        rows: list[dict[str, object]] = []
        for m, metric in enumerate(metrics):
            counts = self.methods[m]
            rows.append(dict(scope=scope, metric=metric, direction=DIRECTION_NAMES[int(direction[m])], n=n,
                             rejections=int(self.reject[m]), rejections_two_sided=int(self.two_sided[m]),
                             rejections_holm=int(self.holm[m]) if self.family[m] else np.nan,  # none: not in it
                             mean_pairs=float(self.pairs[m]) / R,
                             not_computable=int(counts[0]), exact=int(counts[1]), permutation=int(counts[2]),
                             approx=int(counts[3])))
        every = family_all([m for m, inside in zip(metrics, self.family, strict=True) if inside])
        for fam, k in ((every, int(self.family_rows[0])), (FAMILY_ANY, int(self.family_rows[1]))):
            rows.append(dict(scope=scope, metric=fam, direction="", n=n, rejections=k,
                             rejections_two_sided=np.nan, rejections_holm=k, mean_pairs=np.nan,
                             not_computable=0, exact=0, permutation=0, approx=0))
        return rows


#: Peak bytes per (study × participant) element while one chunk of resampled studies is tested: the index
#: (8) and the ranking of :func:`analysis.stats.resampled_wilcoxon.study_tests` (measured 62–66), with a margin.
BYTES_PER_ELEMENT = 96
#: Resampled studies are tested in chunks of at most this many bytes (so ``--resamples`` costs time, not memory).
CHUNK_BYTES = 192 << 20


def chunk_rows(n: int, budget_bytes: int = CHUNK_BYTES) -> int:
    """Resampled studies of ``n`` participants tested at once: as many as ``budget_bytes`` holds (at least one)."""
    return max(1, int(budget_bytes) // (BYTES_PER_ELEMENT * max(1, int(n))))


def memory_needed(n_values: Sequence[int], resamples: int, pool_size: int, budget_bytes: int = CHUNK_BYTES) -> int:
    """Peak bytes :func:`estimate_power` allocates for this request (its largest chunk, and the pool's tables)."""
    n_max = max(int(n) for n in n_values)
    rows = min(int(resamples), chunk_rows(n_max, budget_bytes))
    return rows * n_max * BYTES_PER_ELEMENT + 64 * int(pool_size) + (16 << 20)


def _power_frame(rows: list[dict[str, object]], R: int, alpha: float, interval_level: float) -> pd.DataFrame:
    """power.csv from the rejection counts: the power figures with their Monte Carlo intervals, in column order."""
    frame = pd.DataFrame(rows)
    frame["resamples"] = R
    frame["alpha"] = alpha
    frame["rejections_two_sided"] = frame["rejections_two_sided"].astype("Int64")  # empty on the family rows
    frame["rejections_holm"] = frame["rejections_holm"].astype("Int64")  # empty on a secondary metric's rows
    for prefix, col, power_col in (("", "rejections", "power"),
                                   ("two_sided_", "rejections_two_sided", "power_two_sided"),
                                   ("holm_", "rejections_holm", "power_holm")):
        k = frame[col].to_numpy(dtype=float, na_value=np.nan)
        frame[power_col] = k / R
        lo, hi = monte_carlo_interval(np.nan_to_num(k), R, interval_level)
        frame[f"{prefix}ci_low"] = np.where(np.isnan(k), np.nan, lo)
        frame[f"{prefix}ci_high"] = np.where(np.isnan(k), np.nan, hi)
    return frame[list(POWER_CSV_COLUMNS)]


def _chunk_budget(pool: PairedPool, ns: tuple[int, ...], R: int, chunk_bytes: int) -> int:
    """The bytes one chunk of resampled studies may take here; a :class:`PowerError` when the pool is too small
    to resample from or the request does not fit in the memory available."""
    P = pool.n_participants
    if P < MIN_PILOT:
        raise PowerError(
            f"{pool.source or 'the pool'} has {P} participant{'s' if P != 1 else ''} with both haptic modes: at "
            f"least {MIN_PILOT} are needed to resample planned studies from (with fewer, every resampled study "
            "repeats the same few people)")
    from foundation.resources import available_memory_bytes, memory_problem

    have = available_memory_bytes()
    if have is not None:  # a chunk takes at most a quarter of what is free (the numbers do not depend on it)
        chunk_bytes = min(chunk_bytes, max(have // 4, BYTES_PER_ELEMENT * max(ns)))
    need = memory_needed(ns, R, P, chunk_bytes)
    problem = memory_problem(need, f"power: resampling studies of up to {max(ns)} participants",
                             "ask for smaller --n values (memory grows with n; --resamples costs time only)")
    if problem is not None:
        raise PowerError(problem)
    return chunk_bytes


def _studies_of(n: int, pool: PairedPool, prepared: list[list[PreparedMetric]], direction: np.ndarray, R: int,
                seed: int, zero_method: str, alpha: float, chunk_bytes: int,
                progress: Callable[[int, int], None] | None, done: int, total: int) -> list[_Counts]:
    """The rejection counts of ``R`` resampled studies of ``n`` participants, per scope.

    The studies are drawn in chunks of at most ``chunk_bytes`` from one generator, ``default_rng([seed, n])``: the
    same draws as one call would make.  ``progress(participants drawn, total)`` after each chunk, ``done`` drawn
    before these.
    """
    rng = np.random.default_rng([int(seed), int(n)])
    counts = [_Counts(len(pool.metrics), pool.family) for _ in pool.scopes]
    step = chunk_rows(n, chunk_bytes)
    for start in range(0, R, step):
        idx = rng.integers(0, pool.n_participants, size=(min(step, R - start), n))
        for s in range(len(pool.scopes)):
            counts[s].add(prepared[s], direction[s], idx, zero_method, alpha)
        if progress is not None:
            progress(done + (start + len(idx)) * n, total)
    return counts


def estimate_power(
    pool: PairedPool,
    n_values: Sequence[int] = DEFAULT_N_VALUES,
    *,
    resamples: int = 2000,
    alpha: float = 0.05,
    seed: int = 0,
    zero_method: str = "wilcox",
    interval_level: float = 0.95,
    progress: Callable[[int, int], None] | None = None,
    chunk_bytes: int = CHUNK_BYTES,
) -> PowerResult:
    """Power of the report's ON-vs-OFF tests for studies of each size in ``n_values``.

    The resampled studies are tested in chunks of at most ``chunk_bytes``, so
    memory does not grow with ``resamples`` and the result is the same, bit
    for bit, whatever the chunk size (the chunks are drawn from one generator
    in order).

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
    progress
        ``progress(participants drawn, participants to draw)`` after each chunk.
    chunk_bytes
        Memory one chunk of resampled studies may take (the default suits any machine; tests make it small).

    Returns
    -------
    PowerResult

    Raises
    ------
    PowerError
        Fewer than :data:`MIN_PILOT` participants in the pool, a malformed request, or one whose
        memory exceeds what the machine has available (:func:`memory_needed`).
    """
    ns = _check_request(n_values, resamples, alpha, zero_method)
    P = pool.n_participants
    R = int(resamples)
    chunk_bytes = _chunk_budget(pool, ns, R, chunk_bytes)
    prepared = [[prepare_metric(pool.off[s, m], pool.on[s, m]) for m in range(len(pool.metrics))]
                for s in range(len(pool.scopes))]
    # the pool's own direction of effect, per scope and metric: the side its own test statistic lies on
    whole = np.arange(P)[None, :]
    direction = np.array([[int(study_tests(pm, whole, zero_method)[3][0]) for pm in row] for row in prepared])
    rows: list[dict[str, object]] = []
    total, done = R * sum(ns), 0
    for n in ns:
        counts = _studies_of(n, pool, prepared, direction, R, seed, zero_method, float(alpha), chunk_bytes,
                             progress, done, total)
        done += R * n
        for s, scope in enumerate(pool.scopes):
            rows.extend(counts[s].rows(pool.metrics, direction[s], scope, n, R))
    frame = _power_frame(rows, R, float(alpha), interval_level)
    frame["source"] = pool.source
    return PowerResult(frame, _pool_notes(pool, prepared, direction, ns, float(alpha)), pool.source, P, R,
                       float(alpha), int(seed), zero_method, pool.options, ns, float(interval_level))


# ------------------------------------------------------------------------------------------------
# Names (the plan in words and tables: :mod:`analysis.planning.power_plan`)
# ------------------------------------------------------------------------------------------------
def metric_label(metric: str) -> str:
    if metric == FAMILY_ANY:
        return "at least one (Holm)"
    if is_family_row(metric):
        return f"all {metric.removeprefix('all_').removesuffix('_holm')} (Holm)"
    return METRIC_LABELS.get(metric, metric)


def holm_applies(metric: str) -> bool:
    """Whether a row of power.csv has a power with Holm's correction: a primary metric's and the family rows'."""
    return is_family_row(metric) or metric in PRIMARY_METRICS
