"""A study's participants on a Dask cluster (``haptic-study run --scheduler``): each runs on a worker into a database
in the worker's scratch folder, comes back as that database's bytes, and is merged into the study's database here.

Why not let the workers write the study's database: it lives on the machine that asked (a cluster's workers share
no file system with it, and SQLite over a network file system breaks its locking), and the record has one writer
per session -- here, this process, which holds the study's lease throughout.  A participant is merged whole, in
one transaction (:func:`protocol.storage.merge.merge_participants`), so an interrupted cluster run leaves
participants either complete or absent, and ``--continue`` runs the absent ones.

A participant is the same computation on a worker as in this process (its seeds come from the study seed and
its number; the virtual clock's commits fall on its own records): the merged study's tables equal those of a run
on this machine, row for row, but for the session ids, which follow the order the participants come back in (as
a parallel run's follow the order they start in) and the wall-clock times (``tests/test_fanout.py``).

The workers write only under their scratch folder (:func:`tempfile.mkdtemp` in the Dask worker's own directory,
removed when the participant is done or failed; a worker killed under it leaves it to Dask, which removes a dead
worker's directory when it next starts one there).  Progress is counted by participant as each comes back;
Ctrl-C cancels the rest (:func:`study_app.headless.fanout.run_tasks`).
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pipeline.force.config import FrameworkConfig
from protocol.runner.session_setup import participant_code
from protocol.storage import StudyDatabase, new_owner_token
from protocol.storage.merge import database_bytes, merge_database_bytes
from protocol.study.config import ProtocolConfig
from study_app.headless.fanout import run_tasks
from study_app.headless.plan import Step
from study_app.headless.session_run import StudyProgress, run_steps

__all__ = ["SCRATCH_PREFIX", "run_on_cluster"]

#: A worker's scratch folder for a participant: ``tempfile.mkdtemp(prefix=...)`` in the worker's temporary folder.
SCRATCH_PREFIX = "haptic-study-participant-"

#: What a worker is given: the participant's number and steps, the study seed, protocol, arms, pipeline, covariates.
Task = tuple[int, list[Step], int, ProtocolConfig, tuple[str, ...], FrameworkConfig, dict[str, str]]


def participant_on_worker(task: Task) -> tuple[int, bytes, int, float]:
    """Run one participant into a new database in a scratch folder; (number, the database's bytes, trials run,
    simulated seconds).  The folder is removed before this returns."""
    number, steps, seed, protocol, sim_arms, framework, covariates = task
    scratch = tempfile.mkdtemp(prefix=SCRATCH_PREFIX, dir=_worker_directory())
    try:
        db = StudyDatabase(str(Path(scratch) / f"{participant_code(number)}.db"))
        try:
            owner = new_owner_token()
            db.acquire_lease("study", owner)
            progress = StudyProgress(participants_total=1, participant=number, code=participant_code(number))
            run_steps(db, number, steps, protocol=protocol, seed=seed, clock="virtual", progress=progress,
                      on_progress=None, study_owner=owner, sim_arms=sim_arms, framework=framework,
                      covariates=covariates)
            db.release_lease("study", owner)
            data = database_bytes(db)
        finally:
            db.close()
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return number, data, progress.study_trials_done, progress.study_time_s


def _worker_directory() -> str | None:
    """The Dask worker's own directory (None outside a worker: the temporary folder): a participant's folder left
    by a worker killed under it is removed by Dask when it next starts a worker there."""
    try:
        from distributed import get_worker

        return str(get_worker().local_directory)
    except (ImportError, ValueError):  # (ValueError: not in a worker)
        return None


def run_on_cluster(
    db: StudyDatabase, *, plan: dict[int, list[Step]], seed: int, protocol: ProtocolConfig,
    on_progress: Callable[[StudyProgress], None] | None, progress: StudyProgress, study_owner: str,
    sim_arms: tuple[str, ...], framework: FrameworkConfig, covariates: dict[str, str], client: Any,
) -> StudyProgress:
    """:func:`study_app.headless.study.run_study` with ``client``'s cluster running the participants.

    A participant with an interrupted session to resume (``--continue``) is resumed here, on this machine: its
    stored records are here.  The others run on the cluster and are merged as they come back.
    """
    sessions: dict[int, list[int]] = {}
    remote = [n for n, steps in plan.items() if all(what == "new" for what, _ in steps)]
    for n in (n for n in plan if n not in remote):
        progress.participant, progress.code = n, participant_code(n)
        before = len(progress.sessions)
        run_steps(db, n, plan[n], protocol=protocol, seed=seed, clock="virtual", progress=progress,
                  on_progress=on_progress, study_owner=study_owner, sim_arms=sim_arms, framework=framework,
                  covariates=covariates)
        sessions[n] = progress.sessions[before:]
        del progress.sessions[before:]

    def merge(result: tuple[int, bytes, int, float]) -> None:
        n, data, trials, time_s = result
        mapping = merge_database_bytes(db, data, f"{participant_code(n)} from the cluster")
        sessions[n] = sorted(mapping.values())
        progress.participant, progress.code, progress.kind = n, participant_code(n), "merged"
        progress.trials_done = progress.trials_total = trials  # (the participant's, as a bar's label shows them)
        progress.study_trials_done += trials
        progress.study_time_s += time_s
        if on_progress is not None:
            on_progress(progress)

    run_tasks(participant_on_worker, [(n, plan[n], seed, protocol, sim_arms, framework, covariates) for n in remote],
              merge, client=client, name="haptic-study-run")
    progress.sessions.extend(sid for n in plan for sid in sessions.get(n, []))
    return progress
