"""Planning a two-group study: the power to find the group × haptics interaction against participants per group.

**What is resampled.**  Each participant of a pilot (or of a simulated pool whose protocol places participants in
groups: :mod:`protocol.study.groups`) contributes their per-participant ON − OFF effect of every tested measure,
aggregated exactly as the report aggregates them (:func:`analysis.stats.aggregate.per_participant`).  A planned
study of n participants *per group* is imitated by drawing n participants with replacement from each group's pool.

**The test.**  In each resampled study the two groups' effects are compared as the report compares them
(:mod:`analysis.stats.groups`): the two-sided Mann–Whitney U test, here with the normal approximation and its tie
correction (draws with replacement tie, and the report too leaves the exact distribution where there are ties).
A difference between the groups' ON − OFF effects *is* the group × haptics interaction, tested on participants'
means; the report's trial-level mixed model of it is not refitted in every resampled study (thousands of REML fits
per size: minutes each), so this is the power of the report's between-group test of the interaction.

**Directional power.**  As in :mod:`analysis.planning.power`: ``power`` counts the resampled studies that reject
*and* whose U lies on the side of the pool's own (the direction of the pool's group difference), with a
Clopper–Pearson interval for the Monte Carlo error; ``power_two_sided`` counts every rejection.  The resamples of
each n come from ``numpy.random.default_rng([seed, n, 44])``.  A participant without a value of a measure (TCT
without a success in a mode) is not in that measure's pool.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from analysis.planning.power import PowerError, metric_label, monte_carlo_interval
from analysis.reading.metrics import MetricOptions
from analysis.stats.aggregate import TESTED_METRICS, by_mode, per_participant
from analysis.stats.groups import groups_of
from protocol.study.groups import GroupDesign

__all__ = ["GROUP_POWER_COLUMNS", "MIN_PILOT_GROUP", "GroupPool", "estimate_group_power", "group_pool",
           "group_power_text"]

#: A group of the pilot needs at least this many participants to be resampled.
MIN_PILOT_GROUP = 3
#: Drawn values per group held at once (a chunk of studies): about 40 MB of arrays with the test's own.
_CHUNK_VALUES = 1_000_000
#: group_power.csv: its columns.
GROUP_POWER_COLUMNS = ("metric", "n_per_group", "reference", "group", "pool_reference", "pool_group",
                       "median_effect_reference", "median_effect_group", "direction", "resamples", "alpha",
                       "rejections", "power", "ci_low", "ci_high", "rejections_two_sided", "power_two_sided")


@dataclass(frozen=True, slots=True)
class GroupPool:
    """Each group's per-participant ON − OFF effects, by measure (finite values only).

    Attributes
    ----------
    by, reference, group
        The grouping covariate, the reference group (the first declared level of the two) and the other.
    effects
        ``effects[metric] = (reference group's effects, other group's effects)``.
    n_reference, n_group
        Participants of each group in the pool.
    source
        What the pool is, in words.
    """

    by: str
    reference: str
    group: str
    effects: dict[str, tuple[np.ndarray, np.ndarray]]
    n_reference: int
    n_group: int
    source: str


def group_pool(trials: pd.DataFrame, covariates: pd.DataFrame, design: GroupDesign | None,
               options: MetricOptions = MetricOptions(), *, source: str = "") -> GroupPool:
    """The pool of a pilot's (or a simulated pool's) trials and covariates.

    Raises
    ------
    PowerError
        One line: no ``[groups]`` in the protocol, or fewer than two groups with :data:`MIN_PILOT_GROUP`
        participants (the first two declared levels that have them are used).
    """
    if design is None:
        raise PowerError("--groups: the study's protocol declares no [groups] (which covariate divides the "
                         "participants); see docs/groups.md")
    overall = per_participant(trials, options)
    codes = sorted(overall["participant_code"].unique())
    group = groups_of(covariates, design.by, codes)
    counts = {level: int((group == level).sum()) for level in design.levels}
    enough = [level for level in design.levels if counts[level] >= MIN_PILOT_GROUP]
    if len(enough) < 2:
        said = ", ".join(f"{k} {v}" for k, v in counts.items())
        raise PowerError(f"--groups: two groups of {design.by} with at least {MIN_PILOT_GROUP} participants each are "
                         f"needed to plan a two-group study; the study has {said}")
    ref, other = enough[0], enough[1]
    effects: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for m in (name for name in TESTED_METRICS if name in overall.columns):
        wide = by_mode(overall, m)
        diff = (wide["on"] - wide["off"]).dropna()
        g = diff.index.map(group)
        effects[m] = (diff[g == ref].to_numpy(float), diff[g == other].to_numpy(float))
    return GroupPool(design.by, ref, other, effects, counts[ref], counts[other], source)


def _u_statistics(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """U of each row of ``x`` against the same row of ``y`` and its two-sided p (normal approximation with the tie
    and continuity corrections, as :func:`scipy.stats.mannwhitneyu` computes it); NaN p where every value ties."""
    from scipy.stats import mannwhitneyu

    with np.errstate(invalid="ignore", divide="ignore"):
        res = mannwhitneyu(x, y, alternative="two-sided", method="asymptotic", axis=1)
    return np.asarray(res.statistic, float), np.asarray(res.pvalue, float)


def estimate_group_power(pool: GroupPool, n_values: Sequence[int], *, resamples: int = 2000, alpha: float = 0.05,
                         seed: int = 0, progress: Callable[[int, int], None] | None = None) -> pd.DataFrame:
    """Power of the between-group test of the interaction per measure and n per group (the module); one row per
    measure × n (:data:`GROUP_POWER_COLUMNS`)."""
    rows = []
    total = len(n_values) * len(pool.effects)
    done = 0
    for n in n_values:
        rng = np.random.default_rng([int(seed), int(n), 44])
        for m, (ref, grp) in pool.effects.items():
            row: dict[str, object] = {
                "metric": m, "n_per_group": n, "reference": pool.reference, "group": pool.group,
                "pool_reference": len(ref), "pool_group": len(grp),
                "median_effect_reference": float(np.median(ref)) if len(ref) else math.nan,
                "median_effect_group": float(np.median(grp)) if len(grp) else math.nan,
                "resamples": resamples, "alpha": alpha}
            if min(len(ref), len(grp)) < 2 or np.ptp(np.concatenate([ref, grp])) == 0:
                rows.append({**row, "direction": "none", "rejections": 0, "power": 0.0, "ci_low": math.nan,
                             "ci_high": math.nan, "rejections_two_sided": 0, "power_two_sided": 0.0})
            else:
                rows.append({**row, **_resampled(ref, grp, n, resamples, alpha, rng)})
            done += 1
            if progress is not None:
                progress(done, total)
    return pd.DataFrame(rows, columns=list(GROUP_POWER_COLUMNS))


def _resampled(ref: np.ndarray, grp: np.ndarray, n: int, resamples: int, alpha: float,
               rng: np.random.Generator) -> dict[str, object]:
    """One measure's power at ``n`` per group: ``resamples`` studies drawn from the two pools."""
    u_pool, _ = _u_statistics(grp[None, :], ref[None, :])
    side = float(np.sign(u_pool[0] - len(grp) * len(ref) / 2.0))
    directed = rejected = 0
    rows = max(1, _CHUNK_VALUES // n)  # studies per chunk: the memory of one chunk is bounded, whatever n
    for start in range(0, resamples, rows):
        k = min(rows, resamples - start)
        x = grp[rng.integers(0, len(grp), size=(k, n))]
        y = ref[rng.integers(0, len(ref), size=(k, n))]
        u, p = _u_statistics(x, y)
        reject = np.nan_to_num(p, nan=1.0) < alpha
        rejected += int(reject.sum())
        directed += int((reject & (np.sign(u - n * n / 2.0) == side)).sum()) if side else 0
    lo, hi = monte_carlo_interval(np.array([directed]), resamples)
    return {"direction": {1.0: "group_higher", -1.0: "group_lower"}.get(side, "none"), "rejections": directed,
            "power": directed / resamples, "ci_low": float(lo[0]), "ci_high": float(hi[0]),
            "rejections_two_sided": rejected, "power_two_sided": rejected / resamples}


def group_power_text(frame: pd.DataFrame, pool: GroupPool, alpha: float, targets: Sequence[float] = (0.8, 0.9)) -> str:
    """The plan in words: the pool, the method, and per measure the smallest n per group reaching each target."""
    lines = [f"Two-group study: {pool.group} against {pool.reference} ({pool.by}); pool: {pool.source} "
             f"({pool.n_reference} {pool.reference}, {pool.n_group} {pool.group}).",
             "The group x haptics interaction, tested as the report tests it between groups: each participant's "
             "ON - OFF effect, Mann-Whitney U, two-sided, normal approximation with the tie correction; "
             f"significant at p < {alpha:g} and on the side of the pool's difference (directional power).", ""]
    for m, rows in frame.groupby("metric", sort=False):
        r0 = rows.iloc[0]
        reach = []
        for target in targets:
            hit = rows[rows["power"] >= target]
            reach.append(f"power {target:.0%} at n = {int(hit['n_per_group'].min())} per group" if len(hit) else
                         f"power {target:.0%} not reached by n = {int(rows['n_per_group'].max())} per group")
        curve = ", ".join(f"{int(r.n_per_group)}: {r.power:.2f}" for r in rows.itertuples())
        lines.append(f"{metric_label(str(m))}: median effect {r0.reference} {r0.median_effect_reference:.4g}, "
                     f"{r0.group} {r0.median_effect_group:.4g}; " + "; ".join(reach) + f" (power by n: {curve})")
    return "\n".join(lines)
