"""A damaged recording: found by every reader, named in one line, never a traceback; the rest analysed.

A study of three participants (P03's session interrupted by a kill) is damaged
in ways a lab meets -- one bit flipped in a block on the disk (SQLite's own
check passes it), a block from before checksums that no longer decodes or whose
header changed, a changed checksum, a block row disagreeing with its records -- and every command
that reads the recording is run on it through the real command line: ``check``
names the damage (exit 1), ``report`` analyses the rest, ``export``,
``plot-session`` give a partial result stated as such (exit 1), ``replay`` and
``plot-trial`` of a damaged trial refuse in one line (exit 2), and ``run
--continue`` / ``--resume`` refuse to append to the damaged session (exit 2).
No case prints a traceback or changes the database; each writes only what it
was asked to.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sqlite3
import tomllib
import zlib
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest
from cli_subprocess import cli as _cli
from cli_subprocess import tiny_protocol

from analysis.reading.load import load_study
from protocol.recording import RecordingDamaged
from protocol.recording.integrity import WHOLE_BLOCK, place_crc32
from protocol.runner.session_setup import open_resumed_session
from protocol.storage import StorageError, StudyDatabase
from protocol.storage.damage import recording_damage
from protocol.storage.recordings import read_segment, read_ticks
from protocol.study.config import protocol_from_dict
from study_app.headless import run_study

ROOT = Path(__file__).resolve().parents[2]
PROTOCOL = tiny_protocol("damage")
#: P03's session: interrupted during its 3rd trial (resumable), and the one damaged.
DAMAGED_SESSION = 3
DAMAGED_BLOCK = 2  # 2.0–2.999 s: trial 2 (and the pause before it)



@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """P01 and P02 complete, P03 killed during its 3rd trial; everything in the one file."""
    d = tmp_path_factory.mktemp("damage")
    (d / "p.toml").write_text(PROTOCOL, encoding="utf-8")
    db = d / "study.db"
    run_study(str(db), participants=2, seed=4, protocol=protocol_from_dict(tomllib.loads(PROTOCOL)), jobs=1)
    killed = _cli(["run", "--participants", "3", "--seed", "4", "--db", str(db), "--protocol", str(d / "p.toml"),
                   "--continue", "--inject-fault", "kill@P03:3+0.4"], d)
    assert killed.returncode == -9, killed.stderr
    c = sqlite3.connect(db)
    try:
        c.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        status = c.execute("SELECT status FROM sessions WHERE session_id = ?", (DAMAGED_SESSION,)).fetchone()
        assert status == ("running",)
    finally:
        c.close()
    return db


# -- the damage -------------------------------------------------------------------------------------------------
def _blob(db: Path, session: int, block: int) -> bytes:
    c = sqlite3.connect(db)
    try:
        return bytes(c.execute("SELECT data FROM session_blocks WHERE session_id = ? AND segment = 0 AND block = ?",
                               (session, block)).fetchone()[0])
    finally:
        c.close()


def flip_a_bit(db: Path, session: int = DAMAGED_SESSION, block: int = DAMAGED_BLOCK) -> None:
    """One bit of a block flipped in the file itself, as a failing disk or memory would (SQLite does not notice)."""
    blob = _blob(db, session, block)
    raw = bytearray(db.read_bytes())
    at = raw.find(blob[len(blob) // 2 : len(blob) // 2 + 48])
    assert at > 0 and raw.find(blob[len(blob) // 2 : len(blob) // 2 + 48], at + 1) < 0
    raw[at + 7] ^= 0x10
    db.write_bytes(bytes(raw))


def _sql(db: Path, sql: str, *args: object) -> None:
    c = sqlite3.connect(db)
    try:
        c.execute(sql, args)
        c.commit()
        c.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    finally:
        c.close()


def undecodable_without_checksum(db: Path) -> None:
    """A block from before checksums (crc32 NULL) whose bytes no longer decode."""
    blob = _blob(db, DAMAGED_SESSION, DAMAGED_BLOCK)
    _sql(db, "UPDATE session_blocks SET crc32 = NULL, data = ? WHERE session_id = ? AND segment = 0 AND block = ?",
         blob[:40] + bytes(b ^ 0x5A for b in blob[40:]), DAMAGED_SESSION, DAMAGED_BLOCK)


def header_changed_without_checksum(db: Path) -> None:
    """A block from before checksums whose header lost a column's name: it decodes, to the wrong columns."""
    blob = _blob(db, DAMAGED_SESSION, DAMAGED_BLOCK)
    assert blob.count(b'"raw_fx"') == 1
    _sql(db, "UPDATE session_blocks SET crc32 = NULL, data = ? WHERE session_id = ? AND segment = 0 AND block = ?",
         blob.replace(b'"raw_fx"', b'"raw_fz"'), DAMAGED_SESSION, DAMAGED_BLOCK)


def checksum_changed(db: Path) -> None:
    """The block intact, its checksum changed: which of the two is wrong cannot be told, so the block is damaged."""
    _sql(db, "UPDATE session_blocks SET crc32 = crc32 + 1 WHERE session_id = ? AND segment = 0 AND block = ?",
         DAMAGED_SESSION, DAMAGED_BLOCK)


def row_disagrees(db: Path) -> None:
    """The block's bytes intact, its row's record count changed: what ``check`` decodes in full finds."""
    _sql(db, "UPDATE session_blocks SET n_records = n_records - 1 WHERE session_id = ? AND segment = 0 AND block = ?",
         DAMAGED_SESSION, DAMAGED_BLOCK)


DAMAGE: dict[str, Callable[[Path], None]] = {
    "bit-flip": flip_a_bit, "undecodable-pre-v4": undecodable_without_checksum, "checksum-changed": checksum_changed,
    "header-changed-pre-v4": header_changed_without_checksum, "row-disagrees": row_disagrees,
}


# -- the cases --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Case:
    damage: str
    args: tuple[str, ...]
    code: int
    says: str  # in the one line on stderr naming it
    writes: str = ""  # the file the command was asked to write

    @property
    def id(self) -> str:
        return f"{self.damage}:{'-'.join(a for a in self.args[:2] if not a.startswith('--'))}"


_S = str(DAMAGED_SESSION)
COMMANDS = [  # (args, exit status, what the line says, file written)
    (("check", "--db", "study.db"), 1, "problems found", ""),
    (("export", "samples", "--db", "study.db", "--out", "x.csv"), 1, "left out of", "x.csv"),
    (("plot-session", "--db", "study.db", "--session", _S, "--out", "s.png"), 1, "the result is partial", "s.png"),
    (("replay", "--db", "study.db", "--session", _S), 2, "recording damaged: session 3", ""),
    (("plot-trial", "--db", "study.db", "--session", _S, "--trial", "2", "--out", "t.png"), 2,
     "trial 2 of session 3: recording damaged", ""),
    (("run", "--participants", "3", "--seed", "4", "--db", "study.db", "--protocol", "p.toml", "--continue"), 2,
     "cannot be resumed: its recording is damaged", ""),
    (("run", "--db", "study.db", "--resume", "P03"), 2, "cannot be resumed: its recording is damaged", ""),
]
CASES = [Case("bit-flip", *c) for c in COMMANDS]
CASES += [Case("undecodable-pre-v4", *COMMANDS[i]) for i in (0, 1, 3, 5)]
CASES += [Case("checksum-changed", *COMMANDS[i]) for i in (0, 3)]
CASES += [Case("header-changed-pre-v4", *COMMANDS[i]) for i in (1, 2)]
CASES += [Case("row-disagrees", *COMMANDS[0])]


@dataclass(frozen=True)
class Outcome:
    code: int
    stdout: str
    stderr: str
    before: dict[str, str]
    after: dict[str, str]


def _snapshot(d: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in d.iterdir() if p.is_file()}


def _run(case: Case, d: Path, study: Path) -> Outcome:
    shutil.copy(study, d / "study.db")
    (d / "p.toml").write_text(PROTOCOL, encoding="utf-8")
    DAMAGE[case.damage](d / "study.db")
    before = _snapshot(d)
    r = _cli(list(case.args), d)
    return Outcome(r.returncode, r.stdout, r.stderr, before, _snapshot(d))


@pytest.fixture(scope="module")
def outcomes(study: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Outcome]]:
    base = tmp_path_factory.mktemp("cases")
    folders = {c.id: base / f"case{i:02d}" for i, c in enumerate(CASES)}
    for f in folders.values():
        f.mkdir()
    with ThreadPoolExecutor(max_workers=3) as pool:
        futures = {c.id: pool.submit(_run, c, folders[c.id], study) for c in CASES}
        yield {k: f.result() for k, f in futures.items()}


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_every_reader_names_the_damage_in_one_line_and_changes_nothing(case: Case,
                                                                        outcomes: dict[str, Outcome]) -> None:
    out = outcomes[case.id]
    assert "Traceback" not in out.stdout + out.stderr, out.stderr
    assert out.code == case.code, (out.code, out.stderr)
    damage_lines = [ln for ln in out.stderr.splitlines() if case.says in ln]
    assert len(damage_lines) == 1, out.stderr
    if case.args[0] != "check":
        assert "session 3, recorded run 0, 2.000–2.999 s (block 2)" in damage_lines[0]
        assert "touches trial" in damage_lines[0]
    assert out.after.get("study.db") == out.before["study.db"]  # nothing stored was touched
    new = set(out.after) - set(out.before)
    # an export writes its codebook beside the file
    made = [case.writes, f"{case.writes}.codebook.csv"] if case.args[0] == "export" else [case.writes]
    assert new <= {"study.db-wal", "study.db-shm", *(made if case.writes else [])}, new


def test_one_flipped_bit_passes_sqlites_check_and_is_found_by_check(study: Path, tmp_path: Path) -> None:
    db = tmp_path / "study.db"
    shutil.copy(study, db)
    flip_a_bit(db)
    c = sqlite3.connect(db)
    assert c.execute("PRAGMA quick_check").fetchall() == [("ok",)]  # what the product relied on before
    c.close()
    r = _cli(["check", "--db", str(db), "--json"], tmp_path)
    assert r.returncode == 1, r.stderr
    found = json.loads(r.stdout)
    assert found["integrity"] == ["ok"]
    assert [d["line"] for d in found["damage"]] == [
        ("session 3, recorded run 0, 2.000–2.999 s (block 2): checksum mismatch (the block's bytes, or the place it "
         "is stored at -- session, arm, run, block, ticks -- changed since it was written); touches trial 2")]
    assert found["trials_not_in_recording"] and "trial 2 of session 3" in found["trials_not_in_recording"][0]
    clean = _cli(["check", "--db", str(study)], tmp_path)
    assert clean.returncode == 0 and "No problem found." in clean.stdout, clean.stdout + clean.stderr
    assert "2 of 3 experiment sessions" in clean.stdout  # P03's is interrupted: a note, not a problem
    assert "P03, interrupted): " in clean.stdout and "designed trials done" in clean.stdout
    assert "; resume it with --continue or --resume P03" in clean.stdout


def test_check_says_a_session_another_process_writes_is_in_progress_not_to_be_resumed(
        study: Path, tmp_path: Path) -> None:
    """`check` called a session a live process wrote "running ... resume it", which `run` would then refuse."""
    from protocol.storage import new_owner_token
    from protocol.storage.leases import session_scope

    db = tmp_path / "study.db"
    shutil.copy(study, db)
    (sid,) = sqlite3.connect(db).execute(
        "SELECT session_id FROM sessions JOIN participants USING (participant_id) WHERE code = 'P03'").fetchone()
    writer = StudyDatabase(str(db))
    owner = new_owner_token()
    writer.acquire_lease(session_scope(sid), owner, command="haptic-study run --resume P03")  # this process: live
    try:
        # the report's list of incomplete sessions says the same (not "interrupted ... --resume continues it")
        from analysis.report.study_record import incomplete_sessions

        (reason,) = incomplete_sessions(load_study([db]))["reason"]
        assert reason.startswith(f"P03, session {sid}: in progress (process {os.getpid()} (haptic-study run --resume "
                                 "P03)), ") and "not interrupted" in reason and "--resume P03 continues" not in reason
        busy = _cli(["check", "--db", str(db)], tmp_path)
        assert busy.returncode == 0, busy.stdout + busy.stderr
        (line,) = [n for n in busy.stdout.splitlines() if "P03" in n]
        assert line.startswith(f"  note: session {sid} (P03) in progress (process {os.getpid()}, "
                               "haptic-study run --resume P03): "), line
        assert "designed trials done so far" in line and "resume" not in line.split("): ", 1)[1]
        assert "running" not in busy.stdout and "interrupted" not in busy.stdout
    finally:
        writer.release_lease(session_scope(sid), owner)
        writer.close()
    (reason,) = incomplete_sessions(load_study([db]))["reason"]
    assert "interrupted after" in reason and "haptic-study run --resume P03 continues it" in reason
    idle = _cli(["check", "--db", str(db)], tmp_path)
    (line,) = [n for n in idle.stdout.splitlines() if "P03" in n]
    assert line.startswith(f"  note: session {sid} (P03, interrupted): ") and line.endswith(
        "designed trials done; resume it with --continue or --resume P03"), line


def test_the_report_leaves_out_the_trials_a_damaged_block_touches_and_analyses_the_rest(
        study: Path, tmp_path: Path) -> None:
    db = tmp_path / "study.db"
    shutil.copy(study, db)
    flip_a_bit(db, session=1, block=3)  # P01's completed session, 3.0–3.999 s
    c = sqlite3.connect(db)
    touched = c.execute("SELECT trial_index FROM trials WHERE session_id = 1 AND first_tick <= 3999 "
                        "AND last_tick >= 3000 AND outcome != 'aborted' ORDER BY trial_index").fetchall()
    c.close()
    assert touched
    data = load_study([db])
    hit = data.trials[data.trials["excluded"] == "recording damaged"]
    hit_keys = [(int(s), int(i)) for s, i in zip(hit["session_id"], hit["trial_index"], strict=True)]
    assert hit_keys == [(1, i) for (i,) in touched]
    assert (hit["damage"] == data.damage[0]).all() and len(data.damage) == 1
    assert data.damage[0].startswith(f"{db}: session 1, recorded run 0, 3.000–3.999 s (block 3): checksum mismatch")
    assert f"touches trials {', '.join(str(i + 1) for (i,) in touched)}" in data.damage[0]
    r = _cli(["report", "--db", str(db), "--out", str(tmp_path / "rep")], tmp_path)
    assert r.returncode == 0, r.stderr
    rows = (tmp_path / "rep" / "trials.csv").read_text().splitlines()
    analysed = {(int(ln.split(",")[2]), int(ln.split(",")[3])) for ln in rows[1:]}  # session, trial number
    assert not analysed & {(1, i + 1) for (i,) in touched}  # the touched trials are left out ...
    assert len(analysed) == len(data.included) and {(2, 1), (1, 1)} <= analysed  # ... and only they
    # ... and said so: one line on stderr, the trials listed as not counted, the methods counting them
    said = [ln for ln in r.stderr.splitlines() if "recording damaged" in ln]
    assert len(said) == 1 and "session 1, recorded run 0, 3.000–3.999 s (block 3)" in said[0], r.stderr
    assert "left out of the analysis" in said[0] and "Trials that did not count" in said[0]
    n = len(touched)
    assert f"{n} trial{'s' if n > 1 else ''} with a damaged recording" in r.stdout
    page = (tmp_path / "rep" / "report.html").read_text(encoding="utf-8")
    not_counted = page.split("<h3>Trials that did not count</h3>")[1].split("<h3>")[0]
    for (i,) in touched:
        assert (f"P01, session 1, trial {i + 1}: recording damaged (study.db: session 1, recorded run 0, "
                "3.000–3.999 s (block 3): checksum mismatch") in not_counted
    methods = page.split("<b>Data.</b>")[1].split("</p>")[0]
    assert f"{len(analysed)} analysed trials" in methods
    assert f"and {n} trial{'s' if n > 1 else ''} whose recording is damaged" in methods
    assert f"P01, session 1, trial {touched[0][0] + 1}: recording damaged" in methods


def test_readers_raise_one_error_naming_the_damage_or_read_around_it(study: Path, tmp_path: Path) -> None:
    db = tmp_path / "study.db"
    shutil.copy(study, db)
    flip_a_bit(db)
    c = sqlite3.connect(db)
    try:
        with pytest.raises(RecordingDamaged, match=r"2\.000–2\.999 s \(block 2\).*touches trial 2"):
            read_segment(c, DAMAGED_SESSION, 0)
        with pytest.raises(RecordingDamaged):
            read_ticks(c, DAMAGED_SESSION, 0, 2500, 2600, ["force_n"])
        read_ticks(c, DAMAGED_SESSION, 0, 100, 900, ["force_n"])  # a window of intact blocks reads as ever
        whole = read_segment(c, DAMAGED_SESSION, 0, skip_damaged=True)
        assert [d.first_block for d in whole.damage] == [DAMAGED_BLOCK]
        assert not ((whole.columns["tick"] >= 2000) & (whole.columns["tick"] < 3000)).any()
        assert recording_damage(c, 1) == [] and len(recording_damage(c)) == 1
    finally:
        c.close()


def test_a_block_from_before_checksums_is_not_verifiable_and_not_damaged_until_it_fails_to_decode(
        study: Path, tmp_path: Path) -> None:
    db = tmp_path / "study.db"
    shutil.copy(study, db)
    _sql(db, "UPDATE session_blocks SET crc32 = NULL WHERE session_id = 1")
    c = sqlite3.connect(db)
    assert recording_damage(c, columns=None) == []
    c.close()
    r = _cli(["check", "--db", str(db)], tmp_path)
    assert r.returncode == 0 and "without one (written before version 4) decoded" in r.stdout, r.stdout
    assert "cannot be detected" in r.stdout
    undecodable_without_checksum(db)
    c = sqlite3.connect(db)
    (d,) = recording_damage(c, columns=("force_n",))
    c.close()
    assert d.why.startswith("cannot be decoded (")


def test_the_engines_resume_refuses_a_damaged_session_and_changes_nothing(study: Path, tmp_path: Path) -> None:
    db = tmp_path / "study.db"
    shutil.copy(study, db)
    flip_a_bit(db)
    def content() -> list[object]:
        c = sqlite3.connect(db)
        try:
            return [c.execute(f"SELECT * FROM {t} ORDER BY 1, 2").fetchall()
                    for t in ("sessions", "trials", "events", "leases", "recordings", "session_blocks")]
        finally:
            c.close()

    before = content()
    w = StudyDatabase(db)  # as the GUI's engine opens it
    try:
        with pytest.raises(StorageError, match="cannot be resumed: its recording is damaged: session 3"):
            open_resumed_session(w, DAMAGED_SESSION, lease_owner="gui-test")
    finally:
        w.close()
    assert content() == before  # not even the lease was taken
    # and the engine the GUI drives answers its Resume with that line
    from study_app.engine import messages as m
    from study_app.engine.host import StudyEngine
    from study_app.engine.setup import HostConfig

    events: list[object] = []
    e = StudyEngine(HostConfig(clock="virtual", speed=0), events.append, shared_ring=False)
    e.start()
    try:
        e.handle(m.ResumeSession(str(db), DAMAGED_SESSION))
    finally:
        e.close("test over")
        e.release_ring()
    (refused,) = [ev for ev in events if isinstance(ev, m.CommandRefused)]
    assert "cannot be resumed: its recording is damaged: session 3" in refused.message and "\n" not in refused.message
    assert not [ev for ev in events if isinstance(ev, m.SessionStarted)]
    assert content() == before


def test_checksums_are_the_blocks_own(study: Path) -> None:
    # a run recorded now binds each block's checksum to its place, then its bytes (place_crc32)
    c = sqlite3.connect(study)
    try:
        rows = c.execute("SELECT session_id, segment, block, first_tick, last_tick, n_records, data, crc32 "
                         "FROM session_blocks").fetchall()
    finally:
        c.close()
    assert rows and all(place_crc32(d, arm="", session_id=s, segment=g, block=b, chunk=WHOLE_BLOCK, first_tick=f,
                                    last_tick=t, n_records=n) == crc for s, g, b, f, t, n, d, crc in rows)
    assert not any(zlib.crc32(d) == crc for *_, d, crc in rows)  # not the bytes' alone


def test_a_killed_runs_open_block_reads_from_its_chunks_and_a_damaged_chunk_is_named_as_its_block(
        study: Path, tmp_path: Path) -> None:
    db = tmp_path / "study.db"
    shutil.copy(study, db)
    c = sqlite3.connect(db)
    try:
        chunks = c.execute("SELECT block, chunk, first_tick, last_tick, data FROM session_chunks WHERE session_id = ? "
                           "ORDER BY chunk", (DAMAGED_SESSION,)).fetchall()
        assert chunks and {r[0] for r in chunks} == {chunks[0][0]}  # the kill left one block open, in chunks
        block = chunks[0][0]
        whole = read_segment(c, DAMAGED_SESSION, 0).columns["tick"]
        assert whole[0] == 0 and whole[-1] == chunks[-1][3] and len(whole) == whole[-1] + 1  # none missing
        data = bytes(chunks[-1][4])
        c.execute("UPDATE session_chunks SET data = ? WHERE session_id = ? AND block = ? AND chunk = ?",
                  (data[:-9] + bytes([data[-9] ^ 0x10]) + data[-8:], DAMAGED_SESSION, block, chunks[-1][1]))
        c.commit()
        (d,) = recording_damage(c)
        assert (d.session_id, d.first_block, d.last_block) == (DAMAGED_SESSION, block, block)
        assert d.why.startswith("checksum mismatch")
        assert len(read_segment(c, DAMAGED_SESSION, 0, skip_damaged=True).columns["tick"]) == block * 1000
    finally:
        c.close()


def test_a_block_whose_value_became_text_is_named_as_damage_not_a_utf8_error(study: Path, tmp_path: Path) -> None:
    """A block edited with sqlite3 (``substr(data, ...) || x'..'`` gives TEXT) made every reader fail on
    "Could not decode to UTF-8 column 'data'": check said it could not read the study tables (0 experiment
    sessions) and report refused the whole study, instead of naming the block and leaving out its trials."""
    db = tmp_path / "study.db"
    shutil.copy(study, db)
    _sql(db, "UPDATE session_blocks SET data = substr(data, 1, 300) || x'DEADBEEF' || substr(data, 305) "
             "WHERE session_id = ? AND segment = 0 AND block = ?", DAMAGED_SESSION, DAMAGED_BLOCK)
    c = sqlite3.connect(db)
    try:
        assert c.execute("SELECT typeof(data) FROM session_blocks WHERE session_id = ? AND block = ?",
                         (DAMAGED_SESSION, DAMAGED_BLOCK)).fetchone() == ("text",)
        (d,) = recording_damage(c)
        assert (d.session_id, d.first_block) == (DAMAGED_SESSION, DAMAGED_BLOCK) and "checksum mismatch" in d.why
    finally:
        c.close()
    r = _cli(["check", "--db", str(db)], tmp_path)
    assert r.returncode == 1 and "UTF-8" not in r.stdout + r.stderr, r.stdout
    assert f"damaged: session {DAMAGED_SESSION}, recorded run 0, 2.000–2.999 s (block 2): checksum mismatch" in r.stdout
