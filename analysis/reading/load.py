"""Reading one or more study databases into tidy tables.

Several databases merge into one study (a lab may keep one file per
participant or per day).  Every stored trial is read, with its session and
protocol; the ones analysis leaves out (training sessions, aborted trials) stay
in the table with the reason in ``excluded`` so the report can count them.

Samples are read trial by trial through the ``(trial_id, t_s)`` index, only
the columns the metrics need.
"""

from __future__ import annotations

import json
import math
import os
import sqlite3
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import SupportsInt

import numpy as np
import numpy.typing as npt
import pandas as pd

from analysis.reading.errors import AnalysisError
from analysis.reading.inputs import check_databases
from analysis.reading.session_config import config_fields
from protocol.recording import RecordingDamaged
from protocol.runner.study_rules import DEVIATION_KINDS
from protocol.storage import HEALTH_COLUMNS, Rows, StorageError, StudyReader, trial_id_of
from protocol.storage import connect_readonly as _connect_readonly
from protocol.storage.damage import recording_damage
from protocol.storage.recordings import read_ticks
from protocol.study.records import Outcome, TrialRecord

#: Where a trial's records are in its session's recording (schema version 3).
RECORD_COLUMNS = ("segment", "first_tick", "last_tick")
#: Events the report lists: deviations from the protocol ("deviation": any recorded departure from the
#: design, e.g. an experiment started without a completed training; "calibration_override": a session started
#: without a calibration step on record), which code ran each resumed part of a session ("software") and each resume
#: of an interrupted session ("resume": which trial the interruption cut).
DEVIATION_EVENTS = DEVIATION_KINDS  # their one definition: protocol.runner.study_rules
LISTED_EVENTS = (*DEVIATION_EVENTS, "software", "resume")

__all__ = [
    "DEVIATION_EVENTS",
    "LISTED_EVENTS",
    "AnalysisError",
    "Progress",
    "StudyData",
    "connect_readonly",
    "load_study",
    "read_task_force",
    "read_trial_samples",
    "recorded_samples",
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
        ``outcome``, ``started_at_s``, ``ended_at_s``, the metrics stored live
        (``stored_tct_s``, ``stored_rmse_n``, ``stored_max_ae_n``,
        ``stored_time_in_band_s``, ``stored_peak_force_n``), ``n_samples``,
        ``abort_reason``, ``abort_cause`` and the loop-health columns
        (:data:`protocol.storage.HEALTH_COLUMNS`; empty in version-1
        databases), where its records are in the session's recording
        (``segment``, ``first_tick``, ``last_tick``; empty before version 3, whose
        trials' samples are in the ``samples`` table), the session's ``tolerance_fraction``, ``hold_s`` and
        ``max_trial_s``, ``repeat_of`` (the trial index an aborted trial's re-run repeats), ``excluded``
        (``""`` when analysed, else ``"training session"``, ``"incomplete session"``, ``"aborted trial"`` or
        ``"recording damaged"``) and ``damage`` (for a trial whose records touch a damaged block of the
        recording: the line of :attr:`damage` naming it, else ``""``).
    sessions
        One row per session: ``database``, ``session_id``, ``participant_code``,
        ``participant_number``, ``kind``, ``status``, ``seed``, ``started_at``, ``ended_at``,
        ``end_reason``, ``software_version``, ``rig``, ``protocol_name``, the protocol's
        ``tolerance_fraction``, ``hold_s`` and ``max_trial_s``, and the watchdog limits the session
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
    """

    trials: pd.DataFrame
    sessions: pd.DataFrame
    databases: tuple[str, ...]
    damage: tuple[str, ...] = ()
    events: pd.DataFrame = field(default_factory=pd.DataFrame)
    include_incomplete: bool = False
    runs: pd.DataFrame = field(default_factory=pd.DataFrame)

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


def _protocol_fields(protocol_json: str, where: str) -> dict[str, object]:
    try:
        proto = json.loads(protocol_json)
        trial = proto["trial"]
        return {
            "protocol_name": str(proto.get("name", "")),
            "tolerance_fraction": float(trial["tolerance_fraction"]),
            "hold_s": float(trial["hold_s"]),
            "max_trial_s": float(trial["max_trial_s"]),
        }
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


def _read_one(path: str) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame, list[str], pd.DataFrame]:
    db = _open(path)
    try:
        # schema version 4 records which code ran a session; earlier files do not (NULL)
        sessions = _query(db, db.session_table)
        # schema version 2 records why a trial was aborted and how the loop ran; a version-1 file has neither
        trials = _query(db, lambda: db.trial_table(("abort_cause", *HEALTH_COLUMNS, *RECORD_COLUMNS)))
        damage = _mark_damage(db, path, trials)
        events = _query(db, lambda: db.events(LISTED_EVENTS))
        runs = _query(db, db.recorded_runs)
        writers = db.sessions_being_written()  # a session "running" with a live writer is in progress, not interrupted
    finally:
        db.close()
    if sessions.empty:
        raise AnalysisError(f"{path}: empty study database (no sessions)")
    proto = pd.DataFrame(
        [_protocol_fields(pj, f"{path}: session {sid}")
         for sid, pj in zip(sessions["session_id"], sessions["protocol_json"], strict=True)],
        index=sessions.index,
    )
    watchdog = pd.DataFrame([config_fields(cj) for cj in sessions["config_json"]], index=sessions.index)
    design = pd.DataFrame([_schedule_fields(sj) for sj in sessions["schedule_json"]], index=sessions.index)
    sessions = pd.concat([sessions.drop(columns=["protocol_json", "config_json", "schedule_json"]), proto, watchdog,
                          design], axis=1)
    sessions["software_dirty"] = sessions["software_dirty"].astype("boolean")
    sessions["writer"] = [writers.get(int(sid), "") for sid in sessions["session_id"]]
    for frame in (sessions, trials, events, runs):
        frame.insert(0, "database", path)
    return sessions, trials, events, damage, runs


def _read_all(
    paths: Sequence[str | os.PathLike[str]],
) -> tuple[list[pd.DataFrame], list[pd.DataFrame], list[pd.DataFrame], list[str], list[pd.DataFrame]]:
    """Each database's sessions, trials and events (and the damage found, and its recorded runs), in order; a
    refusal for a path that is missing or names a database given already."""
    all_sessions: list[pd.DataFrame] = []
    all_trials: list[pd.DataFrame] = []
    all_events: list[pd.DataFrame] = []
    all_runs: list[pd.DataFrame] = []
    damage: list[str] = []
    for path in check_databases(paths, open_each=False):  # (each is opened, checked, just below)
        s, t, e, d, r = _read_one(path)
        all_sessions.append(s)
        all_trials.append(t)
        all_events.append(e)
        damage.extend(d)
        all_runs.append(r)
    return all_sessions, all_trials, all_events, damage, all_runs


def load_study(paths: Sequence[str | os.PathLike[str]], *, include_incomplete: bool = False) -> StudyData:
    """Read and merge study databases.

    Parameters
    ----------
    paths
        One or more haptic-study databases.
    include_incomplete
        Analyse the finished trials of experiment sessions that did not complete (ended by the experimenter,
        or interrupted and not resumed).  By default they are left out (``excluded = "incomplete session"``)
        and the report lists them with the reason.

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
    all_sessions, all_trials, all_events, damage, all_runs = _read_all(paths)
    sessions = pd.concat(all_sessions, ignore_index=True)
    owners = sessions.groupby("participant_code")["database"].unique()
    for code, dbs in owners.items():
        if len(dbs) > 1:
            raise AnalysisError(
                f"participant code {code!r} appears in {dbs[0]} and {dbs[1]}; the merge refuses to guess "
                "whether they are one person (analyse the databases separately or re-code one)"
            )
    experiment = sessions["kind"] == "experiment"
    sessions["analysed"] = experiment & ((sessions["status"] == "completed") | include_incomplete)
    events = pd.concat(all_events, ignore_index=True)
    runs = pd.concat(all_runs, ignore_index=True)
    sessions["n_runs"] = _run_counts(sessions, events, runs)
    trials = pd.concat(all_trials, ignore_index=True)
    meta = sessions[["database", "session_id", "participant_code", "participant_number", "kind", "status",
                     "tolerance_fraction", "hold_s", "max_trial_s", "analysed"]].rename(
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
    order = ["database", "participant_code", "participant_number", "session_id", "session_kind", "session_status",
             "trial_id", "trial_index", "target_label", "target_force_n", "haptic_mode", "outcome", "started_at_s",
             "ended_at_s", "stored_tct_s", "stored_rmse_n", "stored_max_ae_n", "stored_time_in_band_s",
             "stored_peak_force_n", "n_samples", "abort_reason", "abort_cause", *HEALTH_COLUMNS, *RECORD_COLUMNS,
             "tolerance_fraction", "hold_s", "max_trial_s", "repeat_of", "excluded", "damage"]
    trials = trials[order]
    names = ", ".join(str(p) for p in paths)
    if not experiment.any():
        raise AnalysisError(f"{names}: only training sessions; there is no experiment session to analyse")
    if (trials["excluded"] == "").sum() == 0:
        if (trials["excluded"] == "incomplete session").any():
            raise AnalysisError(f"{names}: no experiment session completed, and incomplete sessions are left out "
                                "by default; --include-incomplete analyses their finished trials")
        raise AnalysisError(f"{names}: the experiment sessions have no finished trial to analyse")
    return StudyData(trials=trials, sessions=sessions, databases=tuple(str(p) for p in paths), damage=tuple(damage),
                     events=events, include_incomplete=include_incomplete, runs=runs)


def _run_counts(sessions: pd.DataFrame, events: pd.DataFrame, runs: pd.DataFrame) -> pd.Series:
    """How many runs each session took: 1, and one more per resume after an interruption (its ``resume`` events;
    its recorded runs, where they are more -- a resume whose event a version-3 file does not have)."""
    key = list(zip(sessions["database"], sessions["session_id"], strict=True))
    resumes = (events[events["kind"] == "resume"].groupby(["database", "session_id"]).size()
               if len(events) else pd.Series(dtype=np.int64))
    recorded = runs.groupby(["database", "session_id"]).size() if len(runs) else pd.Series(dtype=np.int64)
    return pd.Series([max(1 + int(resumes.get(k, 0)), int(recorded.get(k, 0))) for k in key], index=sessions.index,
                     dtype=np.int64)


def read_task_force(conn: sqlite3.Connection | StudyReader, trial_id: int,
                    where: tuple[int, int, int, int] | None = None,
                    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
    """One trial's task-force samples: times since the cue (int ns) and ``force_n`` (N).

    Parameters
    ----------
    conn
        A reader of the study database (:class:`protocol.storage.StudyReader`), or an open connection to it.
    trial_id
        ``session_id`` · 10⁶ + ``trial_index``.
    where
        ``(session_id, segment, first_tick, last_tick)``: the trial's records in its session's
        recording (schema version 3); None: its rows of the ``samples`` table (versions 1 and 2).

    Returns
    -------
    t_ns, force_n
        In time order; empty when the trial has no samples.  A NULL force
        becomes NaN (out of band, left out of the errors).
    """
    if where is not None:
        cols = read_ticks(conn, *where, ("t_ns", "force_n"))
        t = cols["t_ns"]  # int64, as the tick record has it
        return (t - t[0] if len(t) else t), cols["force_n"]  # the first record is the cue
    rows = StudyReader.over(conn).trial_samples(trial_id, ("t_s", "force_n")).rows
    if not rows:
        return np.empty(0, np.int64), np.empty(0, np.float64)
    block = np.array(rows, dtype=np.float64)
    # t_s was stored as ns / 1e9; rounding recovers the integer ns exactly (|t| ≪ 2^53 ns)
    return np.rint(block[:, 0] * 1e9).astype(np.int64), np.ascontiguousarray(block[:, 1])


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


_SAMPLE_COLUMNS = ("t_s", "force_n", "raw_fx", "raw_fy", "raw_fz", "raw_tx", "raw_ty", "raw_tz",
                   "comp_fx", "comp_fy", "comp_fz", "render_fx", "render_fy", "render_fz")
#: What a trial's trace reads of a recorded session (the compensated force is not stored: replay recomputes it).
_RECORDED_TRACE = ("force_n", "raw_fx", "raw_fy", "raw_fz", "raw_tx", "raw_ty", "raw_tz",
                   "render_fx", "render_fy", "render_fz", "faults")


def read_trial_samples(database: str | os.PathLike[str], session_id: int, trial_index: int,
                       arm: str | None = None) -> pd.DataFrame:
    """Every stored column of one trial's samples, in time order.

    Parameters
    ----------
    database
        The study database.
    session_id, trial_index
        Which trial.
    arm
        A rig of several arms: whose records over the trial's window (None: the task arm's, the trial's own).

    Returns
    -------
    pandas.DataFrame
        Columns ``t_s`` (since the cue), ``force_n``, ``raw_f*``, ``raw_t*``, ``render_f*``, and
        ``faults`` (the latched watchdog faults, a bitmask) for a recorded trial, or
        ``comp_f*`` for a trial of schema version 1 or 2 (a recorded session's compensated force is
        recomputed by replay, :func:`pipeline.force.replay.replay`, not stored).

    Raises
    ------
    AnalysisError
        Not a study database, or no samples for that trial.
    """
    db = _open(str(database))
    try:
        try:
            key = db.arm_key(int(session_id), arm)
        except KeyError as exc:
            raise AnalysisError(f"{database}: {exc.args[0]}") from None
        frame = pd.DataFrame()
        if db.schema_version >= 3:
            row = db.trial_window(trial_id_of(int(session_id), int(trial_index)))
            where = None if row is None else recorded_where(session_id, *row)
            if where is not None:
                try:
                    cols = read_ticks(db, *where, ("t_ns", *_RECORDED_TRACE), arm=key)
                except RecordingDamaged as exc:
                    raise AnalysisError(f"{database}: trial {int(trial_index) + 1} of session {session_id}: "
                                        f"{exc}") from None
                t_ns = cols.pop("t_ns")
                frame = pd.DataFrame({"t_s": (t_ns - t_ns[0]) / 1e9, **{c: cols[c] for c in _RECORDED_TRACE}})
        if frame.empty and not key:
            frame = frame_of(db.trial_samples(trial_id_of(int(session_id), int(trial_index)), _SAMPLE_COLUMNS))
    finally:
        db.close()
    if frame.empty:
        raise AnalysisError(f"{database}: no samples for session {session_id}, trial {trial_index}")
    return frame


#: The columns of :func:`recorded_samples`, in order (``comp_f*`` only for sessions recorded before version 3).
RECORDED_COLUMNS = (
    "session_id", "segment", "tick", "session_time_s", "trial_number", "t_since_cue_s", "phase", "force_n",
    "raw_fx", "raw_fy", "raw_fz", "raw_tx", "raw_ty", "raw_tz", "render_fx", "render_fy", "render_fz", "gain",
    "derate", "haptic_on", "faults", "stylus_x_m", "stylus_y_m", "stylus_z_m", "sensor_age_ms", "pose_age_ms",
    "latency_ms",
)


def recorded_samples(database: str | os.PathLike[str], session_id: int | None = None,
                     arm: str | None = None) -> pd.DataFrame:
    """The 1 kHz records of one session (or all) as one table, with the recording's own column names.

    :func:`analysis.reading.samples.samples_frame` labels it for people (``haptic-study export samples``).

    A session recorded by version 3 gives every record from its start to its
    end (training, pauses, trials, waits, every resumed run); one recorded
    before gives its trials' samples (what version 2 kept).

    Parameters
    ----------
    database
        The study database (opened read-only).
    session_id
        One session, or None for every session.
    arm
        A rig of several arms: the arm whose records to read, by name (None: the task arm's, which the trials are
        judged on).

    Returns
    -------
    pandas.DataFrame
        One row per record, columns :data:`RECORDED_COLUMNS`: the session and its
        recording's segment and loop tick, the session-clock time, the trial (numbered from 1;
        empty between trials) and the time since its cue, the trial phase code, the task force
        and the raw, rendered and gain values, the fraction of the designed force the haptic
        device's thermal derating let through (1: not cut), the feedback switch and latched faults, the stylus
        position and the sensor and pose ages and the latency (ms).  Sorted by session and time.  Records in
        damaged blocks of the recording are left out: ``frame.attrs["damage"]`` then lists them, one line each
        (session, time range, trials), and the table is partial.

    Raises
    ------
    AnalysisError
        Not a study database, or no such session.
    """
    db = _open(str(database))
    try:
        ids = db.session_ids()
        if session_id is not None:
            if int(session_id) not in ids:
                listed = ", ".join(map(str, ids)) or "none"
                raise AnalysisError(f"{database}: no session {session_id} (sessions: {listed})")
            ids = [int(session_id)]
        damage: list[str] = []
        try:
            keys = {sid: db.arm_key(sid, arm) for sid in ids}
        except KeyError as exc:
            raise AnalysisError(f"{database}: {exc.args[0]}") from None
        parts = [_session_samples(db, sid, damage, keys[sid]) for sid in ids]
    finally:
        db.close()
    parts = [p for p in parts if len(p)]
    out = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame({c: [] for c in RECORDED_COLUMNS})
    out.attrs["damage"] = [f"{database}: {line}" for line in damage]
    return out


def _session_samples(db: StudyReader, session_id: int, damage: list[str], arm: str = "") -> pd.DataFrame:
    """A session's records (see :func:`samples_frame`); damaged blocks are left out and described in ``damage``."""
    from protocol.storage.recordings import read_segment, segments_of

    frames = []
    if db.schema_version >= 3:
        cues = db.trial_cues(session_id)
        for seg, _, _ in segments_of(db, session_id, arm):
            d = read_segment(db, session_id, seg, skip_damaged=True, arm=arm)
            damage.extend(x.describe() for x in d.damage)
            c = d.columns
            n = len(c["tick"])
            time_s = d.session_time_s
            trial = c["trial_index"]  # int64, as the tick record has it
            since = np.full(n, np.nan)
            for idx in np.unique(trial[trial >= 0]).tolist():
                if idx in cues:
                    sel = trial == idx
                    cue_tick = cues[idx][0]
                    cue_rows = np.flatnonzero(c["tick"] == cue_tick)
                    if len(cue_rows):
                        since[sel] = (c["t_ns"][sel] - c["t_ns"][cue_rows[0]]) / 1e9
            frame = pd.DataFrame({
                "session_id": session_id, "segment": seg, "tick": c["tick"], "session_time_s": time_s,
                "trial_number": pd.Series(trial + 1, dtype="Int64").mask(trial < 0),
                "t_since_cue_s": since, "phase": c["phase"],
                **{k: c[k] for k in ("force_n", "raw_fx", "raw_fy", "raw_fz", "raw_tx", "raw_ty", "raw_tz",
                                     "render_fx", "render_fy", "render_fz", "gain", "derate")},
                "haptic_on": c["haptic_on"].astype(bool), "faults": c["faults"],
                **{k: c[k] for k in ("stylus_x_m", "stylus_y_m", "stylus_z_m")},
                "sensor_age_ms": c["sensor_age_ns"] / 1e6, "pose_age_ms": c["pose_age_ns"] / 1e6,
                "latency_ms": c["latency_ns"] / 1e6,
            })
            frames.append(frame)
    old = frame_of(db.session_samples(session_id)) if not arm else pd.DataFrame()  # (v1/v2 kept one arm's)
    if len(old):
        frames.append(pd.DataFrame({
            "session_id": session_id, "session_time_s": old["started_at_s"] + old["t_s"],
            "trial_number": pd.array(old["trial_index"] + 1, dtype="Int64"), "t_since_cue_s": old["t_s"],
            **{k: old[k] for k in old.columns if k.startswith(("raw_", "comp_", "render_")) or k == "force_n"},
        }))
    if not frames:
        return pd.DataFrame()
    out = pd.concat(frames, ignore_index=True)
    cols = [c for c in RECORDED_COLUMNS if c in out.columns] + [c for c in out.columns if c.startswith("comp_")]
    return out[cols].sort_values("session_time_s", kind="stable", ignore_index=True)
