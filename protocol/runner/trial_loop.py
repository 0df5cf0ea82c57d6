"""The trials of a session over its task: the pure trial machine, the schedule and where it is, each trial's cue,
its end and its record.

:class:`TrialLoop` feeds the loop's records to the trial machine (:class:`protocol.study.trial.TrialMachine`, pure:
no I/O, no clock), which asks the session's task (:mod:`protocol.tasks`) when a trial succeeded and what it measured;
the loop acts on what the machine says: stores each phase change, makes the finished trial's
:class:`protocol.study.records.TrialRecord` and hands it to the recorder and the listeners.  At a cue it switches the
loop to the trial's condition (feedback per the trial's mode, the bias estimator frozen, the trial's mark) and tells
the simulated participant, if any, what the task asks (:meth:`protocol.tasks.base.Task.aim`).

**A trial's state changes commit in one transaction**: its row and its end's events (and, for an aborted trial, the
schedule with its re-run: else a crash between them could leave an aborted trial never re-run, its cell one short).

Abort policy: an aborted trial is stored with outcome ``aborted``, its reason and its cause, and re-run later --
appended at the end of the schedule (``append``, the default) or re-inserted at a random later position
(``reinsert``) -- so every target × mode cell still gets its full count of completed trials.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable

import numpy as np

from pipeline.core.aim import TrialParticipant
from pipeline.runtime.loop_messages import AllowBiasRefinement, Mark, SetHaptics
from protocol.runner.deliveries import Deliveries
from protocol.runner.session_desk import SessionDesk, SessionPlan, trial_words
from protocol.runner.trial_stimuli import TrialStimuli
from protocol.storage import StudyDatabase
from protocol.storage.trial_answers import insert_answer
from protocol.study.design import HapticMode, TrialSpec, requeue_aborted, schedule_to_json
from protocol.study.records import AbortCause, Outcome, TrialRecord
from protocol.study.trial import PHASE_CODES, RUNNING, PhaseChanged, TrialFinished, TrialMachine, TrialPhase

__all__ = ["TrialLoop"]


class TrialLoop:
    """One session's trials over its task, from its plan's start position to the end of its schedule.

    Parameters
    ----------
    plan
        The session's protocol (its task and timing), schedule, start position, seed and training aid.
    desk
        The session's clock, events, commands, progress and listeners.
    deliveries
        What the loop delivered to each trial (records, health, abort causes).
    participant, participant_time
        A simulated participant to tell each trial's aim and end, and its clock (None: a person).
    """

    def __init__(self, plan: SessionPlan, desk: SessionDesk, deliveries: Deliveries,
                 participant: TrialParticipant | None = None,
                 participant_time: Callable[[], float] | None = None) -> None:
        protocol = plan.protocol
        self.protocol, self.task = protocol, protocol.task
        self.desk, self.deliveries = desk, deliveries
        self.machine = TrialMachine(protocol.trial, protocol.task)
        self.schedule = list(plan.schedule)
        #: The next schedule position to run.
        self.position = plan.start_position
        self.segment = plan.segment
        self.participant = participant
        self.participant_time = participant_time or (lambda: 0.0)
        #: Training: the participant sees the task's training aid (a live force gauge with the target band).
        self.live_force_aid = plan.live_force_aid
        #: The trials finished in this run, in order.
        self.finished: list[TrialRecord] = []
        self._rng = np.random.default_rng([plan.seed, plan.session_id, 7])
        #: A task that presents a force and asks about it: each trial's stimulus and answer.
        self.stimuli = TrialStimuli(protocol.task, plan.seed, plan.session_id, plan.trial_answers, desk.submit,
                                    participant)

    @property
    def running(self) -> TrialSpec | None:
        """The trial that is cued or running (None between trials)."""
        m = self.machine
        return m.spec if m.phase in RUNNING else None

    def feed(self, rows: np.ndarray) -> None:
        """The trial machine over records that need no abort; each trial's end is committed as one transaction."""
        m = self.machine
        spec = m.spec
        running = m.phase in RUNNING
        t_ns_all = rows["t_ns"]
        if spec is not None and running:
            self.stimuli.note(rows, spec.index)
        events: list[PhaseChanged | TrialFinished] = m.feed(
            zip(t_ns_all.tolist(), rows["force_n"].tolist(), rows["trial_index"].tolist(), strict=True))
        if spec is not None and m.phase is TrialPhase.ANSWER and m.cue_ns is not None:
            key = self.stimuli.simulated_answer(spec, m.cue_ns)  # a simulated participant answers at once
            if key is not None:
                events.extend(m.answer(int(t_ns_all[-1]), key))
        if spec is not None and running:
            # only a running trial's records are its samples (records after an abort still carry its mark)
            ended = next((e for e in events if isinstance(e, TrialFinished)), None)
            self.deliveries.window.note_trial(rows, t_ns_all, spec.index, m.cue_ns, ended)
        with self.desk.recorder.atomic():  # a trial's end is one state change: its row and its end's events
            for ev in events:
                self._on_event(ev)
        if m.phase is TrialPhase.ACTIVE:
            self.desk.state.trial_elapsed_s = m.elapsed_ns * 1e-9

    def cue(self, t_ns: int) -> None:
        """Cue the trial at the schedule's position: the loop switched to its condition, the participant told."""
        spec = self.schedule[self.position]
        self.machine.start(spec, t_ns)
        st = self.desk.state
        st.current = spec
        st.trial_position = self.position + 1
        st.trials_total = len(self.schedule)
        st.phase = "cued"
        self.desk.event(t_ns, "cue", f"{trial_words(spec.index)}: {self.task.cue_text(spec)}, "
                                     f"haptics {spec.haptic_mode}")
        submit = self.desk.submit
        submit(AllowBiasRefinement(False))
        submit(SetHaptics(spec.haptic_mode is HapticMode.ON))
        submit(Mark(spec.index, PHASE_CODES[TrialPhase.ACTIVE]))
        self.stimuli.cue(spec)  # (after the mark: the same tick applies both)
        if self.participant is not None:
            self.participant.begin_trial(self.task.aim(spec, self.live_force_aid), self.participant_time())

    def answer(self, t_ns: int, key: str) -> str:
        """A person's answer to the running trial's question, at ``t_ns``; "" when taken, else why not (no
        question open: the answer came before it was asked, or after the trial ended)."""
        m = self.machine
        if m.phase is not TrialPhase.ANSWER:
            return f"answer {key!r} ignored: no question is open ({m.phase})"
        with self.desk.recorder.atomic():
            for ev in m.answer(t_ns, key):
                self._on_event(ev)
        return ""

    def abort(self, t_ns: int, reason: str, cause: AbortCause | str, requeue: bool = True) -> None:
        """Abort the trial that is cued or running (if any), storing its cause; re-queue it per the policy."""
        m = self.machine
        if m.phase not in RUNNING:
            return
        spec = m.spec
        assert spec is not None
        self.deliveries.aborting(spec.index, cause)
        recorder = self.desk.recorder
        # one transaction: the row, its end's events and the schedule with its re-run
        with recorder.atomic():
            for ev in m.abort(t_ns, reason):
                self._on_event(ev)
            if requeue:
                policy, sid = self.protocol.abort_policy, self.desk.session_id
                self.schedule = requeue_aborted(self.schedule, spec, spec.index + 1, policy, self._rng)
                sj = schedule_to_json(self.schedule)
                recorder.call(functools.partial(StudyDatabase.update_schedule, session_id=sid, schedule_json=sj))
                self.desk.state.trials_total = len(self.schedule)

    def _on_event(self, ev: object) -> None:
        desk = self.desk
        if isinstance(ev, PhaseChanged):
            desk.state.phase = str(ev.new)
            desk.event(ev.t_ns, "phase", f"{trial_words(ev.trial_index)}: {ev.old} -> {ev.new}")
            desk.emit(ev)
        elif isinstance(ev, TrialFinished):
            desk.emit(self._finish(ev))

    def _finish(self, ev: TrialFinished) -> TrialRecord:
        """Store the trial that ended and count it; its record (what the listeners get)."""
        spec, desk = ev.spec, self.desk
        ticks, health = self.deliveries.window.take()
        aborted = ev.outcome is Outcome.ABORTED
        cause = self.deliveries.settle(spec.index, aborted)
        assert desk.clock is not None  # a trial ends only on a record
        record = TrialRecord.finished(
            session_id=desk.session_id, spec=spec, outcome=ev.outcome, clock=desk.clock, cue_ns=ev.cue_ns,
            end_ns=ev.end_ns, metrics=ev.metrics, reason=ev.reason, cause=cause, health=health,
            segment=self.segment, ticks=ticks,
        )
        desk.recorder.trial(record)
        answer = self.stimuli.finished(ev, desk.time_s(ev.end_ns))
        if answer is not None:  # in the trial's transaction; the listeners see it on the record
            desk.recorder.call(lambda db: insert_answer(db.conn, answer))
            correct = answer.values.get("correct", math.nan)
            record = dataclasses.replace(record, answer=answer.answer,
                                         answer_correct=correct == 1.0 if math.isfinite(correct) else None)
        desk.mark(ev.end_ns, ev.outcome.value, ev.reason, spec)
        self.finished.append(record)
        st = desk.state
        if aborted:
            st.aborted += 1
        else:
            st.completed += 1
            st.successes += record.success
        desk.rest()
        if self.participant is not None:
            self.participant.end_trial(self.participant_time())
        self.position = spec.index + 1
        return record
