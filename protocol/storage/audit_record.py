"""The record against itself: what ``haptic-study check`` verifies beyond the bytes of the recording.

A trial row, its events and its records are written by one runner at one moment; each can be edited alone
afterwards and still read well.  So :func:`check_record` compares them:

* **references** -- SQLite's ``PRAGMA foreign_key_check``: an event, a trial or a recorded block of a session
  (or run) that does not exist;
* **a trial against its events** -- every stored trial was cued: its ``cue`` event names it, its target (label
  and force) and its haptic mode as the trial row does, within :data:`CUE_TOLERANCE_S` of its start;
* **a trial against its records** -- the session time of the record at its ``first_tick`` (the recording's
  ``started_at_s`` plus the loop time since the run's first record) is its ``started_at_s``, within
  :data:`CUE_TOLERANCE_S`: a window moved to other records is not where the trial ran.

* **a trial's metrics against its records** -- its session's task judges the trial's records again, as the report
  does (:meth:`protocol.tasks.base.Task.judge`, the cue window), and the outcome and every stored metric must be
  the stored ones (:func:`protocol.study.records.disagreement`, to :data:`protocol.study.records.AGREE_REL`).
"""

from __future__ import annotations

import json
import math
import re
import sqlite3
from collections.abc import Callable

from protocol.recording.codec import decode_columns
from protocol.recording.integrity import RecordingDamaged
from protocol.storage.damage import block_rows
from protocol.storage.recordings import read_ticks
from protocol.study.config import ProtocolConfig, ProtocolError, protocol_from_dict
from protocol.study.records import TrialRecord, disagreement
from protocol.tasks.base import TrialTarget
from protocol.tasks.force_regulation import ForceRegulation

__all__ = ["CUE_TOLERANCE_S", "check_record"]

#: How far a trial's first record and its cue event may be from its stored start, s.  The runner's start reaches
#: the loop within a few ticks on the real clock (the same tick on the virtual one); a window or an event moved by
#: more is not where the trial ran.
CUE_TOLERANCE_S = 0.1
#: How events name a trial and say its cue (protocol.runner.session's ``trial_words`` and cue event).
_CUE = re.compile(r"^trial (\d+) \(index (\d+)\): (.+), haptics (\w+)$")


def check_record(conn: sqlite3.Connection, problem: Callable[[str], None]) -> None:
    """Add a line to ``problem`` for every disagreement (see the module docstring)."""
    _references(conn, problem)
    _trials_against_events(conn, problem)
    _trials_against_records(conn, problem)
    _metrics_against_records(conn, problem)


def _protocols(conn: sqlite3.Connection) -> dict[int, ProtocolConfig | None]:
    """Every session's protocol as it ran (None: unreadable, which the design check says)."""
    out: dict[int, ProtocolConfig | None] = {}
    for sid, pj in conn.execute("SELECT session_id, protocol_json FROM sessions"):
        try:
            out[int(sid)] = protocol_from_dict(json.loads(pj), f"session {sid} protocol")
        except (ProtocolError, ValueError, TypeError):
            out[int(sid)] = None
    return out


def _metrics_against_records(conn: sqlite3.Connection, problem: Callable[[str], None]) -> None:
    protocols = _protocols(conn)
    cur = conn.execute("SELECT * FROM trials WHERE segment IS NOT NULL AND first_tick IS NOT NULL "
                       "AND outcome != 'aborted' ORDER BY session_id, trial_index")
    names = [d[0] for d in cur.description]
    for values in cur.fetchall():
        row = dict(zip(names, values, strict=True))
        sid = int(row["session_id"])
        protocol = protocols.get(sid)  # None: no such session, or its protocol unreadable (the other checks say)
        if protocol is None:
            continue
        try:
            cols = read_ticks(conn, sid, int(row["segment"]), int(row["first_tick"]), int(row["last_tick"]),
                              ("t_ns", "force_n"))
        except RecordingDamaged:
            continue  # the recording's check names it
        if len(cols["t_ns"]) == 0:
            continue  # no records there: the recording's check says so
        record = TrialRecord.from_row(row)
        t_ns = cols["t_ns"] - cols["t_ns"][0]  # the first record is the cue
        again = protocol.task.judge(t_ns, cols["force_n"], record, max_trial_s=protocol.trial.max_trial_s)
        why = disagreement(again, record)
        if why:
            problem(f"trial {record.trial_index + 1} of session {sid}: {why} (the stored metrics are not its "
                    "records')")


def _references(conn: sqlite3.Connection, problem: Callable[[str], None]) -> None:
    for table, rowid, parent, _fk in conn.execute("PRAGMA foreign_key_check"):
        problem(f"{table} row {rowid} refers to a row of {parent} that does not exist")


def _trials_against_events(conn: sqlite3.Connection, problem: Callable[[str], None]) -> None:
    cues: dict[tuple[int, int], list[tuple[float, str]]] = {}
    for sid, t_s, detail in conn.execute("SELECT session_id, t_s, detail FROM events WHERE kind = 'cue'"):
        m = _CUE.match(str(detail or ""))
        if m is None:
            problem(f"session {sid}: a cue event at {float(t_s):.3f} s does not name a trial as the runner does "
                    f"({str(detail)[:60]!r})")
            continue
        cues.setdefault((int(sid), int(m.group(2))), []).append((float(t_s), m.group(3) + ", haptics " + m.group(4)))
    protocols = _protocols(conn)
    for sid, idx, label, force_n, mode, start_s in conn.execute(
            "SELECT session_id, trial_index, target_label, target_force_n, haptic_mode, started_at_s FROM trials "
            "ORDER BY session_id, trial_index"):
        where = f"trial {int(idx) + 1} of session {sid}"
        protocol = protocols.get(int(sid))
        task = protocol.task if protocol is not None else ForceRegulation()  # the task of a file without [task]
        # the cue's words are the session's task's (protocol.tasks: cue_text), as the runner wrote them
        said = f"{task.cue_text(TrialTarget(str(label), float(force_n), str(mode)))}, haptics {mode}"
        near = [(t, text) for t, text in cues.get((int(sid), int(idx)), [])
                if -CUE_TOLERANCE_S <= float(start_s) - t <= CUE_TOLERANCE_S]
        if not near:
            problem(f"{where}: no cue event within {CUE_TOLERANCE_S:g} s of its start ({float(start_s):.3f} s)")
        elif all(text != said for _, text in near):
            problem(f"{where}: its cue event says {near[0][1]!r}, the trial row {said!r}")


def _trials_against_records(conn: sqlite3.Connection, problem: Callable[[str], None]) -> None:
    runs = {(int(s), int(g)): (float(a), int(t0)) for s, g, a, t0 in conn.execute(
        "SELECT session_id, segment, started_at_s, t0_ns FROM recordings")}
    for sid, idx, seg, first, start_s in conn.execute(
            "SELECT session_id, trial_index, segment, first_tick, started_at_s FROM trials "
            "WHERE segment IS NOT NULL AND first_tick IS NOT NULL ORDER BY session_id, trial_index"):
        where = f"trial {int(idx) + 1} of session {sid}"
        run = runs.get((int(sid), int(seg)))
        if run is None:
            continue  # no such run: a reference problem, said above
        t_s = _session_time(conn, int(sid), int(seg), int(first), run)
        if t_s is None:
            continue  # the tick is in no readable block: the recording's check says so
        if not math.isclose(t_s, float(start_s), rel_tol=0.0, abs_tol=CUE_TOLERANCE_S):
            problem(f"{where}: its first record (tick {first}) is at {t_s:.3f} s of the session, its start at "
                    f"{float(start_s):.3f} s (its window is not where the trial ran)")


def _session_time(conn: sqlite3.Connection, sid: int, seg: int, tick: int, run: tuple[float, int]) -> float | None:
    """The session time of the record at ``tick`` (None: no readable block holds it)."""
    for row in block_rows(conn, session_id=sid, segment=seg, ticks=(tick, tick)):
        try:
            cols = decode_columns(row.data, ["tick", "t_ns"])
        except Exception:  # a block that does not decode is the recording's check's finding
            return None
        at = (cols["tick"] == tick).nonzero()[0]
        if len(at):
            started_at_s, t0_ns = run
            return started_at_s + (int(cols["t_ns"][at[0]]) - t0_ns) / 1e9
    return None
