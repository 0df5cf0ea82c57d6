"""One writer per session, through the real command line: concurrent resumes and runs, kill -9 at any moment,
the true timeline after --continue, and a version-1 database upgraded only after a backup.
"""

from __future__ import annotations

import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from records import assert_records_unique_and_ordered, trial_samples
from test_faults_in_the_record import assert_true_timeline, rows

from protocol.storage import SCHEMA_VERSION

ROOT = Path(__file__).resolve().parents[2]
PAUSE_S = 2.0


def short_toml(tmp_path: Path, training: bool = False) -> Path:
    p = tmp_path / "short.toml"
    text = (ROOT / "protocol" / "study" / "default.toml").read_text()
    text = text.replace("trials_per_cell = 5", "trials_per_cell = 1")
    text = text.replace("seconds_per_target_per_mode = 20.0", "seconds_per_target_per_mode = 4.0")
    p.write_text(text if training else text.replace("enabled = true", "enabled = false"))
    return p


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "study_app.cli", *args]


def run(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run(cli(*args), capture_output=True, text=True, timeout=timeout, cwd=ROOT)


def no_duplicate_sample_times(db: Path) -> None:
    assert_records_unique_and_ordered(db)


def test_two_concurrent_resumes_of_one_session_exactly_one_proceeds(tmp_path: Path) -> None:
    db, proto = tmp_path / "s.db", short_toml(tmp_path)
    killed = run("run", "--participants", "1", "--seed", "3", "--db", str(db), "--protocol", str(proto),
                 "--inject-fault", "kill@P01:2+2")
    assert killed.returncode == -9
    both = [subprocess.Popen(cli("run", "--db", str(db), "--resume", "P01"), stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, cwd=ROOT) for _ in range(2)]
    results = [(p.wait(300), *p.communicate()) for p in both]
    codes = sorted(r[0] for r in results)
    assert codes == [0, 2], results
    (loser,) = [r for r in results if r[0] == 2]
    err = loser[2].strip()
    assert "\n" not in err and "Traceback" not in err
    # refused by the other's lease, or (if it came later) because there is nothing left to resume
    assert any(why in err for why in ("is being written by process", "no interrupted session", "it has ended")), err
    no_duplicate_sample_times(db)
    assert rows(db, "SELECT status FROM sessions") == [("completed",)]
    assert rows(db, "SELECT COUNT(*) FROM events WHERE kind = 'resume'") == [(1,)]
    assert rows(db, "SELECT COUNT(*) FROM leases") == [(0,)]


def test_two_runs_on_one_new_database_never_split_the_study(tmp_path: Path) -> None:
    db, proto = tmp_path / "new.db", short_toml(tmp_path)
    args = ("run", "--participants", "2", "--jobs", "1", "--seed", "5", "--db", str(db), "--protocol", str(proto))
    both = [subprocess.Popen(cli(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
            for _ in range(2)]
    results = [(p.wait(300), *p.communicate()) for p in both]
    assert sorted(r[0] for r in results) == [0, 2], results
    (loser,) = [r for r in results if r[0] == 2]
    err = loser[2].strip()
    assert "\n" not in err and ("being written by process" in err or "already holds sessions" in err), err
    # the whole study is one run's: each participant once, both complete
    assert rows(db, "SELECT p.code, COUNT(*) FROM sessions s JOIN participants p USING (participant_id) "
                    "GROUP BY p.code ORDER BY p.code") == [("P01", 1), ("P02", 1)]
    assert rows(db, "SELECT DISTINCT status FROM sessions") == [("completed",)]
    no_duplicate_sample_times(db)


def _has_sessions(db: Path) -> bool:
    try:
        return db.exists() and rows(db, "SELECT COUNT(*) FROM sessions")[0][0] > 0
    except sqlite3.OperationalError:  # created but its schema not committed yet
        return False


def test_a_second_run_is_refused_while_a_study_runs_and_names_it(tmp_path: Path) -> None:
    db, proto = tmp_path / "busy.db", tmp_path / "long.toml"
    # one long session on the virtual clock: 400 trials (the most cells a protocol allows), about an hour of study
    # time, minutes of work even on a quiet fast machine -- 120 trials once ended before the second command had
    # started -- and the first run is killed at the end anyway (the real clock would be at the mercy of the
    # machine's load: a loaded machine misses ticks, and the runner stops a session whose trials fail again and
    # again)
    proto.write_text(short_toml(tmp_path).read_text().replace("trials_per_cell = 1", "trials_per_cell = 100"))
    first = subprocess.Popen(cli("run", "--participants", "1", "--jobs", "1", "--seed", "5", "--db", str(db),
                                 "--protocol", str(proto)),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not _has_sessions(db):
            time.sleep(0.1)  # wait for the first run to be under way
        assert _has_sessions(db)
        for args in (("run", "--participants", "1", "--seed", "5", "--continue"), ("run", "--resume", "P01")):
            second = run(*args, "--db", str(db), "--protocol", str(proto))
            err = second.stderr.strip()
            assert second.returncode == 2 and "\n" not in err, err
            assert f"this database is being written by process {first.pid}" in err, err
        # the session it runs is listed as in progress, by whom, not as interrupted; it cannot be resumed
        listing = run("sessions", "--db", str(db))
        assert listing.returncode == 0 and f"in progress (process {first.pid})" in listing.stdout, listing.stdout
        assert "interrupted" not in listing.stdout
        from study_app.engine.sessions import list_resumable

        assert list_resumable(str(db)) == []
        assert first.poll() is None  # (all of this while the first run still wrote)
    finally:
        first.kill()
        first.wait(30)


@pytest.mark.parametrize("kill_at", ["kill@P01:1+0.5", "kill@P01:2+11.95", "kill@P01:3+6"])
def test_kill_at_any_moment_then_continue_keeps_the_true_timeline(tmp_path: Path, kill_at: str) -> None:
    db, proto = tmp_path / "k.db", short_toml(tmp_path)
    args = ("run", "--participants", "1", "--seed", "7", "--db", str(db), "--protocol", str(proto))
    assert run(*args, "--inject-fault", kill_at).returncode == -9

    done = run(*args, "--continue")
    assert done.returncode == 0, done.stderr
    assert rows(db, "SELECT status FROM sessions") == [("completed",)]
    assert_true_timeline(db, PAUSE_S)
    # the resumed session began with the pause: its first cue comes a pause after the last stored moment
    (resume_t,) = rows(db, "SELECT t_s FROM events WHERE kind = 'resume'")[0]
    (next_cue,) = rows(db, "SELECT MIN(t_s) FROM events WHERE kind = 'cue' AND t_s > ?", resume_t)[0]
    assert next_cue - resume_t >= PAUSE_S - 0.002
    interrupted = rows(db, "SELECT trial_index, n_samples, abort_cause FROM trials WHERE outcome = 'aborted'")
    if interrupted:  # killed during a trial: it keeps its samples and is counted as interrupted
        (idx, n, cause), = interrupted
        sid = rows(db, "SELECT session_id FROM sessions")[0][0]
        assert cause == "interrupted" and n == len(trial_samples(db, sid * 1_000_000 + idx))
    no_duplicate_sample_times(db)


def test_kill_during_training_then_continue_keeps_the_true_timeline(tmp_path: Path) -> None:
    db, proto = tmp_path / "t.db", short_toml(tmp_path, training=True)
    code = ("from protocol.study.config import load_protocol\n"
            "from protocol.runner.rehearsal import FaultPlan\n"
            "from study_app.headless import run_study\n"
            f"run_study({str(db)!r}, participants=1, seed=4, protocol=load_protocol({str(proto)!r}), jobs=1, "
            "faults=[FaultPlan('kill', 'P01', 3, 0.5, 'training')])\n")
    assert subprocess.run([sys.executable, "-c", code], cwd=ROOT, timeout=300).returncode == -9
    done = run("run", "--participants", "1", "--seed", "4", "--db", str(db), "--protocol", str(proto), "--continue")
    assert done.returncode == 0, done.stderr
    assert rows(db, "SELECT kind, status FROM sessions ORDER BY session_id") == [
        ("training", "completed"), ("experiment", "completed")]
    assert_true_timeline(db, PAUSE_S)


def _as_version_1(db: Path) -> None:
    """Turn a study database into what version 1 of the software wrote (trial samples in rows; no recording,
    leases or later columns)."""
    import sqlite3

    from protocol.storage import HEALTH_COLUMNS
    from protocol.storage.recordings import read_ticks

    c = sqlite3.connect(db)
    # what version 1 stored of each trial: its window's samples, in rows
    cols = ("t_ns", "force_n", "raw_fx", "raw_fy", "raw_fz", "raw_tx", "raw_ty", "raw_tz",
            "render_fx", "render_fy", "render_fz")
    for tid, sid, seg, first, last in c.execute(
            "SELECT trial_id, session_id, segment, first_tick, last_tick FROM trials WHERE first_tick IS NOT NULL"
    ).fetchall():
        rec = read_ticks(c, sid, seg, first, last, cols)
        t_s = (rec["t_ns"] - rec["t_ns"][0]) / 1e9
        c.executemany(
            "INSERT INTO samples (trial_id, t_s, force_n, raw_fx, raw_fy, raw_fz, raw_tx, raw_ty, raw_tz, "
            "render_fx, render_fy, render_fz) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            zip([tid] * len(t_s), t_s.tolist(), *(rec[k].tolist() for k in cols[1:]), strict=True))
    for col in ("segment", "first_tick", "last_tick"):
        c.execute(f"ALTER TABLE trials DROP COLUMN {col}")
    c.execute("DROP TABLE session_blocks")
    c.execute("DROP TABLE recordings")
    c.execute("DROP TABLE leases")
    for col in ("software_commit", "software_dirty"):
        c.execute(f"ALTER TABLE sessions DROP COLUMN {col}")
    c.execute("DROP INDEX samples_by_trial")
    c.execute("CREATE INDEX samples_by_trial ON samples (trial_id, t_s)")
    c.execute("ALTER TABLE trials DROP COLUMN abort_cause")
    for col in HEALTH_COLUMNS:
        c.execute(f"ALTER TABLE trials DROP COLUMN {col}")
    c.execute("PRAGMA user_version = 1")
    c.commit()
    c.execute("VACUUM")
    c.close()


def test_a_version_1_study_reports_as_it_is_and_continues_after_a_backup(tmp_path: Path) -> None:
    db, proto = tmp_path / "old.db", short_toml(tmp_path)
    assert run("run", "--participants", "1", "--seed", "2", "--db", str(db), "--protocol", str(proto)).returncode == 0
    _as_version_1(db)
    v1 = db.read_bytes()
    report = run("report", "--db", str(db), "--out", str(tmp_path / "rep"))
    assert report.returncode == 0, report.stderr
    assert db.read_bytes() == v1  # read as it is
    page = (tmp_path / "rep" / "report.html").read_text()
    assert "No trial carries a loop-health record (databases of schema version 1)" in page
    more = run("run", "--participants", "2", "--seed", "2", "--db", str(db), "--protocol", str(proto), "--continue")
    assert more.returncode == 0, more.stderr
    (backup,) = tmp_path.glob("old.v1-backup-*.db")
    assert backup.read_bytes() == v1 or rows(backup, "PRAGMA user_version") == [(1,)]
    assert f"upgraded from schema version 1 to {SCHEMA_VERSION}; the file as it was is kept in {backup}" in more.stderr
    assert rows(db, "PRAGMA user_version") == [(SCHEMA_VERSION,)]
    assert rows(db, "SELECT p.code, s.status FROM sessions s JOIN participants p USING (participant_id) "
                    "ORDER BY p.code") == [("P01", "completed"), ("P02", "completed")]
