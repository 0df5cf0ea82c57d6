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
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd

from protocol.storage import HEALTH_COLUMNS, StorageError, StudyDatabase, trial_id_of
from protocol.recording import read_ticks
from protocol.storage import connect_readonly as _connect_readonly

#: Where a trial's records are in its session's recording (schema version 3).
RECORD_COLUMNS = ("segment", "first_tick", "last_tick")

__all__ = [
    "AnalysisError",
    "Progress",
    "StudyData",
    "connect_readonly",
    "load_study",
    "read_task_force",
    "recorded_where",
    "read_trial_samples",
]

#: ``progress(done, total)`` callback, called while samples are read.
Progress = Callable[[float, float], None]


class AnalysisError(ValueError):
    """The input cannot be analysed; the message says which file and why."""


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
        ``max_trial_s``, and ``excluded`` (``""`` when analysed, else
        ``"training session"`` or ``"aborted trial"``).
    sessions
        One row per session: ``database``, ``session_id``, ``participant_code``,
        ``participant_number``, ``kind``, ``status``, ``seed``, ``started_at``, ``ended_at``,
        ``end_reason``, ``software_version``, ``rig``, ``protocol_name``, the protocol's
        ``tolerance_fraction``, ``hold_s`` and ``max_trial_s``, and the watchdog limits the session
        ran with (``watchdog_sensor_max_age_ms``, ``watchdog_pose_max_age_ms``; NaN if not stored).
    databases
        The database paths, in the order given.
    """

    trials: pd.DataFrame
    sessions: pd.DataFrame
    databases: tuple[str, ...]

    @property
    def included(self) -> pd.DataFrame:
        """The trials analysis uses (experiment sessions, not aborted)."""
        return self.trials[self.trials["excluded"] == ""]


def _open(path: str) -> StudyDatabase:
    try:
        # read-only (an archive in a read-only folder opens immutable), and checked: a damaged file is one line
        return StudyDatabase(path, readonly=True, check=True)
    except StorageError as exc:
        raise AnalysisError(str(exc)) from None


def _query(db: StudyDatabase, sql: str) -> pd.DataFrame:
    try:
        return pd.read_sql_query(sql, db.conn)
    except (sqlite3.DatabaseError, pd.errors.DatabaseError) as exc:
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


def _watchdog_limits(config_json: object) -> dict[str, float]:
    """The watchdog's age limits a session ran with, ms (NaN where its configuration does not say)."""
    try:
        wd = json.loads(str(config_json)).get("watchdog", {})
        sensor, pose = float(wd["sensor_max_age_s"]) * 1e3, float(wd["pose_max_age_s"]) * 1e3
    except (ValueError, KeyError, TypeError, AttributeError):
        sensor = pose = math.nan
    return {"watchdog_sensor_max_age_ms": sensor, "watchdog_pose_max_age_ms": pose}


def _read_one(path: str) -> tuple[pd.DataFrame, pd.DataFrame]:
    db = _open(path)
    try:
        sessions = _query(
            db,
            "SELECT s.session_id, p.code AS participant_code, s.participant_number, s.kind, s.status, s.seed, "
            "s.started_at, "
            "s.ended_at, s.end_reason, s.software_version, s.rig, s.protocol_json, s.config_json "
            "FROM sessions s JOIN participants p USING (participant_id) ORDER BY s.session_id",
        )
        # schema version 2 records why a trial was aborted and how the loop ran; a version-1 file has neither
        has = {r[1] for r in db.conn.execute("PRAGMA table_info(trials)")}
        v2 = ", ".join(c if c in has else f"NULL AS {c}"
                       for c in ("abort_cause", *HEALTH_COLUMNS, *RECORD_COLUMNS))
        trials = _query(
            db,
            "SELECT trial_id, session_id, trial_index, target_label, target_force_n, haptic_mode, outcome, "
            "started_at_s, ended_at_s, tct_s AS stored_tct_s, rmse_n AS stored_rmse_n, "
            "max_ae_n AS stored_max_ae_n, time_in_band_s AS stored_time_in_band_s, "
            f"peak_force_n AS stored_peak_force_n, n_samples, abort_reason, {v2} "
            "FROM trials ORDER BY session_id, trial_index",
        )
    finally:
        db.close()
    if sessions.empty:
        raise AnalysisError(f"{path}: empty study database (no sessions)")
    proto = pd.DataFrame(
        [_protocol_fields(pj, f"{path}: session {sid}") for sid, pj in zip(sessions["session_id"], sessions["protocol_json"])],
        index=sessions.index,
    )
    watchdog = pd.DataFrame([_watchdog_limits(cj) for cj in sessions["config_json"]], index=sessions.index)
    sessions = pd.concat([sessions.drop(columns=["protocol_json", "config_json"]), proto, watchdog], axis=1)
    sessions.insert(0, "database", path)
    trials.insert(0, "database", path)
    return sessions, trials


def load_study(paths: Sequence[str | os.PathLike[str]]) -> StudyData:
    """Read and merge study databases.

    Parameters
    ----------
    paths
        One or more haptic-study databases.

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
    if not paths:
        raise AnalysisError("--db: give at least one study database")
    seen: dict[tuple[int, int], str] = {}
    all_sessions, all_trials = [], []
    for raw in paths:
        path = str(raw)
        if not Path(path).exists():
            raise AnalysisError(f"{path}: no such database")
        st = os.stat(path)
        key = (st.st_dev, st.st_ino)
        if key in seen:
            raise AnalysisError(f"{path}: the same database is given twice (also as {seen[key]})")
        seen[key] = path
        s, t = _read_one(path)
        all_sessions.append(s)
        all_trials.append(t)
    sessions = pd.concat(all_sessions, ignore_index=True)
    owners = sessions.groupby("participant_code")["database"].unique()
    for code, dbs in owners.items():
        if len(dbs) > 1:
            raise AnalysisError(
                f"participant code {code!r} appears in {dbs[0]} and {dbs[1]}; the merge refuses to guess "
                "whether they are one person (analyse the databases separately or re-code one)"
            )
    trials = pd.concat(all_trials, ignore_index=True)
    meta = sessions[["database", "session_id", "participant_code", "participant_number", "kind", "status",
                     "tolerance_fraction", "hold_s", "max_trial_s"]].rename(
        columns={"kind": "session_kind", "status": "session_status"}
    )
    trials = trials.merge(meta, on=["database", "session_id"], how="left", validate="many_to_one")
    excluded = np.where(
        trials["session_kind"] != "experiment", "training session",
        np.where(trials["outcome"] == "aborted", "aborted trial", ""),
    )
    trials["excluded"] = excluded
    order = ["database", "participant_code", "participant_number", "session_id", "session_kind", "session_status",
             "trial_id", "trial_index", "target_label", "target_force_n", "haptic_mode", "outcome", "started_at_s",
             "ended_at_s", "stored_tct_s", "stored_rmse_n", "stored_max_ae_n", "stored_time_in_band_s",
             "stored_peak_force_n", "n_samples", "abort_reason", "abort_cause", *HEALTH_COLUMNS, *RECORD_COLUMNS,
             "tolerance_fraction", "hold_s", "max_trial_s", "excluded"]
    trials = trials[order]
    names = ", ".join(str(p) for p in paths)
    if not (sessions["kind"] == "experiment").any():
        raise AnalysisError(f"{names}: only training sessions; there is no experiment session to analyse")
    if (trials["excluded"] == "").sum() == 0:
        raise AnalysisError(f"{names}: the experiment sessions have no finished trial to analyse")
    return StudyData(trials=trials, sessions=sessions, databases=tuple(str(p) for p in paths))


def read_task_force(conn: sqlite3.Connection, trial_id: int, where: tuple[int, int, int, int] | None = None,
                    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
    """One trial's task-force samples: times since the cue (int ns) and ``force_n`` (N).

    Parameters
    ----------
    conn
        An open connection to the study database.
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
        t = cols["t_ns"].astype(np.int64)
        return (t - t[0] if len(t) else t), cols["force_n"].astype(np.float64)  # the first record is the cue
    rows = conn.execute("SELECT t_s, force_n FROM samples WHERE trial_id = ? ORDER BY t_s", (trial_id,)).fetchall()
    if not rows:
        return np.empty(0, np.int64), np.empty(0, np.float64)
    block = np.array(rows, dtype=np.float64)
    # t_s was stored as ns / 1e9; rounding recovers the integer ns exactly (|t| ≪ 2^53 ns)
    return np.rint(block[:, 0] * 1e9).astype(np.int64), np.ascontiguousarray(block[:, 1])


def recorded_where(session_id: object, segment: object, first_tick: object, last_tick: object,
                   ) -> tuple[int, int, int, int] | None:
    """A trial's place in its session's recording, or None when it has none (a trial of schema version 1 or 2)."""
    values = (segment, first_tick, last_tick)
    if any(v is None or (isinstance(v, float) and math.isnan(v)) or v is pd.NA for v in values):
        return None
    return int(session_id), int(segment), int(first_tick), int(last_tick)  # type: ignore[arg-type]


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
                   "render_fx", "render_fy", "render_fz")


def read_trial_samples(database: str | os.PathLike[str], session_id: int, trial_index: int) -> pd.DataFrame:
    """Every stored column of one trial's samples, in time order.

    Parameters
    ----------
    database
        The study database.
    session_id, trial_index
        Which trial.

    Returns
    -------
    pandas.DataFrame
        Columns ``t_s`` (since the cue), ``force_n``, ``raw_f*``, ``raw_t*``, ``render_f*``, and
        ``comp_f*`` for a trial of schema version 1 or 2 (a recorded session's compensated force is
        recomputed by replay, :func:`pipeline.replay.replay`, not stored).

    Raises
    ------
    AnalysisError
        Not a study database, or no samples for that trial.
    """
    db = _open(str(database))
    try:
        frame = pd.DataFrame()
        if db.schema_version >= 3:
            row = db.conn.execute("SELECT segment, first_tick, last_tick FROM trials WHERE trial_id = ?",
                                  (trial_id_of(int(session_id), int(trial_index)),)).fetchone()
            where = None if row is None else recorded_where(session_id, *row)
            if where is not None:
                cols = read_ticks(db.conn, *where, ("t_ns", *_RECORDED_TRACE))
                t_ns = cols.pop("t_ns")
                frame = pd.DataFrame({"t_s": (t_ns - t_ns[0]) / 1e9, **{c: cols[c] for c in _RECORDED_TRACE}})
        if frame.empty:
            frame = pd.read_sql_query(
                f"SELECT {', '.join(_SAMPLE_COLUMNS)} FROM samples WHERE trial_id = ? ORDER BY t_s",
                db.conn, params=(trial_id_of(int(session_id), int(trial_index)),),
            )
    finally:
        db.close()
    if frame.empty:
        raise AnalysisError(f"{database}: no samples for session {session_id}, trial {trial_index}")
    return frame
