"""Simulated studies without a database: one row per trial, and a study's per-participant summary.

:mod:`study_app.headless.sim_trials` runs simulated participants through the
protocol's schedule on the simulated rig and returns :class:`TrialRow` s (their
metrics come from the one definition in :mod:`protocol.study.metrics`, through
:class:`protocol.study.trial.TrialMachine`); :func:`summarise_study` aggregates them
like science.md §6 (success over a participant's trials, mean RMSE and Max AE
over trials, mean TCT over successful trials) and compares the modes.  The
calibration bench (``bench/participant_calibration.py``) and ``haptic-study
sweep`` (:mod:`analysis.planning.sweep`) share both.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["SUMMARY_KEYS", "TrialRow", "summarise_study", "trial_row_from_dict", "trial_row_to_dict"]

#: What :func:`summarise_study` gives per key: ``off``, ``on``, ``change`` (ON/OFF − 1), ``p``, ``n_pairs``.
SUMMARY_KEYS = ("success", "rmse_n", "max_ae_n", "tct_s", "tct_cens_s", "success_GENTLE", "success_FIRM")


@dataclass(frozen=True, slots=True)
class TrialRow:
    """One simulated trial's outcome (``tct_s`` None for a failure)."""

    study: int
    participant: int
    index: int
    target: str
    mode: str
    success: bool
    tct_s: float | None
    rmse_n: float
    max_ae_n: float
    peak_n: float


def trial_row_to_dict(row: TrialRow) -> dict[str, Any]:
    """A row as plain JSON values."""
    return dataclasses.asdict(row)


def trial_row_from_dict(d: Mapping[str, Any]) -> TrialRow:
    """The row :func:`trial_row_to_dict` wrote."""
    return TrialRow(int(d["study"]), int(d["participant"]), int(d["index"]), str(d["target"]), str(d["mode"]),
                    bool(d["success"]), None if d["tct_s"] is None else float(d["tct_s"]), float(d["rmse_n"]),
                    float(d["max_ae_n"]), float(d["peak_n"]))


def _wilcoxon_p(off: list[float], on: list[float]) -> float:
    """Two-sided Wilcoxon signed-rank p of the paired differences (NaN when undefined)."""
    from scipy.stats import wilcoxon

    d = [round(a - b, 12) for a, b in zip(off, on, strict=True) if not (math.isnan(a) or math.isnan(b))]
    if len(d) < 2 or all(x == 0 for x in d):
        return math.nan
    try:
        return float(wilcoxon(d).pvalue)
    except ValueError:
        return math.nan


def _participant_values(mine: Sequence[TrialRow], max_trial_s: float) -> dict[str, float]:
    """One participant's values in one mode (science.md §6)."""
    tcts = [r.tct_s for r in mine if r.success and r.tct_s is not None]
    out = {
        "success": sum(r.success for r in mine) / len(mine),
        "rmse_n": statistics.fmean(r.rmse_n for r in mine),
        "max_ae_n": statistics.fmean(r.max_ae_n for r in mine),
        "tct_s": statistics.fmean(tcts) if tcts else math.nan,
        "tct_cens_s": statistics.fmean(r.tct_s if r.success and r.tct_s is not None else max_trial_s for r in mine),
    }
    for lab in ("GENTLE", "FIRM"):
        sub = [r for r in mine if r.target == lab]
        out[f"success_{lab}"] = sum(r.success for r in sub) / len(sub) if sub else math.nan
    return out


def _nanmean(values: list[float]) -> float:
    return float(np.nanmean(values)) if not all(math.isnan(x) for x in values) else math.nan


def summarise_study(rows: Sequence[TrialRow], max_trial_s: float = 12.0,
                    keys: Sequence[str] = SUMMARY_KEYS) -> dict[str, Any]:
    """Per participant × mode aggregates (science.md §6), group means, changes and Wilcoxon p.

    Returns ``{"n_participants": n, key: {"off", "on", "change", "p", "n_pairs"} for key in keys}``
    (``keys``: some of :data:`SUMMARY_KEYS`; a test with ties is an exact permutation test, ~0.1 s);
    ``change`` is ON/OFF − 1 (NaN when OFF is 0); a mode a participant has no trials of counts as NaN.
    """
    parts = sorted({r.participant for r in rows})
    per: dict[str, dict[str, list[float]]] = {}
    for mode in ("off", "on"):
        per[mode] = {k: [] for k in SUMMARY_KEYS}
        for pid in parts:
            mine = [r for r in rows if r.participant == pid and r.mode == mode]
            vals = _participant_values(mine, max_trial_s) if mine else dict.fromkeys(SUMMARY_KEYS, math.nan)
            for k in SUMMARY_KEYS:
                per[mode][k].append(vals[k])
    out: dict[str, Any] = {"n_participants": len(parts)}
    for key in keys:
        off, on = per["off"][key], per["on"][key]
        m_off, m_on = _nanmean(off), _nanmean(on)
        out[key] = {
            "off": m_off,
            "on": m_on,
            "change": (m_on / m_off - 1.0) if m_off else math.nan,
            "p": _wilcoxon_p(off, on),
            "n_pairs": sum(1 for a, b in zip(off, on, strict=True) if not (math.isnan(a) or math.isnan(b))),
        }
    return out
