"""One session of a headless study on the simulated rig, driven on the virtual or the real clock.

:func:`run_session` builds a fresh simulated rig (calibrating its payload),
hands the stylus to a :class:`pipeline.sim.participant.SimulatedParticipant`,
opens the session through :mod:`protocol.runner.session_setup` (as the GUI's engine
does) and alternates loop ticks and runner blocks until the session ends.
Planned faults (:mod:`protocol.runner.rehearsal`) are fired on the rig at their
trial's time.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from pipeline.assembly.engine import Engine, EngineConfig, build_sim_engine
from pipeline.assembly.sim_config import sim_rig_config
from pipeline.devices.rig import SINGLE_ARM_NAME
from pipeline.force.config import FrameworkConfig
from pipeline.sim.faults import latch_delay_s
from pipeline.sim.learning import Practice
from pipeline.sim.participant import SimulatedParticipant
from protocol.runner.rehearsal import FaultPlan, RehearsalTrigger
from protocol.runner.session import SessionRunner
from protocol.runner.session_driver import SessionDriver
from protocol.runner.session_lsl import attach_lsl, detach_lsl, lsl_skipped
from protocol.runner.session_setup import (
    OpenedSession,
    delivery_limits,
    finish_session,
    open_new_session,
    open_resumed_session,
    participant_code,
    participant_seeds,
    raw_wrench_scales,
    rehearsal_note,
    start_runner,
    store_rehearsal_plan,
    training_schedule,
)
from protocol.storage import StudyDatabase, new_owner_token
from protocol.storage.annotations import covariates_by_code
from protocol.study.config import ProtocolConfig
from protocol.study.groups import simulated_covariates, simulated_profile
from study_app.engine.session_config import config_record, with_profile
from study_app.headless.plan import Step

__all__ = [
    "BLOCK_TICKS", "VIRTUAL_COMMIT_S", "SessionInterrupted", "StudyProgress", "planned_study_time_s", "run_session",
    "run_steps", "set_kill_target", "sim_arms_of",
]

#: Records per step of the headless driver (the runner reads the ring this often).
BLOCK_TICKS = 50
#: On the virtual clock, records wait at most this long (of their own time) for their commit, s: about the live
#: 100 ms of wall clock at the virtual clock's speed (each commit rewrites the open block: every 100 ms of
#: records would double what storing costs).  A session rehearsing a ``kill`` commits every 100 ms, as live.
VIRTUAL_COMMIT_S = 2.0
#: Set in a parallel study's worker (:func:`set_kill_target`): the process a planned ``kill`` ends.
_kill_target_pid: int | None = None


def set_kill_target(pid: int) -> None:
    """In a parallel study's worker: a planned ``kill`` ends ``pid`` (the study's main process), as ``kill -9``
    would."""
    global _kill_target_pid
    _kill_target_pid = pid


class SessionInterrupted(RuntimeError):
    """A session stopped early and stays resumable (a fault that did not clear); the message says why."""


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
    if protocol.parts:  # each part as a study of its own kind (its training part: the training alone), per visit
        parts = protocol.plan_for(1, 0) if protocol.visits else protocol.parts
        return sum(_part_time_s(p) for p in parts) * participants
    tr = protocol.trial
    per = protocol.trials_per_participant * (tr.max_trial_s + tr.pause_s)
    if protocol.training.enabled:
        per += len(training_schedule(protocol)) * (protocol.training.seconds_per_target_per_mode + tr.pause_s)
    return per * participants


def _part_time_s(part: ProtocolConfig) -> float:
    """Upper bound of one part's simulated time (:func:`planned_study_time_s`)."""
    tr = part.trial
    if part.part is not None and part.part.session == "training":
        return len(training_schedule(part)) * (part.training.seconds_per_target_per_mode + tr.pause_s)
    return part.trials_per_participant * (tr.max_trial_s + tr.pause_s)


def _engine(rig_seed: int, clock: str, arms: tuple[str, ...], framework: FrameworkConfig) -> Engine:
    """A fresh simulated rig with ``arms`` (the task arm first: the participant holds its stylus, its ring is the
    session's records, its seed is the one-arm rig's) running the pipeline ``framework``."""
    return build_sim_engine(
        EngineConfig(sim=sim_rig_config(rig_seed), clock=clock, driver="hold", haptics_on=False, refine_bias=True,
                     ring_seconds=30.0, arms=arms, framework=framework)
    )


def sim_arms_of(protocol: ProtocolConfig, arms: Sequence[str]) -> tuple[str, ...]:
    """The simulated rig's arms for ``protocol``, its task arm first (a bad task arm: one
    :class:`protocol.study.config.ProtocolError` line)."""
    task = protocol.task_arm_of(arms)
    return (task, *(a for a in arms if a != task))


def _drive(
    eng: Engine, runner: SessionRunner, clock: str, progress: StudyProgress,
    on_progress: Callable[[StudyProgress], None] | None,
    trigger: RehearsalTrigger | None = None, on_first_tick: Callable[[], None] | None = None,
) -> None:
    """Alternate loop ticks and runner blocks until the session ends (``on_first_tick``: called once the real-clock
    loop has ticked, before the runner's first block: the run's LSL is opened there, on the loop's clock)."""
    ring = eng.ring
    assert ring is not None
    loop = eng.loop
    others = tuple((name, rg, loop.arm(name).replay_log) for name, rg in eng.rings.items()
                   if rg is not None and rg is not ring)
    driver = SessionDriver(ring, loop.replay_log, others)
    loop.on_event = driver.on_loop_event  # a deque's append is atomic: safe from the real-clock loop thread
    t_last_report = 0.0
    base_done = progress.study_trials_done
    planned = runner.state.trials_total  # re-runs of aborted trials add to the study's trials as they are queued
    if trigger is not None:
        runner.listeners.append(trigger.on_runner_event)
    if clock == "real":
        loop.start()
    try:
        if on_first_tick is not None:
            _await_first_tick(ring)
            on_first_tick()
        while not runner.done:
            if clock == "virtual":
                loop.run_ticks(BLOCK_TICKS)
            else:
                time.sleep(0.02)
            block = driver.feed(runner, trigger=trigger)
            n = len(block.rows)
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


def _await_first_tick(ring: Any, wait_s: float = 5.0) -> None:
    """Wait (bounded) until the real-clock loop has written its first record (its clock's zero, ``t0_ns``, is set)."""
    deadline = time.monotonic() + wait_s
    while ring.write_count == 0 and time.monotonic() < deadline:
        time.sleep(0.001)


def run_session(
    db: StudyDatabase, *, code: str, number: int, kind: str | None, protocol: ProtocolConfig, study_seed: int,
    clock: str, progress: StudyProgress, on_progress: Callable[[StudyProgress], None] | None,
    short_transactions: bool = False, resume_id: int | None = None, lease_owner: str, study_owner: str | None = None,
    faults: Sequence[FaultPlan] = (), sim_arms: Sequence[str] = (SINGLE_ARM_NAME,),
    framework: FrameworkConfig | None = None, covariates: Mapping[str, str] | None = None,
    events: Sequence[tuple[str, str]] = (),
) -> int:
    """Run one session to its end on a fresh simulated rig with ``sim_arms``: a new one of ``kind``, or the
    interrupted ``resume_id`` (on the arms it ran on).

    ``framework`` is the pipeline's configuration (default: the paper's), stored in the session's ``config_json``.
    The simulated participant is described by the protocol's covariates as its rule draws them
    (:func:`protocol.study.groups.simulated_covariates`: a grouping covariate placed in turn), ``covariates`` (text
    by name) given instead where named; its group (``[groups]``) decides its profile (:mod:`pipeline.sim.experience`),
    and answers the questionnaires by its rule (:mod:`protocol.study.sim_answers`).  ``events`` are stored with a
    new session (a visit's day and deviation, :mod:`study_app.headless.plan_visits`).
    """
    fw = framework or FrameworkConfig()
    rig_seed, p_seed = participant_seeds(study_seed, number)
    if resume_id is None:
        assert kind is not None
        arms = sim_arms_of(protocol, sim_arms)
        # training and experiment each get their own rig: the same seed gives the same study whatever ran before
        eng = _engine(rig_seed + (1 if kind == "training" else 0), clock, arms, fw)
        given = {**simulated_covariates(protocol.covariates, protocol.groups, study_seed, number),
                 **(covariates or {})}
        opened = open_new_session(
            db, code=code, number=number, kind=kind, protocol=protocol, seed=study_seed, rig="sim",
            config=with_profile(config_record(eng, clock, rig_seed, p_seed), protocol.groups, given),
            calibration=eng.calibration.to_dict(), lease_owner=lease_owner, study_owner=study_owner,
            covariates=given, events=events,
        )
    else:
        info = next(s for s in db.sessions_of(code) if s.session_id == resume_id)
        # a fresh rig (re-calibrated, its own seed) and the same participant (same seed, same parameters)
        arms = info.arms
        eng = _engine(rig_seed + (3 if info.kind == "training" else 2), clock, arms, fw)
        opened = open_resumed_session(db, resume_id, lease_owner=lease_owner, study_owner=study_owner,
                                      calibration=eng.calibration.to_dict())
    # the participant's group, as stored, decides the simulated profile (:mod:`protocol.study.groups`)
    stored = covariates_by_code(db.conn).get(opened.code, {})
    participant = SimulatedParticipant(seed=opened.participant_seed,
                                       profile=simulated_profile(opened.protocol.groups, stored),
                                       practice=practice_of(opened.protocol))
    eng.rig.set_driver(participant)
    progress.sessions.append(opened.session_id)
    progress.kind = opened.kind
    recorder, runner = start_runner(
        db, opened, submit=eng.loop.submit, participant=participant, participant_time=lambda: eng.rig.sim_time_s,
        limits=delivery_limits(eng.loop), auto_reset_faults=True, threaded=(clock == "real"),
        short_transactions=short_transactions, scales=raw_wrench_scales(eng.rig.sensor), arms=arms,
        simulated_answers=True, **_commit_deadline(eng, clock, faults, opened),
    )
    trigger = _trigger(faults, opened, eng, runner)
    lsl = None
    if opened.protocol.lsl.on and clock == "real":
        lsl = lambda: attach_lsl(runner, opened, eng.loop.t0_ns)  # noqa: E731  (once the loop has ticked)
    elif opened.protocol.lsl.on:
        lsl_skipped(runner, opened)
    try:
        _drive(eng, runner, clock, progress, on_progress, trigger, on_first_tick=lsl)
    finally:
        try:
            detach_lsl(runner)
        finally:
            finish_session(db, recorder, opened)
    if runner.stop_reason:
        raise SessionInterrupted(f"{opened.code}'s {opened.kind} session {opened.session_id}: {runner.stop_reason}")
    return opened.session_id


def practice_of(protocol: ProtocolConfig) -> Practice | None:
    """Where in a schedule of visits a session is, for the simulated participant's learning
    (:mod:`pipeline.sim.learning`): its stored visit's number and planned days since the previous visit (so a
    resumed session meets the same participant); None in a study without visits."""
    return Practice.at(protocol.visit)


def _commit_deadline(eng: Engine, clock: str, faults: Sequence[FaultPlan], opened: OpenedSession) -> dict[str, Any]:
    """The recorder's commit deadline for a session run (:func:`protocol.runner.session_setup.start_runner`'s
    arguments).

    On the virtual clock it runs on the records' own time, so the commits fall on the same records every
    time (a crash at the N-th commit is one state: ``tests/protocol/test_crash_points.py``): every
    :data:`VIRTUAL_COMMIT_S` of records -- about what the wall clock's 100 ms are at the virtual clock's
    speed, so a run costs what it did -- and every 100 ms of them, as live, in a session where a ``kill`` is
    rehearsed, so the rehearsal loses what a live crash would.  On the real clock: the loop's clock, 100 ms of
    records counted from their own ticks (however late the driver hands them over).
    """
    if clock != "virtual":  # the loop's own clock, its ticks dated on it (a crash loses 100 ms of ticks at most)
        loop_clock = eng.loop.clock
        return {"commit_clock": lambda: loop_clock.now_ns() * 1e-9, "dated": True}
    kill = any(f.kind == "kill" and f.code == opened.code and f.session == opened.kind for f in faults)
    return {"commit_clock": lambda: eng.loop.clock.now_ns() * 1e-9,
            "commit_interval_s": 0.1 if kill else VIRTUAL_COMMIT_S}


def _trigger(faults: Sequence[FaultPlan], opened: OpenedSession, eng: Engine,
             runner: SessionRunner) -> RehearsalTrigger | None:
    """The rehearsal trigger of a session run, if faults are planned for it (each stored as a
    :data:`~protocol.runner.study_rules.FAULT_REHEARSAL_EVENT` of the session)."""
    if not faults:
        return None
    loop, rig = eng.loop, eng.rig

    def inject(kind: str, at_ns: int) -> None:
        rig.inject_fault(kind, loop.t0_ns + at_ns)  # the records' axis -> the rig's clock

    def kill() -> None:
        # as `kill -9` of `haptic-study run` would: in a parallel study's worker, the study's main process (the
        # other workers then die with it, by PR_SET_PDEATHSIG), and this worker at once: left to PR_SET_PDEATHSIG,
        # it ran on and committed up to 0.35 s of records past the kill's moment (issue 42, class 8)
        from foundation.platform_support.processes import kill_hard

        sys.stdout.flush()
        sys.stderr.flush()
        if _kill_target_pid and _kill_target_pid != os.getpid():
            kill_hard(_kill_target_pid)
        kill_hard(os.getpid())

    def cancel(kind: str, at_ns: int) -> None:
        rig.cancel_fault(kind, loop.t0_ns + at_ns)

    wd = loop.watchdog

    def latch_s(kind: str) -> float:
        return latch_delay_s(kind, wd.sensor_max_age_s, wd.pose_max_age_s)

    trig = RehearsalTrigger.for_session(faults, opened.code, opened.kind, opened.start_position, inject, kill, cancel,
                                        max_trial_s=opened.protocol.trial.max_trial_s, latch_s=latch_s,
                                        note=rehearsal_note(runner))
    for plan in trig.plans:  # committed now: a planned kill ends the process before the session's next commit
        store_rehearsal_plan(runner, plan)
    return trig if trig.plans else None


def run_steps(
    db: StudyDatabase, number: int, steps: list[Step], *, protocol: ProtocolConfig, seed: int, clock: str,
    progress: StudyProgress, on_progress: Callable[[StudyProgress], None] | None, study_owner: str,
    faults: Sequence[FaultPlan] = (), short_transactions: bool = False, sim_arms: Sequence[str] = (SINGLE_ARM_NAME,),
    framework: FrameworkConfig | None = None, covariates: Mapping[str, str] | None = None,
) -> None:
    """Run one participant's steps in order: new sessions from the protocol (a part's: its protocol in the
    participant's order), resumes from what is stored."""
    code = participant_code(number)
    for what, arg in steps:
        kind, run_protocol = (arg if what == "new" else None), protocol
        events: tuple[tuple[str, str], ...] = ()
        if what == "part":  # a study of several parts: this participant's part, its place in their order
            run_protocol = protocol.part_of(arg, number, seed)
            assert run_protocol.part is not None
            kind = run_protocol.part.session
        elif what == "visit":  # a part in a visit of a schedule (plan_visits.VisitStep), with its visit's events
            run_protocol, events = protocol.part_of(arg.part, number, seed, arg.visit), arg.events
            assert run_protocol.part is not None
            kind = run_protocol.part.session
        run_session(db, code=code, number=number, kind=kind, protocol=run_protocol,
                    study_seed=seed, clock=clock, progress=progress, on_progress=on_progress,
                    short_transactions=short_transactions, resume_id=arg if what == "resume" else None,
                    lease_owner=new_owner_token(), study_owner=study_owner, faults=faults, sim_arms=sim_arms,
                    framework=framework, covariates=covariates, events=events)
