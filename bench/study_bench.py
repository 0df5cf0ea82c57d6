"""``haptic-study bench study``: a complete simulated study on the virtual clock, and what storing it costs.

Side by side in the same run, on the same records: the study's whole sessions
written again as the recorder writes them (compressed blocks, schema version 3)
and the trial windows as version 2 kept them (one ``samples`` row per record,
:mod:`bench.row_format`), both handed to the recorder as a live session hands
them (10 records a hand-over) and committed at its rate (every 100 records, i.e.
every 100 ms at 1 kHz).
"""

from __future__ import annotations

import json
import os
import sqlite3
import tempfile
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from bench.row_format import row_format_copy
from pipeline.core.tick_record import TICK_DTYPE
from protocol.storage import Recorder, StudyDatabase, connect_readonly
from protocol.storage.recordings import SegmentData, read_segment, segments_of
from protocol.study.config import load_protocol
from study_app.headless import default_jobs, run_study

__all__ = ["format_study_bench", "rewrite_recording", "run_study_bench"]

_CHUNK = 10  # records per hand-over, as the runner hands them on a live session (~every 10 ms)


class _RecordClock:
    """The recorder's commit clock driven by the records' own time: a commit every 100 records, as live."""

    def __init__(self) -> None:
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


def rewrite_recording(source: str, target: str) -> tuple[float, int]:
    """Write every recorded segment of ``source`` again into ``target`` through the recorder, at the live commit rate.

    Each segment's records are handed over as a live session hands them: loop records as the ring holds them
    (:data:`pipeline.core.tick_record.TICK_DTYPE`; the fields a recording does not keep are zero here), ``_CHUNK``
    at a time, each with the log entries of its ticks.

    Returns
    -------
    seconds, records
        Time spent handing records over and in the recorder (reading the source and cutting it into
        hand-overs is not counted) and records written.
    """
    src = connect_readonly(source)
    dst = sqlite3.connect(target)
    try:
        src.backup(dst)
        segments = [read_segment(src, sid, seg) for (sid,) in src.execute("SELECT session_id FROM sessions")
                    for seg, _, _ in segments_of(src, sid)]
        recordings = src.execute("SELECT session_id, segment, scales_json FROM recordings")
        scales = {(sid, seg): s for sid, seg, s in recordings}
        dst.execute("DELETE FROM session_blocks")
        if dst.execute("SELECT 1 FROM sqlite_master WHERE name = 'session_chunks'").fetchone():  # (a file before it)
            dst.execute("DELETE FROM session_chunks")
        dst.execute("DELETE FROM recordings")
        dst.commit()
    finally:
        src.close()
        dst.close()
    db = StudyDatabase(target)
    clock = _RecordClock()
    rec = Recorder(db, threaded=False, clock=clock)
    n, spent = 0, 0.0
    try:
        for s in segments:
            hand_overs = _hand_overs(s)  # (one segment at a time: a whole study's loop records need GBs)
            t0 = time.perf_counter()
            rec.segment(s.session_id, s.segment, s.started_at_s, s.t0_ns, s.snapshot,
                        json.loads(scales[(s.session_id, s.segment)]))
            for rows, log, now_s in hand_overs:
                clock.now_s = now_s
                rec.records(s.session_id, s.segment, rows, log)
                n += len(rows)
            spent += time.perf_counter() - t0
        t0 = time.perf_counter()
        rec.close()
        spent += time.perf_counter() - t0
    finally:
        db.close()
    return spent, n


def _hand_overs(s: SegmentData) -> list[tuple[np.ndarray, list[tuple[int, str, Any]], float]]:
    """A segment cut as a live session hands it to the recorder: (loop records, their log entries, commit clock)."""
    cols = s.columns
    rows = np.zeros(len(cols["tick"]), TICK_DTYPE)
    for name, values in cols.items():
        rows[name] = values
    log = s.log()
    log_ticks = np.array([e[0] for e in log], dtype=np.int64)
    ticks = cols["tick"]
    out = []
    for lo in range(0, len(ticks), _CHUNK):
        hi = min(lo + _CHUNK, len(ticks))
        a, b = np.searchsorted(log_ticks, [ticks[lo], ticks[hi - 1] + 1])
        if lo == 0:
            a = 0  # entries logged before the first record belong to it
        out.append((rows[lo:hi], log[a:b], (int(cols["t_ns"][hi - 1]) - s.t0_ns) / 1e9))
    return out


def run_study_bench(participants: int = 10, seed: int = 0, protocol_path: str | None = None,
                    log: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run the study into a temporary database and measure it, then its storage both ways.

    Parameters
    ----------
    participants, seed, protocol_path
        The study (participants run in parallel, as ``run`` does by default).
    log
        Called with a line before each long step.
    """
    say = log or (lambda _: None)
    protocol = load_protocol(protocol_path)
    with tempfile.TemporaryDirectory() as tmp:
        db = os.path.join(tmp, "bench.db")
        say(f"running a {participants}-participant study ...")
        t0 = time.perf_counter()
        progress = run_study(db, participants=participants, seed=seed, protocol=protocol)
        wall = time.perf_counter() - t0
        c = connect_readonly(db)
        try:
            trials = c.execute("SELECT COUNT(*) FROM trials t JOIN sessions s USING (session_id) "
                               "WHERE s.kind = 'experiment'").fetchone()[0]
            records = c.execute("SELECT COALESCE(SUM(n_records), 0) FROM session_blocks").fetchone()[0]
        finally:
            c.close()
        size = sum(os.path.getsize(os.path.join(tmp, f)) for f in os.listdir(tmp))
        say("writing its records again as blocks, at the live commit rate ...")
        blocks_s, blocks_n = rewrite_recording(db, os.path.join(tmp, "blocks.db"))
        blocks_size = os.path.getsize(os.path.join(tmp, "blocks.db"))
        say("and its trial windows as rows, as versions 1 and 2 kept them (replaying every session first) ...")
        rows = row_format_copy(db, os.path.join(tmp, "rows.db"))
    ticks = progress.study_time_s * 1000.0
    return {
        "participants": participants,
        "jobs": default_jobs(participants),
        "wall_s": round(wall, 2),
        "study_time_min": round(progress.study_time_s / 60.0, 2),
        "speed_x_real_time": round(progress.study_time_s / wall, 1),
        "us_per_tick": round(wall / ticks * 1e6, 2) if ticks else None,
        "experiment_trials": trials,
        "records_stored": int(records),
        "database_mb": round(size / 1e6, 1),
        "storage": {
            "blocks": {"records": blocks_n, "write_s": round(blocks_s, 2), "database_mb": round(blocks_size / 1e6, 1)},
            "rows": {"records": rows.samples, "write_s": round(rows.insert_s, 2),
                     "database_mb": round(rows.size_bytes / 1e6, 1)},
        },
    }


def format_study_bench(r: dict[str, Any]) -> str:
    """Human-readable summary."""
    b, w = r["storage"]["blocks"], r["storage"]["rows"]

    def per(x: dict[str, Any]) -> str:
        return f"{x['write_s'] / x['records'] * 1e6:5.2f} µs/record" if x["records"] else "   -"

    return (
        f"{r['participants']} simulated participants (training + experiment), virtual clock, "
        f"{r['jobs']} worker process{'es' if r['jobs'] != 1 else ''}:\n"
        f"  wall time             {r['wall_s']:.1f} s\n"
        f"  study time            {r['study_time_min']:.1f} min ({r['speed_x_real_time']:.0f}x real time)\n"
        f"  wall time per tick    {r['us_per_tick']:.1f} µs (all workers together; rig + pipeline + participant + "
        f"runner + storage)\n"
        f"  stored                {r['experiment_trials']} experiment trials, whole sessions: "
        f"{r['records_stored']:,} records, {r['database_mb']:.0f} MB\n"
        f"the same study stored both ways, through the recorder at a live session's pace (10 records a hand-over, "
        f"a commit every 100), same run:\n"
        f"  whole sessions, blocks (v3)      {b['records']:>10,} records  {b['database_mb']:6.1f} MB  "
        f"{b['write_s']:6.1f} s writing ({per(b)})\n"
        f"  trial windows, rows (v1/v2)      {w['records']:>10,} records  {w['database_mb']:6.1f} MB  "
        f"{w['write_s']:6.1f} s writing ({per(w)})"
    )
