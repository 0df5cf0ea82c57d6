"""The study engine's sessions: start, resume, run, rehearse a fault, end -- one at a time.

:class:`EngineSessions` belongs to a :class:`study_app.engine.host.StudyEngine`
and runs on its driver thread.  Sessions are opened and closed through
:mod:`protocol.runner.session_setup`, as the headless runner's are
(:mod:`study_app.headless`); what a session stores of the rig it ran on is
:mod:`study_app.engine.session_config`'s.
"""

from __future__ import annotations

import dataclasses
import gc
import json
import math
import os
import time
from collections.abc import Callable
from typing import Any

from foundation.platform_support.processes import kill_hard
from pipeline.force.config import FrameworkConfig
from protocol.runner.rehearsal import FAULT_KINDS, FaultPlan, RehearsalTrigger
from protocol.runner.session import SessionRunner
from protocol.runner.session_lsl import attach_lsl, detach_lsl, lsl_streams_of
from protocol.runner.session_setup import (
    OpenedSession,
    delivery_limits,
    finish_session,
    open_new_session,
    open_resumed_session,
    participant_seeds,
    raw_wrench_scales,
    rehearsal_note,
    start_runner,
    store_rehearsal_plan,
)
from protocol.runner.study_rules import (
    CALIBRATION_OVERRIDE_EVENT,
    check_arms,
    check_new_session,
    check_settings,
    stored_sessions,
)
from protocol.storage import Recorder, StorageError, StudyDatabase, StudyReader, validate_code
from protocol.storage.annotations import notes
from protocol.study.config import ProtocolConfig, load_protocol
from protocol.study.questionnaires import Prompt, checked_answers
from protocol.study.records import AbortCause, TrialRecord
from protocol.study.trial import PhaseChanged, TrialPhase
from study_app.engine import messages as m
from study_app.engine import session_list
from study_app.engine.commissioning import REST_MAX_FORCE_N, Commissioning
from study_app.engine.core import EngineCore
from study_app.engine.session_config import config_record, real_config_record, with_profile
from study_app.engine.setup import StylusControl
from study_app.engine.visit_start import check_visit_start

__all__ = ["EngineSessions", "list_resumable"]


class EngineSessions:
    """The session the study engine runs (at most one), its runner, recorder and database (driver thread only).

    Parameters
    ----------
    engine
        The engine whose loop the session's runner commands.
    commissioning
        The engine's commissioning chain: the real rig's gate before a start, and what it puts on record.
    """

    def __init__(self, engine: EngineCore, commissioning: Commissioning) -> None:
        self.engine = engine
        self.commissioning = commissioning
        self.runner: SessionRunner | None = None
        self.recorder: Recorder | None = None
        self.db: StudyDatabase | None = None
        self.opened: OpenedSession | None = None
        self.trigger: RehearsalTrigger | None = None
        self.session_code = ""
        #: Whether the participant screen is open where the participant sees it, as the GUI last said (None: its
        #: client never said; a script or a test has no participant screen).
        self.screen_open: bool | None = None
        self.screen_detail = ""

    @property
    def running(self) -> bool:
        """A session runs (not yet done)."""
        return self.runner is not None and not self.runner.done

    def start(self, cmd: m.StartSession) -> None:
        self.engine.require_idle("start")
        self._require_screen("start")
        validate_code(cmd.code)
        if cmd.kind not in ("training", "experiment"):
            raise ValueError(f"session kind = {cmd.kind!r}: allowed values are 'training' and 'experiment'")
        if cmd.seed < 0 or cmd.participant_number < 1:
            raise ValueError(f"seed = {cmd.seed}, participant number = {cmd.participant_number}: need seed ≥ 0 and "
                             "number ≥ 1")
        study = load_protocol(cmd.protocol_path or None)
        protocol = part_to_run(cmd, study)
        protocol.check_ramps(self.engine.eng.framework.config.safety, "protocol with the pipeline's settings")
        self._check_task_arm(protocol)
        _check_rules_first(cmd, protocol, self.engine.eng.framework.config, self._arms(), study)
        protocol, infos = self._lsl_of(protocol)
        if self.commissioning.gate.check(cmd):
            return
        db = self._open_db(cmd.db_path)
        try:
            record = self._config_record(participant_seeds(cmd.seed, cmd.participant_number)[1])
            if self.engine.eng.simulated:  # the simulated participant's profile, from its group (stored or given)
                from protocol.storage.annotations import covariates_by_code

                known = {**covariates_by_code(db.conn).get(cmd.code, {}), **cmd.covariates}
                record = with_profile(record, protocol.groups, known)
            opened = open_new_session(
                db, code=cmd.code, number=cmd.participant_number, kind=cmd.kind, protocol=protocol, seed=cmd.seed,
                rig=self.engine.config.rig,
                config={**record, "app": "gui", **self.commissioning.provenance()},
                calibration=self.engine.calibration.to_dict(), lease_owner=self.engine.lease_owner,
                note=f"{cmd.kind} session for {cmd.code}, seed {cmd.seed} (GUI)",
                training_override=cmd.training_override, covariates=cmd.covariates, events=cmd.events,
            )
        except BaseException:
            db.close()
            raise
        self._run(db, opened, infos)

    def _lsl_of(self, protocol: ProtocolConfig) -> tuple[ProtocolConfig, list[Any] | None]:
        """The protocol with the outlets on where the engine publishes (``gui --lsl``), and the external streams it
        records, found before anything is stored (one line naming a stream not found, or pylsl missing)."""
        if self.engine.config.lsl:
            protocol = dataclasses.replace(protocol, lsl=protocol.lsl.with_outlets())
        if not protocol.lsl.on:
            return protocol, None
        if self.engine.config.clock != "real":
            raise ValueError("[lsl]: a session on the Lab Streaming Layer needs the real clock (the virtual clock's "
                             "times are on no clock LSL shares)")
        return protocol, lsl_streams_of(protocol.lsl)

    def _commit_deadline(self) -> dict[str, Any]:
        """On the real clock, the recorder's deadline counts from the records' own ticks (the loop's clock, its
        ``perf_counter`` scale in this process too): a crash loses 100 ms of them at most, however late the ring was
        read.  On the virtual clock, the wall clock's 100 ms as before (the ticks run on another time)."""
        if self.engine.config.clock != "real":
            return {}
        return {"commit_clock": time.perf_counter, "dated": True}

    def _arms(self) -> tuple[str, ...]:
        """The rig's arms by name, the one whose ring is the session's (the task arm's) first."""
        return tuple(self.engine.eng.calibrations)

    def _check_task_arm(self, protocol: ProtocolConfig) -> None:
        """The protocol's task arm must be the arm whose ring the engine reads as the session's (its first)."""
        arms = self._arms()
        task = protocol.task_arm_of(arms)  # ProtocolError (a ValueError): one line naming the arm
        if task != arms[0]:
            hint = (f"restart the GUI with --sim-arms {','.join((task, *(a for a in arms if a != task)))}"
                    if self.engine.eng.simulated else "list it first in the hardware file")
            raise ValueError(f"design.task_arm = {task!r}: this rig's task arm is {arms[0]!r}, its first; {hint}")

    def _check_stored_arms(self, db: StudyDatabase, session_id: int) -> None:
        """A resumed session continues on the arms it ran on (its config_json's; none stored: one arm)."""
        info = StudyReader.over(db).session(session_id)
        stored = info.arms if info is not None else self._arms()
        if stored != self._arms():
            raise ValueError(f"resume: session {session_id} ran on the arms {', '.join(stored)}; this rig's are "
                             f"{', '.join(self._arms())} (restart the GUI with --sim-arms {','.join(stored)})")

    def _config_record(self, participant_seed: int) -> dict[str, Any]:
        if self.engine.eng.simulated:
            record = config_record(self.engine.eng, self.engine.config.clock, self.engine.config.rig_seed,
                                   participant_seed)
        else:
            assert self.engine.hardware is not None
            record = real_config_record(self.engine.hardware, self.engine.hardware_text, self.engine.eng)
        if self.engine.latency is not None:  # the real clock: the delay a participant feels, as it was at the start
            record["latency"] = self.engine.latency.latency().to_dict()
        return record

    def resume(self, cmd: m.ResumeSession) -> None:
        self.engine.require_idle("resume")
        self._require_screen("resume")
        if self.commissioning.gate.check(cmd):
            return
        db = self._open_db(cmd.db_path)
        try:
            self._check_stored_arms(db, cmd.session_id)
            check_settings([s for s in StudyReader.over(db).sessions() if s.session_id == cmd.session_id],
                           cmd.db_path, self.engine.eng.framework.config)  # a resume runs the pipeline it ran
            opened = open_resumed_session(db, cmd.session_id, lease_owner=self.engine.lease_owner,
                                          calibration=self.engine.calibration.to_dict())
        except BaseException:
            db.close()
            raise
        self._run(db, opened)

    def _run(self, db: StudyDatabase, opened: OpenedSession, lsl_infos: list[Any] | None = None) -> None:
        if self.engine.eng.simulated:
            from pipeline.sim.learning import Practice
            from pipeline.sim.participant import SimulatedParticipant  # the simulated rig only
            from protocol.storage.annotations import covariates_by_code
            from protocol.study.groups import simulated_profile

            # the participant's stored group decides the simulated profile, as in the headless runner
            profile = simulated_profile(opened.protocol.groups, covariates_by_code(db.conn).get(opened.code, {}))
            # in a schedule of visits it learns from visit to visit, as run's does (its stored visit: a resumed
            # session meets the same participant)
            self.engine.driver.install(SimulatedParticipant(seed=opened.participant_seed, profile=profile,
                                                            practice=Practice.at(opened.protocol.visit)))
            sim_rig = self.engine.eng.rig
            participant: StylusControl | None = self.engine.driver

            def sim_time_s() -> float:
                return float(sim_rig.sim_time_s)

            # the cues' time is the rig's own; in the loop's own process it is stamped there (RemoteDriver)
            participant_time: Callable[[], float] | None = sim_time_s if hasattr(sim_rig, "sim_time_s") else None
        else:  # a person holds the Touch: nothing to notify, nothing simulated
            participant, participant_time = None, None
        # a resumed session's table and progress start from what is stored (read before the recorder writes)
        stored = [TrialRecord.from_row(r) for r in db.trial_rows(opened.session_id)] if opened.resumed else []
        noted = [(n.trial_index, n.text, n.deviation) for n in notes(db.conn, [opened.session_id])]
        recorder, runner = start_runner(
            db, opened, submit=self.engine.loop.submit, participant=participant, participant_time=participant_time,
            limits=delivery_limits(self.engine.loop), auto_reset_faults=False, threaded=True,
            scales=raw_wrench_scales(self.engine.eng.rig.sensor), arms=self._arms(), **self._commit_deadline(),
        )
        runner.listeners.append(self._on_runner_event)
        if opened.protocol.lsl.on:  # (a resumed session finds its streams now)
            try:
                attach_lsl(runner, opened, self.engine.loop.t0_ns, lsl_infos)
            except BaseException:
                finish_session(db, recorder, opened)
                db.close()
                raise
        self.trigger = None
        self.db, self.recorder, self.runner, self.opened, self.session_code = db, recorder, runner, opened, opened.code
        override = self.commissioning.gate.take_override()
        if override is not None:
            missing, why, rest_n = override
            recorder.event(opened.session_id, opened.clock_offset_s, CALIBRATION_OVERRIDE_EVENT,
                           "started by the experimenter's override: "
                           f"{missing or 'the calibration chain was on record'}; the compensated force at rest was "
                           f"{rest_n:.3f} N (limit {REST_MAX_FORCE_N:g} N). Reason: {why}")
        if self.engine.config.clock == "real":
            gc.freeze()  # the session's long-lived objects: out of the collector's full passes (see host_main)
        tr = opened.protocol.trial
        self.engine.publish(m.SessionStarted(
            session_id=opened.session_id, code=opened.code, kind=opened.kind, trials_total=len(opened.schedule),
            start_position=opened.start_position, task=opened.protocol.task,
            max_trial_s=tr.max_trial_s, pause_s=tr.pause_s, cue_s=tr.cue_s, live_force_aid=opened.live_force_aid,
            schedule=[dataclasses.asdict(sp) for sp in opened.schedule],
            participant_number=opened.participant_number, stored_trials=stored, seed=opened.seed,
            stored_notes=noted,
        ))

    def control(self, cmd: m.Pause | m.Resume | m.AbortTrial | m.AbortSession) -> None:
        """Pause, resume, abort the running trial or the session -- each bound to what the experimenter confirmed."""
        runner = self.runner
        if runner is None or runner.done:
            raise RuntimeError("no session is running")
        if isinstance(cmd, m.Pause):
            runner.pause()
        elif isinstance(cmd, m.Resume):
            self._require_screen("resume")
            runner.resume()
        elif isinstance(cmd, m.AbortTrial):
            if cmd.trial_index is not None and runner.trial_ended(cmd.trial_index):
                # confirmed for a trial that has ended since: never abort the next one instead
                raise RuntimeError(f"trial {cmd.trial_index + 1} had already ended: nothing was aborted")
            if runner.running_trial is None:
                raise RuntimeError("no trial is running (between trials or paused)")
            if cmd.note.strip():  # the experimenter's words: a note on the trial, in the abort's transaction
                self.note(m.Note(f"reason for the abort: {cmd.note.strip()}", runner.running_trial.index))
            runner.abort_trial(cmd.reason, trial_index=cmd.trial_index)
        else:
            if cmd.session_id is not None and cmd.session_id != runner.session_id:
                raise RuntimeError(f"session {cmd.session_id} had already ended: nothing was aborted")
            runner.abort_session(cmd.reason)

    def note(self, cmd: m.Note) -> None:
        """The experimenter's note on the running session or one of its trials (stored at the next block)."""
        runner = self.runner
        if runner is None or runner.done:
            raise RuntimeError("note: no session is running (haptic-study note adds one to a stored session)")
        runner.note(cmd.text, cmd.trial_index, cmd.deviation)
        self.engine.publish(m.NoteStored(self.engine.last_t_ns * 1e-9, cmd.text.strip(), cmd.trial_index,
                                         cmd.deviation))

    def answer(self, cmd: m.AnswerQuestionnaire) -> None:
        """The participant's answers to the questionnaire on their screen: checked here (a refusal names the item),
        stored by the runner with the next block."""
        runner, asked = self._waiting(cmd, "answers to")
        checked_answers(asked.questionnaire, cmd.answers)  # a ValueError: one line naming the item
        runner.answer(cmd.questionnaire, cmd.block, dict(cmd.answers))

    def skip_questionnaire(self, cmd: m.SkipQuestionnaire) -> None:
        """The experimenter skips the questionnaire waiting for the participant: stored by the runner with the next
        block, as skipped (a deviation, with the reason)."""
        runner, _ = self._waiting(cmd, "skip")
        runner.skip_questionnaire(cmd.questionnaire, cmd.block, cmd.reason)

    def _waiting(self, cmd: m.AnswerQuestionnaire | m.SkipQuestionnaire, what: str) -> tuple[SessionRunner, Prompt]:
        """The running session and the questionnaire ``cmd`` names, the one waiting for answers (else a refusal in
        one line: ``what`` begins it)."""
        runner = self.runner
        if runner is None or runner.done or runner.session_id != cmd.session_id:
            raise RuntimeError(f"{what} {cmd.questionnaire}: session {cmd.session_id} is not running")
        asked = runner.questions.asked
        if asked is None or asked.key != (cmd.questionnaire, cmd.block):
            raise RuntimeError(f"{what} {cmd.questionnaire} ({cmd.block}): that questionnaire is not the one "
                               "waiting for answers")
        return runner, asked

    def answer_trial(self, cmd: m.AnswerTrial) -> None:
        """The participant's answer to the running trial's question: a key the task does not allow is refused in
        one line (``ValueError``); taken by the runner with the next block."""
        runner = self.runner
        if runner is None or runner.done or runner.session_id != cmd.session_id:
            raise RuntimeError(f"answer {cmd.key!r}: session {cmd.session_id} is not running")
        runner.answer_trial(cmd.key)

    def _require_screen(self, what: str) -> None:
        """No trial is cued to a participant screen that is closed: a start or resume is refused, saying why."""
        if self.screen_open is False:
            raise RuntimeError(f"{what}: the participant screen is {self.screen_detail or 'closed'}, so the "
                               "participant would not see the cue; open it (View → Participant screen, Ctrl+P)")

    def participant_screen(self, cmd: m.ParticipantScreenState) -> None:
        """The participant screen opened or closed.  Closed during a session: the running trial is aborted (cause
        ``participant_screen``, stored and run again later, as a trial a closed GUI cut is stored) and the session
        pauses, so no cue goes to a screen nobody sees; the event is stored."""
        was, self.screen_open, self.screen_detail = self.screen_open, cmd.open, cmd.detail
        runner, recorder = self.runner, self.recorder
        if cmd.open or was is False or runner is None or runner.done or recorder is None:
            return
        how = cmd.detail or "closed"
        spec = runner.running_trial
        if spec is not None:
            runner.abort_trial(f"the participant screen was {how} during the trial: the participant could not see "
                               "the cue", cause=AbortCause.PARTICIPANT_SCREEN, trial_index=spec.index)
        runner.pause()
        cut = f"trial {spec.index + 1} is stored as aborted and run again later" if spec is not None else \
            "no trial was running"
        recorder.event(runner.session_id, runner.session_time_s(self.engine.last_t_ns), "participant_screen",
                       f"the participant screen was {how}: {cut}; the session pauses until the screen is open "
                       "and the experimenter resumes")

    def list_sessions(self, cmd: m.ListSessions) -> None:
        """Publish a database's interrupted sessions, every session it holds and who withdrew (read-only)."""
        self.engine.publish(m.SessionsListed(cmd.db_path, list_resumable(cmd.db_path),
                                             session_list.list_sessions(cmd.db_path, check=False),
                                             session_list.list_withdrawn(cmd.db_path),
                                             session_list.list_covariates(cmd.db_path)))

    def inject_fault(self, cmd: m.InjectFault) -> None:
        if not self.engine.eng.simulated:
            raise RuntimeError("fault rehearsal: refused on the real rig (a person's hand is on it); "
                               "rehearse on the simulated rig")
        if cmd.kind not in FAULT_KINDS:
            raise ValueError(f"fault kind = {cmd.kind!r}: allowed values are {', '.join(FAULT_KINDS)}")
        if not (math.isfinite(cmd.seconds) and 0 <= cmd.seconds <= 600):
            raise ValueError(f"fault seconds = {cmd.seconds!r}: must be a number from 0 to 600")
        if cmd.trial is None:
            rig, loop = self.engine.eng.rig, self.engine.loop
            now_ns = loop.clock.now_ns()
            live = self.runner if self.runner is not None and not self.runner.done else None
            if cmd.kind == "kill":
                if live is not None:  # the record says the engine's death was a rehearsal, and when it came
                    _store_kill(live, "kill now", now_ns - loop.t0_ns)
                kill_hard(os.getpid())  # as a crash would: the GUI sees the engine die
            rig.inject_fault(cmd.kind, now_ns)
            if live is not None:  # in a session: its record says it was rehearsed
                rehearsal_note(live)(now_ns - loop.t0_ns,
                                     f"{cmd.kind}: rehearsed on the simulated rig (not a device failure), now")
            self.engine.publish(m.FaultInjected(cmd.kind, "now"))
            return
        runner, opened = self.runner, self.opened
        if runner is None or runner.done or opened is None:
            raise RuntimeError("fault rehearsal at a trial: start or resume a session first (or inject it now)")
        n, begun = len(runner.schedule), runner.state.trial_position
        later = (f"the trials still to come are {begun + 1} to {n}" if begun + 1 < n
                 else f"the one still to come is trial {n}" if begun + 1 == n
                 else f"every trial of this session has begun (all {n}); inject it now instead")
        if cmd.trial < 1 or cmd.trial > n:
            raise ValueError(f"fault trial = {cmd.trial}: the session has trials 1 to {n}; {later}")
        if cmd.trial <= begun:
            raise ValueError(f"fault trial = {cmd.trial}: trial {cmd.trial} has already begun; {later}")
        plan = FaultPlan(cmd.kind, opened.code, cmd.trial, cmd.seconds, opened.kind)
        eng = self.engine.eng

        def inject(kind: str, at_ns: int) -> None:
            eng.rig.inject_fault(kind, eng.loop.t0_ns + at_ns)

        def kill() -> None:
            _store_kill(runner, str(plan), eng.loop.clock.now_ns() - eng.loop.t0_ns)
            kill_hard(os.getpid())

        def cancel(kind: str, at_ns: int) -> None:
            eng.rig.cancel_fault(kind, eng.loop.t0_ns + at_ns)

        from pipeline.sim.faults import latch_delay_s  # the simulated rig only

        wd = eng.loop.watchdog
        trig = RehearsalTrigger.for_session(
            [plan], opened.code, opened.kind, runner.state.trial_position, inject, kill, cancel,
            max_trial_s=opened.protocol.trial.max_trial_s,  # moved to land in its trial, or withdrawn, and said so
            latch_s=lambda kind: latch_delay_s(kind, wd.sensor_max_age_s, wd.pose_max_age_s),
            note=rehearsal_note(runner))
        store_rehearsal_plan(runner, plan, eng.loop.clock.now_ns() - eng.loop.t0_ns)  # committed now (a kill)
        if self.trigger is not None:  # keep what was planned before
            trig._pending.extend(self.trigger._pending)
        else:
            runner.listeners.append(lambda ev: self.trigger.on_runner_event(ev) if self.trigger else None)
        self.trigger = trig
        self.engine.publish(m.FaultInjected(cmd.kind, f"trial {cmd.trial} + {cmd.seconds:g} s"))

    def _on_runner_event(self, ev: object) -> None:
        runner = self.runner
        if runner is None:
            return
        if isinstance(ev, PhaseChanged):
            t_s = ev.t_ns * 1e-9
            if ev.new is TrialPhase.ACTIVE and runner.machine.spec is not None:
                spec = runner.machine.spec
                self.engine.publish(m.TrialStarted(
                    t_s, spec.index, runner.state.trial_position, runner.state.trials_total, spec.target_label,
                    spec.target_force_n, spec.haptic_mode, spec.repeat_of,
                ))
            self.engine.publish(m.PhaseEntered(t_s, ev.trial_index, str(ev.new)))
        elif isinstance(ev, tuple) and ev[:1] == ("score_card",):
            self.engine.publish(m.ScoreCardShown(runner.session_id, ev[1].block, ev[1].lines()))
        elif isinstance(ev, tuple) and ev[:1] in (("questionnaire",), ("questionnaire_answered",),
                                                  ("questionnaire_skipped",)):
            prompt = ev[1]
            self.engine.publish(m.QuestionnaireShown(runner.session_id, prompt.questionnaire, prompt.block)
                                if ev[0] == "questionnaire" else
                                m.QuestionnaireAnswered(runner.session_id, prompt.key[0], prompt.key[1],
                                                        skipped=ev[0] == "questionnaire_skipped"))
        elif isinstance(ev, TrialRecord):
            cause = ev.abort_cause
            if cause in (AbortCause.GAP, AbortCause.FEEDBACK):  # not a watchdog fault, so the loop said nothing
                self.engine.publish(m.EngineFault(ev.end_ns * 1e-9, cause.value, int(self.engine.loop.faults),
                                                  ev.abort_reason or "", ev.ended_at_s))
            self.engine.publish(m.TrialEnded(ev.end_ns * 1e-9, ev, runner.state.trials_total))

    def end(self, status: str, reason: str) -> None:
        runner, recorder, db, opened = self.runner, self.recorder, self.db, self.opened
        assert runner is not None and recorder is not None and db is not None and opened is not None
        self.runner = self.recorder = self.db = self.opened = None
        self.trigger = None
        self.engine.driver.install(None)
        error = ""
        try:
            detach_lsl(runner)
            finish_session(db, recorder, opened)
        except StorageError as exc:
            error = str(exc)
        finally:
            db.close()
        st = runner.state
        self.engine.publish(m.SessionEnded(runner.session_id, status, reason or error, st.completed, st.aborted,
                                           st.successes))

    def _open_db(self, path: str) -> StudyDatabase:
        if not path:
            raise StorageError("study database: no file given")
        return StudyDatabase(path)


def _store_kill(runner: SessionRunner, what: str, t_ns: int) -> None:
    """The record says, committed before the engine dies, that its death is the rehearsal ``what`` and when it came
    (the plan stored earlier says only that it was planned)."""
    rehearsal_note(runner)(t_ns, f"{what}: the engine process is killed now, as a crash would kill it -- a rehearsal "
                                 "on the simulated rig, not a crash or a device failure; the session is left "
                                 "interrupted here, to be resumed")
    runner.recorder.flush()


def part_to_run(cmd: m.StartSession, protocol: ProtocolConfig) -> ProtocolConfig:
    """The protocol a new session runs: in a study of several parts, the part ``cmd.part`` in the participant's
    order (of the kind ``cmd.kind``); refused in one line otherwise."""
    if not protocol.parts:
        if cmd.part:
            raise ValueError(f"part = {cmd.part!r}: the protocol has no parts (a study of one task)")
        return protocol
    try:  # in a schedule of visits, the part of the visit ``cmd.visit``
        part = protocol.part_of(cmd.part, cmd.participant_number, cmd.seed, cmd.visit)
    except KeyError as exc:
        raise ValueError(f"part = {cmd.part!r}: {exc.args[0]}") from None
    assert part.part is not None
    if part.part.session != cmd.kind:
        raise ValueError(f"part = {cmd.part!r} is a {part.part.session} part, not {cmd.kind}")
    return part


def _check_rules_first(cmd: m.StartSession, protocol: ProtocolConfig, framework: FrameworkConfig,
                       arms: tuple[str, ...], study: ProtocolConfig) -> None:
    """The study's rules on a read-only look, before the real rig's 2 s rest check (they are applied again,
    where the session is stored, by :func:`protocol.runner.session_setup.open_new_session`), one pipeline per study
    (``gui --set``: the settings every stored session ran with) and one rig per study (``arms``, the task arm
    first: the arms every stored session ran on, as ``run`` requires) and, in a schedule of visits, the visit's rule
    (:func:`study_app.engine.visit_start.check_visit_start`; ``study``: the whole protocol)."""
    if not cmd.db_path or not os.path.isfile(cmd.db_path) or os.path.getsize(cmd.db_path) == 0:
        check_visit_start(cmd, study, [], [])
        return
    db = StudyDatabase(cmd.db_path, readonly=True)
    try:
        sessions = StudyReader.over(db).sessions()
        check_settings(sessions, cmd.db_path, framework)
        check_arms(sessions, cmd.db_path, arms)
        if not [s for s in db.sessions_of(cmd.code, cmd.kind) if s.part == cmd.part and s.visit == cmd.visit]:
            check_new_session(stored_sessions(db), code=cmd.code, kind=cmd.kind, seed=cmd.seed, protocol=protocol,
                              training_override=cmd.training_override)
        check_visit_start(cmd, study, stored_sessions(db), sessions)
    finally:
        db.close()


def list_resumable(db_path: str) -> list[dict[str, Any]]:
    """Interrupted sessions of a database (none if the file does not exist yet)."""
    if not db_path or not os.path.exists(db_path):
        return []
    db = StudyDatabase(db_path, readonly=True)
    try:
        out = []
        busy = db.sessions_being_written()
        reader = StudyReader.over(db)
        for s in db.open_sessions():
            if s.session_id in busy:
                continue  # another process runs it right now: not interrupted
            info = reader.session(s.session_id)
            schedule = json.loads(s.schedule_json)
            rows = db.trial_rows(s.session_id)
            outcomes = [r["outcome"] for r in rows]
            aborted = sum(o == "aborted" for o in outcomes)
            out.append({
                "session_id": s.session_id, "code": s.code, "kind": s.kind, "started_at": s.started_at,
                # counted as everywhere (study_app.models.session.TrialCount): designed trials done, aborted attempts
                "trials_planned": sum(1 for t in schedule if t.get("repeat_of") is None),
                "trials_done": len(outcomes) - aborted, "trials_aborted": aborted, "trials_total": len(schedule),
                "reruns_run": sum(r["repeat_of"] is not None for r in rows),
                "arms": list(info.arms) if info is not None else [],  # the task arm first: resumed on these only
                "part": s.part,  # a study of several parts: which part it is
                "visit": s.visit,  # a schedule of visits: which visit it belongs to
            })
        return out
    finally:
        db.close()
