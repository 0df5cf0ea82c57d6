"""The session runner: walks the schedule over the haptic loop.

It reads the loop's records (from the ring buffer) and acts on what happens, through its parts, each with one job:

* the trials over the session's task (:mod:`protocol.runner.trial_loop`): the pure trial machine, the cue (the
  trial's condition switched on, its mark stamped into the samples, the simulated participant told what the task
  asks), each finished trial's record;
* what the loop delivered to them (:mod:`protocol.runner.deliveries`): **a trial counts only if it ran under its
  designed condition** -- the runner aborts it at the first record where the loop did not deliver it as designed
  (:mod:`protocol.study.delivery`);
* the fault waiting and reset policy (:mod:`protocol.runner.fault_wait`): every loop event stored, no cue while a
  fault is latched, the protocol's pause again once it is cleared; headless, the reset and the timeout that stops the
  session as *interrupted* (resumable later) with a one-line :attr:`SessionRunner.stop_reason`;
* the experimenter's requests (:mod:`protocol.runner.requests`): :meth:`SessionRunner.pause`, :meth:`resume`,
  :meth:`abort_trial` and :meth:`abort_session` may come from any thread; they take effect at the next
  ``process`` call, at that block's sample time;
* the session's clock, events, progress, listeners and end, which all of them share
  (:mod:`protocol.runner.session_desk`).

It has no thread and no clock of its own: :meth:`SessionRunner.process` is called with each new block of records,
by the headless driver on the virtual clock or by a thread polling the ring in a live session.

Abort policy: an aborted trial is stored with outcome ``aborted``, its reason and its cause (``trials.abort_cause``),
and re-run later per the protocol's ``abort_policy`` (:mod:`protocol.runner.trial_loop`).  Aborting the session
aborts the current trial without re-queueing it and ends the session with status ``aborted``.

A finished trial is one :class:`protocol.study.records.TrialRecord`: stored by the recorder and handed to the runner's
listeners as it is.

**The whole session is recorded** (:mod:`protocol.recording`): the runner asks the loop for a snapshot of the framework
(:class:`pipeline.runtime.loop.StartRecording`) and, from the tick it was taken on, hands every record and the loop's
replay log to the recorder -- trials, pauses and waits alike -- so the session can be replayed through the pipeline
(:mod:`pipeline.force.replay`; the hand-off is :mod:`protocol.runner.session_recording`).  Records before that tick
(the loop ran before the session began) are not the session's.  A trial row names its records: ``segment``,
``first_tick`` (its cue) and ``last_tick``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from pipeline.core.aim import TrialParticipant
from pipeline.devices.interfaces import Fault
from pipeline.runtime.loop_messages import Command, LoopEvent, StartRecording
from protocol.lsl.streams import SessionStreams
from protocol.runner.deliveries import Deliveries
from protocol.runner.fault_wait import FaultWait
from protocol.runner.feedback_wait import FeedbackWait
from protocol.runner.questionnaire_wait import QuestionnaireWait
from protocol.runner.requests import Request, Requests
from protocol.runner.session_desk import SessionDesk, SessionPlan, SessionState, trial_words
from protocol.runner.session_recording import OtherArms, SessionRecording
from protocol.runner.trial_loop import TrialLoop
from protocol.storage import Recorder
from protocol.storage.annotations import Note, insert_note
from protocol.study.clock import SessionClock
from protocol.study.delivery import DeliveryLimits
from protocol.study.design import TrialSpec
from protocol.study.records import AbortCause, TrialRecord
from protocol.study.trial import TrialMachine, TrialPhase

__all__ = ["SessionRunner", "first_unfinished"]


class SessionRunner:
    """Runs one session (training or experiment) from its stored schedule.

    Parameters
    ----------
    plan
        What this run follows: the session, its protocol and task, its schedule and where to start.
    recorder
        The database writer.
    submit
        Sends a command to the haptic loop.
    participant, participant_time
        Simulated participant to tell each trial's aim and end, and its clock (the rig's simulated time); None for
        a person.
    limits
        What the loop must deliver for a trial to count (:mod:`protocol.runner.deliveries`).
    auto_reset_faults
        Headless sessions: reset a latched fault in the pause once its condition is gone, and stop the session as
        interrupted if one is still latched (:mod:`protocol.runner.fault_wait`).  A person's session leaves the
        reset to the experimenter.
    scales
        Counts per unit of the raw wrench columns (the recording codec's hint; empty: store floats).
    """

    def __init__(
        self, plan: SessionPlan, recorder: Recorder, submit: Callable[[Command], None], *,
        participant: TrialParticipant | None = None, participant_time: Callable[[], float] | None = None,
        limits: DeliveryLimits | None = None, auto_reset_faults: bool = False, scales: dict[str, float] | None = None,
    ) -> None:
        self.plan = plan
        #: The rig's arms (() or one: events stored as ever) and the task arm, whose records the runner is given.
        self.arms = plan.arms
        self.task_arm = plan.protocol.task_arm_of(plan.arms) if plan.arms else ""
        self.session_id, self.recorder, self.submit = plan.session_id, recorder, submit
        self.desk = SessionDesk(recorder, plan.session_id, submit, plan.clock_offset_s,
                                SessionState(trials_total=len(plan.schedule)))
        self.state, self.listeners = self.desk.state, self.desk.listeners
        self.deliveries = Deliveries(limits or DeliveryLimits())
        self.trials = TrialLoop(plan, self.desk, self.deliveries, participant, participant_time)
        self.machine: TrialMachine = self.trials.machine
        self.faults = FaultWait(self.desk, plan.protocol.trial.pause_s, auto_reset_faults, plan.arms, self.task_arm)
        self.questions = QuestionnaireWait(self.desk, plan)
        self.feedback = FeedbackWait(self.desk, plan)
        self.requests = Requests()
        self._initial_pause_ns = int(round(plan.initial_pause_s * 1e9))
        self._ready_ns: int | None = None  # no cue before this loop time
        self.segment = plan.segment
        self._recording = SessionRecording(recorder, plan.session_id, plan.segment, scales)
        self.other_arms = OtherArms(self._recording)  # a rig of several arms: the others' records (session_driver)
        #: The run's LSL outlets and stream taps (None: the session publishes and records no stream).
        self.lsl: SessionStreams | None = None
        self.desk.rest()
        # after the pause commands: the snapshot is taken once they are applied, in the same tick
        self.submit(StartRecording(self._recording.token))

    def attach_lsl(self, streams: SessionStreams) -> None:
        """Publish this run's records and markers on ``streams`` (before its first record)."""
        self.lsl = streams
        self.desk.on_mark = streams.mark

    # -- what the displays and the drivers read ------------------------------------------------------------------
    @property
    def done(self) -> bool:
        """The session ended (completed, aborted or interrupted)."""
        return self.desk.done

    @property
    def status(self) -> str:
        """``running``, ``completed``, ``aborted`` or ``interrupted``."""
        return self.desk.status

    @property
    def paused(self) -> bool:
        """No cue until resumed."""
        return self.desk.paused

    @property
    def stop_reason(self) -> str:
        """Why the session stopped early as interrupted, else ""."""
        return self.desk.stop_reason

    @property
    def clock(self) -> SessionClock | None:
        """Session time of loop timestamps, from this run's first record on (None before it)."""
        return self.desk.clock

    @property
    def schedule(self) -> list[TrialSpec]:
        """The whole trial order, its re-runs included."""
        return self.trials.schedule

    @property
    def finished(self) -> list[TrialRecord]:
        """The trials finished in this run."""
        return self.trials.finished

    @property
    def running_trial(self) -> TrialSpec | None:
        """The trial that is cued or running (None between trials, paused or done)."""
        return self.trials.running

    def trial_ended(self, trial_index: int) -> bool:
        """Whether a request naming trial ``trial_index`` comes too late: that trial is not the one running.

        The one test of a late abort: a confirmation answered after its trial ended must never abort the next one
        (the engine refuses it at once, the runner ignores it when it applies the request).
        """
        spec = self.running_trial
        return spec is None or spec.index != trial_index

    def session_time_s(self, t_ns: int) -> float:
        """Session-clock time of a loop timestamp."""
        return self.desk.time_s(t_ns)

    # -- experimenter requests (any thread) ----------------------------------------------------------------------
    def pause(self) -> None:
        """Hold before the next trial (a running trial finishes first)."""
        self.requests.put(Request("pause"))

    def resume(self) -> None:
        """Continue after :meth:`pause`."""
        self.requests.put(Request("resume"))

    def abort_trial(self, reason: str = "aborted by the experimenter",
                    cause: AbortCause | str = AbortCause.EXPERIMENTER, trial_index: int | None = None) -> None:
        """Abort the running trial; it is re-queued per the protocol's abort policy.

        ``cause`` goes to ``trials.abort_cause`` (``experimenter``, or ``interrupted``
        when the controlling program is going away).  With ``trial_index`` the
        request applies to that trial only: if it has ended by the time the
        request is applied, nothing is aborted (a confirmation answered late
        never aborts the next trial).
        """
        self.requests.put(Request("abort_trial", reason, cause, trial_index))

    def abort_session(self, reason: str = "aborted by the experimenter") -> None:
        """Abort the running trial (not re-queued) and end the session."""
        self.requests.put(Request("abort_session", reason))

    def note(self, text: str, trial_index: int | None = None, deviation: bool = False) -> None:
        """Store the experimenter's note on the session (``trial_index`` None) or one of its trials, timestamped on
        the session clock when the next block is processed; ``deviation`` marks it one for the report.

        Raises ``ValueError`` (one line) for a note without text or a trial the session does not have.
        """
        if not text.strip():
            raise ValueError("note = '': a note needs its text")
        if trial_index is not None and not 0 <= trial_index < len(self.schedule):
            raise ValueError(f"note: trial {trial_index + 1}: the session has trials 1 to {len(self.schedule)}")
        self.requests.put(Request("note", text, trial_index=trial_index, deviation=deviation))

    def answer(self, questionnaire: str, block: str, answers: dict[str, float | str]) -> None:
        """The participant's answers to the questionnaire shown (:mod:`protocol.runner.questionnaire_wait`)."""
        self.requests.put(Request("answer", questionnaire, block, answers=tuple(answers.items())))

    def skip_questionnaire(self, questionnaire: str, block: str, reason: str = "") -> None:
        """The experimenter skips the questionnaire waiting for the participant: stored as skipped (a deviation, with
        ``reason``) at the next block, and the next cue no longer waits (:mod:`protocol.runner.questionnaire_wait`)."""
        self.requests.put(Request("skip_questionnaire", questionnaire, block, answers=(("reason", reason),)))

    def answer_trial(self, key: str) -> None:
        """The participant's answer to the running trial's question (a task that asks one: force discrimination's
        ``"1"``/``"2"``), taken at the next block; ``ValueError`` (one line) for a key the task does not allow."""
        keys = self.plan.protocol.task.answer_keys
        if key not in keys:
            raise ValueError(f"answer = {key!r}: the {self.plan.protocol.task.title} task's answers are "
                             f"{', '.join(repr(k) for k in keys) or 'none (it asks no question)'}")
        self.requests.put(Request("trial_answer", key))

    def records_lost(self, count: int) -> None:
        """The caller could not read ``count`` records (the ring lapped it): the running trial has a gap."""
        self.deliveries.lost(count)

    # -- the work ------------------------------------------------------------------------------------------------
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
        if self.done or (len(rows) == 0 and self.desk.clock is None):
            return
        clock = self.desk.clock if self.desk.clock is not None else self._open(rows, loop_events)
        t0 = clock.t0_ns
        for ev in loop_events:
            if ev.t_ns >= t0:  # (the loop's events from before the session are not its own)
                self.faults.store(ev)
        if len(rows) == 0:
            return
        self._recording.record(rows)
        if self.lsl is not None:
            self.lsl.samples(rows)
        self._apply_requests(int(rows["t_ns"][0]))
        if self.done:
            return
        if gap := self.deliveries.take_gap():
            self.trials.abort(int(rows["t_ns"][0]), f"gap: {gap}", AbortCause.GAP)
        self._cut_where_undelivered(rows)

    def _open(self, rows: np.ndarray, loop_events: Sequence[LoopEvent]) -> SessionClock:
        """This run's first records: the session clock starts, the recording's segment opens, the first cue waits."""
        t0 = int(rows["t_ns"][0])
        clock = self.desk.clock = SessionClock(self.desk.clock_offset_s, t0)
        self._recording.open_segment(self.desk.clock_offset_s, t0)
        self._ready_ns = t0 + self._initial_pause_ns
        self.desk.mark(t0, "session_start", f"session {self.session_id}, segment {self.segment}")
        first_faults = int(rows["faults"][0])
        if first_faults and not any(ev.t_ns >= t0 for ev in loop_events):
            self.desk.event(t0, "fault", f"{Fault(first_faults).describe()}: latched before the session started")
        return clock

    def _cut_where_undelivered(self, rows: np.ndarray) -> None:
        """The records in parts: up to where the running trial left its designed condition, the abort there, on."""
        while len(rows) and not self.done:
            cut = self.deliveries.deviation(rows, self.machine, self.faults.detail)
            if cut is None:
                self._process_part(rows)
                break
            i = cut.index
            self._process_part(rows[:i])
            spec = self.running_trial
            if not self.done and spec is not None and int(rows["trial_index"][i]) == spec.index:
                # the record that tripped the abort is the trial's last: its window and health show the cause
                self.deliveries.window.note(rows[i : i + 1])
                self.trials.abort(int(rows["t_ns"][i]), cut.reason, cut.cause)
            rows = rows[i:]

    def _process_part(self, rows: np.ndarray) -> None:
        """The trial machine, the samples and the next cue over records that need no abort."""
        if len(rows) == 0:
            return
        self.trials.feed(rows)
        t_last = int(rows["t_ns"][-1])
        self.faults.latched = int(rows["faults"][-1])
        if self.done or self.running_trial is not None:
            return
        ready = self.faults.between_trials(t_last)
        if ready is not None:
            self._ready_ns = max(self._ready_ns or 0, ready)
        if self.machine.phase is TrialPhase.IDLE and not self.done:
            self._start_next(t_last)

    def _start_next(self, t_ns: int) -> None:
        """The next cue, once nothing holds it: a pause, a latched fault, the protocol's pause, the trials failed."""
        if self.paused or self.faults.latched:
            return
        if self.deliveries.too_many_failed:
            self._too_many_failed(t_ns)
            return
        state = self.state
        if self._ready_ns is not None and t_ns < self._ready_ns:
            state.waiting = "pause"
            return
        if self.feedback.holds(t_ns, self.trials.position, self.trials.schedule, self.finished):
            return  # (the wait's words are the score card's)
        if self.questions.holds(t_ns, self.trials.position, self.trials.schedule):
            return  # (the wait's words are the questionnaire's)
        state.waiting = ""
        if self.trials.position >= len(self.trials.schedule):
            self.desk.end("completed", "all trials done", t_ns)
            return
        self.trials.cue(t_ns)

    def _too_many_failed(self, t_ns: int) -> None:
        """The loop failed several trials in a row: stop cueing (headless: interrupt; a person's session: pause)."""
        last = self.finished[-1]
        why = (f"{self.deliveries.failed_in_a_row} trials in a row were not delivered as designed (the last: "
               f"{last.abort_reason}); the rig or the machine cannot hold the designed condition")
        self.deliveries.failed_in_a_row = 0
        if self.faults.auto_reset:
            self.desk.interrupt(t_ns, f"{why}: the session is interrupted and can be resumed")
            return
        self.desk.set_paused(True)
        self.state.waiting = f"{why}: paused — check the machine's load and the devices, then Resume"
        self.desk.event(t_ns, "waiting", self.state.waiting)
        self.desk.emit(("paused", self.state.waiting))

    def _apply_requests(self, t_ns: int) -> None:
        """The requests queued since the last block, at its first sample time: each with what it changes (an
        abort, the session's end) is one commit."""
        requests = self.requests.take()
        with self.recorder.atomic():
            for r in requests:
                if r.kind in ("note", "answer", "skip_questionnaire"):
                    self._annotate(t_ns, r)
                    continue
                if r.kind == "trial_answer":
                    if why := self.trials.answer(t_ns, r.detail):
                        self.desk.event(t_ns, "answer", why)
                    continue
                if r.kind in ("pause", "resume"):
                    self.desk.set_paused(r.kind == "pause")
                    self.desk.event(t_ns, "experimenter", r.kind)
                    continue
                if r.trial_index is not None and self.trial_ended(r.trial_index):
                    self.desk.event(t_ns, "experimenter",
                                    f"{r.kind} for {trial_words(r.trial_index)} ignored: it had ended")
                    continue
                self.desk.event(t_ns, "experimenter", f"{r.kind}: {r.detail}")
                self.trials.abort(t_ns, r.detail, r.cause, requeue=r.kind == "abort_trial")
                if r.kind == "abort_session":
                    self.desk.end("aborted", r.detail, t_ns)
                    return


    def _annotate(self, t_ns: int, r: Request) -> None:
        """A note stored, or a questionnaire's answers or skip (the next cue after the protocol's pause)."""
        if r.kind == "note":
            note = Note(self.session_id, self.desk.time_s(t_ns), r.trial_index, r.detail, r.deviation, "")
            self.recorder.call(lambda db: insert_note(db.conn, note))
            return
        if r.kind == "skip_questionnaire":
            why = self.questions.skip(t_ns, r.detail, r.cause, str(dict(r.answers).get("reason", "")))
        else:
            why = self.questions.answer(t_ns, r.detail, r.cause, dict(r.answers))
        if why:
            self.desk.event(t_ns, "questionnaire", why)
            return
        self._ready_ns = max(self._ready_ns or 0, t_ns + int(round(self.plan.protocol.trial.pause_s * 1e9)))


def first_unfinished(schedule: list[TrialSpec], trial_rows: list[dict[str, Any]]) -> int:
    """Schedule position of the first trial with no stored row (where a resume continues)."""
    stored = {r["trial_index"] for r in trial_rows}
    for i, spec in enumerate(schedule):
        if spec.index not in stored:
            return i
    return len(schedule)
