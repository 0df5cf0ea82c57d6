"""The Lab Streaming Layer's part of a study database: each run's clock link, the external streams recorded with a
session and their samples (docs/lsl.md).

Three tables, made by the first session that uses LSL (a study that never does has none, and its file is what it
always was):

* ``lsl_runs``: per session and recorded segment, how the records' times map to LSL's clock (``records_to_lsl_s``:
  a record's LSL time is its ``t_ns`` × 1e-9 plus this), the bound of that measurement, and the outlets published;
* ``lsl_streams``: per external stream recorded in a run, what it is (its name, type, source id, channels, rate and
  the full description LSL gave, as XML);
* ``lsl_chunks``: its samples, in the chunks they were taken in: their LSL timestamps on the source's clock
  (float64), their values (float64 by channel; a string stream's as JSON), and the clock offset
  (``time_correction_s``, the source's clock to ours) measured when the chunk was taken.

:func:`aligned_samples` puts the samples on the session clock: a sample's session time is the segment's
``started_at_s`` plus its time on our LSL clock (``lsl_t_s + time_correction_s``) less the segment's first record's
LSL time.  A participant's rows go with them (:mod:`protocol.storage.withdrawal`) and are in their export.
"""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from protocol.storage.common import has_table
from protocol.study.labels import plural

__all__ = ["ALIGNED_COLUMNS", "LSL_TABLES", "LslChunk", "LslStream", "aligned_samples", "audit_lsl",
           "ensure_lsl_tables", "erase_lsl_rows", "insert_chunk", "insert_run", "insert_stream", "stored_marker_times"]

#: The tables, children first (the order a withdrawal deletes in).
LSL_TABLES = ("lsl_chunks", "lsl_streams", "lsl_runs")

_DDL = """
CREATE TABLE IF NOT EXISTS lsl_runs (
    session_id        INTEGER NOT NULL REFERENCES sessions(session_id),
    segment           INTEGER NOT NULL,
    records_to_lsl_s  REAL NOT NULL,  -- LSL time of a record = its t_ns * 1e-9 + this
    uncertainty_s     REAL NOT NULL,  -- half the narrowest bracket of the clocks' readings
    outlets           TEXT NOT NULL,  -- JSON list of the outlets published (name, type, source_id)
    PRIMARY KEY (session_id, segment)
);
CREATE TABLE IF NOT EXISTS lsl_streams (
    session_id     INTEGER NOT NULL REFERENCES sessions(session_id),
    segment        INTEGER NOT NULL,
    stream         INTEGER NOT NULL,  -- its place in the protocol's lsl.record list
    selector       TEXT NOT NULL,     -- how the protocol named it: name = '…' or type = '…'
    name           TEXT NOT NULL,
    type           TEXT NOT NULL,
    source_id      TEXT NOT NULL,
    hostname       TEXT NOT NULL,
    channel_count  INTEGER NOT NULL,
    nominal_srate  REAL NOT NULL,     -- Hz, 0 for an irregular stream
    channel_format TEXT NOT NULL,     -- float32, double64, string, ...
    info_xml       TEXT NOT NULL,
    PRIMARY KEY (session_id, segment, stream)
);
CREATE TABLE IF NOT EXISTS lsl_chunks (
    session_id        INTEGER NOT NULL,
    segment           INTEGER NOT NULL,
    stream            INTEGER NOT NULL,
    chunk             INTEGER NOT NULL,
    n_samples         INTEGER NOT NULL,
    lsl_t             BLOB NOT NULL,  -- float64 little-endian: each sample's LSL timestamp, the source's clock
    data              BLOB NOT NULL,  -- float64 little-endian n_samples x channel_count, or UTF-8 JSON (strings)
    time_correction_s REAL NOT NULL,  -- the source's clock to ours, measured when the chunk was taken
    PRIMARY KEY (session_id, segment, stream, chunk),
    FOREIGN KEY (session_id, segment, stream) REFERENCES lsl_streams(session_id, segment, stream)
);
"""


def ensure_lsl_tables(conn: sqlite3.Connection) -> None:
    """Make the tables (in the caller's transaction) if the file lacks them."""
    for statement in _DDL.split(";"):
        if statement.strip():
            conn.execute(statement)


def insert_run(conn: sqlite3.Connection, session_id: int, segment: int, records_to_lsl_s: float,
               uncertainty_s: float, outlets: list[dict[str, str]]) -> None:
    """One run's clock link and outlets (a resumed run replaces nothing: each segment has its own row)."""
    ensure_lsl_tables(conn)
    conn.execute("INSERT INTO lsl_runs VALUES (?, ?, ?, ?, ?)",
                 (session_id, segment, records_to_lsl_s, uncertainty_s, json.dumps(outlets, sort_keys=True)))


@dataclass(frozen=True, slots=True)
class LslStream:
    """An external stream recorded in one run: the ``lsl_streams`` row."""

    session_id: int
    segment: int
    stream: int
    selector: str
    name: str
    type: str
    source_id: str
    hostname: str
    channel_count: int
    nominal_srate: float
    channel_format: str
    info_xml: str


def insert_stream(conn: sqlite3.Connection, s: LslStream) -> None:
    """The row of a stream whose recording starts."""
    ensure_lsl_tables(conn)
    conn.execute("INSERT INTO lsl_streams VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                 (s.session_id, s.segment, s.stream, s.selector, s.name, s.type, s.source_id, s.hostname,
                  s.channel_count, s.nominal_srate, s.channel_format, s.info_xml))


@dataclass(frozen=True, slots=True)
class LslChunk:
    """Samples of one stream taken together: their LSL timestamps (source's clock), values, and the clock offset."""

    session_id: int
    segment: int
    stream: int
    chunk: int
    lsl_t_s: npt.NDArray[np.float64]
    values: npt.NDArray[np.float64] | list[list[str]]
    time_correction_s: float


def insert_chunk(conn: sqlite3.Connection, c: LslChunk) -> None:
    """One chunk's row."""
    if isinstance(c.values, np.ndarray):
        data = np.ascontiguousarray(c.values, dtype="<f8").tobytes()
    else:
        data = json.dumps(c.values).encode("utf-8")
    conn.execute("INSERT INTO lsl_chunks VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                 (c.session_id, c.segment, c.stream, c.chunk, len(c.lsl_t_s),
                  np.ascontiguousarray(c.lsl_t_s, dtype="<f8").tobytes(), data, c.time_correction_s))


#: The columns of :func:`aligned_samples`' rows.
ALIGNED_COLUMNS = ("session_id", "segment", "stream", "lsl_t_s", "time_correction_s", "session_t_s", "values")


def aligned_samples(conn: sqlite3.Connection, session_id: int) -> Iterator[tuple[Any, ...]]:
    """Every recorded sample of a session's external streams, oldest chunk first, one row (:data:`ALIGNED_COLUMNS`)
    per sample: the stream's name, its LSL timestamp (source's clock), the clock offset then, its session-clock time
    (None where the run recorded no record to align it to) and its channels' values as a JSON list."""
    if not has_table(conn, "lsl_chunks"):
        return
    starts = {int(seg): (float(s), int(t0)) for seg, s, t0 in conn.execute(
        "SELECT segment, started_at_s, t0_ns FROM recordings WHERE session_id = ?", (session_id,))}
    links = {int(seg): float(x) for seg, x in conn.execute(
        "SELECT segment, records_to_lsl_s FROM lsl_runs WHERE session_id = ?", (session_id,))}
    streams = {(int(r[0]), int(r[1])): (str(r[2]), str(r[3]), int(r[4])) for r in conn.execute(
        "SELECT segment, stream, name, channel_format, channel_count FROM lsl_streams WHERE session_id = ?",
        (session_id,))}
    for seg, stream, n, t_blob, data, tc in conn.execute(
            "SELECT segment, stream, n_samples, lsl_t, data, time_correction_s FROM lsl_chunks WHERE session_id = ? "
            "ORDER BY segment, stream, chunk", (session_id,)).fetchall():
        name, fmt, channels = streams[(int(seg), int(stream))]
        t = np.frombuffer(t_blob, dtype="<f8")
        values = (json.loads(bytes(data).decode("utf-8")) if fmt == "string"
                  else np.frombuffer(data, dtype="<f8").reshape(int(n), channels).tolist())
        start, link = starts.get(int(seg)), links.get(int(seg))
        for i in range(int(n)):
            ours = float(t[i]) + float(tc)  # the sample's time on our LSL clock
            session_s = None if start is None or link is None else start[0] + (ours - link) - start[1] * 1e-9
            yield (session_id, int(seg), name, float(t[i]), float(tc), session_s, json.dumps(values[i]))


def stored_marker_times(conn: sqlite3.Connection, session_id: int) -> dict[tuple[str, int | None], float]:
    """Where each stored event a marker stands for lies on our LSL clock, s, by (marker event, trial numbered from
    1): the session's start, every cue, every trial's end (its outcome; ``abort`` for an aborted one), the session's
    end or interruption -- through the first run's clock link (``lsl_runs``); empty for a session without one.  What
    a marker inlet received is held against these (``haptic-study bench lsl``)."""
    if not has_table(conn, "lsl_runs"):
        return {}
    run = conn.execute("SELECT r.started_at_s, r.t0_ns, l.records_to_lsl_s FROM recordings r JOIN lsl_runs l ON "
                       "l.session_id = r.session_id AND l.segment = r.segment WHERE r.session_id = ? "
                       "ORDER BY r.segment", (session_id,)).fetchone()
    if run is None:
        return {}
    started, t0_ns, link = float(run[0]), int(run[1]), float(run[2])
    stored: dict[tuple[str, int | None], float] = {("session_start", None): 0.0}
    for kind, t_s, detail in conn.execute("SELECT kind, t_s, detail FROM events WHERE session_id = ? AND kind IN "
                                          "('cue', 'session_end', 'session_interrupted')", (session_id,)):
        trial = int(str(detail).split("index ")[1].split(")")[0]) + 1 if kind == "cue" else None
        stored[(str(kind), trial)] = float(t_s)
    for index, outcome, end_s in conn.execute("SELECT trial_index, outcome, ended_at_s FROM trials WHERE "
                                              "session_id = ?", (session_id,)):
        stored[({"aborted": "abort"}.get(str(outcome), str(outcome)), int(index) + 1)] = float(end_s)
    return {key: (t_s - started) + t0_ns * 1e-9 + link for key, t_s in stored.items()}


def erase_lsl_rows(conn: sqlite3.Connection, session_id: int) -> None:
    """Remove a session's rows of every LSL table (a withdrawal; the caller's transaction)."""
    for table in LSL_TABLES:
        if has_table(conn, table):
            conn.execute(f"DELETE FROM {table} WHERE session_id = ?", (session_id,))


def audit_lsl(conn: sqlite3.Connection, note: Callable[[str], None], problem: Callable[[str], None]) -> None:
    """``check``'s look at the LSL tables (none: nothing to say): every chunk's bytes hold as many samples as its row
    says, every row belongs to a stored session; one note counting what is recorded."""
    if not has_table(conn, "lsl_chunks"):
        return
    formats = {(int(r[0]), int(r[1]), int(r[2])): (str(r[3]), str(r[4]), int(r[5])) for r in conn.execute(
        "SELECT session_id, segment, stream, name, channel_format, channel_count FROM lsl_streams")}
    samples = 0
    for sid, seg, stream, chunk, n, t_blob, data in conn.execute(
            "SELECT session_id, segment, stream, chunk, n_samples, lsl_t, data FROM lsl_chunks"):
        where = f"session {sid}, recorded run {seg}, LSL stream {stream}, chunk {chunk}"
        known = formats.get((int(sid), int(seg), int(stream)))
        if known is None:
            problem(f"{where}: its stream has no lsl_streams row")
            continue
        samples += int(n)
        fmt, channels = known[1], known[2]
        held = (len(json.loads(bytes(data).decode("utf-8"))) if fmt == "string"
                else len(bytes(data)) // (8 * max(channels, 1)))
        if len(bytes(t_blob)) != 8 * int(n) or held != int(n):
            problem(f"{where} ({known[0]!r}): holds {len(bytes(t_blob)) // 8} timestamps and {held} samples, its row "
                    f"says {n}")
    orphans = conn.execute("SELECT COUNT(*) FROM lsl_streams WHERE session_id NOT IN (SELECT session_id FROM "
                           "sessions)").fetchone()[0]
    if orphans:
        problem(f"{orphans} recorded LSL streams belong to no stored session")
    note(f"LSL: {plural(len(formats), 'external stream')} recorded, {plural(samples, 'sample')}")
