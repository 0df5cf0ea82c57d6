"""The running session as the experimenter sees it: state, progress and the trial table."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from protocol.metrics import Metric, Role
from protocol.study.design import HapticMode
from protocol.study.records import Outcome, TrialRecord
from protocol.tasks.base import Task
from protocol.tasks.force_regulation import ForceRegulation
from study_app.engine import messages as m
from study_app.models import Emitter

__all__ = ["TRIAL_COLUMNS", "SessionModel", "TrialCount", "TrialTable", "time_left_text"]

def table_metrics(task: Task | None) -> tuple[Metric, ...]:
    """The metrics the live trial table shows of a task's trials: its stored measures that the report tests
    (primary and secondary; a yes/no outcome is the Outcome column), in the registry's order."""
    return tuple(m for m in (task or ForceRegulation()).metrics
                 if m.stored and not m.boolean and m.role is not Role.DESCRIPTIVE)


def trial_columns(task: Task | None) -> tuple[str, ...]:
    """The live trial table's columns for a session of ``task`` (None: the paper's): its measures, and the answer
    of a task that asks one."""
    asks = ("Answer",) if task is not None and task.answer_keys else ()
    return ("#", "Target", "Mode", "Outcome", *(m.label for m in table_metrics(task)), *asks, "Note")


#: Columns of the live trial table of the paper's task (another task's: :func:`trial_columns`).
TRIAL_COLUMNS = trial_columns(None)
#: How the table marks a note the experimenter marked a deviation from the protocol.
DEVIATION_MARK = "⚑ "


def _answer(row: TrialRecord) -> str:
    """A trial's answer as the table shows it: ``2 ✓`` (right), ``1 ✗`` (wrong), ``–`` (none)."""
    if row.answer is None:
        return "–"
    return row.answer + ("" if row.answer_correct is None else " ✓" if row.answer_correct else " ✗")


def _num(v: Any, fmt: str = "{:.2f}") -> str:
    return "–" if v is None or (isinstance(v, float) and not math.isfinite(v)) else fmt.format(v)


@dataclass(frozen=True, slots=True)
class TrialCount:
    """A session's progress, counted one way in every panel (the progress line, the status bar, the Trials tab,
    the list of interrupted sessions, the setup form).

    ``designed`` trials are the design's (20 in the paper's protocol); each is ``done`` once, when it or a
    re-run of it ends as a success or a timeout, so ``done`` never passes ``designed`` and the count never
    grows as re-runs are added.  ``aborted`` attempts are counted apart; each queues one re-run, so the
    re-runs left (the one running included) are the aborted attempts less the re-runs already run
    (``reruns_run``).
    """

    designed: int
    done: int = 0
    aborted: int = 0
    reruns_run: int = 0

    @classmethod
    def of(cls, designed: int, records: list[TrialRecord]) -> TrialCount:
        """From the trial records stored so far."""
        aborted = sum(r.outcome is Outcome.ABORTED for r in records)
        return cls(designed, len(records) - aborted, aborted, sum(r.repeat_of is not None for r in records))

    @property
    def reruns_to_come(self) -> int:
        """Re-runs queued and not ended yet (the one running, if one runs, included)."""
        return max(0, self.aborted - self.reruns_run)

    @property
    def fraction(self) -> float:
        """Share of the designed trials done (0–1)."""
        return min(1.0, self.done / self.designed) if self.designed > 0 else 0.0

    def text(self) -> str:
        """``7 of 20 trials done · 2 aborted · 1 re-run left`` (the last two only when not zero)."""
        parts = [f"{self.done} of {self.designed} trials done"]
        if self.aborted:
            parts.append(f"{self.aborted} aborted")
        n = self.reruns_to_come
        if n:
            parts.append(f"{n} re-run{'s' if n > 1 else ''} left")
        return " · ".join(parts)


def time_left_text(seconds: float, *, bound: bool = False) -> str:
    """An estimate of the time left, rounded as people say it: ``about 40 s left``, ``about 4 min left``
    (``at most …`` when ``bound``: no trial has ended yet, so every trial is counted at its cap)."""
    word = "at most" if bound else "about"
    if seconds < 60.0:  # a bound rounds up; an estimate to the nearest 10 s (12.3 s is "about 10 s", not 20)
        tens = math.ceil(seconds / 10.0) if bound else math.floor(seconds / 10.0 + 0.5)
        return f"{word} {max(10, 10 * tens):.0f} s left"
    return f"{word} {math.ceil(seconds / 60.0) if bound else max(1, round(seconds / 60.0)):d} min left"


@dataclass
class TrialTable:
    """Finished trials, filled live from :class:`study_app.engine.messages.TrialEnded` records, and the
    experimenter's notes: on a trial (its row's *Note*, also before the trial has ended) or on the session
    (``notes[None]``)."""

    rows: list[TrialRecord] = field(default_factory=list)
    notes: dict[int | None, list[str]] = field(default_factory=dict)
    #: The session's task (its measures are the columns; None: the paper's).
    task: Task | None = None
    row_added: Emitter = field(default_factory=Emitter)
    cleared: Emitter = field(default_factory=Emitter)
    #: A note was added: the row index it shows in (None: a session note, or a trial with no row yet).
    note_added: Emitter = field(default_factory=Emitter)

    def add(self, row: TrialRecord) -> None:
        """Append a finished trial."""
        self.rows.append(row)
        self.row_added.emit(len(self.rows) - 1)

    @property
    def columns(self) -> tuple[str, ...]:
        """The table's columns: its task's (:func:`trial_columns`)."""
        return trial_columns(self.task)

    def clear(self, task: Task | None = None) -> None:
        """Forget all rows and notes (a new session, of ``task``: its columns)."""
        self.task = task
        self.rows.clear()
        self.notes.clear()
        self.cleared.emit()

    def add_note(self, trial_index: int | None, text: str, deviation: bool) -> None:
        """A note on trial ``trial_index`` (None: the session)."""
        self.notes.setdefault(trial_index, []).append((DEVIATION_MARK if deviation else "") + text)
        row = next((i for i, r in enumerate(self.rows) if trial_index is not None and r.trial_index == trial_index),
                   None)
        self.note_added.emit(row)

    def note_text(self, trial_index: int | None) -> str:
        """A trial's notes (or the session's), oldest first, in one line."""
        return " · ".join(self.notes.get(trial_index, []))

    def designed_of(self, index: int) -> int:
        """The designed trial an attempt is of: a re-run of a re-run (57 re-runs 48, which re-ran 12) is trial 12's,
        followed back through the rows' ``repeat_of``."""
        repeats = {r.trial_index: r.repeat_of for r in self.rows}
        seen, earlier = {index}, repeats.get(index)
        while earlier is not None and earlier not in seen:
            index = earlier
            seen.add(index)
            earlier = repeats.get(index)
        return index

    def cells(self, row: TrialRecord, designed: int | None = None) -> tuple[str, ...]:
        """The displayed text of a row, in :data:`TRIAL_COLUMNS` order (``designed``: the designed trial a re-run
        repeats, :meth:`designed_of`; its ``repeat_of`` when not given)."""
        outcome = str(row.outcome)
        if row.abort_reason:
            outcome += f" ({row.abort_reason})"
        of = row.repeat_of if designed is None else designed
        return (
            str(row.trial_index + 1) + ("" if of is None else f" (re-run of {of + 1})"),
            f"{row.target_label} {row.target_force_n:g} N",
            "haptics ON" if row.haptic_mode is HapticMode.ON else "haptics OFF",
            outcome,
            *(_num(row.metric(m.name), "{:.2f}" if m.unit == "s" else "{:.3f}") for m in table_metrics(self.task)),
            *((_answer(row),) if self.task is not None and self.task.answer_keys else ()),
            self.note_text(row.trial_index),
        )


@dataclass
class SessionModel:
    """Session state from engine events, and the progress line from the newest sample time.

    ``state`` ∈ {connecting, ready, running, paused, ended, stopped, failed}.
    """

    state: str = "connecting"
    message: str = "starting the engine …"
    session: m.SessionStarted | None = None
    trial: m.TrialStarted | None = None
    phase: str = "idle"
    pause_until_s: float | None = None
    paused_requested: bool = False
    #: Why the session runner paused the session itself ("" when it did not): trials it could not deliver.
    paused_by_runner: str = ""
    completed: int = 0
    aborted: int = 0
    reruns_run: int = 0
    #: Trials of the design (re-runs not counted): the "of N" of every count.
    designed: int = 0
    #: Length of each attempt so far (cue to end, s): the time-left estimate.
    _durations_s: list[float] = field(default_factory=list)
    latest_t_s: float = 0.0
    #: The newest trial started, kept after it ends (the live axis keeps its target's scale between trials).
    last_trial: m.TrialStarted | None = None
    #: Sample time of this session's newest cue (None before its first trial): the live plot marks it, draws the
    #: band from it on and judges a force above the axis only on the samples since.
    cue_t_s: float | None = None
    table: TrialTable = field(default_factory=TrialTable)
    #: The database of the session shown (absolute path; "" before one started).
    db_path: str = ""
    changed: Emitter = field(default_factory=Emitter)

    # -- events -------------------------------------------------------------------------------------
    def apply(self, ev: object) -> None:
        """Update from one engine event."""
        if isinstance(ev, m.EngineReady):
            self.state, self.message = "ready", f"engine ready ({ev.rig} rig, {ev.clock} clock)"
        elif isinstance(ev, m.EngineOpening) and self.state == "connecting":
            self.message = f"starting the engine: opening the {ev.device} …"  # a device that hangs is named
        elif isinstance(ev, m.SessionStarted):
            self.session, self.trial, self.phase, self.cue_t_s = ev, None, "idle", None
            resumed = " (resumed)" if ev.stored_trials else ""
            self.state, self.message = "running", f"session {ev.session_id}: {ev.code} {ev.kind}{resumed}"
            self.completed = self.aborted = self.reruns_run = 0
            self._durations_s = []
            designed = [t for t in ev.schedule if t.get("repeat_of") is None]
            self.designed = len(designed) if ev.schedule else ev.trials_total
            self.paused_requested = False
            self.pause_until_s = None
            self.table.clear(ev.task)
            for index, text, deviation in ev.stored_notes:  # a resumed session: its notes, table and progress
                self.table.add_note(index, text, deviation)
            for row in ev.stored_trials:
                self._count(row)
        elif isinstance(ev, m.TrialStarted):
            self.trial, self.phase, self.pause_until_s = ev, "active", None
            self.last_trial, self.cue_t_s = ev, ev.t_s
            if self.session is not None:  # an aborted trial's re-run lengthens the schedule
                self.session = _with_total(self.session, ev.trials_total)
            self.latest_t_s = max(self.latest_t_s, ev.t_s)
        elif isinstance(ev, m.PhaseEntered):
            self.phase = ev.phase
            if ev.phase == "pause" and self.session is not None:
                self.pause_until_s = ev.t_s + self.session.pause_s
        elif isinstance(ev, m.TrialEnded):
            self._count(ev.record)
            if self.session is not None:
                self.session = _with_total(self.session, ev.trials_total)
        elif isinstance(ev, m.SessionEnded):
            self.state = "ended"
            self.message = f"session {ev.session_id} {ev.status}" + (f": {ev.reason}" if ev.reason else "")
            self.trial, self.phase = None, "idle"
        elif isinstance(ev, m.Health):
            if self.state in ("running", "paused") and ev.session_running:
                # the engine reports a pause from the moment it is asked for; it holds only once the trial ends
                holding = ev.paused and self.phase not in ("active", "cued")
                self.paused_requested = ev.paused and not holding
                self.state = "paused" if holding else "running"
                self.paused_by_runner = ev.waiting if holding and ev.waiting not in ("", "pause") else ""
        elif isinstance(ev, m.NoteStored):
            self.table.add_note(ev.trial_index, ev.text, ev.deviation)
        elif isinstance(ev, m.EngineStopped):
            self.state, self.message = "stopped", f"engine stopped: {ev.reason}"
        elif isinstance(ev, m.CommandRefused) and ev.command == "connect":
            self.state, self.message = "failed", ev.message
        else:
            return
        self.changed.emit()

    def listed(self, db_path: str, known: list[dict[str, Any]]) -> None:
        """The engine listed ``db_path``'s sessions: an ended session shown from another database, or one that is
        no longer in it (a withdrawal erased it), is shown no longer -- its trials are not this database's."""
        if self.state != "ended" or self.session is None:
            return
        if db_path == self.db_path and any(s["session_id"] == self.session.session_id for s in known):
            return
        self.reset(f"{os.path.basename(db_path)} open: no session running" if db_path != self.db_path else
                   f"session {self.session.session_id} is no longer stored (withdrawn): no session running", "ready")

    def reset(self, message: str, state: str = "connecting") -> None:
        """No session, no trial, an empty table: a new engine is starting (the old engine's clock is gone), or
        (``state`` ready) the session shown is not the open database's."""
        self.state, self.message = state, message
        self.session = self.trial = self.last_trial = None
        self.cue_t_s = None
        self.phase, self.pause_until_s, self.paused_requested = "idle", None, False
        self.completed = self.aborted = self.reruns_run = self.designed = 0
        self._durations_s = []
        self.latest_t_s = 0.0
        self.table.clear()
        self.changed.emit()

    def _count(self, row: TrialRecord) -> None:
        self.table.add(row)
        if row.outcome is Outcome.ABORTED:
            self.aborted += 1
        else:
            self.completed += 1
        self.reruns_run += row.repeat_of is not None
        if row.end_ns > row.cue_ns and row.outcome is not Outcome.ABORTED:  # an aborted one was cut short
            self._durations_s.append((row.end_ns - row.cue_ns) * 1e-9)

    @property
    def count(self) -> TrialCount:
        """The session's progress, as every panel shows it."""
        return TrialCount(self.designed, self.completed, self.aborted, self.reruns_run)

    def set_time(self, t_s: float) -> None:
        """The newest sample time from the ring (drives the countdowns)."""
        if t_s != self.latest_t_s:
            self.latest_t_s = t_s
            self.changed.emit()

    # -- what the progress line shows --------------------------------------------------------------------
    @property
    def running(self) -> bool:
        """A session is running (possibly paused)."""
        return self.state in ("running", "paused")

    def progress_text(self) -> str:
        """What is happening now: the running trial and its time left, the pause's countdown, or the state."""
        s = self.session
        if s is None or not self.running:
            return self.message
        if self.state == "paused":
            if self.paused_by_runner:  # not the experimenter's pause: say so, and where the reason is
                return "Paused by the session: trials were not delivered as designed (see below) · Resume (Space)"
            return "Paused · Resume (Space) to continue"
        pending = " · pause requested: pausing after this trial" if self.paused_requested else ""
        tr = self.trial
        if self.phase in ("active", "cued", "answer") and tr is not None:
            left = max(0.0, s.max_trial_s - (self.latest_t_s - tr.t_s))
            again = "" if tr.repeat_of is None else f" (re-run of trial {self.table.designed_of(tr.repeat_of) + 1})"
            # when it times out (its cap), not "s left": beside the session's estimate, two "left"s read as one
            return (f"Trial {tr.trial_index + 1}{again} · {tr.target_label} · haptics {tr.haptic_mode.upper()} · "
                    f"times out in {left:.1f} s{pending}")
        if self.phase == "pause" and self.pause_until_s is not None:
            left = max(0.0, self.pause_until_s - self.latest_t_s)
            return "Pausing before the next trial" if pending else f"Next trial in {left:3.1f} s"
        first = tr is None and not self.table.rows
        return ("Session started: the first trial is due" if first else "The next trial is due") + pending

    def abort_session_question(self) -> str:
        """The question Abort session asks, saying what will happen now ("" without a session).

        Only a trial that is running is stored as aborted (and, unlike Abort trial, not run again); paused or
        between trials, none is.  Either way the trials not yet done are not run, and the session cannot be
        resumed.  Between trials (not paused) the next cue may come before the answer: the question says so.
        """
        s = self.session
        if s is None:
            return ""
        tr = self.trial if self.phase in ("active", "cued", "answer") else None
        left = max(0, self.count.designed - self.count.done)
        head = f"Abort session {s.session_id} ({s.code}, {s.kind})?"
        if tr is not None:
            again = "" if tr.repeat_of is None else f" (re-run of trial {self.table.designed_of(tr.repeat_of) + 1})"
            now = (f"Trial {tr.trial_index + 1}{again} ({tr.target_label}, haptics {tr.haptic_mode.upper()}) is "
                   "running: it is stored as aborted (unless it ends before you answer) and not run again.")
            rest = _not_run(left - 1, "other ")
        else:
            where = "the session is paused" if self.state == "paused" else "between trials"
            now = f"No trial is running ({where}): none is stored as aborted."
            if self.state != "paused":
                now += " If the next trial is cued before you answer, that trial is."
            rest = _not_run(left)
        return " ".join(p for p in (head, now, rest, "The session ends; it cannot be resumed.") if p)

    def count_text(self) -> str:
        """The progress count and the time left: ``7 of 20 trials done · 2 aborted · 1 re-run left · about
        4 min left`` ("" without a session)."""
        if self.session is None:
            return ""
        c = self.count
        left = self.time_left_s()
        if c.done >= c.designed or left is None:
            return c.text()
        return f"{c.text()} · {time_left_text(left[0], bound=left[1])}"

    def time_left_s(self) -> tuple[float, bool] | None:
        """(estimated seconds until the last designed trial is done, whether it is an upper bound), or None.

        Every designed trial not yet done takes one more attempt (a re-run left is one of them): the mean
        length of the trials that ended so far (a success or a timeout: an aborted one was cut short), or the trial
        cap before any ended (then it is an upper bound), with the protocol's pause between two of them (none after
        the last).  The running trial counts what it has left of that.
        """
        s = self.session
        if s is None:
            return None
        c = self.count
        remaining = max(0, c.designed - c.done)
        bound = not self._durations_s
        per = s.max_trial_s if bound else min(s.max_trial_s, sum(self._durations_s) / len(self._durations_s))
        total = remaining * per + max(0, remaining - 1) * s.pause_s  # no pause after the last trial
        if self.phase in ("active", "cued", "answer") and self.trial is not None and remaining:
            total -= min(per, max(0.0, self.latest_t_s - self.trial.t_s))
        return max(0.0, total), bound

    def fraction_done(self) -> float:
        """Share of the designed trials done (0–1): it never moves back when a re-run is added."""
        return self.count.fraction if self.session is not None else 0.0

    def band_for_axis(self) -> tuple[float, float] | None:
        """The extent of the current trial's band over the trial (its lowest and highest edge: a band that moves
        stays on the axis), or of the last one between trials (the live axis keeps its scale)."""
        tr = self.last_trial
        if tr is None or self.session is None:
            return None
        return self.session.task.screen(tr).band_extent(0.0, self.session.max_trial_s)

    def band_label(self) -> str:
        """The live plot's words for the band, the task's (``GENTLE: target 0.6 N ± 10 % (0.54–0.66 N)``; "" without
        a band)."""
        if self.trial is None or self.session is None or self.phase != "active":
            return ""
        return self.session.task.screen(self.trial).band_label

    def band(self, t_s: npt.ArrayLike) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None:
        """The current trial's band at session times ``t_s`` as its task draws it (its lower and upper edge, N)
        while a trial is active, else None."""
        if self.trial is None or self.session is None or self.phase != "active":
            return None
        return self.session.task.screen(self.trial).band_over(np.asarray(t_s, dtype=np.float64) - self.trial.t_s)


def _not_run(n: int, other: str = "") -> str:
    """``The 3 other trials not yet done are not run.`` ("" for none)."""
    if n <= 0:
        return ""
    if n == 1:
        return f"The {n} {other}trial not yet done is not run."
    return f"The {n} {other}trials not yet done are not run."


def _with_total(s: m.SessionStarted, total: int) -> m.SessionStarted:
    if total == s.trials_total:
        return s
    from dataclasses import replace

    return replace(s, trials_total=total)
