"""Headless studies on the simulated rig: participants, sessions, resume (``haptic-study run``).

``haptic-study run`` calls :func:`run_study`: for each participant it builds
the simulated rig (calibrating its payload), hands the stylus to a
:class:`pipeline.sim.participant.SimulatedParticipant`, stores a training session
(tagged ``kind = 'training'``, which analysis excludes) and the experiment
session, each with its whole schedule committed before the first trial, and
runs them on the virtual clock (as fast as the CPU allows) or in real time.
:func:`resume_session` continues a participant's interrupted session (training
or experiment) at its first unfinished trial: the interrupted trial is stored
as aborted, with the reason, and re-run per the abort policy.
``run_study(..., continue_study=True)`` (``haptic-study run --continue``)
completes a study that stopped part-way: it resumes every interrupted session,
runs what each participant has not started, and leaves finished sessions alone.

Sessions are opened and closed through :mod:`protocol.runner.session_setup`, as the
GUI's engine does.  A ``run`` owns the whole database while it works (the
``study`` lease): a second ``run`` on it is refused before it writes, and its
parallel workers hold their sessions' leases under it.  Planned faults
(:mod:`protocol.runner.rehearsal`, ``--inject-fault``) are fired on the simulated rig
at their trial's time; a latched fault is reset by the runner in the pause,
and a fault that does not clear stops the study with :class:`SessionInterrupted`.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from pipeline.devices.rig import SINGLE_ARM_NAME
from pipeline.force.config import FrameworkConfig
from protocol.runner.rehearsal import FaultPlan
from protocol.runner.session_setup import participant_code
from protocol.storage import StorageError, StudyDatabase, new_owner_token, validate_code
from protocol.study.config import ProtocolConfig, protocol_from_dict
from protocol.study.covariates import checked_values, simulated_values
from study_app.headless.cluster_study import run_on_cluster
from study_app.headless.plan import (
    Step,
    check_fault_plans,
    check_settings,
    interrupted_session_of,
    open_notes,
    peek,
    plan_study,
    remaining_trials,
)
from study_app.headless.plan_visits import VisitRequest, check_visit_request
from study_app.headless.pool import default_jobs, run_parallel
from study_app.headless.session_run import StudyProgress, planned_study_time_s, run_session, run_steps, sim_arms_of

__all__ = ["resume_session", "run_study", "run_visit"]


def run_study(
    db_path: str, *, participants: int, seed: int, protocol: ProtocolConfig, clock: str = "virtual",
    on_progress: Callable[[StudyProgress], None] | None = None, jobs: int | None = None, continue_study: bool = False,
    faults: Sequence[FaultPlan] = (), sim_arms: Sequence[str] = (SINGLE_ARM_NAME,),
    framework: FrameworkConfig | None = None, covariates: Mapping[str, str] | None = None, client: Any = None,
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
        Participants run at once, each in a worker process with its own connection
        and recorder (one WAL database).  None: the usable cores, at most
        ``participants``; 1: one after the other in this process.
    continue_study
        Complete a study that stopped part-way (a crash, a failed worker, an
        interrupted run) in the same database: every interrupted session is
        resumed (:func:`resume_session`), what a participant has not started
        is run, and finished sessions (completed, or ended by the
        experimenter) are left alone.  ``seed`` and ``protocol`` must be those
        the study was started with.
    faults
        Planned faults (:mod:`protocol.runner.rehearsal`) for the sessions this call runs.
    sim_arms
        The simulated rig's arms (one: ``right``), among them the protocol's task arm (a resume: the stored ones).
    framework
        Every session's pipeline configuration (default: the paper's; stored sessions must have the same).
    covariates
        Values (by name, as text) every participant this call registers is given for the protocol's covariates
        (``run --covariate``): the others are drawn by the simulated participants' rule
        (:func:`protocol.study.covariates.simulated_values`).  Checked before anything is stored.
    client
        A ``distributed.Client``: the participants run on its Dask cluster (the virtual clock, no faults; ``jobs``
        unused), each merged here as it comes back (:mod:`study_app.headless.cluster_study`).

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
        with another seed, protocol or pipeline settings.
    StudyWorkerError
        A participant's worker failed: the others are stopped (their sessions
        stay ``running``); ``continue_study`` completes the study.
    SessionInterrupted
        A fault did not clear (one participant at a time; in parallel it is a
        :class:`StudyWorkerError`); ``continue_study`` completes the study.
    """
    return _run_study(db_path, participants=participants, seed=seed, protocol=protocol, clock=clock,
                      on_progress=on_progress, jobs=jobs, continue_study=continue_study, faults=faults,
                      sim_arms=sim_arms, framework=framework, covariates=covariates, client=client)


def run_visit(
    db_path: str, visit: VisitRequest, *, participants: int, seed: int, protocol: ProtocolConfig,
    clock: str = "virtual", on_progress: Callable[[StudyProgress], None] | None = None, jobs: int | None = None,
    sim_arms: Sequence[str] = (SINGLE_ARM_NAME,), framework: FrameworkConfig | None = None,
    covariates: Mapping[str, str] | None = None,
) -> StudyProgress:
    """Run one visit of a schedule (``run --visit``, :mod:`study_app.headless.plan_visits`) for participants 1 …
    ``participants``, continuing the study in ``db_path`` (created for the first visit): what is left of that visit
    (interrupted sessions resumed, the rest run), held on ``visit.day`` (None: today's study day).  A visit out of
    order or outside its window is refused (:class:`protocol.runner.study_rules.StudyRuleError`, nothing written)
    unless ``visit.deviation`` gives the reason, stored as a deviation.  The other arguments are
    :func:`run_study`'s."""
    return _run_study(db_path, participants=participants, seed=seed, protocol=protocol, clock=clock,
                      on_progress=on_progress, jobs=jobs, continue_study=False, faults=(), sim_arms=sim_arms,
                      framework=framework, covariates=covariates, client=None, visit=visit)


def _run_study(
    db_path: str, *, participants: int, seed: int, protocol: ProtocolConfig, clock: str,
    on_progress: Callable[[StudyProgress], None] | None, jobs: int | None, continue_study: bool,
    faults: Sequence[FaultPlan], sim_arms: Sequence[str], framework: FrameworkConfig | None,
    covariates: Mapping[str, str] | None, client: Any, visit: VisitRequest | None = None,
) -> StudyProgress:
    """:func:`run_study` or :func:`run_visit`: refusals first, then the run under the study's lease."""
    given = {name: str(v) for name, v in (covariates or {}).items()}
    n_jobs = _checked_request(db_path, participants, jobs, continue_study, faults, protocol, given, (client, clock))
    check_visit_request(protocol, visit)
    fw, arms, first_plan, first_kept = _first_look(db_path, participants, seed, protocol, continue_study, framework,
                                                   sim_arms, visit)
    if (continue_study or visit is not None) and not first_plan:  # nothing left to run: nothing to write either
        return StudyProgress(participants_total=participants, sessions=list(first_kept))
    return _run_under_lease(db_path, participants=participants, seed=seed, protocol=protocol, clock=clock,
                            on_progress=on_progress, jobs=n_jobs, continue_study=continue_study, faults=faults,
                            sim_arms=arms, framework=fw, covariates=given, client=client, visit=visit)


def _first_look(db_path: str, participants: int, seed: int, protocol: ProtocolConfig, continue_study: bool,
                framework: FrameworkConfig | None, sim_arms: Sequence[str], visit: VisitRequest | None = None,
                ) -> tuple[FrameworkConfig, tuple[str, ...], dict[int, list[Step]], list[int]]:
    """Every refusal decided on a read-only look first (a refused command leaves the file byte-identical): the
    pipeline, the arms, and the plan with the sessions kept from before."""
    protocol.check_ramps((fw := framework or FrameworkConfig()).safety, "protocol with the pipeline's settings")
    arms = sim_arms_of(protocol, sim_arms)  # a bad task arm: refused before anything is stored
    first_plan, _, first_kept = plan_study(peek(db_path), db_path, participants, seed, protocol, continue_study, fw,
                                           arms, visit)
    return fw, arms, first_plan, first_kept


def _check_cluster_request(client: Any, clock: str, faults: Sequence[FaultPlan]) -> None:
    """A study on a Dask cluster runs on the virtual clock, without planned faults (their kill is this process's)."""
    if client is not None and (clock != "virtual" or faults):
        raise ValueError("--scheduler: a study on a Dask cluster runs on the virtual clock without planned faults "
                         f"(given: --clock {clock}{', --inject-fault' if faults else ''}); run it on this machine")


def _checked_request(db_path: str, participants: int, jobs: int | None, continue_study: bool,
                     faults: Sequence[FaultPlan], protocol: ProtocolConfig, covariates: dict[str, str],
                     cluster: tuple[Any, str] = (None, "virtual")) -> int:
    """Refuse a request :func:`run_study` cannot run (before anything is opened; ``cluster``: its Dask client and
    clock, :func:`_check_cluster_request`); the workers it runs at once."""
    # a value given for every participant: outside its declaration, one line (the drawn ones fit by their rule)
    checked_values(protocol.covariates, {**simulated_values(protocol.covariates, 0, 1), **covariates})
    if participants < 1:
        raise ValueError(f"participants = {participants}: must be ≥ 1")
    if jobs is not None and jobs < 1:
        raise ValueError(f"jobs = {jobs}: must be ≥ 1 (or None for the usable cores)")
    check_fault_plans(faults, protocol, [participant_code(n) for n in range(1, participants + 1)])
    _check_cluster_request(*cluster, faults)
    if continue_study and not os.path.exists(db_path):
        raise StorageError(f"cannot continue a study: no database at {db_path}")
    return default_jobs(participants) if jobs is None else min(jobs, participants)


def _run_under_lease(
    db_path: str, *, participants: int, seed: int, protocol: ProtocolConfig, clock: str,
    on_progress: Callable[[StudyProgress], None] | None, jobs: int, continue_study: bool, faults: Sequence[FaultPlan],
    sim_arms: tuple[str, ...], framework: FrameworkConfig, covariates: dict[str, str], client: Any = None,
    visit: VisitRequest | None = None,
) -> StudyProgress:
    """:func:`run_study` once nothing refused it: take the study lease, plan again under it, run, give it back."""
    owner = new_owner_token()
    # just checked: the writer need not quick_check again; a version-1 file is upgraded (after a backup) only now
    db = StudyDatabase(db_path, check=False)
    held: StudyDatabase | None = db  # None once the workers have the database
    try:
        taken = db.acquire_lease("study", owner)  # a second `run` stops here
        progress = StudyProgress(participants_total=participants,
                                 planned_s=planned_study_time_s(protocol, participants))
        progress.notes.extend(open_notes(db, taken))
        # again under the lease: what another process did in between counts
        plan, progress.study_trials_total, kept = plan_study(db, db_path, participants, seed, protocol, continue_study,
                                                             framework, sim_arms, visit)
        progress.sessions.extend(kept)
        jobs_used = min(jobs, len(plan))
        if client is not None:
            return run_on_cluster(db, plan=plan, seed=seed, protocol=protocol, on_progress=on_progress,
                                  progress=progress, study_owner=owner, sim_arms=sim_arms, framework=framework,
                                  covariates=covariates, client=client)
        if jobs_used > 1:
            db.close()  # the workers open their own connections; none is carried across fork
            held = None
            return run_parallel(db_path, plan=plan, seed=seed, protocol=protocol, clock=clock,
                                on_progress=on_progress, jobs=jobs_used, progress=progress, study_owner=owner,
                                faults=faults, sim_arms=sim_arms, framework=framework, covariates=covariates)
        for n, steps in plan.items():
            progress.participant, progress.code = n, participant_code(n)
            run_steps(db, n, steps, protocol=protocol, seed=seed, clock=clock, progress=progress,
                      on_progress=on_progress, study_owner=owner, faults=faults, sim_arms=sim_arms, framework=framework,
                      covariates=covariates)
        return progress
    finally:
        _release_study(held, db_path, owner)


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



def resume_session(
    db_path: str,
    code: str,
    *,
    clock: str = "virtual",
    on_progress: Callable[[StudyProgress], None] | None = None,
    faults: Sequence[FaultPlan] = (),
    framework: FrameworkConfig | None = None,
) -> StudyProgress:
    """Continue the interrupted session of participant ``code`` (training or experiment).

    The stored schedule is used; trials already stored are kept; the trial that
    was running when the previous run ended is stored as aborted (cause
    ``interrupted``) with its real cue time and samples and re-run per the
    abort policy; no trial is duplicated or skipped
    (:func:`protocol.runner.session_setup.open_resumed_session`).  Only that session is
    continued: a participant interrupted in training still has the experiment
    to run (``run_study(..., continue_study=True)``, ``haptic-study run --continue``).

    Raises
    ------
    StorageError
        No such participant or interrupted session; the session ran with other pipeline settings than
        ``framework`` (default: the paper's); or another process writes
        to the session or runs the study (:class:`protocol.storage.LeaseHeld`): nothing is changed.
    SessionInterrupted
        A fault did not clear; the session stays resumable.
    """
    validate_code(code)
    if not os.path.exists(db_path):
        raise StorageError(f"cannot resume {code}: no database at {db_path}")
    # refusals are decided on a read-only look first: a refused command leaves the file byte-identical
    check_settings([interrupted_session_of(peek(db_path), db_path, code)], db_path, framework)
    db = StudyDatabase(db_path, check=False)
    try:
        info = interrupted_session_of(db, db_path, code)
        remaining = remaining_trials(db, info)
        progress = StudyProgress(participants_total=1, participant=info.participant_number, code=code, kind=info.kind,
                                 study_trials_total=remaining)
        progress.notes.extend(open_notes(db, ""))
        protocol = protocol_from_dict(json.loads(info.protocol_json), f"session {info.session_id} protocol")
        progress.planned_s = remaining * (protocol.trial.max_trial_s + protocol.trial.pause_s)
        run_session(db, code=code, number=info.participant_number, kind=None, protocol=protocol,
                     study_seed=info.seed, clock=clock, progress=progress, on_progress=on_progress,
                     resume_id=info.session_id, lease_owner=new_owner_token(), faults=faults,
                     framework=framework or FrameworkConfig())
        return progress
    finally:
        db.close()
