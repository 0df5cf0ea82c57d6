"""Does the error window change the answer?  The headline results under every window, side by side.

RMSE and Max AE are taken over an error window (:data:`analysis.reading.metrics.ERROR_WINDOWS`): from the cue (the
paper's "during the trial", the default) or from first contact.  From the cue, the approach from 0 N is
part of the error, and Max AE is often exactly the target (the error at the cue, before contact) rather than
a peak excursion.  :func:`window_sensitivity` runs the ON-vs-OFF tests of the primary measures (Holm across
them, as the report: the paper's answer) and the speed–accuracy repeated-measures correlation in each window and
flags every conclusion that differs; :func:`max_ae_from_approach` counts the trials whose Max AE is the approach.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from analysis.reading.metrics import ERROR_WINDOWS, MetricOptions, TrialTable
from analysis.stats.aggregate import PRIMARY_METRICS, mode_tests, per_participant
from analysis.stats.trade import speed_accuracy

__all__ = ["ALPHA", "SENSITIVITY_COLUMNS", "max_ae_from_approach", "window_sensitivity"]

#: The level at which a conclusion is drawn.
ALPHA = 0.05

#: The columns of :func:`window_sensitivity`.
SENSITIVITY_COLUMNS = ("analysis", "measure", "error_window", "n", "estimate", "ci_low", "ci_high", "p_value",
                       "p_holm", "conclusion", "differs")


def _test_conclusion(p_holm: float, rank_biserial: float, computable: bool) -> str:
    if not computable or not math.isfinite(p_holm):
        return "not computable"
    if p_holm >= ALPHA:
        return "no significant difference"
    return "ON higher than OFF" if rank_biserial > 0 else "ON lower than OFF"


def _trade_conclusion(r: float, p: float, computable: bool) -> str:
    if not computable or not math.isfinite(p):
        return "not computable"
    if p >= ALPHA:
        return "no significant association"
    return "negative: faster trials less accurate (a trade)" if r < 0 else "positive: slow trials also inaccurate"


def window_sensitivity(table: TrialTable, options: MetricOptions, *, zero_method: str = "wilcox",
                       confidence: float = 0.95) -> pd.DataFrame:
    """The headline ON-vs-OFF tests and the speed–accuracy correlations in every error window.

    Parameters
    ----------
    table
        The analysed trials with their metrics in every window (:attr:`TrialTable.by_window`).
    options
        The TCT policy (the window of ``options`` is the report's; every window is computed here).
    zero_method, confidence
        As the report's tests.

    Returns
    -------
    pandas.DataFrame
        Long format, :data:`SENSITIVITY_COLUMNS`: per ``analysis`` (``ON vs OFF``: the Hodges–Lehmann shift
        ON − OFF with its interval, p and Holm's p; ``speed-accuracy``: r_rm per mode with its interval and p),
        ``measure`` and ``error_window``; ``conclusion`` at p < 0.05 (Holm's p for the tests), and ``differs``:
        true on every row of a measure whose conclusion is not the same in all windows.
    """
    rows = []
    for window in ERROR_WINDOWS:
        trials = table.in_window(window)
        per = per_participant(trials, options)
        family = [m for m in PRIMARY_METRICS if m in per.columns]  # the study's primary measures
        _, frame = mode_tests(per, family, zero_method=zero_method, confidence=confidence)
        for r in frame.itertuples():
            rows.append({"analysis": "ON vs OFF", "measure": r.metric, "error_window": window, "n": r.n_used,
                         "estimate": r.hl_estimate, "ci_low": r.hl_ci_low, "ci_high": r.hl_ci_high,
                         "p_value": r.p_value, "p_holm": r.p_holm,
                         "conclusion": _test_conclusion(r.p_holm, r.rank_biserial, bool(r.computable))})
        for r in speed_accuracy(trials, options, confidence=confidence).itertuples():
            rows.append({"analysis": "speed-accuracy", "measure": f"r_rm {r.haptic_mode}", "error_window": window,
                         "n": r.n_trials, "estimate": r.r_rm, "ci_low": r.ci_low, "ci_high": r.ci_high,
                         "p_value": r.p_value, "p_holm": math.nan,
                         "conclusion": _trade_conclusion(r.r_rm, r.p_value, bool(r.computable))})
    out = pd.DataFrame(rows)
    n_conclusions = out.groupby(["analysis", "measure"])["conclusion"].transform("nunique")
    out["differs"] = n_conclusions > 1
    return out[list(SENSITIVITY_COLUMNS)]


def max_ae_from_approach(table: TrialTable) -> tuple[int, int]:
    """(trials whose Max AE from the cue comes before first contact, trials with a Max AE from the cue).

    Such a trial's largest error is the approach (the error at the cue's 0 N is the target force itself), not a
    peak force excursion: its Max AE from the cue exceeds its Max AE from first contact, or it never touched.
    """
    if "max_ae_n" not in table.trials.columns:  # a study whose tasks have no Max AE
        return 0, 0
    cue = table.in_window("cue")["max_ae_n"].to_numpy(float)
    contact = table.in_window("first_contact")["max_ae_n"].to_numpy(float)
    has = np.isfinite(cue)
    approach = has & (~np.isfinite(contact) | (cue > contact))
    return int(approach.sum()), int(has.sum())
