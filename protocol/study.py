"""Headless studies on the simulated rig: participants, sessions, resume.

``haptic-study run`` calls :func:`run_study`: for each participant it builds
the simulated rig (calibrating its payload), hands the stylus to a
:class:`protocol.participant.SimulatedParticipant`, stores a training session
(tagged ``kind = 'training'``, which analysis excludes) and the experiment
session, each with its whole schedule committed before the first trial, and
runs them on the virtual clock (as fast as the CPU allows) or in real time.
:func:`resume_session` continues a participant's interrupted session (training
or experiment) at its first unfinished trial: the interrupted trial is stored
as aborted, with the reason, and re-run per the abort policy.
``run_study(..., continue_study=True)`` (``haptic-study run --continue``)
completes a study that stopped part-way: it resumes every interrupted session,
runs what each participant has not started, and leaves finished sessions alone.

Sessions are opened and closed through :mod:`protocol.session_setup`, as the
GUI's engine does.  A ``run`` owns the whole database while it works (the
``study`` lease): a second ``run`` on it is refused before it writes, and its
parallel workers hold their sessions' leases under it.  Planned faults
(:mod:`protocol.rehearsal`, ``--inject-fault``) are fired on the simulated rig
at their trial's time; a latched fault is reset by the runner in the pause,
and a fault that does not clear stops the study with :class:`SessionInterrupted`.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import dataclasses
import json
import multiprocessing as mp
import os
import queue
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from pipeline.engine import EngineConfig, HardwareEngine, SimEngine, build_sim_engine
from pipeline.hardware import HardwareConfig
from pipeline.loop import LoopEvent
from pipeline.sim.rig import SimRigConfig
from protocol.config import ProtocolConfig, protocol_from_dict
from protocol.design import schedule_from_json
from protocol.participant import SimulatedParticipant
from protocol.rehearsal import FaultPlan, RehearsalTrigger
from protocol.session import SessionRunner, first_unfinished
from protocol.session_setup import (
    OpenedSession, delivery_limits, finish_session, open_new_session, open_resumed_session, participant_seeds,
    raw_wrench_scales, start_runner, training_protocol, training_schedule,
)
from protocol.storage import EmptyDatabase, SessionInfo, StorageError, StudyDatabase, new_owner_token, validate_code
from protocol.version import software_version

__all__ = [
    "SessionInterrupted", "StudyProgress", "StudyWorkerError", "config_record", "default_jobs", "participant_code",
    "participant_seeds", "real_config_record", "resume_session", "run_study", "software_version", "training_schedule",
]

#: Records per step of the headless driver (the runner reads the ring this often).
BLOCK_TICKS = 50
#: Set in a parallel study's worker: the process a planned ``kill`` ends (the study's main process).
_kill_target_pid: int | None = None


class SessionInterrupted(RuntimeError):
    """A session stopped early and stays resumable (a fault that did not clear); the message says why."""


def participant_code(number: int) -> str:
    """Pseudonymous code of the n-th simulated participant (P01, P02, …)."""
    return f"P{number:02d}"


@dataclass
class StudyProgress:
    """What a progress display needs (updated as the study runs)."""

    participants_total: int = 0
    participant: int = 0
    code: str = ""
    kind: str = ""
    trials_done: int = 0  # in the current session
    trials_total: int = 0  # in the current session
    study_trials_done: int = 0
    study_trials_total: int = 0
    study_time_s: float = 0.0
    planned_s: float = 0.0
    sessions: list[int] = field(default_factory=list)
    #: What each planned fault did (``--inject-fault``), one line each.
    rehearsals: list[str] = field(default_factory=list)
    #: What the user should know that is not an error (a database upgraded, a lease taken over), one line each.
    notes: list[str] = field(default_factory=list)


def planned_study_time_s(protocol: ProtocolConfig, participants: int) -> float:
    """Upper bound of simulated time (every trial to its cap, plus pauses) for the progress bar."""
    tr = protocol.trial
    per = protocol.trials_per_participant * (tr.max_trial_s + tr.pause_s)
    if protocol.training.enabled:
        per += len(training_schedule(protocol)) * (protocol.training.seconds_per_target_per_mode + tr.pause_s)
    return per * participants


def _engine(rig_seed: int, clock: str) -> SimEngine:
    return build_sim_engine(
        EngineConfig(sim=SimRigConfig(seed=rig_seed), clock=clock, driver="hold", haptics_on=False, refine_bias=True,
                     ring_seconds=30.0)
    )


def _drive(
    eng: SimEngine, runner: SessionRunner, clock: str, progress: StudyProgress, on_progress: Callable[[StudyProgress], None] | None,
    trigger: RehearsalTrigger | None = None,
) -> None:
    """Alternate loop ticks and runner blocks until the session ends."""
    ring = eng.ring
    assert ring is not None
    loop = eng.loop
    events: list[LoopEvent] = []
    loop.on_event = events.append  # list.append is atomic: safe from the real-clock loop thread
    replay_log = loop.replay_log
    cursor = ring.write_count
    t_last_report = 0.0
    base_done = progress.study_trials_done
    planned = runner.state.trials_total  # re-runs of aborted trials add to the study's trials as they are queued
    if trigger is not None:
        runner.listeners.append(trigger.on_runner_event)
    if clock == "real":
        loop.start()
    try:
        while not runner.done:
            if clock == "virtual":
                loop.run_ticks(BLOCK_TICKS)
            else:
                time.sleep(0.02)
            res = ring.read_since(cursor)
            cursor = res.cursor
            if res.lost:
                runner.records_lost(res.lost)
            # events and the replay log after the rows: every entry of a tick whose record was read is in
            n_ev = len(events)
            batch, events[:n_ev] = events[:n_ev], []
            log = [replay_log.popleft() for _ in range(len(replay_log))]
            n = len(res.rows)
            runner.process(res.rows, batch, log)
            if trigger is not None and n:
                trigger.poll(int(res.rows["t_ns"][-1]))
            progress.study_time_s += n * 1e-3
            now = time.monotonic()
            done = runner.state.completed + runner.state.aborted
            if on_progress is not None and (now - t_last_report > 0.1 or runner.done):
                t_last_report = now
                progress.trials_done = done
                progress.trials_total = runner.state.trials_total
                progress.study_trials_total += runner.state.trials_total - planned
                planned = runner.state.trials_total
                progress.study_trials_done = base_done + done
                on_progress(progress)
        progress.study_trials_done = base_done + runner.state.completed + runner.state.aborted
    finally:
        if clock == "real":
            loop.stop()
        else:
            loop.ramp_down()
        eng.rig.close()
        if trigger is not None:
            progress.rehearsals.extend(trigger.report)


def config_record(eng: SimEngine, clock: str, rig_seed: int, participant_seed: int) -> dict[str, Any]:
    """The ``config_json`` of a simulated-rig session: rig, framework and watchdog settings, seeds."""
    fw = eng.framework.config
    return {
        "rig": "sim",
        "clock": clock,
        "rig_seed": rig_seed,
        "participant_seed": participant_seed,
        "sim": _plain(dataclasses.asdict(eng.rig.config)),
        "framework": _plain(dataclasses.asdict(fw)),
        "watchdog": _plain(dataclasses.asdict(eng.loop.watchdog)),
    }


def real_config_record(hw: HardwareConfig, hardware_text: str, eng: HardwareEngine) -> dict[str, Any]:
    """The ``config_json`` of a real-rig session: the hardware file as written and as validated, framework, watchdog."""
    return {
        "rig": "real",
        "clock": "real",
        "participant": "person",
        "hardware_file": hw.source,
        "hardware_toml": hardware_text,
        "hardware": _plain(dataclasses.asdict(hw)),
        "framework": _plain(dataclasses.asdict(eng.framework.config)),
        "watchdog": _plain(dataclasses.asdict(eng.loop.watchdog)),
    }


def _plain(d: Any) -> Any:
    if isinstance(d, dict):
        return {k: _plain(v) for k, v in d.items()}
    if isinstance(d, (list, tuple)):
        return [_plain(v) for v in d]
    return d


def _run_session(
    db: StudyDatabase, *, code: str, number: int, kind: str | None, protocol: ProtocolConfig, study_seed: int,
    clock: str, progress: StudyProgress, on_progress: Callable[[StudyProgress], None] | None,
    short_transactions: bool = False, resume_id: int | None = None, lease_owner: str, study_owner: str | None = None,
    faults: Sequence[FaultPlan] = (),
) -> int:
    """Run one session to its end on a fresh simulated rig: a new one of ``kind``, or the interrupted ``resume_id``."""
    rig_seed, p_seed = participant_seeds(study_seed, number)
    if resume_id is None:
        assert kind is not None
        # training and experiment each get their own rig: the same seed gives the same study whatever ran before
        eng = _engine(rig_seed + (1 if kind == "training" else 0), clock)
        opened = open_new_session(
            db, code=code, number=number, kind=kind, protocol=protocol, seed=study_seed, rig="sim",
            config=config_record(eng, clock, rig_seed, p_seed), calibration=eng.calibration.to_dict(),
            lease_owner=lease_owner, study_owner=study_owner,
        )
    else:
        info = next(s for s in db.sessions_of(code) if s.session_id == resume_id)
        # a fresh rig (re-calibrated, its own seed) and the same participant (same seed, same parameters)
        eng = _engine(rig_seed + (3 if info.kind == "training" else 2), clock)
        opened = open_resumed_session(db, resume_id, lease_owner=lease_owner, study_owner=study_owner,
                                      calibration=eng.calibration.to_dict())
    participant = SimulatedParticipant(seed=opened.participant_seed)
    eng.rig.set_driver(participant)
    progress.sessions.append(opened.session_id)
    progress.kind = opened.kind
    recorder, runner = start_runner(
        db, opened, submit=eng.loop.submit, participant=participant, participant_time=lambda: eng.rig.sim_time_s,
        limits=delivery_limits(eng.loop), auto_reset_faults=True, threaded=(clock == "real"),
        short_transactions=short_transactions, scales=raw_wrench_scales(eng.rig.sensor),
    )
    trigger = _trigger(faults, opened, eng)
    try:
        _drive(eng, runner, clock, progress, on_progress, trigger)
    finally:
        finish_session(db, recorder, opened)
    if runner.stop_reason:
        raise SessionInterrupted(f"{opened.code}'s {opened.kind} session {opened.session_id}: {runner.stop_reason}")
    return opened.session_id


def _trigger(faults: Sequence[FaultPlan], opened: OpenedSession, eng: SimEngine) -> RehearsalTrigger | None:
    """The rehearsal trigger of a session run, if faults are planned for it."""
    if not faults:
        return None
    loop, rig = eng.loop, eng.rig

    def inject(kind: str, at_ns: int) -> None:
        rig.inject_fault(kind, loop.t0_ns + at_ns)  # the records' axis -> the rig's clock

    def kill() -> None:
        # as `kill -9` of `haptic-study run` would: in a parallel study's worker, the study's main process
        # (the workers then die with it, by PR_SET_PDEATHSIG)
        sys.stdout.flush()
        sys.stderr.flush()
        os.kill(_kill_target_pid or os.getpid(), signal.SIGKILL)

    def cancel(kind: str, at_ns: int) -> None:
        rig.cancel_fault(kind, loop.t0_ns + at_ns)

    trig = RehearsalTrigger.for_session(faults, opened.code, opened.kind, opened.start_position, inject, kill, cancel)
    return trig if trig.plans else None


def _remaining_trials(db: StudyDatabase, info: SessionInfo) -> int:
    """Trials a resume of this session will run.

    An interrupted trial is stored as aborted by
    :func:`protocol.session_setup.open_resumed_session`, not run, and its
    re-run takes its place in the count.
    """
    schedule = schedule_from_json(info.schedule_json)
    return len(schedule) - first_unfinished(schedule, db.trial_rows(info.session_id))


#: One step of a participant's part of a study: ("new", kind) or ("resume", session id).
Step = tuple[str, Any]


def _plan_continue(
    db: StudyDatabase, db_path: str, participants: int, seed: int, protocol: ProtocolConfig,
) -> tuple[dict[int, list[Step]], int, list[int]]:
    """What is left of a study: steps per participant, trials they run, and the finished sessions kept.

    Raises :class:`StorageError`, before anything is written, when the stored
    sessions were made with another seed or protocol: continuing them with
    this one would mix two designs in one study.
    """
    kinds = ("training", "experiment") if protocol.training.enabled else ("experiment",)
    wanted = {"training": json.loads(training_protocol(protocol).to_json()), "experiment": json.loads(protocol.to_json())}
    plan: dict[int, list[Step]] = {}
    kept: list[int] = []
    trials = 0
    for n in range(1, participants + 1):
        code = participant_code(n)
        stored = db.sessions_of(code)
        for info in stored:
            if info.seed != seed:
                raise StorageError(
                    f"cannot continue: {code}'s {info.kind} session {info.session_id} in {db_path} was run with "
                    f"--seed {info.seed}, not {seed}; nothing was changed (give the seed the study was started with)"
                )
            if info.kind in wanted and json.loads(info.protocol_json) != wanted[info.kind]:
                raise StorageError(
                    f"cannot continue: {code}'s {info.kind} session {info.session_id} in {db_path} was run with "
                    f"another protocol; nothing was changed (give the --protocol the study was started with)"
                )
        steps: list[Step] = []
        for kind in kinds:
            of_kind = [s for s in stored if s.kind == kind]
            if any(s.status != "running" for s in of_kind):  # completed, or ended by the experimenter
                kept.extend(s.session_id for s in of_kind if s.status != "running")
                continue
            if kind == "training" and not of_kind and any(s.kind == "experiment" for s in stored):
                continue  # practice comes before the experiment or not at all
            if of_kind:
                info = of_kind[-1]
                steps.append(("resume", info.session_id))
                trials += _remaining_trials(db, info)
            else:
                steps.append(("new", kind))
                trials += protocol.trials_per_participant if kind == "experiment" else len(training_schedule(protocol))
        if steps:
            plan[n] = steps
    return plan, trials, kept


def _run_steps(
    db: StudyDatabase, number: int, steps: list[Step], *, protocol: ProtocolConfig, seed: int, clock: str,
    progress: StudyProgress, on_progress: Callable[[StudyProgress], None] | None, study_owner: str,
    faults: Sequence[FaultPlan] = (), short_transactions: bool = False,
) -> None:
    """Run one participant's steps in order: new sessions from the protocol, resumes from what is stored."""
    code = participant_code(number)
    for what, arg in steps:
        _run_session(db, code=code, number=number, kind=arg if what == "new" else None, protocol=protocol,
                     study_seed=seed, clock=clock, progress=progress, on_progress=on_progress,
                     short_transactions=short_transactions, resume_id=arg if what == "resume" else None,
                     lease_owner=new_owner_token(), study_owner=study_owner, faults=faults)


def _all_steps(protocol: ProtocolConfig) -> list[Step]:
    """A participant's whole part of a study: training (if the protocol has one), then the experiment."""
    return [("new", "training"), ("new", "experiment")] if protocol.training.enabled else [("new", "experiment")]


class StudyWorkerError(RuntimeError):
    """A participant's worker process failed in a parallel study; the message says which and what to resume."""


def default_jobs(participants: int) -> int:
    """Worker processes for a study: the usable cores, at most one per participant."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, participants))


def run_study(
    db_path: str,
    *,
    participants: int,
    seed: int,
    protocol: ProtocolConfig,
    clock: str = "virtual",
    on_progress: Callable[[StudyProgress], None] | None = None,
    jobs: int | None = None,
    continue_study: bool = False,
    faults: Sequence[FaultPlan] = (),
) -> StudyProgress:
    """Run a complete simulated study into the database at ``db_path``.

    Parameters
    ----------
    db_path
        Study database (created if missing).
    participants
        Simulated participants P01 … PNN; each runs a training session (if the
        protocol has one) and then the experiment session.
    seed
        Study seed: schedules, rigs and participants derive from it and the
        participant number only, so the results do not depend on ``jobs``.
    protocol
        The study protocol.
    clock
        ``"virtual"`` (as fast as the CPU allows) or ``"real"``.
    on_progress
        Called (in this process) with the aggregated progress, ~10 times a second.
    jobs
        Participants run at once, each in its own worker process (its own
        database connection and recorder, all writing into the same WAL
        database).  None: the usable cores, at most ``participants``; 1: one
        after the other in this process.
    continue_study
        Complete a study that stopped part-way (a crash, a failed worker, an
        interrupted run) in the same database: every interrupted session is
        resumed (:func:`resume_session`), what a participant has not started
        is run, and finished sessions (completed, or ended by the
        experimenter) are left alone.  ``seed`` and ``protocol`` must be those
        the study was started with.
    faults
        Planned faults (:mod:`protocol.rehearsal`) for the sessions this call runs.

    Returns
    -------
    StudyProgress
        The final progress; ``sessions`` lists the session ids in participant
        order (training before experiment), whatever order they were allocated
        in; when continuing, the sessions kept from before come first.

    Raises
    ------
    StorageError
        Before anything is stored, if the database cannot be used, another
        process writes to it (:class:`protocol.storage.LeaseHeld`), or one of
        the participant codes already has sessions in it (without
        ``continue_study``), or, when continuing, the stored sessions were run
        with another seed or protocol.
    StudyWorkerError
        If a participant's worker fails: the other workers are stopped (their
        sessions stay ``running``); ``continue_study`` completes the study.
    SessionInterrupted
        A fault did not clear (one participant at a time; in parallel it is a
        :class:`StudyWorkerError`); ``continue_study`` completes the study.
    """
    if participants < 1:
        raise ValueError(f"participants = {participants}: must be ≥ 1")
    if jobs is not None and jobs < 1:
        raise ValueError(f"jobs = {jobs}: must be ≥ 1 (or None for the usable cores)")
    check_fault_plans(faults, protocol, [participant_code(n) for n in range(1, participants + 1)])
    n_jobs = default_jobs(participants) if jobs is None else min(jobs, participants)
    if continue_study and not os.path.exists(db_path):
        raise StorageError(f"cannot continue a study: no database at {db_path}")
    # every refusal is decided on a read-only look first: a refused command leaves the file byte-identical
    first_plan, first_total, first_kept = _plan_study(_peek(db_path), db_path, participants, seed, protocol,
                                                      continue_study)
    if continue_study and not first_plan:  # nothing left to run: nothing to write either
        done = StudyProgress(participants_total=participants, sessions=list(first_kept))
        return done
    owner = new_owner_token()
    # just checked: the writer need not quick_check again; a version-1 file is upgraded (after a backup) only now
    db: StudyDatabase | None = StudyDatabase(db_path, check=False)
    try:
        taken = db.acquire_lease("study", owner)  # a second `run` stops here
        progress = StudyProgress(participants_total=participants, planned_s=planned_study_time_s(protocol, participants))
        progress.notes.extend(_open_notes(db, taken))
        # again under the lease: what another process did in between counts
        plan, progress.study_trials_total, kept = _plan_study(db, db_path, participants, seed, protocol, continue_study)
        progress.sessions.extend(kept)
        jobs_used = min(n_jobs, len(plan))
        if jobs_used > 1:
            db.close()  # the workers open their own connections; none is carried across fork
            db = None
            return _run_parallel(db_path, plan=plan, seed=seed, protocol=protocol, clock=clock,
                                 on_progress=on_progress, jobs=jobs_used, progress=progress, study_owner=owner,
                                 faults=faults)
        for n, steps in plan.items():
            progress.participant, progress.code = n, participant_code(n)
            _run_steps(db, n, steps, protocol=protocol, seed=seed, clock=clock, progress=progress,
                       on_progress=on_progress, study_owner=owner, faults=faults)
        return progress
    finally:
        _release_study(db, db_path, owner)


def _interrupted_session_of(db: StudyDatabase | None, db_path: str, code: str) -> SessionInfo:
    """The participant's interrupted session (the newest), or a :class:`StorageError` saying why there is none.

    A read-only ``db`` is closed afterwards.
    """
    try:
        open_ = [] if db is None else [s for s in db.sessions_of(code) if s.status == "running"]
        if not open_:
            known = None if db is None else db.participant_id(code, create=False)
            what = "no such participant" if known is None else "no interrupted session"
            raise StorageError(f"cannot resume {code} in {db_path}: {what}")
        return open_[-1]
    finally:
        if db is not None and db.readonly:
            db.close()


def _peek(db_path: str) -> StudyDatabase | None:
    """The study database opened read-only and checked, or None if there is no study in it yet."""
    if not os.path.exists(db_path) or (os.path.isfile(db_path) and os.path.getsize(db_path) == 0):
        return None
    try:
        return StudyDatabase(db_path, readonly=True, check=True)
    except EmptyDatabase:
        return None


def _plan_study(
    db: StudyDatabase | None, db_path: str, participants: int, seed: int, protocol: ProtocolConfig, continue_study: bool,
) -> tuple[dict[int, list[Step]], int, list[int]]:
    """What a ``run`` will do: steps per participant, trials, finished sessions kept; refusals as :class:`StorageError`.

    ``db`` None: a new database.  A read-only ``db`` is closed afterwards.
    """
    try:
        if continue_study:
            if db is None:
                raise StorageError(f"cannot continue a study: no study in {db_path}")
            return _plan_continue(db, db_path, participants, seed, protocol)
        if db is not None:
            for n in range(1, participants + 1):
                code = participant_code(n)
                if db.sessions_of(code):
                    raise StorageError(
                        f"{db_path} already holds sessions for participant {code}; nothing was changed "
                        f"(use a new database, or the same command with --continue to complete the study)"
                    )
        plan = {n: _all_steps(protocol) for n in range(1, participants + 1)}
        per = protocol.trials_per_participant + (len(training_schedule(protocol)) if protocol.training.enabled else 0)
        return plan, per * participants, []
    finally:
        if db is not None and db.readonly:
            db.close()


def _open_notes(db: StudyDatabase, taken_over: str) -> list[str]:
    """What opening the database did that the user should hear of."""
    notes = []
    if db.upgraded_from is not None:
        notes.append(f"{db.path}: upgraded from schema version {db.upgraded_from} to {db.schema_version}; "
                     f"the file as it was is kept in {db.backup_path}")
    if taken_over:
        notes.append(f"{db.path}: {taken_over}")
    return notes


def _release_study(db: StudyDatabase | None, db_path: str, owner: str) -> None:
    """Give the study lease back (reopening the database if the workers had it) and close."""
    try:
        if db is None:
            db = StudyDatabase(db_path, check=False)
        db.release_lease("study", owner)
    except StorageError:
        pass  # the lease is taken over once this process is gone
    finally:
        if db is not None:
            db.close()


def check_fault_plans(faults: Sequence[FaultPlan], protocol: ProtocolConfig, codes: Sequence[str]) -> None:
    """Refuse a planned fault for a participant who is not run, or a trial the session does not have.

    Raises
    ------
    ValueError
        One line naming the plan and what is allowed.
    """
    for f in faults:
        if f.code not in codes:
            shown = ", ".join(codes[:3]) + (f", … {codes[-1]}" if len(codes) > 3 else "")
            raise ValueError(f"--inject-fault = {f}: participant {f.code} is not run by this command ({shown})")
        n = protocol.trials_per_participant if f.session == "experiment" else len(training_schedule(protocol))
        if f.trial > n:
            raise ValueError(f"--inject-fault = {f}: trial {f.trial} is beyond the {n} trials of the "
                             f"{f.session} session")
        cap = (protocol.trial.max_trial_s if f.session == "experiment"
               else protocol.training.seconds_per_target_per_mode)
        if f.seconds > cap:
            raise ValueError(f"--inject-fault = {f}: {f.seconds:g} s is after the trial's end at the latest "
                             f"({cap:g} s after its cue)")


def _die_with_parent(parent_pid: int) -> None:
    """Linux: have the kernel SIGKILL this process when its parent dies, so no orphan keeps writing."""
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
            PR_SET_PDEATHSIG = 1
            libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):  # pragma: no cover - no libc
            pass
    if os.getppid() != parent_pid:  # the parent died before the request took effect
        os._exit(1)


def _participant_worker(
    db_path: str, number: int, steps: list[Step], seed: int, protocol: ProtocolConfig, clock: str, parent_pid: int,
    messages: Any, study_owner: str, faults: Sequence[FaultPlan],
) -> None:
    """One participant's steps (training, then experiment; or what is left of them) in a worker process.

    Reports through ``messages``.

    Messages: ``("progress", number, kind, trials_done, trials_total, participant_trials_done, study_time_s)``,
    ``("done", number, session ids, participant_trials_done, study_time_s, rehearsal reports)``,
    ``("error", number, message)``.
    """
    global _kill_target_pid
    _die_with_parent(parent_pid)
    _kill_target_pid = parent_pid
    code = participant_code(number)
    progress = StudyProgress(participants_total=1, participant=number, code=code)

    def report(p: StudyProgress) -> None:
        messages.put(("progress", number, p.kind, p.trials_done, p.trials_total, p.study_trials_done, p.study_time_s))

    try:
        # the study's main process checked the file a moment ago: no second quick_check per worker
        db = StudyDatabase(db_path, check=False)
        try:
            _run_steps(db, number, steps, protocol=protocol, seed=seed, clock=clock, progress=progress,
                       on_progress=report, study_owner=study_owner, faults=faults, short_transactions=True)
        finally:
            db.close()
    except BaseException as exc:  # noqa: BLE001 - reported to the parent, which stops the study
        why = str(exc) if isinstance(exc, (SessionInterrupted, StorageError)) else f"{type(exc).__name__}: {exc}"
        messages.put(("error", number, why))
        messages.close()
        messages.join_thread()
        os._exit(1)
    messages.put(("done", number, list(progress.sessions), progress.study_trials_done, progress.study_time_s,
                  list(progress.rehearsals)))
    messages.close()
    messages.join_thread()


def _run_parallel(
    db_path: str, *, plan: dict[int, list[Step]], seed: int, protocol: ProtocolConfig, clock: str,
    on_progress: Callable[[StudyProgress], None] | None, jobs: int, progress: StudyProgress, study_owner: str,
    faults: Sequence[FaultPlan],
) -> StudyProgress:
    """:func:`run_study` over ``jobs`` worker processes, one participant per process."""
    # fork is cheap (the workers inherit the imported modules) but unsafe once other threads exist
    ctx = mp.get_context("fork" if threading.active_count() == 1 else "spawn")
    messages = ctx.Queue()
    waiting = list(plan)
    running: dict[int, Any] = {}
    done_trials: dict[int, int] = {}
    time_s: dict[int, float] = {}
    sessions: dict[int, list[int]] = {}
    failure: tuple[int, str] | None = None
    t_last_report = 0.0

    def handle(msg: tuple[Any, ...]) -> tuple[int, str] | None:
        what, n = msg[0], msg[1]
        if what == "progress":
            _, _, kind, trials_done, trials_total, p_done, p_time = msg
            done_trials[n], time_s[n] = p_done, p_time
            progress.participant, progress.code, progress.kind = n, participant_code(n), kind
            progress.trials_done, progress.trials_total = trials_done, trials_total
        elif what == "done":
            sessions[n], done_trials[n], time_s[n] = msg[2], msg[3], msg[4]
            progress.rehearsals.extend(msg[5])
            running.pop(n).join()
        else:
            return (n, msg[2])
        return None

    try:
        while failure is None and (waiting or running):
            while waiting and len(running) < jobs:
                n = waiting.pop(0)
                p = ctx.Process(target=_participant_worker, name=f"study-{participant_code(n)}",
                                args=(db_path, n, plan[n], seed, protocol, clock, os.getpid(), messages, study_owner,
                                      faults), daemon=True)
                p.start()
                running[n] = p
            try:
                msg = messages.get(timeout=0.1)
            except queue.Empty:
                msg = None
            if msg is not None:
                failure = handle(msg)
            else:
                for n, p in list(running.items()):
                    if p.exitcode is None or n in sessions:
                        continue
                    # ended: read what it wrote before it ended (its last words may still be in the pipe)
                    try:
                        while failure is None and n not in sessions:
                            failure = handle(messages.get(timeout=1.0))
                    except queue.Empty:
                        pass
                    if failure is None and n not in sessions:  # died without a word (killed, crashed)
                        failure = (n, f"its worker process ended with exit code {p.exitcode}")
                    if failure is not None:
                        break
            progress.study_trials_done = sum(done_trials.values())
            progress.study_time_s = sum(time_s.values())
            now = time.monotonic()
            if on_progress is not None and msg is not None and (now - t_last_report > 0.1 or not (waiting or running)):
                t_last_report = now
                on_progress(progress)
    finally:
        for p in running.values():
            if p.is_alive():
                p.kill()  # its sessions stay 'running' (resumable); committed data is intact
        for p in running.values():
            p.join()
        messages.close()
    if failure is not None:
        n, why = failure
        raise StudyWorkerError(
            f"participant {participant_code(n)} failed ({why}); the other participants were stopped, "
            f"their committed data is kept; complete the study with the same command and --continue"
        )
    progress.sessions = progress.sessions + [sid for n in plan for sid in sessions[n]]
    progress.study_trials_done = sum(done_trials.values())
    return progress


def resume_session(
    db_path: str,
    code: str,
    *,
    clock: str = "virtual",
    on_progress: Callable[[StudyProgress], None] | None = None,
    faults: Sequence[FaultPlan] = (),
) -> StudyProgress:
    """Continue the interrupted session of participant ``code`` (training or experiment).

    The stored schedule is used; trials already stored are kept; the trial that
    was running when the previous run ended is stored as aborted (cause
    ``interrupted``) with its real cue time and samples and re-run per the
    abort policy; no trial is duplicated or skipped
    (:func:`protocol.session_setup.open_resumed_session`).  Only that session is
    continued: a participant interrupted in training still has the experiment
    to run (``run_study(..., continue_study=True)``, ``haptic-study run --continue``).

    Raises
    ------
    StorageError
        No such participant or interrupted session; or another process writes
        to the session or runs the study (:class:`protocol.storage.LeaseHeld`): nothing is changed.
    SessionInterrupted
        A fault did not clear; the session stays resumable.
    """
    validate_code(code)
    if not os.path.exists(db_path):
        raise StorageError(f"cannot resume {code}: no database at {db_path}")
    # refusals are decided on a read-only look first: a refused command leaves the file byte-identical
    _interrupted_session_of(_peek(db_path), db_path, code)
    db = StudyDatabase(db_path, check=False)
    try:
        info = _interrupted_session_of(db, db_path, code)
        remaining = _remaining_trials(db, info)
        progress = StudyProgress(participants_total=1, participant=info.participant_number, code=code, kind=info.kind,
                                 study_trials_total=remaining)
        progress.notes.extend(_open_notes(db, ""))
        protocol = protocol_from_dict(json.loads(info.protocol_json), f"session {info.session_id} protocol")
        progress.planned_s = remaining * (protocol.trial.max_trial_s + protocol.trial.pause_s)
        _run_session(db, code=code, number=info.participant_number, kind=None, protocol=protocol,
                     study_seed=info.seed, clock=clock, progress=progress, on_progress=on_progress,
                     resume_id=info.session_id, lease_owner=new_owner_token(), faults=faults)
        return progress
    finally:
        db.close()
