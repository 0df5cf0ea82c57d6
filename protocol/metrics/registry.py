"""The registry of trial metrics: every consumer asks it which metrics there are and what each is.

The metrics are :data:`protocol.metrics.definitions.METRICS`, in their order.  A study's metrics are not all of
them: each task declares the metrics it produces by name (:func:`select`; a study's are its tasks',
:func:`protocol.tasks.base.metrics_of`), and everything that lists metrics asks about *those*: the trial's metrics
are computed from its window by :func:`compute`, the storage adds a ``trials`` column for each of :func:`stored`,
the analysis tests :func:`tested` with Holm's correction across :func:`primary`, and the codebook, the report,
learning, power, the sweep and the run summary all list what this module lists of the study's metrics.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

from protocol.metrics.definitions import METRICS
from protocol.metrics.metric import Metric, MetricValue, Role, TrialWindow

__all__ = ["METRICS", "by_participant_name", "compute", "family_word", "get", "names", "primary", "select",
           "stored", "tested", "values_of", "windowed"]

_BY_NAME: dict[str, Metric] = {m.name: m for m in METRICS}
_BY_PARTICIPANT: dict[str, Metric] = {m.participant: m for m in METRICS}
if len(_BY_NAME) != len(METRICS):  # pragma: no cover - a definition error, caught on import
    raise ValueError("two metrics of protocol.metrics.definitions share a name")


def get(name: str) -> Metric:
    """The metric of that name (``rmse_n``); :class:`KeyError` naming the known ones otherwise."""
    try:
        return _BY_NAME[name]
    except KeyError:
        raise KeyError(f"no metric {name!r}: the metrics are {', '.join(_BY_NAME)}") from None


def by_participant_name(name: str) -> Metric | None:
    """The metric whose per-participant column is ``name`` (``success_rate``, ``rmse_n``), or None."""
    return _BY_PARTICIPANT.get(name)


def names(metrics: Sequence[Metric] = METRICS) -> tuple[str, ...]:
    """The metrics' names, in order (default: every metric defined)."""
    return tuple(m.name for m in metrics)


def select(wanted: Iterable[str]) -> tuple[Metric, ...]:
    """The metrics of these names (a task's, or a study's tasks'), in the registry's order."""
    keep = set(wanted)
    unknown = keep - set(_BY_NAME)
    if unknown:
        raise KeyError(f"no metric {', '.join(sorted(unknown))}: the metrics are {', '.join(_BY_NAME)}")
    return tuple(m for m in METRICS if m.name in keep)


def primary(metrics: Sequence[Metric]) -> tuple[Metric, ...]:
    """A study's outcome measures (of its ``metrics``), in order: the family Holm's correction runs across (the
    paper's four for force regulation)."""
    return tuple(m for m in metrics if m.role is Role.PRIMARY)


def tested(metrics: Sequence[Metric]) -> tuple[Metric, ...]:
    """The metrics the report tests ON vs OFF (primary, then any secondary, in the registry's order)."""
    return tuple(m for m in metrics if m.tested)


def stored(metrics: Sequence[Metric]) -> tuple[Metric, ...]:
    """The metrics with a column of their own in the ``trials`` table, in order."""
    return tuple(m for m in metrics if m.stored)


def windowed(metrics: Sequence[Metric]) -> tuple[Metric, ...]:
    """The metrics taken over the error window (they differ between the cue and first-contact windows)."""
    return tuple(m for m in metrics if m.windowed)


_WORDS = ("no", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten")


def family_word(metrics: Sequence[Metric]) -> str:
    """How many primary measures Holm's family has, in a word (``four``), as the report's sentences say it."""
    n = len(primary(metrics))
    return _WORDS[n] if n < len(_WORDS) else str(n)


def compute(window: TrialWindow, metrics: Sequence[Metric]) -> dict[str, MetricValue]:
    """Each metric's value for one trial, by name, in order: the one computation, live and offline."""
    return {m.name: m.compute(window) for m in metrics}


def values_of(row: Mapping[str, object], metrics: Sequence[Metric] = METRICS) -> dict[str, MetricValue]:
    """The stored metrics of a ``trials`` row, by name: those of ``metrics`` the row has a column for (a metric its
    task does not produce has none; a column an older file lacks: the metric is left out)."""
    out: dict[str, MetricValue] = {}
    for m in stored(metrics):
        if m.name in row:
            v = row[m.name]
            out[m.name] = None if v is None else float(v)  # type: ignore[arg-type]  # a REAL column: a number or NULL
    return out
