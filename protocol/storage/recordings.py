"""Reading the recording back: a whole segment (for replay and the samples table), or a trial's window of it.

Every block read is verified first (:mod:`protocol.recording.integrity`): a
damaged one raises :class:`RecordingDamaged` naming it in one line, or, where
the caller asks for what is intact (``skip_damaged``), is left out and listed.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pipeline.core.tick_record import TICK_DTYPE
from pipeline.force.replay import ReplayInputs
from protocol.recording.codec import COLUMNS, decode_block, decode_columns, join_decoded
from protocol.recording.integrity import (
    BlockDamage,
    BlockRow,
    RecordingDamaged,
    block_problem,
    columns_problem,
    decode_failure,
)
from protocol.storage.damage import block_rows, describe_damage, reader_of
from protocol.study.clock import SessionClock

__all__ = ["RecordingDamaged", "SegmentData", "marked_records", "read_segment", "read_ticks", "segments_of"]


@dataclass
class SegmentData:
    """One segment read back: its columns over all its blocks, its poses and log, its snapshot and clock.

    Session time of its records: :attr:`clock` (``started_at_s`` at loop time ``t0_ns``).
    """

    session_id: int
    segment: int
    started_at_s: float
    t0_ns: int
    snapshot: dict[str, Any]
    columns: dict[str, np.ndarray]
    poses: dict[str, np.ndarray]
    events: list[tuple[int, str, Any]]
    #: Damaged blocks left out (``read_segment(..., skip_damaged=True)``): its records are those around them.
    damage: list[BlockDamage] = field(default_factory=list)

    @property
    def clock(self) -> SessionClock:
        """The segment's place on the session clock."""
        return SessionClock(self.started_at_s, self.t0_ns)

    @property
    def session_time_s(self) -> np.ndarray:
        """Session-clock time of every record, s."""
        return self.clock.seconds_of(self.columns["t_ns"])

    def replay_inputs(self) -> ReplayInputs:
        """What :func:`pipeline.force.replay.replay` needs to run this segment through the pipeline again."""
        c = self.columns
        return ReplayInputs(
            tick=c["tick"], period_ns=c["period_ns"],  # int64, as the tick record has them
            raw_wrench=np.stack([c[f"raw_{k}"] for k in ("fx", "fy", "fz", "tx", "ty", "tz")], axis=1),
            haptic_on=c["haptic_on"] != 0, faults=c["faults"], snapshot=self.snapshot,
            events=self.log(),
        )

    @property
    def continuous(self) -> bool:
        """True when no record is missing (ticks consecutive): replay is then exact from end to end."""
        t = self.columns["tick"]
        return bool(len(t) == 0 or np.all(np.diff(t) == 1))

    def log(self) -> list[tuple[int, str, Any]]:
        """The replay log: poses and events merged in tick order, poses last within a tick.

        The loop logs a tick's commands and drops to zero before its pose, and its device limit after
        it; a pose and a device limit commute (:meth:`pipeline.force.framework.HapticFramework.set_pose` and
        ``set_device_limit`` change disjoint state), so this order replays as the loop ran.
        """
        merged = [(t, 0, i, k, p) for i, (t, k, p) in enumerate(self.events)]
        p = self.poses
        for i in range(len(p["tick"])):
            rot = tuple(float(p[f"r{j}"][i]) for j in range(9))
            pos = (float(p["x_m"][i]), float(p["y_m"][i]), float(p["z_m"][i]))
            merged.append((int(p["tick"][i]), 1, i, "pose", (rot, pos, int(p["pose_t_ns"][i]))))
        merged.sort(key=lambda e: (e[0], e[1], e[2]))
        return [(t, k, pl) for t, _, _, k, pl in merged]


def segments_of(conn: Any, session_id: int, arm: str = "") -> list[tuple[int, float, int]]:
    """A session's recorded segments: (segment, started_at_s, t0_ns), in order (none for a version-2 session);
    ``arm``: another arm's than the task arm's (:meth:`protocol.storage.StudyReader.arm_key`)."""
    return reader_of(conn).recordings(session_id, arm)


def _decoded(conn: Any, rows: Iterable[BlockRow], skip_damaged: bool, names: list[str] | None = None,
             ) -> tuple[list[Any], list[BlockDamage]]:
    """Each block decoded (:func:`decode_block`; with ``names`` only those columns), its checksum verified first;
    damaged blocks raise :class:`RecordingDamaged`, or with ``skip_damaged`` are left out and returned."""
    good: list[Any] = []
    bad: list[tuple[BlockRow, str]] = []
    want = [c.name for c in COLUMNS] if names is None else names
    for r in rows:
        why = block_problem(r)
        if not why:
            try:
                decoded: Any = decode_block(r.data) if names is None else decode_columns(r.data, names)
                why = columns_problem(decoded[0] if names is None else decoded, want)
            except Exception as exc:  # any failure to decode is damage (see integrity.block_problem)
                why = decode_failure(exc)
            if not why:
                good.append(decoded)
                continue
        bad.append((r, why))
    damage = describe_damage(conn, bad)
    if damage and not skip_damaged:
        raise RecordingDamaged(damage)
    return good, damage


def read_segment(conn: Any, session_id: int, segment: int, *, skip_damaged: bool = False, arm: str = "",
                 ) -> SegmentData:
    """One segment in full: every column, the poses, the log and the snapshot.

    Raises
    ------
    RecordingDamaged
        A block of it is damaged (one line naming where); with ``skip_damaged`` the damaged blocks are left
        out instead and listed in :attr:`SegmentData.damage`.
    """
    reader = reader_of(conn)
    row = reader.recording(session_id, segment, arm)
    if row is None:
        raise KeyError(f"session {session_id} has no recorded segment {segment}" + (f" of arm {arm}" if arm else ""))
    good, damage = _decoded(reader, block_rows(reader, session_id, segment, arm=arm), skip_damaged)
    cols, poses, events = join_decoded(good)
    return SegmentData(session_id, segment, float(row[0]), int(row[1]), json.loads(row[2]), cols, poses, events,
                       damage)


def read_ticks(conn: Any, session_id: int, segment: int, first_tick: int, last_tick: int,
               names: Iterable[str], arm: str = "") -> dict[str, np.ndarray]:
    """Some columns of the records ``first_tick`` … ``last_tick`` of a segment (a trial's window; ``arm``: of
    another arm than the task arm, the same ticks).

    Raises
    ------
    RecordingDamaged
        A block of the window is damaged (one line naming where).
    """
    names = list(dict.fromkeys(["tick", *names]))
    parts: list[dict[str, np.ndarray]] = []
    bad: list[tuple[BlockRow, str]] = []
    for r in block_rows(conn, session_id, segment, (first_tick, last_tick), arm):
        why = block_problem(r)
        if not why:
            try:
                part, why = _window_part(r, names, first_tick, last_tick)
            except Exception as exc:  # any failure to decode is damage (see integrity.block_problem)
                why = decode_failure(exc)
        if why:
            bad.append((r, why))
        else:
            parts.append(part)
    if bad:
        raise RecordingDamaged(describe_damage(conn, bad))
    if not parts:  # (each empty column with its field's type)
        return {n: np.empty(0, TICK_DTYPE[n] if n in (TICK_DTYPE.names or ()) else np.float64) for n in names}
    return {n: np.concatenate([p[n] for p in parts]) for n in names}


def _window_part(r: BlockRow, names: list[str], first_tick: int, last_tick: int,
                 ) -> tuple[dict[str, np.ndarray], str]:
    """The records ``first_tick`` … ``last_tick`` of one block (``names``, ``"tick"`` first), and what is wrong ("")."""
    b_first, b_last, n = r.first_tick, r.last_tick, r.n_records
    if b_last - b_first + 1 == n:
        # no tick missing in this block (the usual case): its ticks need no decoding, the window is a slice
        cols = decode_columns(r.data, names[1:])
        why = columns_problem(cols, names[1:])
        if not why and len(cols[names[1]]) != n:
            why = f"decodes to {len(cols[names[1]])} records where its row says {n}"
        lo, hi = max(first_tick - b_first, 0), min(last_tick, b_last) - b_first + 1
        part = {k: v[lo:hi] for k, v in cols.items()}
        part["tick"] = np.arange(b_first + lo, b_first + hi, dtype=np.int64)
        return part, why
    cols = decode_columns(r.data, names)
    why = columns_problem(cols, names)
    keep = (cols["tick"] >= first_tick) & (cols["tick"] <= last_tick)
    return ({k: v[keep] for k, v in cols.items()} if not why else {}), why


def marked_records(conn: Any, session_id: int, trial_index: int,
                   names: Iterable[str]) -> tuple[tuple[int, float, int], dict[str, np.ndarray]] | None:
    """The records the loop marked with a trial, in the last segment that has any (an interrupted trial's).

    Returns ((segment, started_at_s, t0_ns), columns), or None when no record carries the mark.

    Raises
    ------
    RecordingDamaged
        A block of a segment it reads is damaged.
    """
    names = list(dict.fromkeys(["tick", "t_ns", "trial_index", *names]))
    reader = reader_of(conn)
    for seg in reversed(segments_of(reader, session_id)):
        parts, _ = _decoded(reader, block_rows(reader, session_id, seg[0]), False, names)
        if not parts:
            continue
        cols = {n: np.concatenate([p[n] for p in parts]) for n in names}
        mark = cols["trial_index"] == trial_index
        if mark.any():
            return seg, {n: v[mark] for n, v in cols.items()}
    return None
