"""What a ``run`` will do before it writes: steps per participant, trials, sessions kept; refusals.

Every refusal is decided here on a read-only look at the database first, so a
refused command leaves the file byte-identical.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from typing import Any

from pipeline.devices.rig import SINGLE_ARM_NAME
from pipeline.force.config import FrameworkConfig
from protocol.runner.rehearsal import FaultPlan
from protocol.runner.session import first_unfinished
from protocol.runner.session_setup import (
    participant_code,
    refuse_damaged_recording,
    training_protocol,
    training_schedule,
)
from protocol.runner.study_rules import (
    StudyRuleError,
    check_arms,
    check_settings,
    seed_refusal,
    stored_sessions,
    training_refusal,
)
from protocol.storage import EmptyDatabase, SessionInfo, StorageError, StudyDatabase
from protocol.storage.reader import StudyReader
from protocol.storage.withdrawal import withdrawals
from protocol.study.config import ProtocolConfig, protocol_from_dict
from protocol.study.design import schedule_from_json
from study_app.headless.plan_parts import part_steps, parts_left
from study_app.headless.plan_visits import VisitRequest

__all__ = [
    "Step", "all_steps", "check_fault_plans", "check_settings", "interrupted_session_of", "open_notes", "peek",
    "plan_study", "remaining_trials",
]


def remaining_trials(db: StudyDatabase, info: SessionInfo) -> int:
    """Trials a resume of this session will run.

    An interrupted trial is stored as aborted by
    :func:`protocol.runner.session_setup.open_resumed_session`, not run, and its
    re-run takes its place in the count.
    """
    schedule = schedule_from_json(info.schedule_json)
    return len(schedule) - first_unfinished(schedule, db.trial_rows(info.session_id))



#: One step of a participant's part of a study: ("new", kind) or ("resume", session id); in a study of several
#: parts, ("part", name) (:mod:`study_app.headless.plan_parts`).
Step = tuple[str, Any]


def _plan_continue(
    db: StudyDatabase, db_path: str, participants: int, seed: int, protocol: ProtocolConfig,
    visit: VisitRequest | None = None,
) -> tuple[dict[int, list[Step]], int, list[int]]:
    """What is left of a study: steps per participant, trials they run, and the finished sessions kept.

    Raises :class:`StorageError`, before anything is written, when the stored
    sessions were made with another seed or protocol: continuing them with
    this one would mix two designs in one study.
    """
    kinds = ("training", "experiment") if protocol.training.enabled else ("experiment",)
    wanted = {"training": json.loads(training_protocol(protocol).to_json()),
              "experiment": json.loads(protocol.to_json())}
    plan: dict[int, list[Step]] = {}
    kept: list[int] = []
    trials = 0
    withdrawn = {w.code for w in withdrawals(db.conn)}
    for n in range(1, participants + 1):
        code = participant_code(n)
        if code in withdrawn:  # erased at their request: their number stays vacant, the others' schedules unchanged
            continue
        stored = db.sessions_of(code)
        for info in stored:
            if info.seed != seed:
                raise StorageError(
                    f"cannot continue: {code}'s {info.kind} session {info.session_id} in {db_path} was run with "
                    f"--seed {info.seed}, not {seed}; nothing was changed (give the seed the study was started with)"
                )
            if info.kind in wanted and not protocol.parts and _same_protocol(info.protocol_json) != wanted[info.kind]:
                raise StorageError(
                    f"cannot continue: {code}'s {info.kind} session {info.session_id} in {db_path} was run with "
                    f"another protocol; nothing was changed (give the --protocol the study was started with)"
                )
        if protocol.parts:  # a study of several parts: one session each, in the participant's order
            part_steps_left, left, kept_here = parts_left(db, db_path, protocol, n, seed, stored, remaining_trials,
                                                          visit)
            kept.extend(kept_here)
            trials += left
            if part_steps_left:
                plan[n] = part_steps_left
            continue
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
                refuse_damaged_recording(db, info.session_id)  # before anything is written (cannot continue it)
                steps.append(("resume", info.session_id))
                trials += remaining_trials(db, info)
            else:
                steps.append(("new", kind))
                trials += protocol.trials_per_participant if kind == "experiment" else len(training_schedule(protocol))
        if steps:
            plan[n] = steps
        _check_training(db, db_path, code, steps, protocol)
    return plan, trials, kept


def _same_protocol(stored_json: str) -> Any:
    """A stored protocol as this version writes it (fields added since, such as ``training.required``, filled in
    with the defaults the stored one meant), for comparing with the one given."""
    try:
        return json.loads(protocol_from_dict(json.loads(stored_json), "stored protocol").to_json())
    except ValueError:
        return json.loads(stored_json)


def _check_training(db: StudyDatabase, db_path: str, code: str, steps: list[Step], protocol: ProtocolConfig) -> None:
    """Refuse, before anything is written, a new experiment session the training rule would refuse
    (:mod:`protocol.runner.study_rules`): one whose training is neither completed nor run by this command."""
    if ("new", "experiment") not in steps or steps.index(("new", "experiment")) > 0:
        return  # no new experiment, or its training runs (or resumes) first in this command
    why = training_refusal(stored_sessions(db), code, protocol)
    if why:
        raise StudyRuleError(f"cannot continue: {why}; nothing was changed ({db_path})")



def all_steps(protocol: ProtocolConfig) -> list[Step]:
    """A participant's whole part of a study: training (if the protocol has one), then the experiment."""
    return [("new", "training"), ("new", "experiment")] if protocol.training.enabled else [("new", "experiment")]



def interrupted_session_of(db: StudyDatabase | None, db_path: str, code: str) -> SessionInfo:
    """The participant's interrupted session (the newest), or a :class:`StorageError` saying why there is none.

    A read-only ``db`` is closed afterwards.
    """
    try:
        open_ = [] if db is None else [s for s in db.sessions_of(code) if s.status == "running"]
        if not open_:
            known = None if db is None else db.participant_id(code, create=False)
            what = "no such participant" if known is None else "no interrupted session"
            raise StorageError(f"cannot resume {code} in {db_path}: {what}")
        assert db is not None
        refuse_damaged_recording(db, open_[-1].session_id)
        return open_[-1]
    finally:
        if db is not None and db.readonly:
            db.close()


def peek(db_path: str) -> StudyDatabase | None:
    """The study database opened read-only and checked, or None if there is no study in it yet."""
    if not os.path.exists(db_path) or (os.path.isfile(db_path) and os.path.getsize(db_path) == 0):
        return None
    try:
        return StudyDatabase(db_path, readonly=True, check=True)
    except EmptyDatabase:
        return None


def plan_study(
    db: StudyDatabase | None, db_path: str, participants: int, seed: int, protocol: ProtocolConfig,
    continue_study: bool, framework: FrameworkConfig | None = None, arms: Sequence[str] = (SINGLE_ARM_NAME,),
    visit: VisitRequest | None = None,
) -> tuple[dict[int, list[Step]], int, list[int]]:
    """What a ``run`` will do: steps per participant, trials, finished sessions kept; refusals as :class:`StorageError`.

    ``db`` None: a new database.  A read-only ``db`` is closed afterwards.  ``framework`` (default: the paper's)
    must be the pipeline configuration every stored session of the study ran with (:func:`check_settings`), and
    ``arms`` (the task arm first) the rig's arms they ran on (:func:`check_arms`).  ``visit`` (``run --visit``):
    only that visit of a schedule, continuing the study in ``db`` (:mod:`study_app.headless.plan_visits`).
    """
    try:
        if visit is not None and db is not None:
            planned = _plan_continue(db, db_path, participants, seed, protocol, visit)
            _check_seed(db, db_path, seed)
            _check_rig(db, db_path, framework, arms)
            return planned
        if continue_study:
            if db is None and not os.path.exists(db_path):
                raise StorageError(f"cannot continue a study: no study in {db_path}")
            # an empty file (a run killed before it stored a session) holds nothing to continue: all of it is
            # still to run
            if db is not None:
                planned = _plan_continue(db, db_path, participants, seed, protocol)
                _check_seed(db, db_path, seed)
                _check_rig(db, db_path, framework, arms)
                return planned
        if db is not None:
            for n in range(1, participants + 1):
                code = participant_code(n)
                if db.sessions_of(code):
                    raise StorageError(
                        f"{db_path} already holds sessions for participant {code}; nothing was changed "
                        f"(use a new database, or the same command with --continue to complete the study)"
                    )
            _check_seed(db, db_path, seed)
            _check_rig(db, db_path, framework, arms)
        if protocol.parts:
            per_part = {n: part_steps(protocol, n, seed, visit) for n in range(1, participants + 1)}
            return {n: steps for n, (steps, _) in per_part.items()}, sum(t for _, t in per_part.values()), []
        plan = {n: all_steps(protocol) for n in range(1, participants + 1)}
        per = protocol.trials_per_participant + (len(training_schedule(protocol)) if protocol.training.enabled else 0)
        return plan, per * participants, []
    finally:
        if db is not None and db.readonly:
            db.close()


def _check_rig(db: StudyDatabase, db_path: str, framework: FrameworkConfig | None, arms: Sequence[str]) -> None:
    """One pipeline and one rig per study, as one seed: the stored sessions' settings and arms."""
    sessions = StudyReader.over(db).sessions()
    check_settings(sessions, db_path, framework)
    check_arms(sessions, db_path, arms)


def _check_seed(db: StudyDatabase, db_path: str, seed: int) -> None:
    """One seed per study (:mod:`protocol.runner.study_rules`), whoever ran its sessions (this command, the GUI)."""
    why = seed_refusal(stored_sessions(db), seed)
    if why:
        raise StudyRuleError(f"{db_path}: {why}; nothing was changed")


def open_notes(db: StudyDatabase, taken_over: str) -> list[str]:
    """What opening the database did that the user should hear of."""
    notes = []
    if db.upgraded_from is not None:
        notes.append(f"{db.path}: upgraded from schema version {db.upgraded_from} to {db.schema_version}; "
                     f"the file as it was is kept in {db.backup_path}")
    if taken_over:
        notes.append(f"{db.path}: {taken_over}")
    gone = [w.code for w in withdrawals(db.conn)]
    if gone:
        notes.append(f"{db.path}: {', '.join(gone)} withdrew (haptic-study withdraw): not run again; the participant "
                     "numbers stay vacant, so the other participants keep their schedules")
    return notes



def check_fault_plans(faults: Sequence[FaultPlan], protocol: ProtocolConfig, codes: Sequence[str]) -> None:
    """Refuse a planned fault for a participant who is not run, or a trial the session does not have.

    Raises
    ------
    ValueError
        One line naming the plan and what is allowed.
    """
    if faults and protocol.parts:
        raise ValueError(f"--inject-fault = {faults[0]}: faults are rehearsed in a study of one task; this protocol "
                         f"has parts ({', '.join(protocol.part_names)}): rehearse on a protocol of one of them")
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
