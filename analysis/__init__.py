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

Names are loaded on first use, so importing one module (e.g. :mod:`analysis.stats`)
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
    "AnalysisError": "analysis.load",
    "load_study": "analysis.load",
    "read_trial_samples": "analysis.load",
    "samples_frame": "analysis.samples",
    "MetricOptions": "analysis.metrics",
    "compute_trials": "analysis.metrics",
    "per_participant": "analysis.aggregate",
    "mode_tests": "analysis.aggregate",
    "speed_accuracy": "analysis.trade",
    "paired_wilcoxon": "analysis.stats",
    "build_report": "analysis.report",
}


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        return getattr(importlib.import_module(_WHERE[name]), name)
    raise AttributeError(f"module 'analysis' has no attribute {name!r}")
