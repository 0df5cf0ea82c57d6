"""Turning study databases into statistics, figures and a report.

For a notebook::

    from analysis import load_study, compute_trials, per_participant, mode_tests, MetricOptions

    study = load_study(["study.db"])
    trials = compute_trials(study).trials              # one row per analysed trial
    per_part = per_participant(trials)                  # per participant × haptic mode
    results, table = mode_tests(per_part)               # paired Wilcoxon ON vs OFF, Holm across metrics

or the whole report: ``build_report(["study.db"], "out/")`` (``haptic-study report``).
Every 1 kHz record of a session, as a pandas table: ``samples_frame("study.db", session_id=2)``
(``haptic-study export samples``).

Names are loaded on first use, so importing one module (e.g. :mod:`analysis.stats.wilcoxon`)
does not pull in matplotlib.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = [
    "AnalysisError",
    "MetricOptions",
    "build_report",
    "compute_trials",
    "load_study",
    "mode_tests",
    "paired_wilcoxon",
    "per_participant",
    "read_trial_samples",
    "samples_frame",
    "speed_accuracy",
]

_WHERE = {
    "AnalysisError": "analysis.reading.load",
    "load_study": "analysis.reading.load",
    "read_trial_samples": "analysis.reading.recorded",
    "samples_frame": "analysis.reading.samples",
    "MetricOptions": "analysis.reading.metrics",
    "compute_trials": "analysis.reading.metrics",
    "per_participant": "analysis.stats.aggregate",
    "mode_tests": "analysis.stats.aggregate",
    "speed_accuracy": "analysis.stats.trade",
    "paired_wilcoxon": "analysis.stats.wilcoxon",
    "build_report": "analysis.report.report",
}


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        return getattr(importlib.import_module(_WHERE[name]), name)
    raise AttributeError(f"module 'analysis' has no attribute {name!r}")
