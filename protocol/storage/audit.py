"""Verifying a whole study database: what ``haptic-study check`` finds.

Five checks, each reported with what it found:

1. **SQLite's own** -- ``PRAGMA integrity_check``: the file's pages, indexes and
   constraints.  It cannot see a flipped bit inside a value;
2. **every recorded block** -- its CRC-32 (schema version 4) and a full decoding,
   whose records must agree with its row (count, first and last tick).  A block
   written before version 4 has no checksum: it is counted *not verifiable*
   (not damaged) when it decodes;
3. **trials against the recording** -- every trial's first and last records
   (``first_tick``, ``last_tick``) lie in its recorded run, in readable blocks
   with no damaged block between them;
4. **the record against itself** -- references, every trial against its cue event and its first record
   (:mod:`protocol.storage.audit_record`);
5. **the design** -- per experiment session, every trial row is a trial of the
   stored schedule, every aborted trial has exactly one re-run in it, the
   designed trials are the protocol's, and the trials that count fill each
   target × mode cell: exactly for a completed session, at most for one
   interrupted or ended early (said so).

:func:`audit_database` returns an :class:`Audit`; ``problems`` empty means clean.
"""

from __future__ import annotations

import json
import re
import sqlite3
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

from protocol.recording.integrity import BlockDamage, BlockRow, block_problem
from protocol.storage.audit_record import check_record
from protocol.storage.damage import block_rows, describe_damage
from protocol.storage.lsl_streams import audit_lsl
from protocol.storage.reader import StudyReader
from protocol.study.config import ProtocolError, protocol_from_dict
from protocol.study.design import schedule_from_json

__all__ = ["Audit", "audit_database"]


@dataclass
class Audit:
    """What :func:`audit_database` found.

    Attributes
    ----------
    schema_version
        The file's schema version.
    sessions, experiment_sessions, trials
        Counts of what is stored.
    integrity
        SQLite's integrity check: ``["ok"]`` or its findings.
    blocks_verified, blocks_unverifiable
        Recorded blocks whose checksum matched and that decoded; blocks without a checksum (written before
        version 4) that decoded.
    damage
        Runs of damaged blocks (checksum mismatch, not decodable, records disagreeing with their row).
    trials_in_recording, trials_not_in_recording
        Trials whose records lie in readable parts of the recording; the others, one line each.
    cells_complete
        Experiment sessions whose every designed cell is full.
    notes
        What is worth knowing and is not a problem (interrupted sessions, blocks not verifiable).
    problems
        Everything wrong, one line each (empty: the database is clean).
    """

    path: str
    schema_version: int = 0
    sessions: int = 0
    experiment_sessions: int = 0
    trials: int = 0
    integrity: list[str] = field(default_factory=list)
    blocks_verified: int = 0
    blocks_unverifiable: int = 0
    damage: list[BlockDamage] = field(default_factory=list)
    trials_in_recording: int = 0
    trials_not_in_recording: list[str] = field(default_factory=list)
    cells_complete: int = 0
    notes: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        """Plain data for ``--json``."""
        out = asdict(self)
        out["damage"] = [{**asdict(d), "line": d.describe()} for d in self.damage]
        return out


def _integrity(conn: sqlite3.Connection, audit: Audit) -> bool:
    """SQLite's integrity check; False when the file cannot be read at all."""
    try:
        rows = StudyReader.over(conn).integrity_check(20)
    except sqlite3.DatabaseError as exc:
        audit.integrity = [str(exc)]
        audit.problems.append(f"SQLite integrity check: {exc}")
        return False
    audit.integrity = rows
    if rows != ["ok"]:
        audit.problems.extend(f"SQLite integrity check: {r}" for r in rows)
    return True


def _blocks(conn: sqlite3.Connection, audit: Audit, progress: Callable[[int, int], None] | None) -> dict[
        tuple[int, int], list[tuple[int, int, bool]]]:
    """Verify every block; per (session, segment) the tick ranges of its blocks and whether each is readable."""
    total = StudyReader.over(conn).block_count()
    runs: dict[tuple[int, int], list[tuple[int, int, bool]]] = {}
    bad: list[tuple[BlockRow, str]] = []
    last: dict[tuple[int, int], int] = {}
    for i, row in enumerate(block_rows(conn)):
        key = (row.session_id, row.segment)
        why = block_problem(row, whole=True)
        if not why and last.get(key, -1) + 1 != row.block:
            audit.problems.append(f"session {row.session_id}, recorded run {row.segment}: block {row.block} follows "
                                  f"block {last.get(key, -1)} (blocks missing from the recording)")
        last[key] = row.block
        if why:
            bad.append((row, why))
        elif row.crc32 is None:
            audit.blocks_unverifiable += 1
        else:
            audit.blocks_verified += 1
        runs.setdefault(key, []).append((row.first_tick, row.last_tick, not why))
        if progress is not None and (i % 200 == 0 or i + 1 == total):
            progress(i + 1, total)
    _runs_complete(conn, audit, last)
    audit.damage = describe_damage(conn, bad)
    audit.problems.extend(f"recording damaged: {d.describe()}" for d in audit.damage)
    if audit.blocks_unverifiable:
        audit.notes.append(f"{audit.blocks_unverifiable} recorded block(s) were written before schema version 4 and "
                           "carry no checksum: they decode, but a changed value in them cannot be detected")
    return runs


def _other_arms(conn: sqlite3.Connection, audit: Audit) -> None:
    """Verify the other arms' blocks (a rig of several arms): each one's checksum and decoding, and no block missing;
    a damaged one is a problem naming its arm (the trials are the task arm's: their records are checked above)."""
    for arm in StudyReader.over(conn).arms():
        last: dict[tuple[int, int], int] = {}
        for row in block_rows(conn, arm=arm):
            key = (row.session_id, row.segment)
            why = block_problem(row, whole=True)
            if why:
                audit.problems.append(f"arm {arm}, session {row.session_id}, recorded run {row.segment}, block "
                                      f"{row.block} (ticks {row.first_tick}–{row.last_tick}): {why}")
            elif last.get(key, -1) + 1 != row.block:
                audit.problems.append(f"arm {arm}, session {row.session_id}, recorded run {row.segment}: block "
                                      f"{row.block} follows block {last.get(key, -1)} (blocks missing)")
            elif row.crc32 is None:
                audit.blocks_unverifiable += 1
            else:
                audit.blocks_verified += 1
            last[key] = row.block
        _runs_complete(conn, audit, last, arm)


def _runs_complete(conn: sqlite3.Connection, audit: Audit, last: Mapping[tuple[int, int], int], arm: str = "") -> None:
    """Every run that counts its blocks holds them all, its last ones too (a block deleted from the end leaves no
    gap to see): ``last`` is each run's last block found (an open one, in chunks, may follow the count)."""
    where = f"arm {arm}, " if arm else ""
    for sid, seg, n_blocks in StudyReader.over(conn).block_counts(arm):
        found = last.get((sid, seg), -1)
        if found < n_blocks - 1:
            missing = f"block {n_blocks - 1}" if found == n_blocks - 2 else f"blocks {found + 1}–{n_blocks - 1}"
            audit.problems.append(f"{where}session {sid}, recorded run {seg}: {n_blocks} blocks were written, "
                                  f"{missing} missing from the recording")


def _readable(runs: list[tuple[int, int, bool]], first: int, last: int) -> bool:
    """Whether ticks ``first`` … ``last`` lie in readable blocks with no damaged block between them."""
    touching = [r for r in runs if r[1] >= first and r[0] <= last]
    return (bool(touching) and all(ok for _, _, ok in touching)
            and touching[0][0] <= first and touching[-1][1] >= last)


def _trials_against_recording(conn: sqlite3.Connection, audit: Audit,
                              runs: dict[tuple[int, int], list[tuple[int, int, bool]]],
                              writers: Mapping[int, str]) -> None:
    pending: Counter[int] = Counter()
    for sid, idx, seg, first, last in StudyReader.over(conn).trial_places():
        blocks = runs.get((sid, seg), [])
        if _readable(blocks, first, last):
            audit.trials_in_recording += 1
            continue
        written = max((b[1] for b in blocks), default=-1)  # the segment's newest committed tick
        if sid in writers and last > written and (first > written or _readable(blocks, first, written)):
            # a session written now: its newest records are still in the recorder's buffer (a trial is stored when
            # it ends, its last records with the next block); they are not missing
            pending[sid] += 1
            continue
        line = (f"trial {idx + 1} of session {sid}: its records (run {seg}, ticks {first}–{last}) are not all in "
                "readable blocks of the recording")
        audit.trials_not_in_recording.append(line)
        audit.problems.append(line)
    for sid, n in sorted(pending.items()):
        audit.notes.append(f"session {sid} in progress: the newest records of {n} trial{'s' if n > 1 else ''} are not "
                           "written yet (the recorder writes them with its next block)")


def _where(sid: int, code: str, status: str, writer: str | None) -> str:
    """A session named for a finding: its status as ``sessions`` says it (a running one is in progress or
    interrupted)."""
    if status == "running" and writer:
        who = re.sub(r"^(process \d+) \((.*)\)$", r"\1, \2", writer)  # "process N (command)" -> "process N, command"
        return f"session {sid} ({code}) in progress ({who})"
    return f"session {sid} ({code}, {'interrupted' if status == 'running' else status})"


def _cells(conn: sqlite3.Connection, audit: Audit, writers: Mapping[int, str]) -> None:
    """Every experiment session's trials against its schedule and its protocol's design."""
    sessions = StudyReader.over(conn).experiment_designs()
    audit.experiment_sessions = len(sessions)
    for sid, code, status, protocol_json, schedule_json in sessions:
        live = status == "running" and bool(writers.get(int(sid)))
        where = _where(int(sid), code, status, writers.get(int(sid)))
        try:
            protocol = protocol_from_dict(json.loads(protocol_json), f"session {sid} protocol")
            schedule = schedule_from_json(schedule_json)
        except (ProtocolError, ValueError, TypeError, KeyError) as exc:
            audit.problems.append(f"{where}: its protocol or schedule cannot be read ({exc})")
            continue
        rows = {int(i): (lab, mode, out) for i, lab, mode, out in StudyReader.over(conn).trial_cells(sid)}
        found: list[str] = []
        for i, (lab, mode, _out) in sorted(rows.items()):
            if i >= len(schedule) or (schedule[i].target_label, str(schedule[i].haptic_mode)) != (lab, mode):
                found.append(f"trial {i + 1} ({lab}, {mode}) is not that trial of the stored schedule")
        reruns = Counter(s.repeat_of for s in schedule if s.repeat_of is not None)
        for i, (_, _, out) in sorted(rows.items()):
            if (out == "aborted") != (reruns[i] == 1) or reruns[i] > 1:
                found.append(f"aborted trial {i + 1} has {reruns[i]} re-runs in the schedule" if out == "aborted"
                             else f"trial {i + 1} ({out}) has {reruns[i]} re-runs in the schedule")
        want = Counter((t.label, str(m)) for t in protocol.targets for m in protocol.modes
                       for _ in range(protocol.trials_per_cell))
        if Counter((s.target_label, str(s.haptic_mode)) for s in schedule if s.repeat_of is None) != want:
            found.append("its designed trials are not its protocol's cells")
        done = Counter((lab, mode) for lab, mode, out in rows.values() if out != "aborted")
        over = {c: n for c, n in done.items() if n > want[c]}
        if over:
            found.append("cells holding more trials than designed: " + ", ".join(
                f"{lab} {mode} {n}/{want[(lab, mode)]}" for (lab, mode), n in sorted(over.items())))
        full = all(done[c] == n for c, n in want.items())
        if status == "completed" and not full:
            short = ", ".join(f"{lab} {mode} {done[(lab, mode)]}/{n}" for (lab, mode), n in sorted(want.items())
                              if done[(lab, mode)] != n)
            found.append(f"marked completed with cells not full: {short}")
        elif status != "completed" and not full:
            # a session another process writes now is not resumed (that would be refused): no advice
            advice = f"; resume it with --continue or --resume {code}" if status == "running" and not live else ""
            audit.notes.append(f"{where}: {sum(done.values())} of {sum(want.values())} designed trials done"
                               f"{' so far' if live else advice}")
        audit.problems.extend(f"{where}: {f}" for f in found)
        audit.cells_complete += full and not found


def audit_database(conn: sqlite3.Connection, path: str,
                   progress: Callable[[int, int], None] | None = None,
                   writers: Mapping[int, str] | None = None) -> Audit:
    """Check a study database read-only (see the module docstring).

    Parameters
    ----------
    conn
        A read-only connection to it.
    path
        Its name, for the findings.
    progress
        ``progress(blocks done, blocks)`` while the blocks are decoded.
    writers
        The sessions a live process writes right now, session id -> ``"process N (command)"``
        (:meth:`protocol.storage.StudyDatabase.sessions_being_written`): such a running session is said to be
        in progress, by whom, with no advice to resume it; a running session without one was interrupted.
    """
    audit = Audit(path=path)
    # one read transaction: every finding is of one snapshot of the file, whatever a live writer commits meanwhile
    # (read in separate statements, a trial stored after the blocks were scanned looked unrecorded)
    conn.execute("BEGIN")
    try:
        return _audit(conn, audit, progress, writers or {})
    finally:
        conn.execute("ROLLBACK")


def _audit(conn: sqlite3.Connection, audit: Audit, progress: Callable[[int, int], None] | None,
           writers: Mapping[int, str]) -> Audit:
    """:func:`audit_database` in its read transaction."""
    audit.schema_version = StudyReader.over(conn).schema_version
    if not _integrity(conn, audit):
        return audit
    try:
        audit.sessions = StudyReader.over(conn).session_count()
        audit.trials = StudyReader.over(conn).trial_count()
        if audit.schema_version >= 3:
            runs = _blocks(conn, audit, progress)
            _other_arms(conn, audit)
            _trials_against_recording(conn, audit, runs, writers)
        else:
            audit.notes.append(f"schema version {audit.schema_version}: sessions were not recorded whole "
                               "(trial windows in the samples table), so there are no blocks to verify")
        _cells(conn, audit, writers)
        check_record(conn, audit.problems.append)
        audit_lsl(conn, audit.notes.append, audit.problems.append)  # (a study that never used LSL: nothing)
        for w in StudyReader.over(conn).withdrawals():  # not a problem: what the study no longer holds, and why
            if w.rewritten == 0:  # their rows are gone, their bytes may not be: the rewrite did not finish
                audit.problems.append(f"withdrawal of {w.code} incomplete: their rows were removed but the file was "
                                      "not rewritten, so their bytes may still be read back from it; run withdraw "
                                      f"again (haptic-study withdraw --db {audit.path} --participant {w.code})")
                continue
            audit.notes.append(f"participant {w.code} withdrew ({w.withdrawn_at[:16].replace('T', ' ')} UTC): "
                               f"{w.counts()} erased; their number stays vacant")
    except sqlite3.DatabaseError as exc:
        audit.problems.append(f"cannot read the study tables ({' '.join(str(exc).split())})")
    return audit
