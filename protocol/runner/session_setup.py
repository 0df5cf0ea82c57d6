"""Opening a session: the one way in for the headless study runner and the GUI's study engine.

Starting or resuming a session is always the same sequence, whoever drives it:

1. **own it** -- take the session's lease (:meth:`protocol.storage.StudyDatabase.acquire_lease`)
   so no other process can write to it; a new session takes it in the very
   transaction that creates it;
2. **store it** -- a new session is stored with its whole schedule and
   provenance before its first trial; a resumed one first closes the books on
   the trial the previous run left half-done (:func:`open_resumed_session`);
3. **run it** -- a :class:`protocol.storage.Recorder` and a :class:`protocol.runner.session.SessionRunner`
   over the loop (:func:`start_runner`);
4. **give it back** -- :func:`finish_session` commits what is pending and releases the lease.

**A resume keeps the true timeline.**  The trial that was running when the
previous run ended keeps its real cue time and the samples it had (stored
as ``aborted``, cause ``interrupted``, with its metrics over those samples)
and is re-run per the abort policy; the session clock continues from the
last stored moment (event, trial end or sample), and the resumed session
begins with the protocol's pause before its next cue.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from foundation.version import software_provenance
from pipeline.core.aim import TrialParticipant
from pipeline.runtime.loop_messages import Command
from pipeline.runtime.loop_view import LoopView
from protocol.metrics import stored
from protocol.runner.feedback_wait import cards_shown, earlier_trials
from protocol.runner.session import SessionRunner, first_unfinished
from protocol.runner.session_desk import SessionPlan, trial_words
from protocol.runner.study_rules import DEVIATION_EVENT, FAULT_REHEARSAL_EVENT, check_new_session, stored_sessions
from protocol.storage import Recorder, SessionInfo, StorageError, StudyDatabase, StudyReader, session_scope
from protocol.storage.annotations import answered_blocks
from protocol.storage.damage import recording_damage
from protocol.storage.recordings import marked_records
from protocol.storage.trial_answers import trial_answers
from protocol.study.clock import SessionClock
from protocol.study.config import ProtocolConfig, protocol_from_dict
from protocol.study.covariates import checked_values
from protocol.study.delivery import DeliveryLimits
from protocol.study.design import (
    HapticMode,
    TrialSpec,
    build_schedule,
    requeue_aborted,
    schedule_from_json,
    schedule_to_json,
)
from protocol.study.records import AbortCause, Outcome, TrialRecord, trial_id_of
from protocol.tasks.base import Answered

__all__ = [
    "OpenedSession",
    "delivery_limits",
    "finish_session",
    "open_new_session",
    "open_resumed_session",
    "participant_seeds",
    "raw_wrench_scales",
    "refuse_damaged_recording",
    "rehearsal_note",
    "start_runner",
    "store_rehearsal_plan",
    "training_protocol",
    "training_schedule",
]

#: Session time between the last stored moment of an interrupted run and the resumed run's first record.
RESUME_STEP_S = 0.001


def participant_code(number: int) -> str:
    """Pseudonymous code of the n-th simulated participant (P01, P02, …)."""
    return f"P{number:02d}"


def participant_seeds(study_seed: int, number: int) -> tuple[int, int]:
    """(rig seed, participant seed) for a participant: independent streams from one study seed."""
    s = np.random.SeedSequence([study_seed, number]).generate_state(2)
    return int(s[0]), int(s[1])


def training_schedule(protocol: ProtocolConfig) -> list[TrialSpec]:
    """Free practice: each mode in turn, each target once, with the live force aid."""
    out: list[TrialSpec] = []
    for m in protocol.modes:
        for t in protocol.targets:
            out.append(TrialSpec(len(out), t.label, t.force_n, HapticMode(m)))
    return out


def training_protocol(protocol: ProtocolConfig) -> ProtocolConfig:
    """The protocol a training session runs (and stores): trials last the training's time per target and mode, and
    no questionnaire is asked (they ask about the experiment's conditions)."""
    return dataclasses.replace(
        protocol, trial=dataclasses.replace(protocol.trial, max_trial_s=protocol.training.seconds_per_target_per_mode),
        questionnaires=(),
    )


@dataclass(frozen=True)
class OpenedSession:
    """A session this process owns and may run: what the runner and the displays need.

    Attributes
    ----------
    session_id, code, kind, seed, participant_number
        The stored session.
    protocol
        The protocol the session runs (a training session's own, see :func:`training_protocol`).
    schedule
        The whole trial order, as stored.
    start_position
        First schedule position to run.
    clock_offset_s
        Session-clock time of the runner's first record.
    initial_pause_s
        Hold before the first cue (a resumed session begins with the protocol's pause).
    live_force_aid
        Training with the participant's live force gauge.
    lease_owner
        The lease token this process holds the session under.
    segment
        The recording's segment this run writes (:mod:`protocol.recording`): 0, then one more per resume.
    resumed
        Continues an interrupted session.
    notes
        What happened on the way in that the caller may want to show (a lease taken over, an interrupted trial).
    """

    session_id: int
    code: str
    kind: str
    seed: int
    participant_number: int
    protocol: ProtocolConfig
    schedule: list[TrialSpec]
    start_position: int
    clock_offset_s: float
    initial_pause_s: float
    live_force_aid: bool
    lease_owner: str
    resumed: bool
    notes: list[str] = field(default_factory=list)
    segment: int = 0
    #: The questionnaires (name, block) the session has answers of (a resume asks them not again).
    answered: tuple[tuple[str, str], ...] = ()
    #: The trials answered so far (a task that asks: its procedure continues from them).
    trial_answers: tuple[Answered, ...] = ()
    #: The participant's earlier trials a score card compares with, and the blocks shown a card
    #: (:mod:`protocol.runner.feedback_wait`; read only where the protocol allows feedback).
    earlier: tuple[tuple[int, str, dict[str, Any], str], ...] = ()
    cards_shown: tuple[str, ...] = ()

    @property
    def participant_seed(self) -> int:
        """Seed of the simulated participant of this session's participant number."""
        return participant_seeds(self.seed, self.participant_number)[1]

    def plan(self, arms: tuple[str, ...] = (), simulated_answers: bool = False) -> SessionPlan:
        """What the session runner follows in this run, on a rig whose arms are ``arms``; the questionnaires
        answered by the simulated participant of this number (``simulated_answers``), or by a person."""
        return SessionPlan(
            session_id=self.session_id, protocol=self.protocol, schedule=self.schedule,
            start_position=self.start_position, clock_offset_s=self.clock_offset_s,
            initial_pause_s=self.initial_pause_s, segment=self.segment, seed=self.seed,
            live_force_aid=self.live_force_aid, arms=arms, answered=self.answered,
            answers_seed=self.participant_seed if simulated_answers else None, trial_answers=self.trial_answers,
            score_cards=self.protocol.feedback.in_session(self.kind), earlier=self.earlier,
            cards_shown=self.cards_shown,
        )


def open_new_session(
    db: StudyDatabase, *, code: str, number: int, kind: str, protocol: ProtocolConfig, seed: int, rig: str,
    config: dict[str, Any], calibration: dict[str, Any] | None, lease_owner: str, study_owner: str | None = None,
    note: str = "", training_override: str = "", covariates: Mapping[str, Any] | None = None,
    events: Sequence[tuple[str, str]] = (),
) -> OpenedSession:
    """Store a new session (whole schedule, provenance) and take its lease, before its first trial.

    Parameters
    ----------
    db
        The study database (open for writing).
    code, number
        Participant code and number (the number drives counterbalancing).
    kind
        ``"training"`` or ``"experiment"``.
    protocol
        The study protocol (a training session runs :func:`training_protocol` of it).
    seed
        Study seed (schedules).
    rig, config, calibration
        Provenance stored with the session.
    lease_owner, study_owner
        This command's lease token, and the study lease it works under (a parallel ``run``'s workers).
    note
        Detail of the ``session_start`` event.
    training_override
        The experimenter's reason for an experiment without the completed training session the protocol
        requires: the session starts, and a ``deviation`` event stores the reason (:mod:`protocol.runner.study_rules`).
    covariates
        Who the participant is (by name; text or typed), as the protocol's ``[[covariates]]`` declare: checked
        before anything is stored, and stored with a participant this session registers.
    events
        Events ``(kind, detail)`` stored with the session at session time 0, in the transaction that stores it (a
        visit's day, a visit's deviation: :mod:`study_app.headless.plan_visits`).

    Raises
    ------
    CovariateError
        A covariate outside its declaration, or a required one missing (one line; nothing stored).
    StorageError
        The participant already has a session of this kind, or another process runs the study.
    StudyRuleError
        The study's rules refuse it (:mod:`protocol.runner.study_rules`): another seed than the study's, or an
        experiment without a completed training session and no ``training_override``.
    """
    if kind == "experiment":
        schedule = build_schedule(protocol, seed, number)
        run_protocol = protocol
    elif kind == "training":
        schedule = training_schedule(protocol)
        run_protocol = training_protocol(protocol)
    else:
        raise ValueError(f"session kind = {kind!r}: allowed values are 'training' and 'experiment'")

    def rules(locked: StudyDatabase) -> list[tuple[str, str]]:
        # runs inside create_session's transaction, after its refusal of a second session of a kind:
        # what it read cannot change before the session is stored
        deviation = check_new_session(stored_sessions(locked), code=code, kind=kind, seed=seed, protocol=protocol,
                                      training_override=training_override)
        return [*([(DEVIATION_EVENT, deviation)] if deviation else []), *events]

    described = checked_values(protocol.covariates, covariates or {})  # before anything is stored
    code_ran = software_provenance()  # which code runs the session: version, commit, uncommitted changes
    session_id = db.create_session(
        code=code, kind=kind, seed=seed, participant_number=number, protocol_json=run_protocol.to_json(),
        schedule_json=schedule_to_json(schedule), software_version=code_ran.version, rig=rig, config=config,
        calibration=calibration, lease_owner=lease_owner, study_owner=study_owner,
        start_event=note or f"{kind} session for {code}, seed {seed}",  # in the same transaction
        rules=rules,
        software_commit=code_ran.commit, software_dirty=code_ran.dirty,
        covariates=described, declared=protocol.covariates,
        metric_columns=[m.name for m in stored(run_protocol.task.metrics)],  # its task's trials columns
    )
    return OpenedSession(
        session_id=session_id, code=code, kind=kind, seed=seed, participant_number=number, protocol=run_protocol,
        schedule=schedule, start_position=0, clock_offset_s=0.0, initial_pause_s=0.0,
        live_force_aid=kind == "training" and protocol.training.live_force_aid, lease_owner=lease_owner, resumed=False,
        earlier=earlier_trials(db, code, session_id) if run_protocol.feedback.in_session(kind) else (),
    )


def open_resumed_session(
    db: StudyDatabase, session_id: int, *, lease_owner: str, study_owner: str | None = None,
    calibration: dict[str, Any] | None = None,
) -> OpenedSession:
    """Take an interrupted session over and get it ready to continue (see the module docstring).

    Parameters
    ----------
    db
        The study database (open for writing).
    session_id
        An interrupted session (status ``running``).
    lease_owner, study_owner
        As in :func:`open_new_session`.
    calibration
        The payload calibration this run uses: stored as an event (the session's own row keeps the first one).

    Raises
    ------
    StorageError
        No such interrupted session, or its recording is damaged (:func:`refuse_damaged_recording`;
        nothing was changed).
    LeaseHeld
        Another live process writes to it (nothing was changed).
    """
    refuse_damaged_recording(db, session_id)
    takeover = db.acquire_lease(session_scope(session_id), lease_owner, study_owner=study_owner)
    # read it only now that it is ours: another process may have finished it meanwhile
    info = next((s for s in db.open_sessions() if s.session_id == session_id), None)
    if info is None:
        db.release_lease(session_scope(session_id), lease_owner)
        stored = StudyReader.over(db).session(session_id)
        why = ("there is no such session" if stored is None else
               f"it has ended (status {stored.status}), perhaps run to its end by another process meanwhile")
        raise StorageError(f"session {session_id} in {db.path} cannot be resumed: {why}; nothing was changed")
    protocol = protocol_from_dict(json.loads(info.protocol_json), f"session {session_id} protocol")
    schedule = schedule_from_json(info.schedule_json)
    notes = [takeover] if takeover else []
    with db.transaction():
        if takeover:
            db.insert_event(session_id, db.last_session_time_s(session_id), "lease", takeover)
        pos = first_unfinished(schedule, db.trial_rows(session_id))
        last_s = db.last_session_time_s(session_id)  # events, trial ends and recorded records alike
        segment = db.next_segment(session_id)
        interrupted = _interrupted_trial(db, info, protocol, schedule, pos)
        if interrupted is not None:
            record = interrupted
            spec = schedule[pos]
            db.insert_trial(record.to_row())
            schedule = requeue_aborted(schedule, spec, spec.index + 1, protocol.abort_policy,
                                       np.random.default_rng([info.seed, session_id, 7]))
            db.update_schedule(session_id, schedule_to_json(schedule))
            last_s = max(last_s, record.ended_at_s)
            what = (f"{trial_words(spec.index)} (cue at {record.started_at_s:.3f} s, {record.n_samples} samples) was "
                    "stored as aborted (interrupted) and re-queued")
            notes.append(what)
            pos += 1
        else:
            what = f"continuing at trial position {pos}"
        offset_s = last_s + RESUME_STEP_S
        db.insert_event(session_id, offset_s, "resume", what)
        # which code runs this part of the session (the session row names the code that started it)
        db.insert_event(session_id, offset_s, "software", json.dumps(dataclasses.asdict(software_provenance())))
        if calibration is not None:
            db.insert_event(session_id, offset_s, "calibration", json.dumps(calibration))
    return OpenedSession(
        session_id=session_id, code=info.code, kind=info.kind, seed=info.seed,
        participant_number=info.participant_number, protocol=protocol, schedule=schedule, start_position=pos,
        clock_offset_s=offset_s, initial_pause_s=protocol.trial.pause_s,
        live_force_aid=info.kind == "training" and protocol.training.live_force_aid, lease_owner=lease_owner,
        resumed=True, notes=notes, segment=segment, answered=tuple(answered_blocks(db.conn, session_id)),
        trial_answers=stored_answers(db, session_id),
        earlier=earlier_trials(db, info.code, session_id) if protocol.feedback.in_session(info.kind) else (),
        cards_shown=cards_shown(db, session_id),
    )


def refuse_damaged_recording(db: StudyDatabase, session_id: int) -> None:
    """Refuse to append to a session whose recording is damaged (read only: nothing is written).

    A resumed run would add a segment to a session whose earlier records fail their checksum or do not
    decode: the session would look whole while part of it cannot be analysed or replayed.

    Raises
    ------
    StorageError
        One line naming the damage and what to do.
    """
    damage = recording_damage(db.conn, session_id, columns=None)
    if damage:
        more = (f" (and {len(damage) - 1} more damaged stretch{'es' if len(damage) > 2 else ''})"
                if len(damage) > 1 else "")
        raise StorageError(
            f"session {session_id} in {db.path} cannot be resumed: its recording is damaged: {damage[0].describe()}"
            f"{more}; a resumed run would append to a session part of which cannot be read; nothing was changed "
            f"(haptic-study check --db {db.path} lists the damage; restore the file from a backup to resume)")


def _interrupted_trial(
    db: StudyDatabase, info: SessionInfo, protocol: ProtocolConfig, schedule: list[TrialSpec], pos: int,
) -> TrialRecord | None:
    """The record of a trial that was cued but never finished, or None.

    Its records are those the loop marked with it: in the session's recording
    (version 3), or its rows of the ``samples`` table (a session begun by version 2).
    """
    if pos >= len(schedule):
        return None
    spec = schedule[pos]
    sid = info.session_id
    cue_s = _cue_time_s(db, sid, spec.index)
    if cue_s is None:
        return None  # never cued: it simply runs now
    segment, ticks, origin_ns = None, None, 0
    marked = marked_records(db.conn, sid, spec.index, ("force_n",))
    if marked is not None:
        (segment, started_at_s, t0_ns), cols = marked
        t_ns = cols["t_ns"]  # loop clock, int64; the first marked record is the trial's time origin
        force = cols["force_n"]
        origin_ns = int(t_ns[0])
        cue_s = SessionClock(started_at_s, t0_ns).seconds(origin_ns)
        ticks = (int(cols["tick"][0]), int(cols["tick"][-1]))
    else:
        samples = StudyReader.over(db).trial_samples(trial_id_of(sid, spec.index), ("t_s", "force_n")).rows
        # t_s was stored as ns / 1e9 since the cue: rounding recovers the integer ns exactly
        t_ns = np.rint(np.array([r[0] for r in samples], dtype=np.float64) * 1e9).astype(np.int64)
        force = np.array([np.nan if r[1] is None else r[1] for r in samples], dtype=np.float64)
    met = protocol.task.judge(t_ns - origin_ns, force, spec, max_trial_s=protocol.trial.max_trial_s)
    record = TrialRecord.finished(
        session_id=sid, spec=spec, outcome=Outcome.ABORTED, clock=SessionClock(cue_s, origin_ns),
        cue_ns=origin_ns, end_ns=int(t_ns[-1]) if len(t_ns) else origin_ns, metrics=met,
        reason="interrupted: the previous run ended during this trial", cause=AbortCause.INTERRUPTED,
        segment=segment, ticks=ticks,
    )
    return dataclasses.replace(record, n_samples=len(t_ns))  # every record it had, not only those up to the cap


def _cue_time_s(db: StudyDatabase, session_id: int, trial_index: int) -> float | None:
    """When a trial's time origin was (its first record under the trial's condition), from the stored events.

    The phase change to ``active`` carries it exactly; the ``cue`` event (one
    tick earlier at most) stands in when the run ended before that was stored.
    """
    name, old = trial_words(trial_index), f"trial {trial_index}"  # (versions 1 and 2 named trials by index)
    by_kind = dict(StudyReader.over(db).trial_start_events(session_id, (name, old)))
    t = by_kind.get("phase", by_kind.get("cue"))
    return None if t is None else float(t)


def delivery_limits(loop: LoopView) -> DeliveryLimits:
    """What a trial on this loop must get: its safety stage's ramps and its watchdog's sensor-age limit."""
    safety = loop.framework.config.safety
    return DeliveryLimits(feedback_ramp_in_s=safety.ramp_in_s, feedback_ramp_out_s=safety.fault_ramp_s,
                          max_gap_s=loop.watchdog.sensor_max_age_s)


def raw_wrench_scales(sensor: Any) -> dict[str, float]:
    """Counts per unit of a sensor's raw wrench (its ``counts_per_unit``), for the recording; {} if it has none."""
    per = getattr(sensor, "counts_per_unit", None)
    if per is None:
        return {}
    force, torque = per
    return {**{f"raw_f{a}": float(force) for a in "xyz"}, **{f"raw_t{a}": float(torque) for a in "xyz"}}


def start_runner(
    db: StudyDatabase, opened: OpenedSession, *, submit: Callable[[Command], None],
    participant: TrialParticipant | None, participant_time: Callable[[], float] | None, limits: DeliveryLimits,
    auto_reset_faults: bool, threaded: bool, short_transactions: bool = False, scales: dict[str, float] | None = None,
    commit_clock: Callable[[], float] | None = None, commit_interval_s: float = 0.1, arms: tuple[str, ...] = (),
    simulated_answers: bool = False, dated: bool = False,
) -> tuple[Recorder, SessionRunner]:
    """The writer and the runner of an opened session.

    Parameters
    ----------
    db
        The database the session was opened in (the recorder becomes its writer).
    opened
        From :func:`open_new_session` or :func:`open_resumed_session`.
    submit
        Sends commands to the haptic loop.
    participant, participant_time
        A simulated participant to notify and its clock (None for a person).
    limits
        What the loop must deliver for a trial to count.
    auto_reset_faults
        Headless: the runner resets faults itself (see :class:`protocol.runner.session.SessionRunner`).
    threaded, short_transactions
        Recorder options (a thread for live sessions; short transactions for parallel writers).
    scales
        Counts per unit of the raw wrench (:func:`raw_wrench_scales`), so the recording keeps counts.
    commit_clock, commit_interval_s
        The recorder's commit deadline: its clock, s (None: the wall clock), and the longest time a record waits
        for its commit (100 ms).  A run on the virtual clock passes the loop's time, so its commits fall on the
        same records every time (see :mod:`study_app.headless.session_run`).
    dated
        The records' tick times are on ``commit_clock`` (the loop's own clock, on the real clock): their deadline
        counts from their tick, so a crash loses at most ``commit_interval_s`` of them however late the driver
        handed them over (:class:`protocol.storage.recorder.Recorder`).
    arms
        The rig's arms by name (:attr:`protocol.runner.session.SessionRunner.arms`; the task arm's records are the
        runner's).
    simulated_answers
        The simulated participant answers the questionnaires by its rule (headless); else a person answers them
        on the participant screen (the GUI, on either rig).
    """
    recorder = Recorder(db, threaded=threaded, short_transactions=short_transactions, max_latency_s=commit_interval_s,
                        dated=dated, **({} if commit_clock is None else {"clock": commit_clock}))
    runner = SessionRunner(opened.plan(arms, simulated_answers), recorder, submit, participant=participant,
                           participant_time=participant_time, limits=limits, auto_reset_faults=auto_reset_faults,
                           scales=scales)
    return recorder, runner


def finish_session(db: StudyDatabase, recorder: Recorder, opened: OpenedSession) -> None:
    """Commit what the recorder holds, then give the session's lease back (also after a recorder error)."""
    try:
        recorder.close()
    finally:
        # a lease left behind is taken over once this process is gone
        with contextlib.suppress(Exception):
            db.release_lease(session_scope(opened.session_id), opened.lease_owner)


def rehearsal_note(runner: SessionRunner) -> Callable[[int, str], None]:
    """What a :class:`protocol.runner.rehearsal.RehearsalTrigger` (or a fault rehearsed "now") of ``runner``'s
    session stores: ``note(t_ns, text)`` writes a :data:`~protocol.runner.study_rules.FAULT_REHEARSAL_EVENT` at loop
    time ``t_ns``, committed with the session's next commit."""

    def note(t_ns: int, text: str) -> None:
        runner.recorder.event(runner.session_id, runner.session_time_s(t_ns), FAULT_REHEARSAL_EVENT, text)

    return note


def store_rehearsal_plan(runner: SessionRunner, plan: object, t_ns: int = 0) -> None:
    """Store, committed at once, that ``plan`` (a :class:`protocol.runner.rehearsal.FaultPlan`, or a fault's kind) is to
    be rehearsed in ``runner``'s session: a planned ``kill`` ends the process before the session's next commit, and
    the record must still say the interruption was a rehearsal.  ``t_ns``: loop time it was planned at (0: before
    the session's first record)."""
    t_s = runner.session_time_s(t_ns)
    text = f"{plan}: planned, to be rehearsed on the simulated rig (not a device failure)"
    runner.recorder.call(lambda db: db.insert_event(runner.session_id, t_s, FAULT_REHEARSAL_EVENT, text))


def stored_answers(db: StudyDatabase, session_id: int) -> tuple[Answered, ...]:
    """A session's answered trials, as its task's procedure rebuilds from them (a resume continues the block)."""
    labels = {int(r["trial_index"]): str(r["target_label"]) for r in db.trial_rows(session_id)}
    return tuple(Answered(labels.get(a.trial_index, ""), a.values, a.answer)
                 for a in trial_answers(db.conn, session_id))
