"""A study's participants over worker processes, one participant per process.

Each worker opens its own database connection and recorder (all write into
the same WAL database) and dies with the study's main process
(``PR_SET_PDEATHSIG``), so no orphan keeps writing.
"""

from __future__ import annotations

import os
import queue
import time
from collections.abc import Callable, Sequence
from typing import Any

from foundation.platform_support.processes import die_with, worker_context
from foundation.platform_support.threads import usable_cpu_count
from pipeline.force.config import FrameworkConfig
from pipeline.sim import block as sim_block
from protocol.runner.rehearsal import FaultPlan
from protocol.runner.session_setup import participant_code
from protocol.storage import StorageError, StudyDatabase
from protocol.study.config import ProtocolConfig
from study_app.headless.plan import Step
from study_app.headless.session_run import SessionInterrupted, StudyProgress, run_steps, set_kill_target

__all__ = ["StudyWorkerError", "default_jobs", "run_parallel"]


class StudyWorkerError(RuntimeError):
    """A participant's worker process failed in a parallel study; the message says which and what to resume."""


def default_jobs(participants: int) -> int:
    """Worker processes for a study: the usable cores, at most one per participant."""
    return max(1, min(usable_cpu_count(), participants))



def _participant_worker(
    db_path: str, number: int, steps: list[Step], seed: int, protocol: ProtocolConfig, clock: str, parent_pid: int,
    messages: Any, study_owner: str, faults: Sequence[FaultPlan], sim_arms: tuple[str, ...],
    framework: FrameworkConfig, covariates: dict[str, str],
) -> None:
    """One participant's steps (training, then experiment; or what is left of them) in a worker process.

    Reports through ``messages``.

    Messages: ``("progress", number, kind, trials_done, trials_total, participant_trials_done, study_time_s)``,
    ``("done", number, session ids, participant_trials_done, study_time_s, rehearsal reports)``,
    ``("error", number, message)``.
    """
    die_with(parent_pid)  # Linux: the kernel SIGKILLs this process when its parent dies: no orphan keeps writing
    set_kill_target(parent_pid)
    code = participant_code(number)
    progress = StudyProgress(participants_total=1, participant=number, code=code)

    def report(p: StudyProgress) -> None:
        messages.put(("progress", number, p.kind, p.trials_done, p.trials_total, p.study_trials_done, p.study_time_s))

    try:
        # the study's main process checked the file a moment ago: no second quick_check per worker
        db = StudyDatabase(db_path, check=False)
        try:
            run_steps(db, number, steps, protocol=protocol, seed=seed, clock=clock, progress=progress,
                       on_progress=report, study_owner=study_owner, faults=faults, short_transactions=True,
                       sim_arms=sim_arms, framework=framework, covariates=covariates)
        finally:
            db.close()
    except BaseException as exc:  # reported to the parent, which stops the study
        why = str(exc) if isinstance(exc, (SessionInterrupted, StorageError)) else f"{type(exc).__name__}: {exc}"
        messages.put(("error", number, why))
        messages.close()
        messages.join_thread()
        os._exit(1)
    messages.put(("done", number, list(progress.sessions), progress.study_trials_done, progress.study_time_s,
                  list(progress.rehearsals)))
    messages.close()
    messages.join_thread()


def _ended_workers(
    running: dict[int, Any], sessions: dict[int, list[int]], messages: Any,
    handle: Callable[[tuple[Any, ...]], tuple[int, str] | None],
) -> tuple[int, str] | None:
    """Workers that have ended: read what each wrote before it ended; one that died without a word is a failure."""
    for n, p in list(running.items()):
        if p.exitcode is None or n in sessions:
            continue
        failure = None
        try:  # its last words may still be in the pipe
            while failure is None and n not in sessions:
                failure = handle(messages.get(timeout=1.0))
        except queue.Empty:
            pass
        if failure is None and n not in sessions:  # died without a word (killed, crashed)
            failure = (n, f"its worker process ended with exit code {p.exitcode}")
        if failure is not None:
            return failure
    return None


def run_parallel(
    db_path: str, *, plan: dict[int, list[Step]], seed: int, protocol: ProtocolConfig, clock: str,
    on_progress: Callable[[StudyProgress], None] | None, jobs: int, progress: StudyProgress, study_owner: str,
    faults: Sequence[FaultPlan], sim_arms: tuple[str, ...], framework: FrameworkConfig,
    covariates: dict[str, str] | None = None,
) -> StudyProgress:
    """:func:`run_study` over ``jobs`` worker processes, one participant per process."""
    # fork is cheap (the workers inherit the imported modules) but unsafe once other threads exist
    ctx = worker_context()
    if ctx.get_start_method() == "fork":  # once here, not once a participant: the children inherit the machine code
        sim_block.warm_kernels()
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
                                      faults, sim_arms, framework, dict(covariates or {})), daemon=True)
                p.start()
                running[n] = p
            try:
                msg = messages.get(timeout=0.1)
            except queue.Empty:
                msg = None
            failure = handle(msg) if msg is not None else _ended_workers(running, sessions, messages, handle)
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
