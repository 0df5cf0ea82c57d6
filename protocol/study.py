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
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pipeline.engine import EngineConfig, HardwareEngine, SimEngine, build_sim_engine
from pipeline.hardware import HardwareConfig
from pipeline.sim.rig import SimRigConfig
from protocol.config import ProtocolConfig, protocol_from_dict
from protocol.design import TrialSpec, build_schedule, requeue_aborted, schedule_from_json, schedule_to_json
from protocol.participant import SimulatedParticipant
from protocol.session import SessionRunner, first_unfinished, has_samples
from protocol.storage import Recorder, SessionInfo, StorageError, StudyDatabase, trial_id_of, validate_code
from protocol.version import software_version

__all__ = [
    "StudyProgress", "StudyWorkerError", "config_record", "default_jobs", "participant_code", "participant_seeds", "prepare_resume", "real_config_record", "resume_session", "run_study",
    "software_version", "training_schedule",
]

#: Records per step of the headless driver (the runner reads the ring this often).
BLOCK_TICKS = 50
#: Fault injection for the crash-safety test: SIGKILL this process after this many loop ticks
#: (in a parallel study: the study's main process, after this many ticks of one worker).
KILL_ENV = "HAPTIC_STUDY_SIGKILL_AFTER_TICKS"
#: Fault injection for the error-path test: raise an exception in the session driver after this many loop ticks.
RAISE_ENV = "HAPTIC_STUDY_RAISE_AFTER_TICKS"
#: Set in a parallel study's worker: the process the fault injection kills (the study's main process).
_kill_target_pid: int | None = None


def participant_code(number: int) -> str:
    """Pseudonymous code of the n-th simulated participant (P01, P02, …)."""
    return f"P{number:02d}"


def participant_seeds(study_seed: int, number: int) -> tuple[int, int]:
    """(rig seed, participant seed) for a participant: independent streams from one study seed."""
    s = np.random.SeedSequence([study_seed, number]).generate_state(2)
    return int(s[0]), int(s[1])


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


def training_schedule(protocol: ProtocolConfig) -> list[TrialSpec]:
    """Free practice: each mode in turn, each target once, with the live force aid."""
    out = []
    for m in protocol.modes:
        for t in protocol.targets:
            out.append(TrialSpec(len(out), t.label, t.force_n, m))
    return out


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
    tick_budget: list[int],
) -> None:
    """Alternate loop ticks and runner blocks until the session ends."""
    ring = eng.ring
    assert ring is not None
    loop = eng.loop
    cursor = ring.write_count
    t_last_report = 0.0
    kill_after = int(os.environ.get(KILL_ENV, "0") or 0)
    raise_after = int(os.environ.get(RAISE_ENV, "0") or 0)
    base_done = progress.study_trials_done
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
                raise RuntimeError(f"the session runner fell {res.lost} records behind the loop")
            n = len(res.rows)
            runner.process(res.rows)
            progress.study_time_s += n * 1e-3
            tick_budget[0] += n
            if kill_after and tick_budget[0] >= kill_after:
                # in a parallel study's worker: kill the study's main process, as `kill -9` of
                # `haptic-study run` would (the workers then die with it, by PR_SET_PDEATHSIG)
                os.kill(_kill_target_pid or os.getpid(), signal.SIGKILL)
            if raise_after and tick_budget[0] >= raise_after:
                raise RuntimeError(f"fault injected by {RAISE_ENV} after {tick_budget[0]} ticks")
            now = time.monotonic()
            done = runner.state.completed + runner.state.aborted
            if on_progress is not None and (now - t_last_report > 0.1 or runner.done):
                t_last_report = now
                progress.trials_done = done
                progress.trials_total = runner.state.trials_total
                progress.study_trials_done = base_done + done
                on_progress(progress)
        progress.study_trials_done = base_done + runner.state.completed + runner.state.aborted
    finally:
        if clock == "real":
            loop.stop()
        else:
            loop.ramp_down()
        eng.rig.close()


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
    db: StudyDatabase, *, code: str, number: int, kind: str, protocol: ProtocolConfig, study_seed: int, clock: str,
    progress: StudyProgress, on_progress: Callable[[StudyProgress], None] | None, tick_budget: list[int],
    short_transactions: bool = False,
) -> int:
    rig_seed, p_seed = participant_seeds(study_seed, number)
    eng = _engine(rig_seed + (1 if kind == "training" else 0), clock)
    participant = SimulatedParticipant(seed=p_seed)
    eng.rig.set_driver(participant)
    if kind == "experiment":
        schedule = build_schedule(protocol, study_seed, number)
        run_protocol = protocol
    else:
        schedule = training_schedule(protocol)
        run_protocol = _training_protocol(protocol)
    session_id = db.create_session(
        code=code, kind=kind, seed=study_seed, participant_number=number, protocol_json=run_protocol.to_json(),
        schedule_json=schedule_to_json(schedule), software_version=software_version(), rig="sim",
        config=config_record(eng, clock, rig_seed, p_seed), calibration=eng.calibration.to_dict(),
    )
    progress.sessions.append(session_id)
    recorder = Recorder(db, threaded=(clock == "real"), short_transactions=short_transactions)
    runner = SessionRunner(
        protocol=run_protocol, schedule=schedule, session_id=session_id, recorder=recorder, submit=eng.loop.submit,
        participant=participant, participant_time=lambda: eng.rig.sim_time_s, seed=study_seed,
    )
    runner.live_force_aid = kind == "training" and protocol.training.live_force_aid
    recorder.event(session_id, 0.0, "session_start", f"{kind} session for {code}, seed {study_seed}")
    progress.kind = kind
    try:
        _drive(eng, runner, clock, progress, on_progress, tick_budget)
    finally:
        recorder.close()
    return session_id


def _training_protocol(protocol: ProtocolConfig) -> ProtocolConfig:
    """The protocol a training session runs (and stores): trials last the training's time per target and mode."""
    return dataclasses.replace(
        protocol, trial=dataclasses.replace(protocol.trial, max_trial_s=protocol.training.seconds_per_target_per_mode)
    )


def _resume_run(
    db: StudyDatabase, info: SessionInfo, *, clock: str, progress: StudyProgress,
    on_progress: Callable[[StudyProgress], None] | None, tick_budget: list[int], short_transactions: bool = False,
) -> int:
    """Continue one interrupted session (either kind) to its end with a fresh rig and the same participant."""
    protocol, schedule, pos, offset = prepare_resume(db, info)
    rig_seed, p_seed = participant_seeds(info.seed, info.participant_number)
    # a fresh rig (re-calibrated, its own seed) and the same participant (same seed, same parameters)
    eng = _engine(rig_seed + (3 if info.kind == "training" else 2), clock)
    participant = SimulatedParticipant(seed=p_seed)
    eng.rig.set_driver(participant)
    recorder = Recorder(db, threaded=(clock == "real"), short_transactions=short_transactions)
    runner = SessionRunner(
        protocol=protocol, schedule=schedule, session_id=info.session_id, recorder=recorder, submit=eng.loop.submit,
        start_position=pos, session_clock_offset_s=offset + 0.001, participant=participant,
        participant_time=lambda: eng.rig.sim_time_s, seed=info.seed,
    )
    runner.live_force_aid = info.kind == "training" and protocol.training.live_force_aid
    progress.kind = info.kind
    progress.sessions.append(info.session_id)
    try:
        _drive(eng, runner, clock, progress, on_progress, tick_budget)
    finally:
        recorder.close()
    return info.session_id


def _remaining_trials(db: StudyDatabase, info: SessionInfo) -> int:
    """Trials a resume of this session will run.

    An interrupted trial is stored as aborted by :func:`prepare_resume`, not
    run, and its re-run takes its place in the count.
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
    wanted = {"training": json.loads(_training_protocol(protocol).to_json()), "experiment": json.loads(protocol.to_json())}
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
    progress: StudyProgress, on_progress: Callable[[StudyProgress], None] | None, tick_budget: list[int],
    short_transactions: bool = False,
) -> None:
    """Run one participant's steps in order: new sessions from the protocol, resumes from what is stored."""
    code = participant_code(number)
    for what, arg in steps:
        if what == "new":
            _run_session(db, code=code, number=number, kind=arg, protocol=protocol, study_seed=seed, clock=clock,
                         progress=progress, on_progress=on_progress, tick_budget=tick_budget,
                         short_transactions=short_transactions)
        else:
            info = next(s for s in db.sessions_of(code) if s.session_id == arg)
            _resume_run(db, info, clock=clock, progress=progress, on_progress=on_progress, tick_budget=tick_budget,
                        short_transactions=short_transactions)


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

    Returns
    -------
    StudyProgress
        The final progress; ``sessions`` lists the session ids in participant
        order (training before experiment), whatever order they were allocated
        in; when continuing, the sessions kept from before come first.

    Raises
    ------
    StorageError
        Before anything is stored, if the database cannot be used or one of
        the participant codes already has sessions in it (without
        ``continue_study``), or, when continuing, the stored sessions were run
        with another seed or protocol.
    StudyWorkerError
        If a participant's worker fails: the other workers are stopped (their
        sessions stay ``running``); ``continue_study`` completes the study.
    """
    if participants < 1:
        raise ValueError(f"participants = {participants}: must be ≥ 1")
    if jobs is not None and jobs < 1:
        raise ValueError(f"jobs = {jobs}: must be ≥ 1 (or None for the usable cores)")
    n_jobs = default_jobs(participants) if jobs is None else min(jobs, participants)
    if continue_study and not os.path.exists(db_path):
        raise StorageError(f"cannot continue a study: no database at {db_path}")
    db = StudyDatabase(db_path)
    try:
        progress = StudyProgress(participants_total=participants, planned_s=planned_study_time_s(protocol, participants))
        if continue_study:
            plan, progress.study_trials_total, kept = _plan_continue(db, db_path, participants, seed, protocol)
            progress.sessions.extend(kept)
        else:
            for n in range(1, participants + 1):
                code = participant_code(n)
                if db.sessions_of(code):
                    raise StorageError(
                        f"{db_path} already holds sessions for participant {code}; nothing was changed "
                        f"(use a new database, or the same command with --continue to complete the study)"
                    )
            plan = {n: _all_steps(protocol) for n in range(1, participants + 1)}
            per = protocol.trials_per_participant + (len(training_schedule(protocol)) if protocol.training.enabled else 0)
            progress.study_trials_total = per * participants
        jobs_used = min(n_jobs, len(plan))
        if jobs_used > 1:
            db.close()  # the workers open their own connections; none is carried across fork
            return _run_parallel(db_path, plan=plan, seed=seed, protocol=protocol, clock=clock,
                                 on_progress=on_progress, jobs=jobs_used, progress=progress)
        ticks = [0]
        for n, steps in plan.items():
            progress.participant, progress.code = n, participant_code(n)
            _run_steps(db, n, steps, protocol=protocol, seed=seed, clock=clock, progress=progress,
                       on_progress=on_progress, tick_budget=ticks)
        return progress
    finally:
        db.close()


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
    messages: Any,
) -> None:
    """One participant's steps (training, then experiment; or what is left of them) in a worker process.

    Reports through ``messages``.

    Messages: ``("progress", number, kind, trials_done, trials_total, participant_trials_done, study_time_s)``,
    ``("done", number, session ids, participant_trials_done, study_time_s)``, ``("error", number, message)``.
    """
    global _kill_target_pid
    _die_with_parent(parent_pid)
    _kill_target_pid = parent_pid
    code = participant_code(number)
    progress = StudyProgress(participants_total=1, participant=number, code=code)

    def report(p: StudyProgress) -> None:
        messages.put(("progress", number, p.kind, p.trials_done, p.trials_total, p.study_trials_done, p.study_time_s))

    try:
        db = StudyDatabase(db_path)
        try:
            _run_steps(db, number, steps, protocol=protocol, seed=seed, clock=clock, progress=progress,
                       on_progress=report, tick_budget=[0], short_transactions=True)
        finally:
            db.close()
    except BaseException as exc:  # noqa: BLE001 - reported to the parent, which stops the study
        messages.put(("error", number, f"{type(exc).__name__}: {exc}"))
        messages.close()
        messages.join_thread()
        os._exit(1)
    messages.put(("done", number, list(progress.sessions), progress.study_trials_done, progress.study_time_s))
    messages.close()
    messages.join_thread()


def _run_parallel(
    db_path: str, *, plan: dict[int, list[Step]], seed: int, protocol: ProtocolConfig, clock: str,
    on_progress: Callable[[StudyProgress], None] | None, jobs: int, progress: StudyProgress,
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
            running.pop(n).join()
        else:
            return (n, msg[2])
        return None

    try:
        while failure is None and (waiting or running):
            while waiting and len(running) < jobs:
                n = waiting.pop(0)
                p = ctx.Process(target=_participant_worker, name=f"study-{participant_code(n)}",
                                args=(db_path, n, plan[n], seed, protocol, clock, os.getpid(), messages), daemon=True)
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
) -> StudyProgress:
    """Continue the interrupted session of participant ``code`` (training or experiment).

    The stored schedule is used; trials already stored are kept; a trial that
    was interrupted mid-way (samples but no summary) is stored as aborted with
    the reason and re-run per the abort policy; no trial is duplicated or
    skipped.  Only that session is continued: a participant interrupted in
    training still has the experiment to run (``run_study(...,
    continue_study=True)``, ``haptic-study run --continue``).
    """
    validate_code(code)
    if not os.path.exists(db_path):
        raise StorageError(f"cannot resume {code}: no database at {db_path}")
    db = StudyDatabase(db_path)
    try:
        open_ = [s for s in db.sessions_of(code) if s.status == "running"]
        if not open_:
            known = db.participant_id(code, create=False)
            what = "no such participant" if known is None else "no interrupted session"
            raise StorageError(f"cannot resume {code} in {db_path}: {what}")
        info = open_[-1]
        remaining = _remaining_trials(db, info)
        progress = StudyProgress(participants_total=1, participant=info.participant_number, code=code, kind=info.kind,
                                 study_trials_total=remaining)
        protocol = protocol_from_dict(json.loads(info.protocol_json), f"session {info.session_id} protocol")
        progress.planned_s = remaining * (protocol.trial.max_trial_s + protocol.trial.pause_s)
        _resume_run(db, info, clock=clock, progress=progress, on_progress=on_progress, tick_budget=[0])
        return progress
    finally:
        db.close()


def prepare_resume(db: StudyDatabase, info: SessionInfo) -> tuple[ProtocolConfig, list[TrialSpec], int, float]:
    """Get an interrupted session ready to continue: (protocol, schedule, start position, clock offset s).

    A trial that was interrupted mid-way (samples but no summary) is stored as
    aborted with the reason and re-queued per the abort policy, in one
    transaction; otherwise a ``resume`` event records where the session continues.
    Used by :func:`resume_session` and by the GUI's study engine.
    """
    protocol = protocol_from_dict(json.loads(info.protocol_json), f"session {info.session_id} protocol")
    schedule = schedule_from_json(info.schedule_json)
    rows = db.trial_rows(info.session_id)
    pos = first_unfinished(schedule, rows)
    offset = db.last_session_time_s(info.session_id) + 1.0
    if pos < len(schedule) and has_samples(db, info.session_id, schedule[pos].index):
        spec = schedule[pos]
        reason = "interrupted: the previous run ended during this trial"
        schedule = requeue_aborted(schedule, spec, spec.index + 1, protocol.abort_policy,
                                   np.random.default_rng([info.seed, info.session_id, 7]))
        with db.transaction():
            db.insert_trial({
                "trial_id": trial_id_of(info.session_id, spec.index), "session_id": info.session_id,
                "trial_index": spec.index, "target_label": spec.target_label,
                "target_force_n": spec.target_force_n, "haptic_mode": spec.haptic_mode, "outcome": "aborted",
                "started_at_s": offset, "ended_at_s": offset, "abort_reason": reason, "repeat_of": spec.repeat_of,
            })
            db.update_schedule(info.session_id, schedule_to_json(schedule))
            db.insert_event(info.session_id, offset, "resume", f"trial {spec.index} aborted ({reason}) and re-queued")
        pos += 1
    else:
        db.insert_event(info.session_id, offset, "resume", f"continuing at trial position {pos}")
    return protocol, schedule, pos, offset
