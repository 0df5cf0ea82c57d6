"""The session runner: walks the schedule over the haptic loop.

It reads the loop's records (from the ring buffer), feeds the trial machine,
and acts on what happens: switches haptic feedback per trial, stamps trial and
phase into the samples, allows online bias refinement only between trials,
sends samples, trial summaries and events to the recorder, and tells the
simulated participant (if any) when a trial starts and ends.

It has no thread and no clock of its own: :meth:`SessionRunner.process` is
called with each new block of records, by the headless driver on the virtual
clock or by a thread polling the ring in a live session.  Experimenter
requests (:meth:`pause`, :meth:`resume`, :meth:`abort_trial`,
:meth:`abort_session`) may come from any thread; they take effect at the next
``process`` call, at that block's sample time.

Abort policy: an aborted trial is stored with outcome ``aborted``, its
reason and its cause (``trials.abort_cause``), and re-run later -- appended at
the end of the schedule (``append``, the default) or re-inserted at a random
later position (``reinsert``) -- so every target × mode cell still gets its
full count of completed trials.  Aborting the session aborts the current
trial without re-queueing it and ends the session with status ``aborted``.

**A trial counts only if it ran under its designed condition**: the runner aborts it at the
first record where the loop did not deliver it as designed (:mod:`protocol.study.delivery`).

Every loop event (a fault latched with the value that tripped it, a
condition gone, a reset) is stored as an event.  No trial is cued while a
fault is latched; once it is cleared the protocol's pause runs again before
the next cue.  In a headless session (``auto_reset_faults``) the runner
itself resets a fault in the pause once its condition is gone; if one is
still latched ``fault_timeout_s`` (10 s) later the session stops as
*interrupted* (resumable later) with a one-line :attr:`SessionRunner.stop_reason`.

A finished trial is one :class:`protocol.study.records.TrialRecord`: stored by the recorder and handed
to the runner's listeners as it is.

**The whole session is recorded** (:mod:`protocol.recording`): the runner asks
the loop for a snapshot of the framework (:class:`pipeline.runtime.loop.StartRecording`)
and, from the tick it was taken on, hands every record and the loop's replay
log to the recorder -- trials, pauses and waits alike -- so the session can be
replayed through the pipeline (:mod:`pipeline.force.replay`; the hand-off is
:mod:`protocol.runner.session_recording`).  Records before that tick (the loop ran
before the session began) are not the session's.  A trial
row names its records: ``segment``, ``first_tick`` (its cue) and ``last_tick``.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from pipeline.devices.interfaces import Fault
from pipeline.runtime.loop_messages import (
    AllowBiasRefinement,
    Command,
    LoopEvent,
    Mark,
    ResetFaults,
    SetHaptics,
    StartRecording,
    StopRecording,
)
from protocol.runner.session_recording import OtherArms, SessionRecording
from protocol.storage import Recorder, StudyDatabase
from protocol.study.clock import SessionClock
from protocol.study.config import ProtocolConfig
from protocol.study.delivery import DeliveryLimits, Deviation, TrialWindow
from protocol.study.design import HapticMode, TrialSpec, requeue_aborted, schedule_to_json
from protocol.study.records import AbortCause, Outcome, TrialRecord
from protocol.study.trial import PHASE_CODES, PhaseChanged, TrialFinished, TrialMachine, TrialPhase

__all__ = ["SessionRunner", "SessionState", "TrialParticipant", "first_unfinished", "trial_words"]


class TrialParticipant(Protocol):
    """What the runner tells a simulated participant."""

    def begin_trial(self, target_force_n: float, haptic_on: bool, t_s: float) -> None:
        """The cue appeared."""
        ...

    def end_trial(self, t_s: float) -> None:
        """The trial ended; rest until the next cue."""
        ...


@dataclass
class SessionState:
    """Progress for displays (plain data, read from any thread)."""

    trial_position: int = 0  # trials finished or running (1-based during a trial)
    trials_total: int = 0
    completed: int = 0
    aborted: int = 0
    successes: int = 0
    phase: str = "idle"
    paused: bool = False
    done: bool = False
    status: str = "running"
    current: TrialSpec | None = None
    trial_elapsed_s: float = 0.0
    #: Why the next cue is held back ("" = not held): a latched fault, the pause after one.
    waiting: str = ""


#: Headless: a latched fault is reset at most this often while its condition may still be there.
RESET_RETRY_S = 0.5
#: Headless: a fault still latched this long after the runner started waiting stops the session (interrupted).
FAULT_TIMEOUT_S = 10.0
#: Trials in a row the loop failed to deliver (fault, feedback, gap) before the runner stops cueing: a machine or
#: rig that cannot hold the designed condition would otherwise re-run trials without end.
MAX_FAILED_IN_A_ROW = 3


def trial_words(trial_index: int) -> str:
    """How events name a trial: numbered from 1 for people, with the database's index to join on.

    ``trial_words(3)`` is ``"trial 4 (index 3)"``; a pause (index −1) is ``"the pause"``.
    """
    return "the pause" if trial_index < 0 else f"trial {trial_index + 1} (index {trial_index})"


class SessionRunner:
    """Runs one session (training or experiment) from its stored schedule.

    Parameters
    ----------
    protocol
        The validated protocol (timing, abort policy).
    schedule
        The whole trial order, already stored with the session.
    session_id
        The session's database id.
    recorder
        The database writer.
    submit
        Sends a command to the haptic loop.
    start_position
        First schedule position to run (resume).
    session_clock_offset_s
        Session-clock time at the first record processed (resume continues the clock).
    participant
        Simulated participant to notify, or None for a person.
    participant_time
        The participant's clock (the rig's simulated time), for its notifications.
    seed
        Seeds the ``reinsert`` abort policy.
    limits
        What the loop must deliver for a trial to count (see the module docstring).
    initial_pause_s
        Hold the first cue this long (a resumed session begins with the protocol's pause).
    auto_reset_faults
        Headless sessions: reset a latched fault in the pause once its
        condition is gone, and stop the session as interrupted if one is still
        latched ``FAULT_TIMEOUT_S`` later.  A person's session leaves the
        reset to the experimenter.
    segment
        The recording's segment this run writes (0, then one more per resume).
    scales
        Counts per unit of the raw wrench columns (the recording codec's hint; empty: store floats).
    """

    def __init__(
        self,
        *,
        protocol: ProtocolConfig,
        schedule: list[TrialSpec],
        session_id: int,
        recorder: Recorder,
        submit: Callable[[Command], None],
        start_position: int = 0,
        session_clock_offset_s: float = 0.0,
        participant: TrialParticipant | None = None,
        participant_time: Callable[[], float] | None = None,
        seed: int = 0,
        limits: DeliveryLimits | None = None,
        initial_pause_s: float = 0.0,
        auto_reset_faults: bool = False,
        segment: int = 0,
        scales: dict[str, float] | None = None,
        arms: tuple[str, ...] = (),
    ) -> None:
        self.protocol = protocol
        #: The rig's arms (() or one: events stored as ever) and the task arm, whose records the runner is given.
        self.arms = arms
        self.task_arm = protocol.task_arm_of(arms) if arms else ""
        self.schedule = list(schedule)
        self.session_id, self.recorder, self.submit = session_id, recorder, submit
        self.position = start_position
        self.participant = participant
        #: Training: the participant sees a live force gauge with the target band.
        self.live_force_aid = False
        self.participant_time = participant_time or (lambda: 0.0)
        self.machine = TrialMachine(protocol.trial)
        self._rng = np.random.default_rng([seed, session_id, 7])
        self._offset_s = session_clock_offset_s
        #: Session time of loop timestamps, from this run's first record on (None before it).
        self.clock: SessionClock | None = None
        self._last_t_ns = 0
        self._lock = threading.Lock()
        self._requests: list[tuple[str, str, str, int | None]] = []
        self.paused = False
        self.done = False
        self.status = "running"
        self.state = SessionState(trials_total=len(self.schedule))
        self.finished: list[TrialRecord] = []
        self.listeners: list[Callable[[object], None]] = []
        self.limits = limits or DeliveryLimits()
        self.auto_reset_faults = auto_reset_faults
        #: Why the session stopped early as interrupted (headless fault timeout), else "".
        self.stop_reason = ""
        self._initial_pause_ns = int(round(initial_pause_s * 1e9))
        self._ready_ns: int | None = None  # no cue before this loop time
        self._faults = 0  # latched, as the newest record says
        self._fault_detail = ""  # the newest fault event's detail
        self._condition_gone = False  # the loop said a latched fault's condition went away
        self._waiting_since_ns: int | None = None
        self._next_reset_ns = 0
        self._window = TrialWindow()  # the running trial's records
        self._abort_cause: dict[int, AbortCause] = {}  # trial index -> cause of its abort
        self._pending_gap = ""  # records lost before the next block
        self.segment = segment
        self._recording = SessionRecording(recorder, session_id, segment, scales)
        self.other_arms = OtherArms(self._recording)  # a rig of several arms: the others' records (session_driver)
        self._failed_in_a_row = 0  # trials the loop did not deliver as designed, since the last that it did
        self._enter_pause_commands()
        # after the pause commands: the snapshot is taken once they are applied, in the same tick
        self.submit(StartRecording(self._recording.token))

    # -- experimenter requests (any thread) ----------------------------------------------------
    def pause(self) -> None:
        """Hold before the next trial (a running trial finishes first)."""
        self._request("pause")

    def resume(self) -> None:
        """Continue after :meth:`pause`."""
        self._request("resume")

    def abort_trial(self, reason: str = "aborted by the experimenter",
                    cause: AbortCause | str = AbortCause.EXPERIMENTER, trial_index: int | None = None) -> None:
        """Abort the running trial; it is re-queued per the protocol's abort policy.

        ``cause`` goes to ``trials.abort_cause`` (``experimenter``, or ``interrupted``
        when the controlling program is going away).  With ``trial_index`` the
        request applies to that trial only: if it has ended by the time the
        request is applied, nothing is aborted (a confirmation answered late
        never aborts the next trial).
        """
        self._request("abort_trial", reason, cause, trial_index)

    def records_lost(self, count: int) -> None:
        """The caller could not read ``count`` records (the ring lapped it): the running trial has a gap."""
        self._pending_gap = f"{count} loop records were lost before they could be stored"

    def abort_session(self, reason: str = "aborted by the experimenter") -> None:
        """Abort the running trial (not re-queued) and end the session."""
        self._request("abort_session", reason)

    def _request(self, kind: str, detail: str = "", cause: str = "experimenter",
                 trial_index: int | None = None) -> None:
        with self._lock:
            self._requests.append((kind, detail, cause, trial_index))

    @property
    def running_trial(self) -> TrialSpec | None:
        """The trial that is cued or running (None between trials, paused or done)."""
        m = self.machine
        return m.spec if m.phase in (TrialPhase.CUED, TrialPhase.ACTIVE) else None

    def trial_ended(self, trial_index: int) -> bool:
        """Whether a request naming trial ``trial_index`` comes too late: that trial is not the one running.

        The one test of a late abort: a confirmation answered after its trial ended must never abort the next one
        (the engine refuses it at once, the runner ignores it when it applies the request).
        """
        spec = self.running_trial
        return spec is None or spec.index != trial_index

    # -- helpers ------------------------------------------------------------------------------------
    def session_time_s(self, t_ns: int) -> float:
        """Session-clock time of a loop timestamp."""
        clock = self.clock if self.clock is not None else SessionClock(self._offset_s, t_ns)
        return clock.seconds(t_ns)

    def _event(self, t_ns: int, kind: str, detail: str = "") -> None:
        self.recorder.event(self.session_id, self.session_time_s(t_ns), kind, detail)

    def _enter_pause_commands(self) -> None:
        self.submit(SetHaptics(False))
        self.submit(Mark(-1, PHASE_CODES[TrialPhase.PAUSE]))
        # the tool rests in free space between trials: let the bias estimator track drift
        self.submit(AllowBiasRefinement(True))

    def _emit(self, ev: object) -> None:
        for fn in list(self.listeners):
            try:
                fn(ev)
            except Exception:  # a display must never stop the session
                pass

    # -- the work ----------------------------------------------------------------------------------
    def process(self, rows: np.ndarray, loop_events: Sequence[LoopEvent] = (),
                replay_log: Sequence[tuple[int, str, object]] = ()) -> None:
        """Consume a block of loop records (rows of :data:`pipeline.core.tick_record.TICK_DTYPE`, as the ring holds
        them).

        ``loop_events`` are the loop's events since the previous call (times on the records' axis); they are stored,
        and a fault's detail names the cause of the trial it aborts.  ``replay_log`` is what the loop logged for
        replay since the previous call (:attr:`pipeline.runtime.loop.HapticLoop.replay_log`), read after the records.
        """
        if self._recording.start_tick is not None:  # every record is the session's now: only the log to keep
            self._recording.keep_log(replay_log)
        elif (session_rows := self._recording.session_rows(rows, replay_log)) is None:
            return  # the loop has not taken the snapshot yet: these records are not the session's
        else:
            rows = session_rows
        if self.done or (len(rows) == 0 and self.clock is None):
            return
        if self.clock is None:
            t0 = int(rows["t_ns"][0])
            self.clock = SessionClock(self._offset_s, t0)
            self._recording.open_segment(self._offset_s, t0)
            self._ready_ns = t0 + self._initial_pause_ns
            first_faults = int(rows["faults"][0])
            if first_faults and not any(ev.t_ns >= t0 for ev in loop_events):
                self._event(t0, "fault", f"{Fault(first_faults).describe()}: latched before the session started")
        t0 = self.clock.t0_ns
        for ev in loop_events:
            if ev.t_ns >= t0:  # (the loop's events from before the session are not its own)
                self._store_loop_event(ev)
        if len(rows) == 0:
            return
        self._recording.record(rows)
        t_ns_all = rows["t_ns"]  # int64 (pipeline.core.tick_record)
        self._handle_requests(int(t_ns_all[0]))
        if self.done:
            return
        if self._pending_gap:
            gap, self._pending_gap = self._pending_gap, ""
            self._abort_running(int(t_ns_all[0]), f"gap: {gap}", AbortCause.GAP)
        while len(rows) and not self.done:
            cut = self._deviation(rows)
            if cut is None:
                self._process_part(rows)
                break
            i = cut.index
            self._process_part(rows[:i])
            m = self.machine
            if not self.done and m.phase in (TrialPhase.CUED, TrialPhase.ACTIVE) and m.spec is not None \
                    and int(rows["trial_index"][i]) == m.spec.index:
                # the record that tripped the abort is the trial's last: its window and health show the cause
                self._window.note(rows[i : i + 1])
                self._abort_running(int(rows["t_ns"][i]), cut.reason, cut.cause)
            rows = rows[i:]

    def _process_part(self, rows: np.ndarray) -> None:
        """The trial machine, the samples and the next cue over records that need no abort."""
        if len(rows) == 0:
            return
        m = self.machine
        spec = m.spec
        running = m.phase in (TrialPhase.CUED, TrialPhase.ACTIVE)
        t_ns_all = rows["t_ns"]
        events = m.feed(zip(t_ns_all.tolist(), rows["force_n"].tolist(), rows["trial_index"].tolist(), strict=True))
        if spec is not None and running:
            # only a running trial's records are its samples (records after an abort still carry its mark)
            ended = next((e for e in events if isinstance(e, TrialFinished)), None)
            self._window.note_trial(rows, t_ns_all, spec.index, m.cue_ns, ended)
        with self.recorder.atomic():  # a trial's end is one state change: its row and its end's events commit together
            for ev in events:
                self._on_event(ev)
        t_last = self._last_t_ns = int(t_ns_all[-1])
        self._faults = int(rows["faults"][-1])
        if m.phase is TrialPhase.ACTIVE:
            self.state.trial_elapsed_s = m.elapsed_ns * 1e-9
        if self.done or m.phase in (TrialPhase.CUED, TrialPhase.ACTIVE):
            return
        if self._faults:
            self._wait_for_reset(t_last)
        elif self._waiting_since_ns is not None:
            # the fault is cleared: the protocol's pause runs again before the next cue
            self._waiting_since_ns = None
            pause_s = self.protocol.trial.pause_s
            self._ready_ns = max(self._ready_ns or 0, t_last + int(round(pause_s * 1e9)))
            self.state.waiting = ""
            self._event(t_last, "waiting", f"faults cleared; the next cue follows a {pause_s:g} s pause")
        if m.phase is TrialPhase.IDLE and not self.done:
            self._start_next(t_last)

    def _deviation(self, rows: np.ndarray) -> Deviation | None:
        """The first record at which the running trial left its designed condition (None: no trial, or none)."""
        m = self.machine
        if m.phase not in (TrialPhase.CUED, TrialPhase.ACTIVE) or m.spec is None:
            return None
        return self._window.deviation(rows, m.spec, m.cue_ns, self.limits, self._fault_detail)

    def _store_loop_event(self, ev: LoopEvent) -> None:
        if len(self.arms) > 1 and ev.arm != self.task_arm:
            # another arm's event: stored with its arm; the task's trial sees that arm only through the task arm's
            # own records (its OTHER_ARM fault under the policy "both"), so it does not name the trial's fault
            self._event(int(ev.t_ns), ev.kind, f"arm {ev.arm}: {self._loop_event_detail(ev)}")
            return
        if ev.kind == "fault":
            self._fault_detail = ev.detail
            self._condition_gone = False
        elif ev.kind == "fault_cleared":
            self._condition_gone = True  # a reset can clear it now
        detail = self._loop_event_detail(ev)
        self._event(int(ev.t_ns), ev.kind, f"arm {ev.arm}: {detail}" if len(self.arms) > 1 else detail)

    @staticmethod
    def _loop_event_detail(ev: LoopEvent) -> str:  # what the events table keeps of a loop event
        if ev.kind != "faults_reset":
            return ev.detail
        return f"cleared {ev.detail}" if not ev.faults else \
            f"{Fault(ev.faults).describe()} still latched (its condition persists)"

    def _on_event(self, ev: object) -> None:
        if isinstance(ev, PhaseChanged):
            self.state.phase = str(ev.new)
            self._event(ev.t_ns, "phase", f"{trial_words(ev.trial_index)}: {ev.old} -> {ev.new}")
            self._emit(ev)
        elif isinstance(ev, TrialFinished):
            self._emit(self._finish_trial(ev))

    def _finish_trial(self, ev: TrialFinished) -> TrialRecord:
        """Store the trial that ended and count it; its record (what the listeners get)."""
        spec = ev.spec
        ticks, health = self._window.take()
        aborted = ev.outcome is Outcome.ABORTED
        cause = self._abort_cause.pop(spec.index, AbortCause.EXPERIMENTER) if aborted else None
        self._failed_in_a_row = self._failed_in_a_row + 1 if cause is not None and cause.undelivered else 0
        assert self.clock is not None  # a trial ends only on a record
        record = TrialRecord.finished(
            session_id=self.session_id, spec=spec, outcome=ev.outcome, clock=self.clock, cue_ns=ev.cue_ns,
            end_ns=ev.end_ns, metrics=ev.metrics, reason=ev.reason, cause=cause, health=health,
            segment=self.segment, ticks=ticks,
        )
        self.recorder.trial(record)
        self.finished.append(record)
        st = self.state
        if aborted:
            st.aborted += 1
        else:
            st.completed += 1
            st.successes += record.success
        self._enter_pause_commands()
        if self.participant is not None:
            self.participant.end_trial(self.participant_time())
        self.position = spec.index + 1
        return record

    def _start_next(self, t_ns: int) -> None:
        if self.paused or self._faults:
            return
        if self._failed_in_a_row >= MAX_FAILED_IN_A_ROW:
            self._too_many_failed(t_ns)
            return
        if self._ready_ns is not None and t_ns < self._ready_ns:
            self.state.waiting = "pause"
            return
        self.state.waiting = ""
        if self.position >= len(self.schedule):
            self._end("completed", "all trials done", t_ns)
            return
        spec = self.schedule[self.position]
        self.machine.start(spec, t_ns)
        self.state.current = spec
        self.state.trial_position = self.position + 1
        self.state.trials_total = len(self.schedule)
        self.state.phase = "cued"
        self._event(t_ns, "cue", f"{trial_words(spec.index)}: {spec.target_label} {spec.target_force_n:g} N, "
                                 f"haptics {spec.haptic_mode}")
        self.submit(AllowBiasRefinement(False))
        on = spec.haptic_mode is HapticMode.ON
        self.submit(SetHaptics(on))
        self.submit(Mark(spec.index, PHASE_CODES[TrialPhase.ACTIVE]))
        p = self.participant
        if p is not None:
            if self.live_force_aid and hasattr(p, "practice"):
                p.practice(spec.target_force_n, on, self.participant_time(), True)
            else:
                p.begin_trial(spec.target_force_n, on, self.participant_time())

    def _too_many_failed(self, t_ns: int) -> None:
        """The loop failed several trials in a row: stop cueing (headless: interrupt; a person's session: pause)."""
        last = self.finished[-1]
        why = (f"{self._failed_in_a_row} trials in a row were not delivered as designed (the last: "
               f"{last.abort_reason}); the rig or the machine cannot hold the designed condition")
        self._failed_in_a_row = 0
        if self.auto_reset_faults:
            self._interrupt(t_ns, f"{why}: the session is interrupted and can be resumed")
            return
        self.paused = self.state.paused = True
        self.state.waiting = f"{why}: paused — check the machine's load and the devices, then Resume"
        self._event(t_ns, "waiting", self.state.waiting)
        self._emit(("paused", self.state.waiting))

    def _interrupt(self, t_ns: int, reason: str) -> None:
        """Stop the session here, resumable later: the reason is stored as an event and is :attr:`stop_reason`."""
        self.stop_reason = reason
        self._event(t_ns, "session_interrupted", reason)
        self._enter_pause_commands()
        self.submit(StopRecording())
        self.done = self.state.done = True
        self.status = self.state.status = "interrupted"
        self._emit(("session_end", "interrupted", reason))

    def _wait_for_reset(self, t_ns: int) -> None:
        """A fault is latched outside a trial: hold the next cue; headless, reset it once it can be."""
        what = Fault(self._faults).describe()
        if self._waiting_since_ns is None:
            self._waiting_since_ns = t_ns
            # reset at once when the loop said the condition is gone, else try every RESET_RETRY_S (a device
            # error or an operator stop only clears with a reset)
            self._next_reset_ns = t_ns + int(RESET_RETRY_S * 1e9)
            how = "the runner resets it once its condition is gone" if self.auto_reset_faults else \
                "the experimenter resets it"
            self._event(t_ns, "waiting", f"{what} latched: no cue until it is reset ({how})")
        self.state.waiting = f"fault latched ({what}): reset to continue"
        if not self.auto_reset_faults:
            return
        if t_ns - self._waiting_since_ns > int(FAULT_TIMEOUT_S * 1e9):
            self._interrupt(t_ns, f"{what} was still latched {FAULT_TIMEOUT_S:g} s after the runner began waiting "
                                  "for it to clear; the session is interrupted and can be resumed")
            return
        if self._condition_gone or t_ns >= self._next_reset_ns:
            self._condition_gone = False
            self._next_reset_ns = t_ns + int(RESET_RETRY_S * 1e9)
            self.submit(ResetFaults())

    def _abort_running(self, t_ns: int, reason: str, cause: AbortCause | str, requeue: bool = True) -> None:
        """Abort the trial that is cued or running (if any), storing its cause; re-queue it per the policy."""
        m = self.machine
        if m.phase not in (TrialPhase.CUED, TrialPhase.ACTIVE):
            return
        spec = m.spec
        assert spec is not None
        self._abort_cause[spec.index] = AbortCause(cause)
        # one transaction: the row, its end's events and the schedule with its re-run (else a crash between them
        # could leave an aborted trial never re-run, its cell one short)
        with self.recorder.atomic():
            for ev in m.abort(t_ns, reason):
                self._on_event(ev)
            if requeue:
                policy, sid = self.protocol.abort_policy, self.session_id
                self.schedule = requeue_aborted(self.schedule, spec, spec.index + 1, policy, self._rng)
                sj = schedule_to_json(self.schedule)
                self.recorder.call(functools.partial(StudyDatabase.update_schedule, session_id=sid, schedule_json=sj))
                self.state.trials_total = len(self.schedule)

    def _handle_requests(self, t_ns: int) -> None:
        with self._lock:
            reqs, self._requests = self._requests, []
        with self.recorder.atomic():  # a request and what it changes (an abort, a session's end) are one commit
            self._apply_requests(reqs, t_ns)

    def _apply_requests(self, reqs: list[tuple[str, str, str, int | None]], t_ns: int) -> None:
        for kind, detail, cause, trial_index in reqs:
            if kind == "pause":
                self.paused = self.state.paused = True
                self._event(t_ns, "experimenter", "pause")
            elif kind == "resume":
                self.paused = self.state.paused = False
                self._event(t_ns, "experimenter", "resume")
            elif kind in ("abort_trial", "abort_session"):
                if trial_index is not None and self.trial_ended(trial_index):
                    self._event(t_ns, "experimenter", f"{kind} for {trial_words(trial_index)} ignored: it had ended")
                    continue
                self._event(t_ns, "experimenter", f"{kind}: {detail}")
                self._abort_running(t_ns, detail, cause, requeue=kind == "abort_trial")
                if kind == "abort_session":
                    self._end("aborted", detail, t_ns)
                    return

    def _end(self, status: str, reason: str, t_ns: int) -> None:
        self._enter_pause_commands()
        self.submit(StopRecording())
        sid = self.session_id
        with self.recorder.atomic():
            self._event(t_ns, "session_end", f"{status}: {reason}")
            self.recorder.call(lambda db: db.end_session(sid, status, reason))
        self.done = self.state.done = True
        self.status = self.state.status = status
        self._emit(("session_end", status, reason))


def first_unfinished(schedule: list[TrialSpec], trial_rows: list[dict[str, Any]]) -> int:
    """Schedule position of the first trial with no stored row (where a resume continues)."""
    stored = {r["trial_index"] for r in trial_rows}
    for i, spec in enumerate(schedule):
        if spec.index not in stored:
            return i
    return len(schedule)
