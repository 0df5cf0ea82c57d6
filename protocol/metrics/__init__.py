"""The trial metrics: each defined once (:mod:`protocol.metrics.definitions`), asked for by name (:mod:`.registry`).

The bottom floor of ``protocol``: a metric is a pure function of a trial's window (:class:`TrialWindow`: its
samples, the task's target and verdict, the error window) with the data every consumer needs to store, export,
test and show it (:class:`Metric`).  It knows no task, no schedule and no storage; the tasks, the trial records,
the storage and the analysis above read it.
"""

from protocol.metrics.definitions import TRADE_PHASES
from protocol.metrics.metric import UNIT_TOKENS, Metric, MetricValue, Role, TrialWindow, exported_name, split_unit
from protocol.metrics.registry import (
    METRICS,
    by_participant_name,
    compute,
    family_word,
    get,
    names,
    primary,
    select,
    stored,
    tested,
    values_of,
    windowed,
)

__all__ = [
    "METRICS",
    "TRADE_PHASES",
    "UNIT_TOKENS",
    "Metric",
    "MetricValue",
    "Role",
    "TrialWindow",
    "by_participant_name",
    "compute",
    "exported_name",
    "family_word",
    "get",
    "names",
    "primary",
    "select",
    "split_unit",
    "stored",
    "tested",
    "values_of",
    "windowed",
]
