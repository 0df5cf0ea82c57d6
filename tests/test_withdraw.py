"""A participant withdraws (``haptic-study withdraw``), and one asks for their data (``export participant``).

One small study of four simulated participants (counterbalanced, one trial per cell) is run once for the module;
P02 withdraws from it.  What must hold: none of P02's values remains anywhere in the file's bytes (their recorded
blocks, their trials' numbers, their schedule and events), the withdrawal record holds only the code, the time,
the reason and the counts, ``check`` passes, the report lists the withdrawal and analyses the other three, whose
counterbalancing is unchanged; a second withdrawal, a withdrawal while a session runs, and bad input are one-line
refusals that leave the file byte-identical.  The export of another participant opens in pandas and matches what
the report used for them.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import os
import shutil
import sqlite3
import stat
import struct
from pathlib import Path

import pandas as pd
import pytest

from analysis.report.report import build_report
from protocol.storage import StorageError, StudyDatabase, new_owner_token, session_scope
from protocol.storage.reader import StudyReader
from protocol.storage.withdrawal import footprint, withdrawals
from protocol.study.config import default_protocol
from study_app.cli.main import main
from study_app.headless import run_study

GONE = "P02"
pytestmark = pytest.mark.xdist_group("withdraw")  # one worker builds the study once


def _protocol():
    p = default_protocol()
    return dataclasses.replace(p, trials_per_cell=1, ordering="counterbalanced",
                               trial=dataclasses.replace(p.trial, max_trial_s=6.0, pause_s=1.0),
                               training=dataclasses.replace(p.training, enabled=False, required=False))


def _rows(db: Path, sql: str, *args: object) -> list[tuple]:
    c = sqlite3.connect(db)
    try:
        return c.execute(sql, args).fetchall()
    finally:
        c.close()


def _traces(db: Path, code: str) -> list[bytes]:
    """Byte strings only this participant's rows hold: windows of their recorded blocks' compressed columns
    (past each block's header, which all blocks share), their trials' metrics as SQLite stores a REAL (8 bytes,
    big-endian), their schedule and their session's start event."""
    c = sqlite3.connect(db)
    try:
        sids = [r[0] for r in c.execute("SELECT session_id FROM sessions JOIN participants USING (participant_id) "
                                        "WHERE code = ?", (code,))]
        out: list[bytes] = []
        for sid in sids:
            for (blob,) in c.execute("SELECT data FROM session_blocks WHERE session_id = ?", (sid,)):
                out += [blob[i:i + 32] for i in range(len(blob) // 2, len(blob) - 32, max(1, len(blob) // 6))]
            for row in c.execute("SELECT rmse_n, max_ae_n, peak_force_n FROM trials WHERE session_id = ?", (sid,)):
                out += [struct.pack(">d", v) for v in row if isinstance(v, float) and v not in (0.0, 1.0)]
            out += [r[0].encode() for r in c.execute("SELECT schedule_json FROM sessions WHERE session_id = ?", (sid,))]
            out += [r[0].encode() for r in c.execute("SELECT detail FROM events WHERE session_id = ? AND "
                                                     "kind = 'session_start'", (sid,))]
        return out
    finally:
        c.close()


def _file_bytes(db: Path) -> bytes:
    wal = Path(f"{db}-wal")
    return db.read_bytes() + (wal.read_bytes() if wal.exists() else b"")


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> dict:
    """The study before (``pristine``, a copy) and after P02 withdrew (``db``), with what P02 left before."""
    folder = tmp_path_factory.mktemp("withdraw")
    db = folder / "study.db"
    run_study(str(db), participants=4, seed=11, protocol=_protocol(), jobs=1)
    pristine = folder / "pristine.db"
    shutil.copy(db, pristine)
    others = {code: _traces(db, code) for code in ("P01", "P03", "P04")}
    shared = {t for ts in others.values() for t in ts}  # (a schedule may be another participant's too)
    before = {
        "traces": [t for t in _traces(db, GONE) if t not in shared], "others": others["P01"],
        "sessions": _rows(db, "SELECT session_id, participant_number, schedule_json FROM sessions "
                              "JOIN participants USING (participant_id) WHERE code != ? ORDER BY session_id", GONE),
    }
    c = sqlite3.connect(db)
    before["footprint"] = footprint(c, GONE)
    c.close()
    return {"folder": folder, "db": db, "pristine": pristine, "before": before}


@pytest.fixture(scope="module")
def withdrawn(study) -> dict:
    """P02 withdraws, as a script does it (``--yes P02``); what the command printed is kept."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["withdraw", "--db", str(study["db"]), "--participant", GONE, "--reason",
                     "withdrew consent by e-mail", "--yes", GONE])
    assert code == 0, err.getvalue()
    return {**study, "out": out.getvalue()}


@pytest.fixture(scope="module")
def report(withdrawn) -> Path:
    """The report of the study after the withdrawal."""
    out = withdrawn["folder"] / "report"
    summary = build_report([withdrawn["db"]], out, workers=1)
    assert summary.n_participants == 3
    return out


def _content(db: Path) -> list[str]:
    c = sqlite3.connect(db)
    try:
        return list(c.iterdump())
    finally:
        c.close()


def _refused(capsys, db: Path, *argv: str, expect: str, same_bytes: bool = True) -> None:
    """The command is refused in one line naming ``expect``, exit 2, and the file is byte-identical (or, where the
    refusal comes after the study's lease was taken and given back, holds the same rows)."""
    before = _file_bytes(db) if same_bytes else _content(db)
    try:
        code = main(list(argv))
    except SystemExit as exc:  # argparse's one line
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1 and expect in err, err
    assert (_file_bytes(db) if same_bytes else _content(db)) == before


# -- the withdrawal ---------------------------------------------------------------------------------------------
def test_none_of_their_values_remains_in_the_file(withdrawn) -> None:
    db, before = withdrawn["db"], withdrawn["before"]
    data = _file_bytes(db)
    assert before["traces"] and all(t in _file_bytes(withdrawn["pristine"]) for t in before["traces"])  # they were
    assert [t for t in before["traces"] if t in data] == []
    assert all(t in data for t in before["others"])  # the search finds what is still there
    assert not Path(f"{db}-wal").exists() or Path(f"{db}-wal").stat().st_size == 0
    # the code itself: only where a live row holds it (the withdrawal record and its key; the calibration's pose
    # labels "P02" of the other sessions), never in freed space
    c = sqlite3.connect(db)
    try:
        live = 1  # the withdrawals table's primary-key index holds the code once more
        for (table,) in c.execute("SELECT name FROM sqlite_master WHERE type = 'table'"):
            for row in c.execute(f"SELECT * FROM {table}"):
                live += sum((v.encode() if isinstance(v, str) else v).count(GONE.encode())
                            for v in row if isinstance(v, (str, bytes)))
        assert c.execute("SELECT COUNT(*) FROM participants WHERE code = ?", (GONE,)).fetchone() == (0,)
    finally:
        c.close()
    assert data.count(GONE.encode()) <= live


def test_the_record_keeps_only_the_code_time_reason_and_counts(withdrawn) -> None:
    fp = withdrawn["before"]["footprint"]
    c = sqlite3.connect(withdrawn["db"])
    try:
        (w,) = withdrawals(c)
        cols = [r[1] for r in c.execute("PRAGMA table_info(withdrawals)")]
    finally:
        c.close()
    assert cols == ["code", "withdrawn_at", "reason", "removed_sessions", "removed_trials", "removed_events",
                    "removed_blocks", "removed_records", "removed_samples", "rewritten",
                    "removed_lsl_streams", "removed_lsl_chunks"]
    assert (w.code, w.reason, w.rewritten) == (GONE, "withdrew consent by e-mail", 1)  # the rewrite finished
    assert (w.removed_lsl_streams, w.removed_lsl_chunks) == (0, 0) and "LSL" not in w.counts()  # a study without LSL
    assert (w.removed_sessions, w.removed_trials, w.removed_events, w.removed_blocks, w.removed_records) == (
        len(fp.sessions), fp.trials, fp.events, fp.blocks, fp.records) and fp.trials == 4 and fp.records > 1000
    out = withdrawn["out"]
    assert f"Withdrew {GONE}" in out and "write-ahead log emptied" in out and "files it did not make" in out


def test_check_passes_and_the_others_are_unchanged(withdrawn, capsys) -> None:
    assert main(["check", "--db", str(withdrawn["db"])]) == 0, capsys.readouterr().out
    assert main(["check", "--db", str(withdrawn["db"])]) == 0
    out = capsys.readouterr().out
    assert "participant P02 withdrew (" in out and "erased; their number stays vacant" in out  # said, not a problem
    after = _rows(withdrawn["db"], "SELECT session_id, participant_number, schedule_json FROM sessions "
                                   "JOIN participants USING (participant_id) ORDER BY session_id")
    assert after == withdrawn["before"]["sessions"]  # same sessions, numbers and schedules: counterbalancing kept


def test_the_report_lists_the_withdrawal_and_analyses_the_other_three(report) -> None:
    trials = pd.read_csv(report / "trials.csv")
    assert sorted(trials["participant_code"].unique()) == ["P01", "P03", "P04"]
    page = (report / "report.html").read_text(encoding="utf-8")
    assert "1 participant withdrew; excluded: P02" in page
    assert "counterbalancing of the remaining participants is unchanged" in page
    assert "numbers 1, 3, 4" in page and "began 2 with haptics ON, 1 with haptics OFF" in page


def test_a_second_withdrawal_is_a_one_line_refusal(withdrawn, capsys) -> None:
    _refused(capsys, withdrawn["db"], "withdraw", "--db", str(withdrawn["db"]), "--participant", GONE, "--reason",
             "again", "--yes", GONE, expect="already withdrew")


def test_a_withdrawn_code_is_not_run_again(withdrawn, tmp_path) -> None:
    db = tmp_path / "again.db"
    shutil.copy(withdrawn["db"], db)
    run_study(str(db), participants=4, seed=11, protocol=_protocol(), jobs=1, continue_study=True)
    assert _rows(db, "SELECT COUNT(*) FROM participants WHERE code = ?", GONE) == [(0,)]
    # withdraw again: the later sessions' free pages are not a withdrawal's rewrite left undone -- refused, the
    # file untouched (it rewrote the whole file and said the first withdrawal had not finished)
    before = _file_bytes(db)
    assert main(["withdraw", "--db", str(db), "--participant", GONE, "--reason", "again", "--yes", GONE]) == 2
    assert _file_bytes(db) == before
    d = StudyDatabase(db)
    try:
        with pytest.raises(StorageError, match="withdrew from the study"):
            d.create_session(code=GONE, kind="experiment", seed=11, participant_number=2, protocol_json="{}",
                             schedule_json="[]", software_version="0", rig="sim", config={}, calibration=None)
    finally:
        d.close()


def test_the_gui_form_hears_of_the_withdrawal_and_refuses_the_code_before_start(withdrawn) -> None:
    from study_app.engine.session_list import list_sessions, list_withdrawn
    from study_app.models.setup import SetupModel

    gone = list_withdrawn(withdrawn["db"])
    assert [w["code"] for w in gone] == [GONE] and gone[0]["withdrawn_at"][:4].isdigit()
    form = SetupModel()
    form.update(db_path=str(withdrawn["db"]))
    form.set_known(list_sessions(withdrawn["db"]), gone)
    form.update(code=GONE)
    assert form.errors["code"].startswith(f"{GONE} withdrew from the study (") and not form.valid


# -- refusals: nothing touched --------------------------------------------------------------------------------
@pytest.fixture
def copy(study, tmp_path) -> Path:
    db = tmp_path / "copy.db"
    shutil.copy(study["pristine"], db)
    return db


def test_a_withdrawal_during_a_running_session_is_refused(copy, capsys) -> None:
    sid = _rows(copy,
                "SELECT session_id FROM sessions JOIN participants USING (participant_id) WHERE code = 'P03'")[0][0]
    other = StudyDatabase(copy)  # a live writer of P03's session: this process, under another command's token
    try:
        other.acquire_lease(session_scope(sid), new_owner_token(), command="haptic-study gui")
        _refused(capsys, copy, "withdraw", "--db", str(copy), "--participant", "P03", "--reason", "x", "--yes", "P03",
                 expect=f"session {sid} is running")
        # another participant's session runs: withdraw rewrites the whole file, so it waits too
        _refused(capsys, copy, "withdraw", "--db", str(copy), "--participant", "P04", "--reason", "x", "--yes", "P04",
                 expect="is being written by process")
    finally:
        other.close()


@pytest.mark.parametrize("argv, expect", [
    (["--participant", "P09", "--reason", "x", "--yes", "P09"], "no such participant"),
    (["--participant", "P0 2", "--reason", "x", "--yes", "P02"], "--participant"),
    (["--participant", "P02", "--reason", "  ", "--yes", "P02"], "--reason"),
    (["--participant", "P02", "--reason", "x", "--yes", "P03"], "must repeat the participant code P02"),
    (["--participant", "P02", "--reason", "x"], "give --yes P02 in a script"),  # no terminal to ask at
])
def test_bad_input_is_one_line_and_touches_nothing(copy, capsys, argv, expect) -> None:
    _refused(capsys, copy, "withdraw", "--db", str(copy), *argv, expect=expect)


def test_the_confirmation_names_what_will_go_and_needs_the_code(copy, capsys, monkeypatch) -> None:
    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    monkeypatch.setattr("sys.stdin", Terminal("P2\n"))
    _refused(capsys, copy, "withdraw", "--db", str(copy), "--participant", "P02", "--reason", "x",
             expect="not confirmed")
    monkeypatch.setattr("sys.stdin", Terminal("P02\n"))
    assert main(["withdraw", "--db", str(copy), "--participant", "P02", "--reason", "x"]) == 0
    out = capsys.readouterr().out
    assert "This erases from" in out and "participant P02: 1 session: experiment session" in out and "4 trials" in out
    assert _rows(copy, "SELECT code FROM withdrawals") == [("P02",)]


# -- export participant -------------------------------------------------------------------------------------------
def test_the_export_opens_in_pandas_and_matches_what_the_report_used(withdrawn, report, capsys) -> None:
    db, out = withdrawn["db"], withdrawn["folder"] / "P03-data"
    assert main(["export", "participant", "--db", str(db), "--participant", "P03", "--out", str(out)]) == 0
    said = capsys.readouterr().out  # counts in words, as every command says them (it said "1 session(s)")
    assert f"Wrote {out}/ for P03: 1 session, " in said and "(s)" not in said, said
    mine = pd.read_csv(out / "trials.csv")
    used = pd.read_csv(report / "trials.csv")
    theirs = used[used["participant_code"] == "P03"].reset_index(drop=True)
    pd.testing.assert_frame_equal(mine[list(theirs.columns)], theirs)
    stored = pd.read_csv(out / "stored_trials.csv")
    assert list(stored["trial_index"]) == list(mine["trial_number"] - 1) and set(stored["session_id"]) == {3}
    samples = pd.read_csv(out / "samples.csv")
    blocks = pd.read_csv(out / "blocks.csv")
    assert len(samples) == blocks["n_records"].sum() > 1000 and set(samples["session_id"]) == {3}
    import json

    settings = json.loads((out / "sessions.json").read_text(encoding="utf-8"))
    (s,) = settings["sessions"]
    assert s["protocol"]["design"]["ordering"] == "counterbalanced" and s["schedule"] and s["config"]
    assert s["recordings"][0]["snapshot"]
    codebook = pd.read_csv(out / "codebook.csv", keep_default_na=False)
    for f in out.glob("*.csv"):
        cols = list(pd.read_csv(f, nrows=0).columns)
        assert sorted(codebook.loc[codebook["file"] == f.name, "column"]) == sorted(cols), f.name
    assert (codebook["description"] != "").all(), codebook[codebook["description"] == ""]
    assert stat.S_IMODE(out.stat().st_mode) == 0o700
    assert all(stat.S_IMODE(f.stat().st_mode) == 0o600 for f in out.iterdir())
    # never over a folder it did not make, and a withdrawn participant has nothing to export
    capsys.readouterr()
    assert main(["export", "participant", "--db", str(db), "--participant", "P03", "--out", str(out)]) == 2
    assert main(["export", "participant", "--db", str(db), "--participant", GONE, "--out",
                 str(withdrawn["folder"] / "gone")]) == 2
    assert "withdrew" in capsys.readouterr().err and not (withdrawn["folder"] / "gone").exists()


def test_the_export_in_parquet_opens_in_pandas(withdrawn) -> None:
    out = withdrawn["folder"] / "P01-parquet"
    assert main(["export", "participant", "--db", str(withdrawn["db"]), "--participant", "P01", "--format", "parquet",
                 "--out", str(out)]) == 0
    assert len(pd.read_parquet(out / "samples.parquet")) > 1000
    assert list(pd.read_parquet(out / "participant.parquet")["code"]) == ["P01"]


def test_a_version_4_file_from_before_withdrawals_and_chunks_gains_the_tables(tmp_path) -> None:
    db = tmp_path / "old4.db"
    StudyDatabase(db).close()
    c = sqlite3.connect(db)
    c.execute("DROP TABLE withdrawals")
    c.execute("DROP TABLE session_chunks")
    c.commit()
    c.close()
    r = StudyDatabase(db, readonly=True)
    try:
        assert withdrawals(r.conn) == []  # a reader takes it as it is
        reader = StudyReader.over(r)
        assert list(reader.blocks()) == [] and reader.block_count() == 0 and reader.record_count([1]) == 0
    finally:
        r.close()
    StudyDatabase(db).close()  # a writer completes version 4
    assert _rows(db, "SELECT COUNT(*) FROM withdrawals") == [(0,)]
    assert _rows(db, "SELECT COUNT(*) FROM session_chunks") == [(0,)]
    assert os.path.getsize(db) > 0


def test_a_reader_that_holds_up_the_rewrite_is_named_and_a_second_run_finishes_it(study, copy, capsys,
                                                                                  monkeypatch) -> None:
    import protocol.storage.withdrawal as w

    monkeypatch.setattr(w, "CHECKPOINT_WAIT_S", 0.2)
    reader = sqlite3.connect(copy, isolation_level=None)
    try:
        reader.execute("BEGIN")
        reader.execute("SELECT COUNT(*) FROM trials").fetchone()  # a report reading: its snapshot holds the file
        _refused(capsys, copy, "withdraw", "--db", str(copy), "--participant", GONE, "--reason", "x", "--yes", GONE,
                 expect="another program is reading the study", same_bytes=False)
        reader.execute("COMMIT")
        db = StudyDatabase(copy)  # it starts reading again between the check and the rewrite
        try:
            assert w.nobody_reading(db)
            w.erase_participant(db, GONE, "x")
            reader.execute("BEGIN")
            reader.execute("SELECT COUNT(*) FROM trials").fetchone()
            assert not w.rewrite_file(db)
        finally:
            db.close()
        reader.execute("COMMIT")  # it has finished reading, but keeps the file open
        assert main(["withdraw", "--db", str(copy), "--participant", GONE, "--reason", "x", "--yes", GONE]) == 0
        assert "the rewrite is finished now" in capsys.readouterr().out
        assert Path(f"{copy}-wal").stat().st_size == 0
        assert [t for t in study["before"]["traces"] if t in _file_bytes(copy)] == []
    finally:
        reader.close()


@pytest.mark.parametrize("blob_bytes", [None, 4096])
def test_free_pages_a_writer_left_unzeroed_are_zeroed_by_the_withdrawal(tmp_path, monkeypatch, blob_bytes) -> None:
    """A writer frees its chunks with ``secure_delete = FAST`` (their bytes stay in free pages); the withdrawal
    zeroes every free page before the file is rewritten, so no copy is left on the file's blocks that VACUUM drops.
    Also with the zeros in many small rows (as a free list over SQLite's 1e9-byte value limit is written)."""
    from protocol.storage import withdrawal
    from protocol.storage.withdrawal import erase_participant
    from protocol.study.design import build_schedule, schedule_to_json

    if blob_bytes is not None:
        monkeypatch.setattr(withdrawal, "_SCRUB_BLOB_BYTES", blob_bytes)

    path = tmp_path / "s.db"
    db = StudyDatabase(path)
    p = default_protocol()
    sid = db.create_session(code="P01", kind="experiment", seed=7, participant_number=1, protocol_json=p.to_json(),
                            schedule_json=schedule_to_json(build_schedule(p, seed=7, participant_number=1)),
                            software_version="0.1.0+test", rig="sim", config={}, calibration={})
    marker = b"PARTICIPANT-DATA" * 1000  # 16 kB: overflow pages
    db.begin()
    db.insert_recording(sid, 0, 0.0, 0, {}, {})
    for k in range(5):
        db.write_chunk(sid, 0, 0, k, 0, 1, 2, 0.0, 0.001, marker)
    db.commit()
    db.begin()
    db.write_block(sid, 0, 0, 0, 1, 2, 0.0, 0.001, b"x" * 100)  # the chunks go, their pages freed (FAST)
    db.commit()
    db.conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    assert path.read_bytes().count(b"PARTICIPANT-DATA") > 100  # what FAST leaves (the test can fail)
    erase_participant(db, "P01", "test")
    db.conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")  # what rewrite_file does first, before VACUUM shrinks
    assert path.read_bytes().count(b"PARTICIPANT-DATA") == 0
    assert not db.conn.execute("SELECT 1 FROM sqlite_master WHERE name = 'withdrawal_scrub'").fetchone()
    db.close()


_STOPPED = """
import os, sys
import protocol.storage.withdrawal as w
from foundation.platform_support.processes import kill_hard

real = w.rewrite_file


def rewrite_file(db):
    if {where!r} == "before the rewrite":
        kill_hard(os.getpid())
    # killed as VACUUM begins: the log was just emptied into the file, the free pages are still there
    db.conn.set_trace_callback(lambda sql: sql.lstrip().upper().startswith("VACUUM") and kill_hard(os.getpid()))
    return real(db)


w.rewrite_file = rewrite_file
from study_app.cli.main import main
sys.exit(main(["withdraw", "--db", {db!r}, "--participant", {code!r}, "--reason", "x", "--yes", {code!r}]))
"""


@pytest.mark.parametrize("where", ["before the rewrite", "as VACUUM begins"])
def test_a_withdrawal_killed_between_the_removal_and_the_rewrite_is_finished_by_running_it_again(
        study, copy, capsys, where) -> None:
    """kill -9 after the rows were committed and before the file was rewritten: the same command run again said
    "already withdrew ... nothing to remove" and the file kept its free pages for ever; now it finishes the rewrite."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": str(root)}
    stopped = subprocess.run([sys.executable, "-c", _STOPPED.format(where=where, db=str(copy), code=GONE)],
                             cwd=root, env=env, capture_output=True, text=True, timeout=300, check=False)
    assert stopped.returncode == -9, stopped.stderr
    # (these looks, each a connection of its own, empty the log into the file as they close, as any program that
    # opens the study may: then only the free pages say the rewrite is still to do)
    assert [r[0] for r in _rows(copy, "SELECT code FROM withdrawals")] == [GONE]  # the removal was committed
    assert _rows(copy, "SELECT COUNT(*) FROM participants WHERE code = ?", GONE) == [(0,)]
    assert _rows(copy, "PRAGMA freelist_count")[0][0] > 0  # ... and the file not rewritten
    # check does not call it done (it said "erased ... No problem found" while their bytes were in the file)
    assert main(["check", "--db", str(copy)]) == 1
    said = capsys.readouterr().out
    assert f"withdrawal of {GONE} incomplete" in said and "run withdraw again" in said, said
    assert main(["withdraw", "--db", str(copy), "--participant", GONE, "--reason", "x", "--yes", GONE]) == 0
    out = capsys.readouterr().out
    assert "still held pages the withdrawal's rewrite drops" in out and "the rewrite is finished now" in out, out
    assert _rows(copy, "PRAGMA freelist_count") == [(0,)]
    assert not Path(f"{copy}-wal").exists() or Path(f"{copy}-wal").stat().st_size == 0
    assert [t for t in study["before"]["traces"] if t in _file_bytes(copy)] == []
    assert main(["check", "--db", str(copy)]) == 0, capsys.readouterr().out
    capsys.readouterr()
    _refused(capsys, copy, "withdraw", "--db", str(copy), "--participant", GONE, "--reason", "again", "--yes", GONE,
             expect="already withdrew")  # finished: a third run has nothing to do


def test_a_finished_withdrawal_is_done_whatever_the_clocks_said(withdrawn, tmp_path, capsys) -> None:
    """Sessions added while the wall clock ran behind (started before the withdrawal's time) and free pages of
    their own: a second withdraw rewrote the file and said the rewrite had been unfinished; the file's own mark
    says it finished."""
    db = tmp_path / "later.db"
    shutil.copy(withdrawn["db"], db)
    c = sqlite3.connect(db)
    try:
        assert c.execute("SELECT rewritten FROM withdrawals WHERE code = ?", (GONE,)).fetchone() == (1,)
        c.execute("UPDATE withdrawals SET withdrawn_at = '2999-01-01T00:00:00+00:00'")  # every session "before" it
        c.execute("CREATE TABLE scratch (x BLOB)")  # a later writer's free pages
        c.executemany("INSERT INTO scratch VALUES (?)", [(bytes(4096),)] * 20)
        c.commit()
        c.execute("DROP TABLE scratch")
        c.commit()
        c.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        assert c.execute("PRAGMA freelist_count").fetchone()[0] > 0
    finally:
        c.close()
    _refused(capsys, db, "withdraw", "--db", str(db), "--participant", GONE, "--reason", "again", "--yes", GONE,
             expect="already withdrew")
