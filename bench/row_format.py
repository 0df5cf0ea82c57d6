"""The row format of versions 1 and 2, rebuilt from a recorded study: the reference the benchmarks measure against.

Until schema version 3 the database kept each trial's window only, one
``samples`` row per 1 kHz sample (time since the cue, the task force, the raw,
compensated and rendered force: 15 values).  :func:`row_format_copy` writes
that file from a version-3 study: the trial windows come from the recording,
and the compensated force, which the recording does not keep, from running the
session through the pipeline again (:func:`pipeline.force.replay.replay`, checked bit
for bit against the recorded rendered force first).  The copy is then a
version-2 database, as the software of that version would have written it,
which the analysis reads from its ``samples`` table.

``bench study`` and ``bench report`` time the two formats side by side on the
same records, in the same run.
"""

from __future__ import annotations

import os
import sqlite3
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from foundation.parallel import default_workers, run_tasks
from pipeline.force.replay import replay
from protocol.storage import Recorder, StudyDatabase, connect_readonly
from protocol.storage.recordings import read_segment, segments_of

__all__ = ["ROW_COLUMNS", "RowCopy", "row_format_copy", "trial_window_rows"]

#: One ``samples`` row of versions 1 and 2 (after ``trial_id``).
ROW_COLUMNS = ("t_s", "force_n", "raw_fx", "raw_fy", "raw_fz", "raw_tx", "raw_ty", "raw_tz",
               "comp_fx", "comp_fy", "comp_fz", "render_fx", "render_fy", "render_fz")
_HANDOVER = 10  # rows a hand-over, as the blocks are handed over in ``bench study`` (a live session: ~every 10 ms)


@dataclass(frozen=True)
class RowCopy:
    """What :func:`row_format_copy` wrote and how long each part took."""

    path: str
    trials: int
    samples: int
    replay_s: float  # recomputing the compensated force (not part of what version 2 paid)
    insert_s: float  # writing the rows through the recorder, committed every 100 rows as version 2 did
    size_bytes: int


def trial_window_rows(database: str, session_id: int) -> list[tuple[int, npt.NDArray[np.float64]]]:
    """Every recorded trial's window of one session as version 2 stored it: ``(trial_id, rows)``.

    ``rows`` has the columns :data:`ROW_COLUMNS`; ``t_s`` counts from the trial's first record (its cue).

    Raises
    ------
    ValueError
        The session does not replay bit for bit (its compensated force could not be trusted).
    """
    conn = connect_readonly(database)
    try:
        trials = conn.execute("SELECT trial_id, segment, first_tick, last_tick FROM trials WHERE session_id = ? "
                              "AND first_tick IS NOT NULL ORDER BY trial_index", (session_id,)).fetchall()
        out: list[tuple[int, npt.NDArray[np.float64]]] = []
        for seg, _, _ in segments_of(conn, session_id):
            data = read_segment(conn, session_id, seg)
            replayed = replay(data.replay_inputs())
            c = data.columns
            render = np.stack([c[f"render_{a}"] for a in ("fx", "fy", "fz")], axis=1)
            if not np.array_equal(replayed.stage_force("render"), render):
                raise ValueError(f"session {session_id}, run {seg}: the replay differs from the recording")
            for trial_id, t_seg, first, last in trials:
                if t_seg != seg:
                    continue
                keep = (c["tick"] >= first) & (c["tick"] <= last)
                t_ns = c["t_ns"][keep]
                rows = np.column_stack([
                    (t_ns - t_ns[0]) / 1e9, c["force_n"][keep],
                    *(c[f"raw_{a}"][keep] for a in ("fx", "fy", "fz", "tx", "ty", "tz")),
                    replayed.stage_force("comp")[keep], render[keep],
                ])
                out.append((int(trial_id), rows))
        return out
    finally:
        conn.close()


def row_format_copy(source: str, target: str, *, workers: int | None = None,
                    progress: Callable[[int, int], None] | None = None) -> RowCopy:
    """Write ``target``: ``source`` (schema version 3 or 4) as version 2 kept it, trial windows in ``samples`` rows.

    Parameters
    ----------
    source
        A recorded study database (read only).
    target
        A new file (refused if it exists).
    workers
        Processes replaying sessions (default: :func:`foundation.parallel.default_workers`).
    progress
        ``progress(sessions done, sessions)``.
    """
    if os.path.exists(target):
        raise FileExistsError(f"{target}: exists")
    src = connect_readonly(source)
    dst = sqlite3.connect(target)
    try:
        src.backup(dst)
        sessions = [int(s) for (s,) in src.execute("SELECT session_id FROM sessions ORDER BY session_id")]
    finally:
        src.close()
    try:
        # version 2's pragmas (protocol.storage): write-ahead log, synced at checkpoints
        dst.execute("PRAGMA journal_mode = WAL")
        dst.execute("PRAGMA synchronous = NORMAL")
        dst.commit()
    finally:
        dst.close()
    t0 = time.perf_counter()
    n_workers = default_workers() if workers is None else workers
    done = [0]

    def tick(_: int, __: object) -> None:
        done[0] += 1
        if progress is not None:
            progress(done[0], len(sessions))

    per_session = run_tasks(trial_window_rows, [(source, s) for s in sessions], workers=n_workers, on_done=tick)
    replay_s = time.perf_counter() - t0
    trials, n, insert_s = _insert_rows(target, per_session)
    dst = sqlite3.connect(target)
    try:
        # what version 2 did not have: the recording and where each trial is in it
        dst.execute("DROP TABLE session_blocks")
        dst.execute("DROP TABLE IF EXISTS session_chunks")
        dst.execute("DROP TABLE recordings")
        for col in ("software_commit", "software_dirty"):  # (version 4: which code ran the session)
            dst.execute(f"ALTER TABLE sessions DROP COLUMN {col}")
        for col in ("segment", "first_tick", "last_tick"):
            dst.execute(f"ALTER TABLE trials DROP COLUMN {col}")
        dst.execute("PRAGMA user_version = 2")
        dst.commit()
        dst.execute("VACUUM")
        dst.execute("PRAGMA journal_mode = DELETE")  # one file, as the benchmark compares sizes
    finally:
        dst.close()
    return RowCopy(target, trials, n, replay_s, insert_s, os.path.getsize(target))


def _insert_rows(target: str, per_session: list[list[tuple[int, npt.NDArray[np.float64]]]]) -> tuple[int, int, float]:
    """Write the trial windows into ``target``'s ``samples`` as version 2's session runner did: ``_HANDOVER`` rows
    at a time, each built into one float array and queued to the recorder, which commits every 100 ms of records
    (a clock the records drive: every 100 rows) -- the same recorder path and cadence ``bench study`` times the blocks
    through.  Returns (trials, rows, seconds spent handing over and writing)."""
    db = StudyDatabase(target)
    now_s = [0.0]
    rec = Recorder(db, threaded=False, clock=lambda: now_s[0])
    trials = n = 0
    try:
        t0 = time.perf_counter()
        for windows in per_session:
            for trial_id, rows in windows:
                trials += 1
                for i in range(0, len(rows), _HANDOVER):
                    part = rows[i : i + _HANDOVER]
                    n += len(part)
                    now_s[0] = n * 1e-3  # (from the count: a sum of 0.01 s steps drifts and commits late)
                    rec.samples(np.column_stack((np.full(len(part), float(trial_id)), part)))
        rec.close()
        return trials, n, time.perf_counter() - t0
    finally:
        db.close()
