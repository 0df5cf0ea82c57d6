"""Benchmark of analysis.stats.wilcoxon at study scale: 10 000 simulated participants.

``python -m bench.stats_bench`` prints wall times (best of ``repeats``) of

* :func:`analysis.stats.wilcoxon.paired_wilcoxon` on n = 10 000 pairs with heavy ties
  and zeros (values on a 0.1 grid), the Hodges–Lehmann interval included;
* :func:`analysis.stats.wilcoxon.hodges_lehmann` alone on the same differences
  (5·10⁷ Walsh averages, never materialized) and on 200 000 trial-level differences;
* :func:`analysis.stats.wilcoxon.correlation` (Spearman) on 200 000 trials (TCT vs RMSE);
* :func:`analysis.stats.holm.holm` on 10 metrics.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from analysis.stats.correlation import correlation
from analysis.stats.hodges_lehmann import hodges_lehmann
from analysis.stats.holm import holm
from analysis.stats.wilcoxon import paired_wilcoxon

__all__ = ["format_stats_bench", "run_stats_bench"]


def _best_s(fn: Callable[[], Any], repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def run_stats_bench(participants: int = 10_000, trials: int = 200_000, repeats: int = 3,
                    seed: int = 0) -> dict[str, Any]:
    """Time the statistics on synthetic paired data; returns seconds per call (best of ``repeats``)."""
    rng = np.random.default_rng(seed)
    # Per-participant means on a 0.1 grid: many ties and about 1 in 4 zero differences.
    off = np.round(rng.normal(0.40, 0.10, participants), 1)
    on = np.round(off + rng.normal(-0.05, 0.15, participants), 1)
    d = np.round(on - off, 10)
    d_trials = np.round(rng.normal(-0.03, 0.1, trials), 2)
    tct_s = rng.uniform(2.0, 12.0, trials)
    rmse_n = 0.5 - 0.01 * tct_s + rng.normal(0.0, 0.05, trials)
    p = rng.uniform(0.0, 0.2, 10)
    res = paired_wilcoxon(off, on, metric="rmse_n")
    return {
        "participants": participants,
        "trials": trials,
        "n_zero": res.n_zero,
        "n_tie_groups": res.n_ties,
        "method": res.method,
        "paired_wilcoxon_s": _best_s(lambda: paired_wilcoxon(off, on, metric="rmse_n"), repeats),
        "hodges_lehmann_s": _best_s(lambda: hodges_lehmann(d), repeats),
        "hodges_lehmann_trials_s": _best_s(lambda: hodges_lehmann(d_trials), repeats),
        "spearman_trials_s": _best_s(lambda: correlation(tct_s, rmse_n), repeats),
        "holm_10_s": _best_s(lambda: holm(p), repeats),
        "four_metrics_s": _best_s(
            lambda: [paired_wilcoxon(off, on + k * 0.1, metric=f"m{k}") for k in range(4)], 1),
    }


def format_stats_bench(r: dict[str, Any]) -> str:
    """Human-readable lines of :func:`run_stats_bench`'s result."""
    return "\n".join([
        f"analysis.stats.wilcoxon, {r['participants']} participants "
        f"({r['n_zero']} zero differences, {r['n_tie_groups']} tie groups, method {r['method']}):",
        f"  paired_wilcoxon (test + effect sizes + HL interval): {r['paired_wilcoxon_s'] * 1e3:8.1f} ms",
        f"  hodges_lehmann, n = {r['participants']}:                  {r['hodges_lehmann_s'] * 1e3:8.1f} ms",
        f"  hodges_lehmann, n = {r['trials']} trials:          {r['hodges_lehmann_trials_s'] * 1e3:8.1f} ms",
        f"  correlation (Spearman), {r['trials']} trials:        {r['spearman_trials_s'] * 1e3:8.1f} ms",
        f"  holm, 10 metrics:                                  {r['holm_10_s'] * 1e6:8.1f} µs",
        f"  four metrics (paired_wilcoxon × 4):                {r['four_metrics_s'] * 1e3:8.1f} ms",
    ])


if __name__ == "__main__":
    print(format_stats_bench(run_stats_bench()))
