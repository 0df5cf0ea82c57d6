"""Reading one or more study databases into tidy tables.

Several databases merge into one study (a lab may keep one file per
participant or per day).  Every stored trial is read, with its session and
protocol; the ones analysis leaves out (training sessions, aborted trials) stay
in the table with the reason in ``excluded`` so the report can count them.

The records themselves -- a trial's samples, a session's records -- are read by :mod:`analysis.reading.recorded`.
"""

from __future__ import annotations

import json
import math
import os
import sqlite3
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import SupportsInt

import numpy as np
import pandas as pd

from analysis.reading.errors import AnalysisError
from analysis.reading.inputs import check_databases
from analysis.reading.session_config import config_fields
from protocol.metrics import Metric, stored
from protocol.runner.study_rules import DEVIATION_KINDS
from protocol.storage import HEALTH_COLUMNS, Rows, StorageError, StudyReader
from protocol.storage import connect_readonly as _connect_readonly
from protocol.storage.damage import recording_damage
from protocol.storage.database import part_key
from protocol.study.feedback import FEEDBACK_EVENT
from protocol.study.records import Outcome, TrialRecord
from protocol.tasks.base import Task, metrics_of
from protocol.tasks.registry import stored_task

#: Where a trial's records are in its session's recording (schema version 3).
RECORD_COLUMNS = ("segment", "first_tick", "last_tick")
#: Events the report lists: deviations from the protocol ("deviation": any recorded departure from the
#: design, e.g. an experiment started without a completed training; "calibration_override": a session started
#: without a calibration step on record), which code ran each resumed part of a session ("software") and each resume
#: of an interrupted session ("resume": which trial the interruption cut).
DEVIATION_EVENTS = DEVIATION_KINDS  # their one definition: protocol.runner.study_rules
LISTED_EVENTS = (*DEVIATION_EVENTS, "software", "resume", FEEDBACK_EVENT)

__all__ = [
    "DEVIATION_EVENTS",
    "LISTED_EVENTS",
    "AnalysisError",
    "Progress",
    "StudyData",
    "connect_readonly",
    "load_study",
    "recorded_where",
    "stored_records",
]

#: ``progress(done, total)`` callback, called while samples are read.
Progress = Callable[[float, float], None]


@dataclass(frozen=True, slots=True)
class StudyData:
    """The trials and sessions of one study, merged from its databases.

    Attributes
    ----------
    trials
        One row per stored trial.  Columns: ``database``, ``participant_code``,
        ``participant_number``, ``session_id``, ``session_kind``, ``session_status``, ``trial_id``,
        ``trial_index``, ``target_label``, ``target_force_n``, ``haptic_mode``,
        ``outcome``, ``started_at_s``, ``ended_at_s``, the metrics stored live (``stored_tct_s``,
        ``stored_rmse_n``, … one per stored metric of the study's, :attr:`metrics`; empty in a file from before a
        metric existed, or for a session whose task does not produce it), ``n_samples``,
        ``abort_reason``, ``abort_cause`` and the loop-health columns
        (:data:`protocol.storage.HEALTH_COLUMNS`; empty in version-1
        databases), where its records are in the session's recording
        (``segment``, ``first_tick``, ``last_tick``; empty before version 3, whose
        trials' samples are in the ``samples`` table), the session's task's parameters (the paper's:
        ``tolerance_fraction``, ``hold_s``) and ``max_trial_s``, ``repeat_of`` (the trial index an aborted
        trial's re-run repeats), ``excluded``
        (``""`` when analysed, else ``"training session"``, ``"incomplete session"``, ``"aborted trial"`` or
        ``"recording damaged"``) and ``damage`` (for a trial whose records touch a damaged block of the
        recording: the line of :attr:`damage` naming it, else ``""``).
    sessions
        One row per session: ``database``, ``session_id``, ``participant_code``,
        ``participant_number``, ``kind``, ``status``, ``seed``, ``started_at``, ``ended_at``,
        ``end_reason``, ``software_version``, ``rig``, ``protocol_name``, the protocol's task's parameters (the
        paper's: ``tolerance_fraction``, ``hold_s``) and ``max_trial_s``, and the watchdog limits the session
        ran with (``watchdog_sensor_max_age_ms``, ``watchdog_pose_max_age_ms``; NaN if not stored),
        ``pipeline_settings`` (the pipeline settings it ran with that are not the paper's, ``run --set``, as
        ``filter_window=50, f_scale_n=3``; ``""`` for the paper's or when not stored), which code
        ran it (``software_commit``, ``software_dirty``; empty before schema version 4 or when not known),
        ``n_designed`` (the trials its design has: the schedule less its re-runs), ``first_mode`` (the haptic
        mode of the schedule's first trial) and ``analysed`` (its trials are analysed: an experiment session,
        completed, or any with ``include_incomplete``) and ``n_runs`` (the runs it took: 1, and one more per
        resume after an interruption).
    databases
        The database paths, in the order given.
    damage
        One line per run of damaged recorded blocks (a checksum that does not match, a block that does not
        decode): the database, session, session-time range and the trials it touches.  Those trials are
        excluded (``"recording damaged"``): their metrics' window is not whole, so they are not analysed
        from what is left; every other trial is.
    events
        The events the report lists (:data:`LISTED_EVENTS`): ``database, session_id, t_s, kind, detail``.
    runs
        Every recorded run of every session (a resumed session has one per run): ``database, session_id, segment,
        started_at_s, last_record_s`` (session clock; empty before schema version 3).
    include_incomplete
        Whether experiment sessions that did not complete are analysed.
    sites
        Each database's site (``report --site``), in the order of :attr:`databases`; ``""`` for every one when no
        site was named.  A named site's participant codes are re-coded ``SITE:CODE`` in every table.
    tasks
        Each session's task (:mod:`protocol.tasks`), by database and session id (:meth:`task_of`).
    part
        The part of a study of several parts whose sessions these are (:mod:`protocol.study.parts`; the report says
        so on its page); None: the study's every session.
    metrics
        The study's metrics: those its sessions' tasks produce (:func:`protocol.tasks.base.metrics_of`), which every
        table, test, file and figure of the analysis lists.
    """

    trials: pd.DataFrame
    sessions: pd.DataFrame
    databases: tuple[str, ...]
    damage: tuple[str, ...] = ()
    events: pd.DataFrame = field(default_factory=pd.DataFrame)
    include_incomplete: bool = False
    runs: pd.DataFrame = field(default_factory=pd.DataFrame)
    sites: tuple[str, ...] = ()
    tasks: Mapping[tuple[str, int], Task] = field(default_factory=dict)
    part: str | None = None

    @property
    def metrics(self) -> tuple[Metric, ...]:
        """The study's metrics (its tasks'), in the registry's order."""
        return metrics_of(self.tasks.values())

    def task_of(self, database: str, session_id: int) -> Task:
        """The task a session ran (its protocol's), which judges, measures and draws its trials."""
        return self.tasks[(database, int(session_id))]

    @property
    def included(self) -> pd.DataFrame:
        """The trials analysis uses (experiment sessions, not aborted)."""
        return self.trials[self.trials["excluded"] == ""]


def _open(path: str) -> StudyReader:
    try:
        # read-only (an archive in a read-only folder opens immutable), and checked: a damaged file is one line
        return StudyReader(path, check=True)
    except StorageError as exc:
        raise AnalysisError(str(exc)) from None


def frame_of(rows: Rows) -> pd.DataFrame:
    """A reader's table as a DataFrame, typed as ``pandas.read_sql_query`` types a query's result."""
    if not rows.rows:
        return pd.DataFrame(columns=list(rows.columns))
    return pd.DataFrame.from_records(rows.rows, columns=list(rows.columns), coerce_float=True)


def _query(db: StudyReader, read: Callable[[], Rows]) -> pd.DataFrame:
    try:
        return frame_of(read())
    except sqlite3.DatabaseError as exc:
        raise AnalysisError(f"{db.path}: cannot read the study tables ({exc})") from None


def _protocol_fields(protocol_json: str, where: str) -> tuple[dict[str, object], Task]:
    """A session's protocol name, its task's parameters (columns by name) and its trial cap, and its task."""
    try:
        proto = json.loads(protocol_json)
        task = stored_task(proto, where, AnalysisError)
        training = proto.get("training") or {}
        return {
            "protocol_name": str(proto.get("name", "")),
            "protocol_version": proto.get("version", np.nan),
            **task.parameters(),
            "max_trial_s": float(proto["trial"]["max_trial_s"]),
            # the training the protocol asked for (a training session runs its trials with this cap)
            "training_enabled": bool(training.get("enabled", False)),
            "training_cap_s": float(training.get("seconds_per_target_per_mode", np.nan)),
            "training_live_aid": bool(training.get("live_force_aid", False)),
            "training_required": bool(training.get("required", False)),
        }, task
    except AnalysisError:
        raise
    except (ValueError, KeyError, TypeError) as exc:
        raise AnalysisError(f"{where}: protocol_json is unreadable ({exc!r})") from None


#: What analysis decodes of a recorded block (a block written before version 4 has no checksum: these are tried).
_ANALYSED_COLUMNS = ("t_ns", "force_n", "raw_fx", "raw_fy", "raw_fz", "raw_tx", "raw_ty", "raw_tz",
                     "render_fx", "render_fy", "render_fz")


def _mark_damage(db: StudyReader, path: str, trials: pd.DataFrame) -> list[str]:
    """Verify the recording's blocks; name each trial touching a damaged one in ``trials["damage"]``; the lines."""
    trials["damage"] = ""
    if db.schema_version < 3:
        return []
    try:
        damage = recording_damage(db, columns=_ANALYSED_COLUMNS)
    except sqlite3.DatabaseError as exc:
        raise AnalysisError(f"{path}: cannot read the recording ({exc})") from None
    lines = []
    for d in damage:
        line = f"{path}: {d.describe()}"
        lines.append(line)
        hit = ((trials["session_id"] == d.session_id) & (trials["segment"] == d.segment)
               & (trials["first_tick"] <= d.last_tick) & (trials["last_tick"] >= d.first_tick))
        trials.loc[hit & (trials["damage"] == ""), "damage"] = line
    return lines


def _schedule_fields(schedule_json: object) -> dict[str, object]:
    """The trials a session's design has (its stored schedule less the re-runs) and its first trial's mode."""
    try:
        schedule = json.loads(str(schedule_json))
        designed = [t for t in schedule if t.get("repeat_of") is None]
        return {"n_designed": len(designed), "first_mode": str(schedule[0]["haptic_mode"]) if schedule else ""}
    except (ValueError, KeyError, TypeError, AttributeError, IndexError):
        return {"n_designed": np.nan, "first_mode": ""}


def _read_one(path: str, part: str | None = None) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame, list[str],
                                                          pd.DataFrame, dict[tuple[str, int], Task]]:
    db = _open(path)
    try:
        # schema version 4 records which code ran a session; earlier files do not (NULL)
        sessions = _query(db, db.session_table)
        if part is not None:  # one part of a study of several (protocol.study.parts): its sessions only
            sessions = sessions[[part_key(pj) == part for pj in sessions["protocol_json"]]]
            sessions = sessions.reset_index(drop=True)
        read = [_protocol_fields(pj, f"{path}: session {sid}")
                for sid, pj in zip(sessions["session_id"], sessions["protocol_json"], strict=True)]
        # the stored metrics of this file's tasks; schema version 2 records why a trial was aborted and how the
        # loop ran, a version-1 file has neither
        kept = [m.name for m in stored(metrics_of(task for _, task in read))]
        trials = _query(db, lambda: db.trial_table(("abort_cause", *HEALTH_COLUMNS, *RECORD_COLUMNS), kept))
        damage = _mark_damage(db, path, trials)
        events = _query(db, lambda: db.events(LISTED_EVENTS))
        runs = _query(db, db.recorded_runs)
        writers = db.sessions_being_written()  # a session "running" with a live writer is in progress, not interrupted
    finally:
        db.close()
    if sessions.empty:
        raise AnalysisError(f"{path}: empty study database (no sessions)" if part is None else
                            f"{path}: no session of the part {part!r}")
    if part is not None:
        own = set(sessions["session_id"].astype(int))
        trials, events, runs = (frame[frame["session_id"].astype(int).isin(own)].reset_index(drop=True)
                                for frame in (trials, events, runs))
    proto = pd.DataFrame([fields for fields, _ in read], index=sessions.index)
    tasks = {(path, int(sid)): task for sid, (_, task) in zip(sessions["session_id"], read, strict=True)}
    watchdog = pd.DataFrame([config_fields(cj) for cj in sessions["config_json"]], index=sessions.index)
    design = pd.DataFrame([_schedule_fields(sj) for sj in sessions["schedule_json"]], index=sessions.index)
    sessions = pd.concat([sessions.drop(columns=["protocol_json", "config_json", "schedule_json"]), proto, watchdog,
                          design], axis=1)
    sessions["software_dirty"] = sessions["software_dirty"].astype("boolean")
    sessions["writer"] = [writers.get(int(sid), "") for sid in sessions["session_id"]]
    for frame in (sessions, trials, events, runs):
        frame.insert(0, "database", path)
    return sessions, trials, events, damage, runs, tasks


def _read_all(
    paths: Sequence[str | os.PathLike[str]], part: str | None = None,
) -> tuple[list[pd.DataFrame], list[pd.DataFrame], list[pd.DataFrame], list[str], list[pd.DataFrame],
           dict[tuple[str, int], Task]]:
    """Each database's sessions, trials and events (and the damage found, its recorded runs and each session's
    task), in order; a refusal for a path that is missing or names a database given already."""
    all_sessions: list[pd.DataFrame] = []
    all_trials: list[pd.DataFrame] = []
    all_events: list[pd.DataFrame] = []
    all_runs: list[pd.DataFrame] = []
    damage: list[str] = []
    tasks: dict[tuple[str, int], Task] = {}
    for path in check_databases(paths, open_each=False):  # (each is opened, checked, just below)
        s, t, e, d, r, k = _read_one(path, part)
        tasks.update(k)
        all_sessions.append(s)
        all_trials.append(t)
        all_events.append(e)
        damage.extend(d)
        all_runs.append(r)
    return all_sessions, all_trials, all_events, damage, all_runs, tasks


def _recode_sites(all_sessions: list[pd.DataFrame], sites: Sequence[str] | None) -> tuple[str, ...]:
    """Each database's site in a ``site`` column of its sessions, its participant codes re-coded ``SITE:CODE`` (in
    memory: the file is not touched); the sites, one per database (``""`` each when none was named)."""
    named = tuple(str(x) for x in sites) if sites else ("",) * len(all_sessions)
    if len(named) != len(all_sessions):
        raise AnalysisError(f"--site: {len(named)} sites for {len(all_sessions)} databases; give one --site after "
                            "each --db (report --db a.db --site A --db b.db --site B)")
    for frame, site in zip(all_sessions, named, strict=True):
        frame.insert(1, "site", site)
        if site:
            frame["participant_code"] = site + ":" + frame["participant_code"].astype(str)
    return named


def load_study(paths: Sequence[str | os.PathLike[str]], *, include_incomplete: bool = False,
               sites: Sequence[str] | None = None, part: str | None = None) -> StudyData:
    """Read and merge study databases.

    Parameters
    ----------
    paths
        One or more haptic-study databases.
    include_incomplete
        Analyse the finished trials of experiment sessions that did not complete (ended by the experimenter,
        or interrupted and not resumed).  By default they are left out (``excluded = "incomplete session"``)
        and the report lists them with the reason.
    sites
        One site per database (``report --db A.db --site A --db B.db --site B``): each database's participant codes
        are re-coded ``SITE:CODE`` as they are read (so two sites' ``P01`` are two participants) and every session
        and trial carries its ``site``.  None: no sites (``site`` empty).
    part
        In a study of several parts (:mod:`protocol.study.parts`): read that part's sessions only (its task's
        report, :mod:`analysis.report.plan_report`; ``VISIT-PART`` in a study with visits,
        :func:`protocol.storage.database.part_key`); None: every session.

    Returns
    -------
    StudyData

    Raises
    ------
    AnalysisError
        A path that is not a study database, an empty database, a database
        given twice, a participant code that appears in two databases (the
        merge refuses to guess whether they are one person), or a study with
        no experiment trial to analyse.
    """
    all_sessions, all_trials, all_events, damage, all_runs, tasks = _read_all(paths, part)
    named = _recode_sites(all_sessions, sites)
    # each task's parameters are columns of the sessions and trials tables (the paper's: tolerance_fraction, hold_s)
    params = list(dict.fromkeys(name for task in tasks.values() for name in task.parameters()))
    sessions = pd.concat(all_sessions, ignore_index=True)
    owners = sessions.groupby("participant_code")["database"].unique()
    for code, dbs in owners.items():
        if len(dbs) > 1:
            raise AnalysisError(
                f"participant code {code!r} appears in {dbs[0]} and {dbs[1]}; the merge refuses to guess "
                "whether they are one person (name each database's site, report --db A.db --site A --db B.db "
                "--site B, which re-codes them A:P01 and B:P01; or analyse the databases separately)"
            )
    experiment = sessions["kind"] == "experiment"
    sessions["analysed"] = experiment & ((sessions["status"] == "completed") | include_incomplete)
    events = pd.concat(all_events, ignore_index=True)
    runs = pd.concat(all_runs, ignore_index=True)
    sessions["n_runs"] = _run_counts(sessions, events, runs)
    trials = _analysed_trials(pd.concat(all_trials, ignore_index=True), sessions, params, tasks)
    names = ", ".join(str(p) for p in paths)
    if not experiment.any():
        raise AnalysisError(f"{names}: only training sessions; there is no experiment session to analyse")
    if (trials["excluded"] == "").sum() == 0:
        if (trials["excluded"] == "incomplete session").any():
            raise AnalysisError(f"{names}: no experiment session completed, and incomplete sessions are left out "
                                "by default; --include-incomplete analyses their finished trials")
        raise AnalysisError(f"{names}: the experiment sessions have no finished trial to analyse")
    return StudyData(trials=trials, sessions=sessions, databases=tuple(str(p) for p in paths), damage=tuple(damage),
                     events=events, include_incomplete=include_incomplete, runs=runs, sites=named, tasks=tasks,
                     part=part)


def _analysed_trials(trials: pd.DataFrame, sessions: pd.DataFrame, params: list[str],
                     tasks: dict[tuple[str, int], Task]) -> pd.DataFrame:
    """The trials with their session's columns and why each is left out of the analysis ("" when it is not)."""
    meta = sessions[["database", "site", "session_id", "participant_code", "participant_number", "kind", "status",
                     *params, "max_trial_s", "analysed"]].rename(
        columns={"kind": "session_kind", "status": "session_status"}
    )
    trials = trials.merge(meta, on=["database", "session_id"], how="left", validate="many_to_one")
    excluded = np.where(
        trials["session_kind"] != "experiment", "training session",
        np.where(~trials["analysed"].astype(bool), "incomplete session",
                 np.where(trials["outcome"] == Outcome.ABORTED, "aborted trial",
                          np.where(trials["damage"] != "", "recording damaged", ""))),
    )
    trials["excluded"] = excluded
    # the study's stored metrics (a database whose tasks do not produce one has it empty)
    kept = [f"stored_{m.name}" for m in stored(metrics_of(tasks.values()))]
    order = ["database", "site", "participant_code", "participant_number", "session_id", "session_kind",
             "session_status",
             "trial_id", "trial_index", "target_label", "target_force_n", "haptic_mode", "outcome", "started_at_s",
             "ended_at_s", *kept, "n_samples", "abort_reason", "abort_cause", *HEALTH_COLUMNS,
             *RECORD_COLUMNS,
             *params, "max_trial_s", "repeat_of", "excluded", "damage"]
    trials = trials[order]
    return trials


def _run_counts(sessions: pd.DataFrame, events: pd.DataFrame, runs: pd.DataFrame) -> pd.Series:
    """How many runs each session took: 1, and one more per resume after an interruption (its ``resume`` events;
    its recorded runs, where they are more -- a resume whose event a version-3 file does not have)."""
    key = list(zip(sessions["database"], sessions["session_id"], strict=True))
    resumes = (events[events["kind"] == "resume"].groupby(["database", "session_id"]).size()
               if len(events) else pd.Series(dtype=np.int64))
    recorded = runs.groupby(["database", "session_id"]).size() if len(runs) else pd.Series(dtype=np.int64)
    return pd.Series([max(1 + int(resumes.get(k, 0)), int(recorded.get(k, 0))) for k in key], index=sessions.index,
                     dtype=np.int64)


#: Integer columns of a trials frame that read as floats once one of them is empty.
_INT_COLUMNS = ("n_samples", "periods_over_2ms", *RECORD_COLUMNS)


def _empty(v: object) -> bool:
    return v is None or v is pd.NA or (isinstance(v, float) and math.isnan(v))


def stored_records(trials: pd.DataFrame) -> list[TrialRecord]:
    """The rows of a trials frame (:attr:`StudyData.trials` or a part of it) as the records stored live.

    The ``stored_*`` metric columns are the records' metrics; an empty value is None.
    """
    out = []
    for row in trials.rename(columns=lambda c: c.removeprefix("stored_")).to_dict("records"):
        clean = {k: None if _empty(v) else v for k, v in row.items()}
        for k in _INT_COLUMNS:
            v = clean.get(k)
            if v is not None:
                clean[k] = int(v)
        out.append(TrialRecord.from_row(clean))
    return out


def recorded_where(session_id: SupportsInt, segment: SupportsInt | None, first_tick: SupportsInt | None,
                   last_tick: SupportsInt | None) -> tuple[int, int, int, int] | None:
    """A trial's place in its session's recording, or None when it has none (a trial of schema version 1 or 2)."""
    if segment is None or first_tick is None or last_tick is None or any(
            (isinstance(v, float) and math.isnan(v)) or v is pd.NA for v in (segment, first_tick, last_tick)):
        return None
    return int(session_id), int(segment), int(first_tick), int(last_tick)


def connect_readonly(database: str | os.PathLike[str]) -> sqlite3.Connection:
    """A read-only connection (never creates, migrates or locks the study database for writing).

    See :func:`protocol.storage.connect_readonly` (archives in read-only folders open immutable).
    """
    try:
        return _connect_readonly(database)
    except StorageError as exc:
        raise AnalysisError(str(exc)) from None


