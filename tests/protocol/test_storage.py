"""Tests of the study database and the Recorder: schema, refusals, round trip, commit rules.

Every database lives in ``tmp_path``.  The Recorder's commit deadline runs on an injected fake
clock, so no test waits on the wall clock; a second connection plays the analysis reader.
"""

from __future__ import annotations

import json
import os
import sqlite3
import stat
from pathlib import Path

import pytest

from protocol.metrics import stored
from protocol.storage import (
    SAMPLE_COLUMNS,
    SCHEMA_VERSION,
    Recorder,
    SessionInfo,
    StorageError,
    StudyDatabase,
    connect_readonly,
    schema_path,
    trial_id_of,
    validate_code,
)
from protocol.study.config import default_protocol
from protocol.study.design import build_schedule, schedule_to_json
from protocol.study.records import TrialRecord
from protocol.tasks.force_regulation import ForceRegulation

COLUMNS = {
    "participants": ["participant_id", "code", "created_at"],
    "sessions": [
        "session_id", "participant_id", "kind", "seed", "participant_number", "protocol_json", "schedule_json",
        "status", "started_at", "ended_at", "end_reason", "software_version", "rig", "config_json", "calibration_json",
        "software_commit", "software_dirty",
    ],
    "trials": [
        "trial_id", "session_id", "trial_index", "target_label", "target_force_n", "haptic_mode", "outcome",
        "started_at_s", "ended_at_s", "tct_s", "rmse_n", "max_ae_n", "time_in_band_s", "peak_force_n", "n_samples",
        "abort_reason", "repeat_of", "abort_cause", "period_p50_ms", "period_p99_ms", "period_max_ms",
        "periods_over_2ms", "sensor_age_max_ms", "pose_age_max_ms", "latency_p50_ms", "latency_max_ms",
        "segment", "first_tick", "last_tick",
    ],
    "samples": [
        "trial_id", "t_s", "force_n", "raw_fx", "raw_fy", "raw_fz", "raw_tx", "raw_ty", "raw_tz",
        "comp_fx", "comp_fy", "comp_fz", "render_fx", "render_fy", "render_fz",
    ],
    "events": ["session_id", "t_s", "kind", "detail"],
    "leases": ["scope", "owner", "pid", "host", "process_start", "command", "acquired_at", "heartbeat_at"],
    "recordings": ["session_id", "segment", "started_at_s", "t0_ns", "snapshot_json", "scales_json", "n_blocks"],
    "session_blocks": ["session_id", "segment", "block", "first_tick", "last_tick", "n_records", "t_first_s",
                       "t_last_s", "data", "crc32"],
    "session_chunks": ["session_id", "segment", "block", "chunk", "first_tick", "last_tick", "n_records", "t_first_s",
                       "t_last_s", "data", "crc32"],
    "withdrawals": ["code", "withdrawn_at", "reason", "removed_sessions", "removed_trials", "removed_events",
                    "removed_blocks", "removed_records", "removed_samples", "rewritten",
                    "removed_lsl_streams", "removed_lsl_chunks"],
    "arm_recordings": ["session_id", "arm", "segment", "started_at_s", "t0_ns", "snapshot_json", "scales_json",
                       "n_blocks"],
    "arm_blocks": ["session_id", "arm", "segment", "block", "first_tick", "last_tick", "n_records", "t_first_s",
                   "t_last_s", "data", "crc32"],
    "arm_chunks": ["session_id", "arm", "segment", "block", "chunk", "first_tick", "last_tick", "n_records",
                   "t_first_s", "t_last_s", "data", "crc32"],
    "covariates": ["participant_id", "name", "kind", "value"],
    "notes": ["session_id", "t_s", "trial_index", "text", "deviation", "written_at"],
    "questionnaire_answers": ["session_id", "questionnaire", "block", "item", "rating", "choice", "answered_at_s"],
}


class FakeClock:
    """A monotonic clock the test advances by hand, s."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def _session_args(code: str = "P01", kind: str = "experiment", seed: int = 7) -> dict:
    p = default_protocol()
    return dict(
        code=code, kind=kind, seed=seed, participant_number=1, protocol_json=p.to_json(),
        schedule_json=schedule_to_json(build_schedule(p, seed=seed, participant_number=1)),
        software_version="0.1.0+test", rig="sim", config={"f_max_n": 4.0, "rate_hz": 1000},
        calibration={"bias": [0.1, -0.2, 0.3]},
    )


def _sample_row(trial_id: int, k: int) -> tuple:
    return (trial_id, k / 1000, 0.5 + k / 10000, *tuple(float(k + j) for j in range(12)))


def _trial_row(session_id: int, index: int, outcome: str = "success", tct_s: float | None = 1.5) -> dict:
    return {
        "trial_id": trial_id_of(session_id, index), "session_id": session_id, "trial_index": index,
        "target_label": "GENTLE", "target_force_n": 0.6, "haptic_mode": "on", "outcome": outcome,
        "started_at_s": 10.25, "ended_at_s": 11.75,
        # every stored metric of the paper's task (those named below, and any other)
        **dict.fromkeys((m.name for m in stored(ForceRegulation().metrics)), 0.25),
        "tct_s": tct_s, "rmse_n": 0.125, "max_ae_n": 0.5,
        "time_in_band_s": 1.001, "peak_force_n": 0.66, "n_samples": 1501, "abort_reason": None, "repeat_of": None,
        "abort_cause": None, "period_p50_ms": 1.0, "period_p99_ms": 1.004, "period_max_ms": 1.25,
        "periods_over_2ms": 0, "sensor_age_max_ms": 1.0, "pose_age_max_ms": 8.0, "latency_p50_ms": 0.5,
        "latency_max_ms": 1.125, "segment": None, "first_tick": None, "last_tick": None,
    }


def _count(path: Path, table: str) -> int:
    """Rows visible to another connection (the analysis reader)."""
    with sqlite3.connect(path) as other:
        return other.execute(f"SELECT COUNT(*) FROM {table}").fetchone()[0]


@pytest.fixture
def db_path(tmp_path) -> Path:
    return tmp_path / "study.db"


@pytest.fixture
def db(db_path):
    d = StudyDatabase(db_path)
    yield d
    d.close()


# -- a new database -------------------------------------------------------------------------------
def test_new_database_gets_the_schema(db, db_path):
    other = sqlite3.connect(db_path)
    try:
        tables = {r[0] for r in other.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        assert tables == set(COLUMNS)
        for table, columns in COLUMNS.items():
            # (the trials table: the schema's columns; a metric defined after them is added by a session of a task
            # that produces it, protocol.storage.schema.add_metric_columns)
            assert [r[1] for r in other.execute(f"PRAGMA table_info({table})")] == columns
        assert other.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert other.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION == 4
        named = other.execute("SELECT name FROM sqlite_master WHERE type = 'index' AND sql IS NOT NULL")
        indexes = {r[0] for r in named}
        assert indexes == {"samples_by_trial", "events_by_session"}
    finally:
        other.close()
    assert list(SAMPLE_COLUMNS) == COLUMNS["samples"]
    assert db.conn.execute("PRAGMA foreign_keys").fetchone()[0] == 1


def test_reopening_keeps_the_data(db_path):
    d = StudyDatabase(db_path)
    sid = d.create_session(**_session_args())
    d.close()
    again = StudyDatabase(db_path)
    try:
        assert [s.session_id for s in again.sessions_of("P01")] == [sid]
        assert again.conn.execute("PRAGMA user_version").fetchone()[0] == 4
    finally:
        again.close()
    ro = StudyDatabase(db_path, readonly=True)
    try:
        assert [s.session_id for s in ro.sessions_of("P01")] == [sid]
        with pytest.raises(sqlite3.OperationalError, match="readonly"):
            ro.conn.execute("INSERT INTO participants (code, created_at) VALUES ('X', 'now')")
    finally:
        ro.close()


def test_an_empty_file_becomes_a_database(db_path):
    db_path.write_bytes(b"")
    d = StudyDatabase(db_path)
    d.close()
    assert _count(db_path, "sessions") == 0


# -- refusals -------------------------------------------------------------------------------------
def test_newer_schema_is_refused(db_path):
    with sqlite3.connect(db_path) as c:
        c.execute("PRAGMA user_version = 5")
        c.execute("CREATE TABLE participants (participant_id INTEGER PRIMARY KEY)")
    c.close()
    before = db_path.read_bytes()
    with pytest.raises(StorageError) as info:
        StudyDatabase(db_path)
    msg = str(info.value)
    assert str(db_path) in msg
    assert "version 5 is newer than this software supports (4)" in msg
    assert db_path.read_bytes() == before


def test_a_file_that_is_not_a_database_is_refused(db_path):
    junk = bytes((i * 37 + 11) % 256 for i in range(4096))  # arbitrary, fixed bytes
    db_path.write_bytes(junk)
    with pytest.raises(StorageError) as info:
        StudyDatabase(db_path)
    assert str(info.value).startswith(f"{db_path}: not a haptic-study database")
    assert db_path.read_bytes() == junk


def test_another_applications_database_is_refused(db_path):
    with sqlite3.connect(db_path) as c:
        c.execute("CREATE TABLE invoices (id INTEGER PRIMARY KEY, total REAL)")
        c.execute("INSERT INTO invoices VALUES (1, 9.5)")
    c.close()
    with pytest.raises(StorageError) as info:
        StudyDatabase(db_path)
    assert str(info.value) == f"{db_path}: not a haptic-study database (it has other tables: invoices)"
    with sqlite3.connect(db_path) as c:
        assert [r[0] for r in c.execute("SELECT name FROM sqlite_master")] == ["invoices"]
        assert c.execute("PRAGMA user_version").fetchone()[0] == 0
    c.close()


def test_a_versioned_database_without_our_tables_is_refused(db_path):
    with sqlite3.connect(db_path) as c:
        c.execute("PRAGMA user_version = 1")
        c.execute("CREATE TABLE participants (participant_id INTEGER PRIMARY KEY)")
    c.close()
    with pytest.raises(StorageError, match="not a haptic-study database"):
        StudyDatabase(db_path)


def test_a_path_in_a_missing_folder_is_refused_and_nothing_is_created(tmp_path):
    path = tmp_path / "no_such_folder" / "study.db"
    with pytest.raises(StorageError) as info:
        StudyDatabase(path)
    assert str(path) in str(info.value)
    assert "does not exist" in str(info.value)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0,
                    reason="needs a POSIX user that folder permissions apply to")
def test_a_read_only_folder_is_refused_and_nothing_is_created(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(stat.S_IRUSR | stat.S_IXUSR)
    try:
        path = folder / "study.db"
        with pytest.raises(StorageError) as info:
            StudyDatabase(path)
        assert str(path) in str(info.value)
        assert "not writable" in str(info.value)
        assert list(folder.iterdir()) == []
    finally:
        folder.chmod(stat.S_IRWXU)


def test_a_folder_reported_read_only_is_refused_and_nothing_is_created(tmp_path, monkeypatch):
    # the same refusal where permissions cannot be dropped (e.g. running as root): the OS says "not writable"
    folder = tmp_path / "ro"
    folder.mkdir()
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: False if Path(p) == folder else real_access(p, mode, **kw))
    path = folder / "study.db"
    with pytest.raises(StorageError) as info:
        StudyDatabase(path)
    assert str(info.value) == f"{path}: cannot create the database here (folder {folder} is not writable)"
    assert list(folder.iterdir()) == []


def test_a_folder_as_the_database_path_is_refused(tmp_path):
    with pytest.raises(StorageError, match="is a directory"):
        StudyDatabase(tmp_path)


def test_readonly_open_of_a_missing_database_creates_nothing(tmp_path):
    path = tmp_path / "absent.db"
    with pytest.raises(StorageError, match="no such database"):
        StudyDatabase(path, readonly=True)
    assert list(tmp_path.iterdir()) == []


# -- participant codes ----------------------------------------------------------------------------
@pytest.mark.parametrize("code", ["P01", "a_b-9", "X", "Z" * 32])
def test_valid_codes(code):
    assert validate_code(code) == code


def test_a_code_is_normalised_before_it_is_checked():
    # a pasted code's line end and spaces go, and a full-width P01 reads as P01 (protocol.storage.codes)
    assert validate_code("P01\n") == validate_code(" Ｐ０１ ") == "P01"


@pytest.mark.parametrize("code", ["", "Q" * 33, "P 01", "P01;DROP", "P0\n1", "Pé", None, 1])
def test_invalid_codes_are_refused(code):
    with pytest.raises(StorageError) as info:
        validate_code(code)
    assert str(info.value) == (
        f"participant code = {code!r}: must be 1–32 characters from A–Z, a–z, 0–9, '_' and '-'"
    )


def test_invalid_code_is_refused_before_anything_is_written(db, db_path):
    args = _session_args(code="P01;DROP")
    with pytest.raises(StorageError, match="participant code"):
        db.create_session(**args)
    assert _count(db_path, "participants") == 0
    assert _count(db_path, "sessions") == 0


# -- sessions -------------------------------------------------------------------------------------
def test_create_session_stores_schedule_and_provenance(db, db_path):
    args = _session_args()
    sid = db.create_session(**args)
    # committed before trial 1: another connection sees it
    assert _count(db_path, "sessions") == 1
    (info,) = db.sessions_of("P01")
    assert info == SessionInfo(
        session_id=sid, participant_id=info.participant_id, code="P01", kind="experiment", seed=7,
        participant_number=1, protocol_json=args["protocol_json"], schedule_json=args["schedule_json"],
        status="running", started_at=info.started_at, calibration_json=json.dumps(args["calibration"]),
        config_json=json.dumps(args["config"], sort_keys=True),
    )
    assert info.participant_id == db.participant_id("P01", create=False)
    assert db.open_sessions() == [info]
    assert db.sessions_of("P01", "training") == []


def test_a_second_session_of_the_same_kind_is_refused_and_the_first_is_untouched(db, db_path):
    sid = db.create_session(**_session_args())
    with sqlite3.connect(db_path) as c:
        before = c.execute("SELECT * FROM sessions").fetchall()
    c.close()
    with pytest.raises(StorageError) as info:
        db.create_session(**_session_args(seed=99))
    msg = str(info.value)
    assert f"session {sid}" in msg
    assert "participant P01 already has an experiment session" in msg
    assert "--resume P01" in msg  # it is still running: resume it
    with sqlite3.connect(db_path) as c:
        assert c.execute("SELECT * FROM sessions").fetchall() == before
        assert c.execute("SELECT COUNT(*) FROM participants").fetchone()[0] == 1
    c.close()


def test_a_second_session_of_one_being_run_names_the_process_running_it(db):
    from protocol.storage.leases import new_owner_token

    sid = db.create_session(**_session_args(), lease_owner=new_owner_token(), command="haptic-study gui")
    with pytest.raises(StorageError) as info:
        db.create_session(**_session_args())
    msg = str(info.value)
    assert f"session {sid}, status running" in msg
    assert f"it is being run right now by process {os.getpid()} (haptic-study gui)" in msg
    assert "--resume" not in msg  # not interrupted: nothing to resume


def test_a_second_session_after_the_end_asks_for_a_new_code(db):
    sid = db.create_session(**_session_args())
    db.end_session(sid, "completed", "all trials done")
    with pytest.raises(StorageError, match=f"session {sid}, status completed.*use a new participant code"):
        db.create_session(**_session_args())


def test_training_and_experiment_sessions_coexist(db):
    a = db.create_session(**_session_args(kind="training"))
    b = db.create_session(**_session_args(kind="experiment"))
    assert [s.session_id for s in db.sessions_of("P01")] == [a, b]
    assert [s.kind for s in db.sessions_of("P01")] == ["training", "experiment"]
    with pytest.raises(StorageError, match="already has a training session"):
        db.create_session(**_session_args(kind="training"))


def test_end_session_only_once(db, db_path):
    sid = db.create_session(**_session_args())
    db.end_session(sid, "aborted", "participant left")
    with sqlite3.connect(db_path) as c:
        first = c.execute("SELECT status, ended_at, end_reason FROM sessions").fetchone()
    c.close()
    assert (first[0], first[2]) == ("aborted", "participant left")
    assert first[1] is not None
    with pytest.raises(StorageError, match=f"session {sid} is not running; its end is already recorded"):
        db.end_session(sid, "completed", "again")
    with sqlite3.connect(db_path) as c:
        assert c.execute("SELECT status, ended_at, end_reason FROM sessions").fetchone() == first
    c.close()
    assert db.open_sessions() == []


def test_end_session_of_an_unknown_session_is_refused(db):
    with pytest.raises(StorageError, match="session 42 is not running"):
        db.end_session(42, "completed")


def test_update_schedule(db):
    sid = db.create_session(**_session_args())
    db.update_schedule(sid, "[]")
    assert db.sessions_of("P01")[0].schedule_json == "[]"


# -- round trip -----------------------------------------------------------------------------------
def test_round_trip_of_a_session(db, db_path):
    sid = db.create_session(**_session_args())
    samples = [_sample_row(trial_id_of(sid, i), k) for i in range(3) for k in range(50)]
    trials = [
        _trial_row(sid, 0),
        _trial_row(sid, 1, outcome="timeout", tct_s=None),
        {**_trial_row(sid, 2, outcome="aborted", tct_s=None), "abort_reason": "probe slipped",
         "abort_cause": "experimenter"},
        {**_trial_row(sid, 3), "repeat_of": 2},
    ]
    events = [(sid, 0.5, "cue", "trial 0: GENTLE 0.6 N, haptics on"), (sid, 1.25, "phase", "trial 0: cued -> active")]
    with db.transaction():
        db.insert_samples(samples)
        for row in trials:
            db.insert_trial(row)
        for ev in events:
            db.insert_event(*ev)
    assert db.trial_rows(sid) == trials
    assert db.last_session_time_s(sid) == 11.75
    reader = StudyDatabase(db_path, readonly=True)
    try:
        assert reader.trial_rows(sid) == trials
        got = reader.conn.execute(f"SELECT {', '.join(SAMPLE_COLUMNS)} FROM samples ORDER BY rowid").fetchall()
        assert got == samples
        assert reader.conn.execute("SELECT * FROM events ORDER BY rowid").fetchall() == events
    finally:
        reader.close()


def test_trial_index_is_unique_per_session(db):
    sid = db.create_session(**_session_args())
    db.insert_trial(_trial_row(sid, 0))
    with pytest.raises(sqlite3.IntegrityError):
        db.insert_trial({**_trial_row(sid, 0), "trial_id": trial_id_of(sid, 0) + 500_000})


@pytest.mark.parametrize("outcome", ["timeout", "aborted"])
def test_tct_only_for_successful_trials(db, db_path, outcome):
    sid = db.create_session(**_session_args())
    with pytest.raises(sqlite3.IntegrityError, match="CHECK constraint failed"):
        db.insert_trial(_trial_row(sid, 0, outcome=outcome, tct_s=5.0))
    assert _count(db_path, "trials") == 0


@pytest.mark.parametrize(("column", "value"), [("outcome", "failure"), ("haptic_mode", "ON")])
def test_trial_enumerations_are_checked(db, column, value):
    sid = db.create_session(**_session_args())
    with pytest.raises(sqlite3.IntegrityError, match="CHECK constraint failed"):
        db.insert_trial({**_trial_row(sid, 0), column: value})


def test_trial_of_an_unknown_session_is_refused(db):
    with pytest.raises(sqlite3.IntegrityError, match="FOREIGN KEY"):
        db.insert_trial(_trial_row(99, 0))


def test_trial_id_of():
    assert trial_id_of(3, 17) == 3_000_017


# -- Recorder, inline -----------------------------------------------------------------------------
def test_inline_samples_wait_for_the_deadline(db, db_path):
    sid = db.create_session(**_session_args())
    tid = trial_id_of(sid, 0)
    clock = FakeClock()
    rec = Recorder(db, threaded=False, clock=clock)
    rec.samples([_sample_row(tid, k) for k in range(10)])
    assert _count(db_path, "samples") == 0
    clock.now = 0.05
    rec.samples([_sample_row(tid, k) for k in range(10, 20)])
    rec.event(sid, 0.05, "phase", "trial 0: cued -> active")
    clock.now = 0.0999
    rec.samples([_sample_row(tid, k) for k in range(20, 30)])
    assert _count(db_path, "samples") == 0
    assert _count(db_path, "events") == 0
    # 100 ms after the first uncommitted batch: the next call commits everything
    clock.now = 0.1
    rec.samples([_sample_row(tid, k) for k in range(30, 40)])
    assert _count(db_path, "samples") == 40
    assert _count(db_path, "events") == 1
    # the deadline restarts with the next batch
    clock.now = 0.15
    rec.samples([_sample_row(tid, k) for k in range(40, 50)])
    clock.now = 0.2499
    rec.samples([])
    assert _count(db_path, "samples") == 40
    clock.now = 0.25
    rec.samples([])
    assert _count(db_path, "samples") == 50
    rec.close()


def test_inline_deadline_follows_max_latency(db, db_path):
    sid = db.create_session(**_session_args())
    clock = FakeClock()
    rec = Recorder(db, threaded=False, clock=clock, max_latency_s=0.5)
    rec.samples([_sample_row(trial_id_of(sid, 0), 0)])
    clock.now = 0.25
    rec.samples([])
    assert _count(db_path, "samples") == 0
    clock.now = 0.5
    rec.samples([])
    assert _count(db_path, "samples") == 1
    rec.close()


def test_inline_trial_summary_commits_at_once_with_the_samples_before_it(db, db_path):
    sid = db.create_session(**_session_args())
    clock = FakeClock()
    rec = Recorder(db, threaded=False, clock=clock)
    rec.samples([_sample_row(trial_id_of(sid, 0), k) for k in range(25)])
    rec.event(sid, 11.75, "phase", "trial 0: active -> pause")
    assert (_count(db_path, "samples"), _count(db_path, "trials")) == (0, 0)
    clock.now = 0.01  # well before the deadline
    rec.trial(TrialRecord.from_row(_trial_row(sid, 0)))
    assert (_count(db_path, "samples"), _count(db_path, "trials"), _count(db_path, "events")) == (25, 1, 1)
    rec.close()


def test_inline_call_commits_at_once(db, db_path):
    sid = db.create_session(**_session_args())
    rec = Recorder(db, threaded=False, clock=FakeClock())
    rec.call(lambda d: d.end_session(sid, "completed", "all trials done"))
    with sqlite3.connect(db_path) as c:
        assert c.execute("SELECT status FROM sessions").fetchone() == ("completed",)
    c.close()
    rec.close()


def test_inline_flush_and_close_commit_pending_work(db, db_path):
    sid = db.create_session(**_session_args())
    rec = Recorder(db, threaded=False, clock=FakeClock())
    rec.samples([_sample_row(trial_id_of(sid, 0), 0)])
    assert _count(db_path, "samples") == 0
    rec.flush()
    assert _count(db_path, "samples") == 1
    rec.samples([_sample_row(trial_id_of(sid, 0), 1)])
    rec.close()
    assert _count(db_path, "samples") == 2


# -- Recorder, threaded ---------------------------------------------------------------------------
def test_threaded_flush_makes_everything_visible(db, db_path):
    sid = db.create_session(**_session_args())
    rec = Recorder(db, clock=FakeClock())
    try:
        for b in range(5):
            rec.samples([_sample_row(trial_id_of(sid, 0), 10 * b + k) for k in range(10)])
        rec.event(sid, 0.5, "phase", "trial 0: cued -> active")
        rec.trial(TrialRecord.from_row(_trial_row(sid, 0)))
        rec.samples([_sample_row(trial_id_of(sid, 1), 0)])
        rec.flush()
        assert (_count(db_path, "samples"), _count(db_path, "events"), _count(db_path, "trials")) == (51, 1, 1)
        # flush returns only after the commit, every time (the writer must not wake the caller first);
        # a reader that is already open checks at once, leaving a premature return no time to hide
        reader = sqlite3.connect(db_path)
        try:
            for k in range(1, 101):
                rec.samples([_sample_row(trial_id_of(sid, 1), k)])
                rec.flush()
                assert reader.execute("SELECT COUNT(*) FROM samples").fetchone()[0] == 51 + k
        finally:
            reader.close()
    finally:
        rec.close()


def test_threaded_close_commits_pending_work_and_stops_the_thread(db, db_path):
    sid = db.create_session(**_session_args())
    rec = Recorder(db, clock=FakeClock())
    thread = rec._thread
    rec.samples([_sample_row(trial_id_of(sid, 0), k) for k in range(30)])
    rec.event(sid, 0.5, "cue", "trial 0")
    rec.close()
    assert not thread.is_alive()
    assert (_count(db_path, "samples"), _count(db_path, "events")) == (30, 1)


def test_threaded_writer_error_reaches_the_producer(db, db_path):
    sid = db.create_session(**_session_args())
    rec = Recorder(db, clock=FakeClock())
    # a timeout with a TCT: the record allows it, the CHECK in the writer does not
    rec.trial(TrialRecord.from_row(_trial_row(sid, 0, outcome="timeout", tct_s=5.0)))
    with pytest.raises(StorageError, match="the recorder stopped"):
        rec.flush()
    with pytest.raises(StorageError, match="the recorder stopped after an error: CHECK constraint failed"):
        rec.samples([_sample_row(trial_id_of(sid, 0), 0)])
    with pytest.raises(StorageError, match="the recorder failed"):
        rec.close()
    assert _count(db_path, "trials") == 0


def test_samples_given_as_one_float_array_are_stored_like_rows(db):
    # the live session runner hands the recorder one 2-D array per block (no per-row lists to collect)
    import numpy as np

    sid = db.create_session(**_session_args())
    rows = [_sample_row(trial_id_of(sid, 0), k) for k in range(20)]
    with db.transaction():
        db.insert_samples(np.array(rows[:10], dtype=np.float64))
        db.insert_samples(rows[10:])
        db.insert_samples(np.empty((0, len(SAMPLE_COLUMNS))))
    got = db.conn.execute(f"SELECT {', '.join(SAMPLE_COLUMNS)} FROM samples ORDER BY rowid").fetchall()
    assert got == rows
    assert {type(v) for r in got for v in r} == {int, float}  # trial_id stays an integer key


def _listing(folder: Path) -> dict[str, tuple[int, bytes]]:
    return {p.name: (p.stat().st_mode, p.read_bytes()) for p in sorted(folder.iterdir())}


def test_a_file_and_folder_without_write_bits_are_not_written_even_by_root(tmp_path):
    """``chmod a-w`` on an archived study was no refusal for root (os.access allows root everything): ``withdraw``
    removed a participant from a 0444 file in a 0555 folder, ``run --continue`` added one, and every reader left
    -wal and -shm files beside it.  The mode is the owner's word, and in a container everyone is root."""
    from foundation.platform_support.files import may_write

    folder = tmp_path / "archive"
    folder.mkdir()
    path = folder / "study.db"
    StudyDatabase(path).close()
    for extra in folder.glob("study.db-*"):
        extra.unlink()
    path.chmod(0o444)
    folder.chmod(0o555)
    try:
        before = _listing(folder)
        assert not may_write(path) and not may_write(folder, os.W_OK | os.X_OK)
        with pytest.raises(StorageError) as info:
            StudyDatabase(path)
        assert str(info.value) == f"{path}: the database is not writable (open it read-only, e.g. with report)"
        conn = connect_readonly(path)  # an archive: read immutable, nothing made beside it
        try:
            assert conn.execute("PRAGMA user_version").fetchone()[0] > 0
        finally:
            conn.close()
        assert _listing(folder) == before
    finally:
        folder.chmod(0o755)
        path.chmod(0o644)
    assert may_write(path) and may_write(folder, os.W_OK | os.X_OK)


def test_a_file_from_before_the_participant_screen_cause_is_widened_by_a_writer(tmp_path):
    """Issue 40, item 1: a trial aborted because the participant screen closed is stored with its own cause; a file
    made before that cause existed lists the older causes in its CHECK and is widened by the first writer (no row
    changes; a reader leaves it as it is)."""
    from protocol.storage.schema import _CAUSES_BEFORE, _CAUSES_NOW

    path = tmp_path / "before.db"
    c = sqlite3.connect(path)  # a version-4 file as the schema made it before the cause was added
    c.executescript(schema_path().read_text(encoding="utf-8").replace(_CAUSES_NOW, _CAUSES_BEFORE)
                    + "\nPRAGMA user_version = 4;")
    c.close()
    row = {**_trial_row(1, 0, outcome="aborted", tct_s=None), "abort_cause": "participant_screen",
           "abort_reason": "the participant screen was closed during the trial"}
    r = StudyDatabase(path, readonly=True)
    r.close()
    assert _CAUSES_BEFORE in sqlite3.connect(path).execute("SELECT sql FROM sqlite_master WHERE name = 'trials'"
                                                           ).fetchone()[0]  # a reader changes nothing
    db = StudyDatabase(path)
    try:
        sid = db.create_session(**_session_args())
        db.insert_trial({**row, "trial_id": trial_id_of(sid, 0), "session_id": sid})
        assert db.conn.execute("SELECT abort_cause FROM trials").fetchall() == [("participant_screen",)]
        assert db.conn.execute("PRAGMA integrity_check").fetchone() == ("ok",)
        with pytest.raises(sqlite3.IntegrityError):  # the CHECK still holds for anything else
            db.insert_trial({**row, "trial_id": trial_id_of(sid, 1), "session_id": sid, "trial_index": 1,
                             "abort_cause": "bored"})
    finally:
        db.close()
