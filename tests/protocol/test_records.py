"""The typed trial record: one shape for the runner, the recorder, the GUI and analysis, stored as ever."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from protocol.storage import HEALTH_COLUMNS, StudyDatabase, trial_id_of
from protocol.study.clock import SessionClock
from protocol.study.config import default_protocol
from protocol.study.design import HapticMode, TrialSpec, build_schedule, schedule_to_json
from protocol.study.records import AbortCause, LoopHealth, Outcome, TrialRecord, trial_health
from protocol.tasks.force_regulation import trial_metrics

SPEC = TrialSpec(3, "FIRM", 1.2, "off", repeat_of=1)


def _metrics():
    t = np.arange(0, 4_000_000_001, 1_000_000, dtype=np.int64)
    return trial_metrics(t, np.full(len(t), 1.2), 1.2)


def _db(tmp_path: Path) -> tuple[StudyDatabase, int]:
    db = StudyDatabase(tmp_path / "s.db")
    p = default_protocol()
    sid = db.create_session(code="P01", kind="experiment", seed=1, participant_number=1, protocol_json=p.to_json(),
                            schedule_json=schedule_to_json(build_schedule(p, 1)), software_version="t", rig="sim",
                            config={}, calibration=None)
    return db, sid


def test_the_row_has_the_trials_columns_in_table_order(tmp_path: Path) -> None:
    db, sid = _db(tmp_path)
    rec = TrialRecord.finished(session_id=sid, spec=SPEC, outcome=Outcome.SUCCESS, clock=SessionClock(0.0, 0),
                               cue_ns=0, end_ns=1, metrics=_metrics())
    db.insert_trial(rec.to_row())  # (a metric after the schema file: the writer adds its column, the table's last)
    columns = [r[1] for r in db.conn.execute("PRAGMA table_info(trials)")]
    # (in the table's order but for a metric defined after the schema file: the table's last column, the row's
    # among the metrics)
    assert sorted(rec.to_row()) == sorted(columns)
    assert [f.name for f in dataclasses.fields(LoopHealth)] == list(HEALTH_COLUMNS)
    db.close()


def test_a_finished_record_stores_seconds_and_text_and_reads_back(tmp_path: Path) -> None:
    db, sid = _db(tmp_path)
    clock = SessionClock(2.5, 7_000_000_123)
    health = trial_health(np.full(3, 0.001), np.full(3, 0.0005), np.full(3, 0.008), np.full(3, 0.0002))
    rec = TrialRecord.finished(
        session_id=sid, spec=SPEC, outcome=Outcome.ABORTED, clock=clock, cue_ns=7_000_000_123 + 1_234_567_891,
        end_ns=7_000_000_123 + 3_000_000_000, metrics=_metrics(), reason="probe slipped", cause=AbortCause.GAP,
        health=health, segment=0, ticks=(1234, 4000),
    )
    row = rec.to_row()
    # the session clock is the recordings' formula; the enums are stored as plain TEXT
    # (ns to s: equal up to the last bit of that conversion, however the product orders its operations)
    assert row["started_at_s"] == pytest.approx(2.5 + 1_234_567_891 / 1e9, rel=1e-15)
    assert row["ended_at_s"] == pytest.approx(2.5 + 3.0, rel=1e-15)
    assert (row["trial_id"], row["haptic_mode"], row["outcome"], row["abort_cause"]) == (
        trial_id_of(sid, 3), "off", "aborted", "gap")
    assert all(type(row[k]) is str for k in ("haptic_mode", "outcome", "abort_cause"))
    assert row["tct_s"] is None and row["repeat_of"] == 1 and (row["first_tick"], row["last_tick"]) == (1234, 4000)
    db.insert_trial(row)
    (stored,) = db.trial_rows(sid)
    assert stored == row
    back = TrialRecord.from_row(stored)
    assert back.to_row() | {"ended_at_s": row["ended_at_s"]} == row
    assert back.ended_at_s == pytest.approx(row["ended_at_s"], abs=1e-9)  # (read back: the stored duration to the ns)
    assert back.haptic_mode is HapticMode.OFF and back.outcome is Outcome.ABORTED and back.abort_cause is AbortCause.GAP
    db.close()


def test_a_record_refuses_values_outside_its_vocabulary() -> None:
    base = dict(session_id=1, trial_index=0, target_label="FIRM", target_force_n=1.2, haptic_mode="on",
                outcome="success", clock=SessionClock(0.0, 0), cue_ns=0, end_ns=0)
    with pytest.raises(ValueError, match="'sucess' is not a valid Outcome"):
        TrialRecord(**{**base, "outcome": "sucess"})
    with pytest.raises(ValueError, match="'ON' is not a valid HapticMode"):
        TrialRecord(**{**base, "haptic_mode": "ON"})
    with pytest.raises(ValueError, match="'operator' is not a valid AbortCause"):
        TrialRecord(**{**base, "outcome": "aborted", "abort_cause": "operator"})
    assert TrialRecord(**base).outcome is Outcome.SUCCESS and TrialRecord(**base).success


def test_only_causes_of_the_loop_count_as_undelivered() -> None:
    assert {c for c in AbortCause if c.undelivered} == {AbortCause.FAULT, AbortCause.FEEDBACK, AbortCause.GAP}


def test_the_schedule_is_stored_with_the_same_text(tmp_path: Path) -> None:
    schedule = build_schedule(default_protocol(), 5)
    assert {type(s.haptic_mode) for s in schedule} == {HapticMode}
    text = schedule_to_json(schedule)
    assert '"haptic_mode": "on"' in text and '"haptic_mode": "off"' in text and "HapticMode" not in text


def test_the_session_clock_is_one_formula_for_scalars_and_arrays() -> None:
    clock = SessionClock(123.456, 10**12 + 7)
    t = np.array([10**12 + 7, 10**12 + 1_000_008, 10**12 + 987_654_321_000], dtype=np.int64)
    assert clock.seconds_of(t).tolist() == [clock.seconds(int(v)) for v in t]
    assert clock.seconds(10**12 + 7) == pytest.approx(123.456, rel=1e-15)  # the offset, up to a rounding
