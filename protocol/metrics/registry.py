"""The registry of trial metrics: every consumer asks it which metrics there are and what each is.

The metrics are :data:`protocol.metrics.definitions.METRICS`, in their order.  A task declares the metrics it
produces by name (:func:`select`) and the trial's metrics are computed, from its window, by :func:`compute`; the
storage reads :func:`stored` for the ``trials`` columns, the analysis :func:`tested` and :func:`primary` for its
tests, and the codebook, the report, learning, power, the sweep and the run summary all list what this module lists.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

from protocol.metrics.definitions import METRICS, TASK_METRICS
from protocol.metrics.metric import Metric, MetricValue, Role, TrialWindow

__all__ = ["METRICS", "by_participant_name", "compute", "family_word", "get", "names", "primary", "select",
           "stored", "tested", "values_of", "windowed"]

_BY_NAME: dict[str, Metric] = {m.name: m for m in (*METRICS, *TASK_METRICS)}
_BY_PARTICIPANT: dict[str, Metric] = {m.participant: m for m in METRICS}
if len(_BY_NAME) != len(METRICS) + len(TASK_METRICS):  # pragma: no cover - a definition error, caught on import
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


def names() -> tuple[str, ...]:
    """Every metric's name, in order: the metrics of every study (:data:`METRICS`; a task's own, such as force
    tracking's lag and gain, are :data:`protocol.metrics.definitions.TASK_METRICS`)."""
    return tuple(m.name for m in METRICS)


def select(wanted: Iterable[str]) -> tuple[Metric, ...]:
    """The metrics of these names (a task's), in the registry's order."""
    keep = set(wanted)
    unknown = keep - set(_BY_NAME)
    if unknown:
        raise KeyError(f"no metric {', '.join(sorted(unknown))}: the metrics are {', '.join(_BY_NAME)}")
    return tuple(m for m in (*METRICS, *TASK_METRICS) if m.name in keep)


def primary() -> tuple[Metric, ...]:
    """The paper's outcome measures, in order: the family Holm's correction runs across."""
    return tuple(m for m in METRICS if m.role is Role.PRIMARY)


def tested() -> tuple[Metric, ...]:
    """The metrics the report tests ON vs OFF (primary, then any secondary, in the registry's order)."""
    return tuple(m for m in METRICS if m.tested)


def stored() -> tuple[Metric, ...]:
    """The metrics with a column of their own in the ``trials`` table, in order."""
    return tuple(m for m in METRICS if m.stored)


def windowed() -> tuple[Metric, ...]:
    """The metrics taken over the error window (they differ between the cue and first-contact windows)."""
    return tuple(m for m in METRICS if m.windowed)


_WORDS = ("no", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten")


def family_word() -> str:
    """How many primary measures Holm's family has, in a word (``four``), as the report's sentences say it."""
    n = len(primary())
    return _WORDS[n] if n < len(_WORDS) else str(n)


def compute(window: TrialWindow, metrics: Sequence[Metric] = METRICS) -> dict[str, MetricValue]:
    """Each metric's value for one trial, by name, in order: the one computation, live and offline."""
    return {m.name: m.compute(window) for m in metrics}


def values_of(row: Mapping[str, object], metrics: Sequence[Metric] = METRICS) -> dict[str, MetricValue]:
    """The stored metrics of a ``trials`` row, by name (a column an older file lacks reads as None)."""
    out: dict[str, MetricValue] = {}
    for m in metrics:
        v = row.get(m.name)
        out[m.name] = None if v is None else float(v)  # type: ignore[arg-type]  # a REAL column: a number or NULL
    return out
