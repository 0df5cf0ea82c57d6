"""A study's 1 kHz records read back for analysis: one trial's task force, one trial's every column, a session's
records as one table.

A recorded session (schema version 3 and later) is read from its blocks (:mod:`protocol.storage.recordings`),
a trial by its place in the recording (:func:`analysis.reading.load.recorded_where`); a session of versions 1 and 2
from its ``samples`` rows.  :mod:`analysis.reading.samples` labels a session's table for people.
"""

from __future__ import annotations

import os
import sqlite3

import numpy as np
import numpy.typing as npt
import pandas as pd

from analysis.reading.errors import AnalysisError
from analysis.reading.load import _open, frame_of, recorded_where
from protocol.recording import RecordingDamaged
from protocol.storage import StudyReader, trial_id_of
from protocol.storage.recordings import read_ticks

__all__ = ["RECORDED_COLUMNS", "read_task_force", "read_trial_samples", "recorded_samples"]


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
