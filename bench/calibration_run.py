"""The calibration bench on the study users run: ``haptic-study run``'s code path, then the report's own reading.

Issue 48: the bench used to walk the experiment schedule without the training block and aggregate by a summary
of its own, and the README's study -- `run` with the default protocol, training first, then `report` -- came out
differently (Max AE OFF a third above the paper's).  Here each study is exactly what a lab runs:

* :func:`study_app.headless.run_study` with the protocol file (default: the paper's, its training block included)
  into a study database in a scratch folder -- the product's runner, trial machine, recorder, on this machine's
  processes or a Dask cluster;
* the report's reading of that database: :func:`analysis.reading.load.load_study` (training sessions excluded as
  the report excludes them), :func:`analysis.reading.metrics.compute_trials` (every trial recomputed from its
  1 kHz records), :func:`analysis.stats.aggregate.per_participant` (each participant's mean per mode) and
  :func:`analysis.stats.aggregate.mode_tests` (the report's Wilcoxon signed-rank tests);

so the bench cannot drift from the study again.  Its summary has the shape of
:func:`analysis.planning.sim_study.summarise_study`'s, for the bench's table and verdict.

The effect sizes beside an external anchor: Bergholz et al. (2023, 56 studies of haptic feedback in robot-assisted
surgery) report Hedges' g for the force applied, ~0.83 [0.66, 1.01] over all studies and ~0.98 for inexperienced
users.  Here g is computed per measure on each participant's means as the paired "average" standardised mean
difference (Cumming 2012; Lakens 2013: d_av = mean difference / mean of the two SDs' squares' root, with Hedges'
small-sample correction J = 1 − 3 / (4 (n − 1) − 1)), signed so that an improvement with haptics is positive.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from analysis.reading.load import load_study
from analysis.reading.metrics import MetricOptions, compute_trials
from analysis.stats.aggregate import by_mode, mode_tests, per_participant
from protocol.study.config import ProtocolConfig, default_protocol

__all__ = ["BERGHOLZ_G", "format_effect_sizes", "hedges_g_av", "run_and_read", "summarise_database"]

#: Bergholz et al. 2023 (meta-analysis, 56 studies): Hedges' g of haptic feedback on the force applied, with its
#: 95 % interval, over all studies; and for inexperienced users.
BERGHOLZ_G = {"all": (0.83, 0.66, 1.01)}
#: Their Hedges' g for inexperienced users (no interval quoted here).
BERGHOLZ_G_INEXPERIENCED = 0.98
#: The measures whose improvement with haptics is a decrease (their g's sign is turned).
LOWER_IS_BETTER = ("rmse_n", "max_ae_n", "tct_s", "tct_cens_s")


def hedges_g_av(off: np.ndarray, on: np.ndarray, lower_is_better: bool) -> float:
    """Hedges' g_av of paired per-participant values (NaN pairs left out), positive for an improvement ON."""
    keep = ~(np.isnan(off) | np.isnan(on))
    off, on = off[keep], on[keep]
    n = len(off)
    if n < 3:
        return math.nan
    sd_av = math.sqrt((float(np.var(off, ddof=1)) + float(np.var(on, ddof=1))) / 2.0)
    if sd_av == 0.0:
        return math.nan
    d = (float(np.mean(on)) - float(np.mean(off))) / sd_av
    j = 1.0 - 3.0 / (4.0 * (n - 1) - 1.0)
    return -d * j if lower_is_better else d * j


def _mean(values: np.ndarray) -> float:
    """The mean of the values that are numbers (NaN when none is: a measure nobody has, e.g. TCT with no success)."""
    kept = values[~np.isnan(values)]
    return float(kept.mean()) if len(kept) else math.nan


def format_effect_sizes(summaries: list[dict[str, Any]]) -> str:
    """Each measure's Hedges' g_av per study (mean ± SD over studies) beside Bergholz et al.'s anchor."""
    g, lo, hi = BERGHOLZ_G["all"]
    lines = [f"effect sizes, Hedges' g_av of each participant's means (positive: better with haptics); "
             f"anchor: Bergholz et al. 2023, force applied, g {g} [{lo}, {hi}] over 56 studies, "
             f"{BERGHOLZ_G_INEXPERIENCED} for inexperienced users"]
    for key, label in (("success", "success"), ("rmse_n", "RMSE"), ("max_ae_n", "Max AE"),
                       ("tct_s", "TCT, successes"), ("tct_cens_s", "TCT, fail = cap")):
        vals = [s[key]["g"] for s in summaries if math.isfinite(s[key]["g"])]
        if not vals:
            lines.append(f"  {label:16s} n/a")
            continue
        sd = f" ± {float(np.std(vals, ddof=1)):.2f}" if len(vals) > 1 else ""
        inside = "inside" if lo <= float(np.mean(vals)) <= hi else "outside"
        lines.append(f"  {label:16s} g {float(np.mean(vals)):.2f}{sd} over {len(vals)} studies ({inside} the "
                     "anchor's interval)")
    return "\n".join(lines)


def _entry(per: pd.DataFrame, column: str, p: float, lower_is_better: bool) -> dict[str, float]:
    wide = by_mode(per, column)
    off, on = wide["off"].to_numpy(dtype=float), wide["on"].to_numpy(dtype=float)
    m_off, m_on = _mean(off), _mean(on)
    return {"off": m_off, "on": m_on, "change": (m_on / m_off - 1.0) if m_off else math.nan, "p": p,
            "n_pairs": int((~(np.isnan(off) | np.isnan(on))).sum()), "g": hedges_g_av(off, on, lower_is_better)}


def summarise_database(db: str | Path) -> dict[str, Any]:
    """A study database read as the report reads it: per measure the mean over participants of each participant's
    mean per mode, the change, the report's Wilcoxon p and Hedges' g_av (the shape of
    :func:`analysis.planning.sim_study.summarise_study`'s summary, with ``g``)."""
    study = load_study([db])
    out: dict[str, Any] = {}
    for policy, tct_key in (("successful", "tct_s"), ("censored", "tct_cens_s")):
        options = MetricOptions(tct_policy=policy)
        trials = compute_trials(study, options, workers=1).trials
        per = per_participant(trials, options)
        _, frame = mode_tests(per)
        p = dict(zip(frame["metric"], frame["p_value"], strict=True))
        out["n_participants"] = int(per["participant_code"].nunique())
        out[tct_key] = _entry(per, "tct_s", p.get("tct_s", math.nan), True)
        if policy == "successful":
            for key, column in (("success", "success_rate"), ("rmse_n", "rmse_n"), ("max_ae_n", "max_ae_n")):
                out[key] = _entry(per, column, p.get(column, math.nan), key in LOWER_IS_BETTER)
            by_target = per_participant(trials, options, by_target=True)
            for label in ("GENTLE", "FIRM"):
                sub = by_target[by_target["target_label"] == label]
                _, f = mode_tests(sub, ["success_rate"])
                out[f"success_{label}"] = _entry(sub, "success_rate", float(f["p_value"].iloc[0]), False)
    return out


def run_and_read(study: int, participants: int, *, protocol: ProtocolConfig | None = None, jobs: int | None = None,
                 client: Any = None, keep: Path | None = None) -> dict[str, Any]:
    """Study ``study`` (its seed) of ``participants`` run as ``haptic-study run --seed STUDY`` runs it, then read as
    the report reads it (:func:`summarise_database`).  The database is made in a scratch folder and removed after,
    or kept in ``keep`` (``study-K.db``)."""
    from study_app.headless import run_study  # the study floor: the bench sits above it

    with tempfile.TemporaryDirectory(prefix="haptic-study-calibration-") as scratch:
        db = (keep or Path(scratch)) / f"study-{study}.db"
        run_study(str(db), participants=participants, seed=study, protocol=protocol or default_protocol(),
                  jobs=jobs, client=client)
        return summarise_database(db)
