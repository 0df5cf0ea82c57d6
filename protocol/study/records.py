"""A finished trial, typed: what the runner stores, the GUI shows and analysis checks.

A :class:`TrialRecord` is made once, when a trial ends (:meth:`TrialRecord.finished`,
or for a trial a run left half-done, by the resume), and travels as it is: to
the recorder, which writes it as a ``trials`` row (:meth:`TrialRecord.to_row`,
the only place a record becomes seconds and TEXT), to the runner's listeners
and across the process boundary to the GUI.  A stored row reads back with
:meth:`TrialRecord.from_row`.

Times are integer ns on the loop clock (``cue_ns``, ``end_ns``) with the
:class:`protocol.study.clock.SessionClock` that makes them session seconds; the
enums are :class:`enum.StrEnum`, so a stored value is the same TEXT as ever
(``'on'``, ``'success'``, ``'fault'`` …) and compares equal to it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from enum import StrEnum
from typing import Any

import numpy as np
import numpy.typing as npt

from protocol.metrics import MetricValue, get, values_of
from protocol.study.clock import SessionClock
from protocol.study.design import HapticMode, TrialSpec
from protocol.tasks.window import TrialMetrics

__all__ = [
    "AGREE_REL",
    "AbortCause",
    "LoopHealth",
    "Outcome",
    "TrialRecord",
    "disagreement",
    "trial_health",
    "trial_id_of",
]


class Outcome(StrEnum):
    """How a trial ended (``trials.outcome``)."""

    SUCCESS = "success"
    TIMEOUT = "timeout"
    ABORTED = "aborted"


class AbortCause(StrEnum):
    """Why an aborted trial was aborted (``trials.abort_cause``, schema version 2)."""

    EXPERIMENTER = "experimenter"
    FAULT = "fault"
    FEEDBACK = "feedback"
    GAP = "gap"
    INTERRUPTED = "interrupted"
    #: The participant screen closed (or was minimised, or left every monitor) during the trial: the participant
    #: could not see the cue.  Added after schema version 4's files existed: a writer widens an older file's list.
    PARTICIPANT_SCREEN = "participant_screen"

    @property
    def undelivered(self) -> bool:
        """The loop did not deliver the designed condition (a fault, wrong feedback, missing records)."""
        return self in (AbortCause.FAULT, AbortCause.FEEDBACK, AbortCause.GAP)


def trial_id_of(session_id: int, trial_index: int) -> int:
    """The trial key used by ``trials`` and ``samples`` (allocated at trial start)."""
    return session_id * 1_000_000 + trial_index


@dataclass(frozen=True, slots=True)
class LoopHealth:
    """How the 1 kHz loop ran over a trial's records (the ``trials`` health columns); all None without records.

    Times in ms; ``periods_over_2ms`` a count of ticks whose period exceeded 2 ms.
    """

    period_p50_ms: float | None = None
    period_p99_ms: float | None = None
    period_max_ms: float | None = None
    periods_over_2ms: int | None = None
    sensor_age_max_ms: float | None = None
    pose_age_max_ms: float | None = None
    latency_p50_ms: float | None = None
    latency_max_ms: float | None = None

    def columns(self) -> dict[str, float | int | None]:
        """The ``trials`` columns, in table order."""
        return asdict(self)


def trial_health(period_s: npt.NDArray[np.float64], sensor_age_s: npt.NDArray[np.float64],
                 pose_age_s: npt.NDArray[np.float64], latency_s: npt.NDArray[np.float64]) -> LoopHealth:
    """The loop's health over a trial's records.

    Parameters
    ----------
    period_s, sensor_age_s, pose_age_s, latency_s
        The loop records' ``period_ns``, ``sensor_age_ns``, ``pose_age_ns`` and ``latency_ns`` × 1e-9, s
        (the product the loop itself formed before its records carried ns, so the stored ms are the same).

    Returns
    -------
    LoopHealth
        All None for a trial without records.
    """
    if len(period_s) == 0:
        return LoopHealth()
    p50, p99 = np.quantile(period_s, (0.5, 0.99))
    return LoopHealth(
        period_p50_ms=float(p50) * 1e3,
        period_p99_ms=float(p99) * 1e3,
        period_max_ms=float(np.max(period_s)) * 1e3,
        periods_over_2ms=int(np.count_nonzero(period_s > 0.002)),
        sensor_age_max_ms=float(np.max(sensor_age_s)) * 1e3,
        pose_age_max_ms=float(np.max(pose_age_s)) * 1e3,
        latency_p50_ms=float(np.quantile(latency_s, 0.5)) * 1e3,
        latency_max_ms=float(np.max(latency_s)) * 1e3,
    )


@dataclass(frozen=True, slots=True)
class TrialRecord:
    """One finished trial (a ``trials`` row), typed.

    Attributes
    ----------
    session_id, trial_index
        Which trial (:attr:`trial_id` is the table's key).
    target_label, target_force_n, haptic_mode
        Its designed condition.
    outcome
        How it ended.
    clock
        Maps ``cue_ns`` and ``end_ns`` to session time (:attr:`started_at_s`, :attr:`ended_at_s`).
    cue_ns, end_ns
        The trial's time origin (its first record under its condition) and its end, loop clock, ns.
    metrics
        Its metrics as stored (its task's judgement, :meth:`protocol.tasks.base.Task.judge`), by name: each
        metric of its task with a ``trials`` column (:func:`protocol.metrics.stored`; a success-only one, TCT, None
        unless a success).  A metric its task does not produce is not among them (read back from a file that has
        its column, for another task's sessions: None); :meth:`metric` reads one.
    n_samples
        The samples of its trial window.
    abort_reason, abort_cause
        Why an aborted trial was aborted (None otherwise).
    repeat_of
        The index of the aborted trial this one re-runs, if any.
    health
        How the loop ran over its records.
    segment, first_tick, last_tick
        Where its records are in the session's recording (None: in ``samples``, or none).
    answer, answer_correct
        A task that asks (force discrimination): the participant's answer and whether it was right, for the live
        views (stored in ``trial_answers``, not in the row: :mod:`protocol.storage.trial_answers`).
    """

    session_id: int
    trial_index: int
    target_label: str
    target_force_n: float
    haptic_mode: HapticMode
    outcome: Outcome
    clock: SessionClock
    cue_ns: int
    end_ns: int
    metrics: Mapping[str, MetricValue] = field(default_factory=dict, hash=False)
    n_samples: int | None = None
    abort_reason: str | None = None
    abort_cause: AbortCause | None = None
    repeat_of: int | None = None
    health: LoopHealth = field(default_factory=LoopHealth)
    segment: int | None = None
    first_tick: int | None = None
    last_tick: int | None = None
    answer: str | None = None
    answer_correct: bool | None = None

    def __post_init__(self) -> None:
        # the enums are the record's vocabulary: a stray string (or a typo) fails here, not in the database
        object.__setattr__(self, "haptic_mode", HapticMode(self.haptic_mode))
        object.__setattr__(self, "outcome", Outcome(self.outcome))
        if self.abort_cause is not None:
            object.__setattr__(self, "abort_cause", AbortCause(self.abort_cause))

    @classmethod
    def finished(
        cls, *, session_id: int, spec: TrialSpec, outcome: Outcome, clock: SessionClock, cue_ns: int, end_ns: int,
        metrics: TrialMetrics, reason: str = "", cause: AbortCause | None = None, health: LoopHealth = LoopHealth(),
        segment: int | None = None, ticks: tuple[int, int] | None = None,
    ) -> TrialRecord:
        """The record of a trial that just ended, from its schedule entry and its metrics.

        ``ticks`` are its first and last record's loop ticks in recording ``segment`` (None: it has no records).
        """
        kept = {name: (None if m.success_only and outcome is not Outcome.SUCCESS else value)
                for name, value in metrics.values.items() if (m := get(name)).stored}
        return cls(
            session_id=session_id, trial_index=spec.index, target_label=spec.target_label,
            target_force_n=spec.target_force_n, haptic_mode=spec.haptic_mode, outcome=outcome, clock=clock,
            cue_ns=cue_ns, end_ns=end_ns, metrics=kept, n_samples=metrics.n_samples, abort_reason=reason or None,
            abort_cause=cause, repeat_of=spec.repeat_of, health=health,
            segment=segment if ticks is not None else None,
            first_tick=ticks[0] if ticks is not None else None, last_tick=ticks[1] if ticks is not None else None,
        )

    @property
    def trial_id(self) -> int:
        """The ``trials`` key."""
        return trial_id_of(self.session_id, self.trial_index)

    @property
    def started_at_s(self) -> float:
        """The cue, session clock, s."""
        return self.clock.seconds(self.cue_ns)

    @property
    def ended_at_s(self) -> float:
        """The trial end, session clock, s."""
        return self.clock.seconds(self.end_ns)

    @property
    def success(self) -> bool:
        """The trial succeeded."""
        return self.outcome is Outcome.SUCCESS

    def metric(self, name: str) -> MetricValue:
        """One stored metric by name (``record.metric("rmse_n")``; None: not stored, not its task's, or undefined for
        this trial)."""
        return self.success if get(name).boolean else self.metrics.get(name)

    def to_row(self) -> dict[str, Any]:
        """The ``trials`` row: times in session seconds, the enums as their TEXT, a column per metric of its task (the
        writer adds one the file lacks: :meth:`protocol.storage.StudyDatabase.insert_trial`)."""
        return {
            "trial_id": self.trial_id, "session_id": self.session_id, "trial_index": self.trial_index,
            "target_label": self.target_label, "target_force_n": self.target_force_n,
            "haptic_mode": self.haptic_mode.value, "outcome": self.outcome.value,
            "started_at_s": self.started_at_s, "ended_at_s": self.ended_at_s,
            **self.metrics, "n_samples": self.n_samples,
            "abort_reason": self.abort_reason, "repeat_of": self.repeat_of,
            "abort_cause": None if self.abort_cause is None else self.abort_cause.value,
            **self.health.columns(),
            "segment": self.segment, "first_tick": self.first_tick, "last_tick": self.last_tick,
        }

    @classmethod
    def from_row(cls, row: Mapping[str, Any]) -> TrialRecord:
        """A stored ``trials`` row (from :meth:`protocol.storage.StudyDatabase.trial_rows`) as a record.

        Columns a file of an older schema lacks read as None.  The row's
        session times become the record's clock (anchored at the cue), so
        :attr:`started_at_s` is the stored value; ``end_ns`` is the stored
        duration to the nearest ns.
        """
        started, ended = float(row["started_at_s"]), float(row["ended_at_s"])
        names = {f.name for f in fields(LoopHealth)}
        return cls(
            session_id=int(row["session_id"]), trial_index=int(row["trial_index"]),
            target_label=str(row["target_label"]), target_force_n=float(row["target_force_n"]),
            haptic_mode=HapticMode(row["haptic_mode"]), outcome=Outcome(row["outcome"]),
            clock=SessionClock(started, 0), cue_ns=0, end_ns=round((ended - started) * 1e9),
            metrics=values_of(row), n_samples=row.get("n_samples"), abort_reason=row.get("abort_reason"),
            abort_cause=row.get("abort_cause"), repeat_of=row.get("repeat_of"),
            health=LoopHealth(**{k: row.get(k) for k in names}),
            segment=row.get("segment"), first_tick=row.get("first_tick"), last_tick=row.get("last_tick"),
        )


#: Relative agreement required between a trial's metrics recomputed from its recording and those stored live: the
#: same samples and the same definitions, so only the summation's order may differ (a few ulps of a sum of
#: thousands of terms).
AGREE_REL = 1e-9


def _close(a: float, b: float) -> bool:
    if a != a and b != b:  # both NaN (stored NULL)
        return True
    return abs(a - b) <= AGREE_REL * max(abs(a), abs(b), 1e-12)


def disagreement(recomputed: TrialMetrics, record: TrialRecord) -> str:
    """What differs between a trial's metrics recomputed over the cue window and the ones stored during its
    session ("" when nothing does): the outcome, and every stored metric the record has a value for (a metric
    defined after the file was written has none; NaN is stored as NULL, and an undefined TCT is None on both
    sides).  The report uses the recomputed values either way; ``check`` calls a difference a problem."""
    if recomputed.success != record.success:
        return (f"its outcome recomputed from the recording is {'success' if recomputed.success else 'no success'}, "
                f"stored {record.outcome.value}")
    for name, kept in record.metrics.items():
        value = recomputed.values.get(name)
        again = float("nan") if value is None else float(value)
        if kept is not None and not _close(again, float(kept)):
            return f"its {name} recomputed from the recording is {again:.6g}, stored {float(kept):.6g}"
    return ""
