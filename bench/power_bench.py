"""``haptic-study bench power``: the power analysis against a plain loop over the paired Wilcoxon test.

The figure the planning issue asks for: ``--resamples 2000`` over the 7
default study sizes and the 4 metrics, in one process.  In the same run, the
same resampled studies are tested by a straightforward loop that calls
:func:`analysis.stats.wilcoxon.paired_wilcoxon` once per study and metric (its side,
for the directional power, from the sign of its rank-biserial correlation,
(W⁺ − W⁻)/(W⁺ + W⁻)) and applies :func:`analysis.stats.holm.holm` per study; the
loop is timed on the first ``reference_resamples`` studies of each n and
scaled to all of them, and the two must give identical p-values and sides on
every study both ran.

The pilot is a synthetic 10-participant trial table
(:func:`bench.analysis_bench.synthetic_trials`: success rates on a 0.1 grid,
TCT undefined for a participant without a success) unless a database is given.
Caches are emptied before every timed engine run, so each figure includes
computing the exact and permutation null distributions.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np

from analysis.planning.paired_pool import PairedPool, load_pool, pool_from_trials
from analysis.planning.power import DEFAULT_N_VALUES, estimate_power, resample_indices
from analysis.stats.holm import holm
from analysis.stats.resampled_wilcoxon import _PERM_CACHE, _exact_p, resampled_p_values
from analysis.stats.wilcoxon import paired_wilcoxon
from bench.analysis_bench import synthetic_trials
from bench.machine import cpu_times, load_average, steal_percent

__all__ = ["format_power_bench", "run_power_bench"]


def _cold(fn):
    _PERM_CACHE.clear()
    _exact_p.cache_clear()
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def _overall_only(pool: PairedPool) -> PairedPool:
    return dataclasses.replace(pool, scopes=pool.scopes[:1], off=pool.off[:1], on=pool.on[:1])


def _reference_loop(pool: PairedPool, n_values: tuple[int, ...], resamples: int, reference_resamples: int,
                    seed: int) -> tuple[float, int, int, int, int]:
    """The reference: one paired_wilcoxon per study and metric, Holm per study, overall scope, on the first
    ``reference_resamples`` of the engine's draw.  (seconds, tests, identical p-values, identical sides, sided
    tests)."""
    P = pool.n_participants
    metrics = range(len(pool.metrics))
    loop_s = 0.0
    tests = identical = same_side = sided = 0
    for n in n_values:
        idx = resample_indices(seed, n, resamples, P)[:reference_resamples]
        got = [resampled_p_values(pool.off[0, m], pool.on[0, m], idx, sides=True) for m in metrics]
        engine = np.stack([g[0] for g in got], axis=1)
        engine_side = np.stack([g[2] for g in got], axis=1)
        t0 = time.perf_counter()
        ref = np.empty_like(engine)
        ref_side = np.zeros_like(engine_side)
        computable = np.zeros(engine.shape, dtype=bool)  # a side is compared only where the test could run
        for r, rows in enumerate(idx):
            for m in metrics:
                res = paired_wilcoxon(pool.off[0, m, rows], pool.on[0, m, rows], metric=pool.metrics[m])
                ref[r, m] = res.p_value if res.computable else np.nan
                if res.computable:
                    ref_side[r, m], computable[r, m] = np.sign(res.rank_biserial), True
            holm(ref[r])
        loop_s += time.perf_counter() - t0
        tests += engine.size
        identical += int(((engine == ref) | (np.isnan(engine) & np.isnan(ref))).sum())
        same_side += int(((engine_side == ref_side) & computable).sum())
        sided += int(computable.sum())
    return loop_s, tests, identical, same_side, sided


def run_power_bench(db: str | None = None, *, resamples: int = 2000, reference_resamples: int = 100,
                    n_values: tuple[int, ...] = DEFAULT_N_VALUES, repeats: int = 3, seed: int = 0) -> dict[str, Any]:
    """Time :func:`analysis.planning.power.estimate_power` and the paired_wilcoxon loop on the same resampled studies.

    Parameters
    ----------
    db
        A pilot study database, or None for the synthetic 10-participant pilot.
    resamples
        Resampled studies per n for the engine.
    reference_resamples
        Studies per n run by the loop (the first ones of the engine's draw); its time is scaled to ``resamples``.
    n_values
        Study sizes.
    repeats
        Engine runs per figure; the median is reported.
    seed
        Resampling seed.
    """
    if db is None:
        pool = pool_from_trials(synthetic_trials(10, seed=seed), source="a synthetic 10-participant pilot")
    else:
        pool = load_pool([db])
    overall = _overall_only(pool)
    cpu_before = cpu_times()
    runs_overall = [_cold(lambda: estimate_power(overall, n_values, resamples=resamples, seed=seed))[0]
                    for _ in range(repeats)]
    runs_all = [_cold(lambda: estimate_power(pool, n_values, resamples=resamples, seed=seed))[0]
                for _ in range(repeats)]
    stolen = steal_percent(cpu_before, cpu_times())

    P = pool.n_participants
    loop_s, tests, identical, same_side, sided = _reference_loop(pool, n_values, resamples, reference_resamples, seed)
    loop_scaled = loop_s * resamples / reference_resamples
    overall_s = float(np.median(runs_overall))
    return {
        "source": pool.source,
        "participants": P,
        "resamples": resamples,
        "n_values": list(n_values),
        "metrics": len(pool.metrics),
        "scopes": list(pool.scopes),
        "engine_overall_s": round(overall_s, 3),
        "engine_overall_runs_s": [round(x, 3) for x in runs_overall],
        "engine_all_scopes_s": round(float(np.median(runs_all)), 3),
        "reference_resamples": reference_resamples,
        "reference_loop_s": round(loop_s, 3),
        "reference_scaled_s": round(loop_scaled, 1),
        "speedup": round(loop_scaled / overall_s, 1) if overall_s > 0 else None,
        "reference_tests": tests,
        "identical_p_values": identical,
        "identical_sides": same_side,
        "sided_tests": sided,
        "load_average": load_average(),
        "cpu_stolen_percent": stolen,
    }


def format_power_bench(r: dict[str, Any]) -> str:
    """Human-readable lines of :func:`run_power_bench`'s result."""
    ns = r["n_values"]
    tests = r["resamples"] * len(ns) * r["metrics"]
    return "\n".join([
        f"power analysis of {r['source']} ({r['participants']} participants), {r['resamples']} resampled studies "
        f"× {len(ns)} n ({ns[0]}–{ns[-1]}), one process, caches emptied before each run:",
        f"  ours, {r['metrics']} metrics (overall)      {r['engine_overall_s']:7.2f} s median of "
        f"{len(r['engine_overall_runs_s'])} ({', '.join(f'{x:.2f}' for x in r['engine_overall_runs_s'])}); "
        f"{tests:,} Wilcoxon tests + Holm",
        f"  ours, {r['metrics']} metrics × {len(r['scopes'])} scopes        {r['engine_all_scopes_s']:7.2f} s "
        f"({', '.join(r['scopes'])})",
        f"  paired_wilcoxon loop, overall  {r['reference_scaled_s']:7.1f} s scaled from {r['reference_loop_s']:.2f} s "
        f"for {r['reference_resamples']} studies per n",
        f"  speed-up                       {r['speedup']:7.1f}x   (p-values identical in "
        f"{r['identical_p_values']:,} of {r['reference_tests']:,} tests both ran, sides in {r['identical_sides']:,} of "
        f"{r['sided_tests']:,} computable)",
        f"  machine                        load {r['load_average'][0]:.2f}, CPU stolen by the hypervisor "
        f"{'n/a' if r['cpu_stolen_percent'] is None else format(r['cpu_stolen_percent'], '.1f') + ' %'} "
        "(during our runs)",
    ])


if __name__ == "__main__":
    print(format_power_bench(run_power_bench()))
