"""The task arm: the protocol names it, a study on the two-arm simulated rig runs on it and recomputes clean, the
other arm's events are stored with its name and do not stand for the trial's fault."""

from __future__ import annotations

import dataclasses
import json
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from analysis.reading.load import load_study
from analysis.reading.metrics import compute_trials
from pipeline.runtime.loop_messages import LoopEvent
from protocol.runner.session import SessionRunner
from protocol.runner.session_desk import SessionPlan
from protocol.storage.audit import audit_database
from protocol.study.config import ProtocolError, default_protocol, protocol_from_dict
from protocol.study.design import build_schedule
from study_app.headless import run_study


def short_protocol(task_arm: str = "") -> object:
    p = default_protocol()
    return dataclasses.replace(p, trials_per_cell=1, training=dataclasses.replace(p.training, enabled=False),
                               task_arm=task_arm)


def test_task_arm_is_validated_stored_only_when_named_and_resolved_against_the_rig() -> None:
    base = default_protocol().to_dict()
    assert "task_arm" not in base["design"]  # a protocol of before the arms stores what it always stored
    named = protocol_from_dict({**base, "design": {**base["design"], "task_arm": "left"}})
    assert named.task_arm == "left" and named.to_dict()["design"]["task_arm"] == "left"
    assert protocol_from_dict(named.to_dict()) == named
    with pytest.raises(ProtocolError, match=r"design\.task_arm = '2nd'"):
        protocol_from_dict({**base, "design": {**base["design"], "task_arm": "2nd"}})
    p = default_protocol()
    assert p.task_arm_of(("tool",)) == "tool"  # the only arm
    assert p.task_arm_of(("left", "right")) == "right"  # the default of two
    with pytest.raises(ProtocolError, match="none called 'right'"):
        p.task_arm_of(("left", "centre"))
    with pytest.raises(ProtocolError, match=r"'left': the rig has no such arm \(its arms: right\)"):
        named.task_arm_of(("right",))


def test_a_study_whose_task_arm_is_left_runs_on_the_left_arm_and_recomputes_clean(tmp_path: Path) -> None:
    db = tmp_path / "left.db"
    proto = short_protocol("left")
    run_study(str(db), participants=1, seed=5, protocol=proto, jobs=1, sim_arms=("right", "left"))
    conn = sqlite3.connect(db)
    try:
        (cfg,), = conn.execute("SELECT config_json FROM sessions").fetchall()
        arms = json.loads(cfg)["arms"]
        assert arms["names"] == ["left", "right"] and set(arms["calibrations"]) == {"left", "right"}
        audit = audit_database(conn, str(db))
        assert audit.problems == [] and audit.trials_in_recording == 4
    finally:
        conn.close()
    table = compute_trials(load_study([db]), workers=1)
    assert table.n_disagree == 0 and table.n_from_samples == 4
    # the participant presses on the left arm; the right arm's stylus is held still (no contact), so a trial
    # computed from its records would never reach the targets' forces
    assert table.trials["peak_force_n"].max() > 0.5


def _runner(arms: tuple[str, ...]) -> tuple[SessionRunner, list[tuple[str, str]]]:
    stored: list[tuple[str, str]] = []

    class Recorder:
        def event(self, session_id: int, t_s: float, kind: str, detail: str | None) -> None:
            stored.append((kind, detail or ""))

    proto = short_protocol("left")
    plan = SessionPlan(session_id=1, protocol=proto, schedule=build_schedule(proto, 1, 1), arms=arms)  # type: ignore[arg-type]
    runner = SessionRunner(plan, Recorder(), lambda cmd: None)  # type: ignore[arg-type]
    return runner, stored


def test_another_arms_fault_is_stored_with_its_arm_and_does_not_name_the_task_trials_fault() -> None:
    runner, stored = _runner(("left", "right"))
    runner.faults.store(LoopEvent(5, "fault", 64, "NON_FINITE: force x = nan", "right"))
    runner.faults.store(LoopEvent(6, "fault", 512, "OTHER_ARM: arm right faulted", "left"))
    assert stored == [("fault", "arm right: NON_FINITE: force x = nan"),
                      ("fault", "arm left: OTHER_ARM: arm right faulted")]
    assert runner.faults.detail == "OTHER_ARM: arm right faulted"  # the task arm's own fault names the trial's


def test_a_one_arm_rig_stores_its_events_as_before() -> None:
    runner, stored = _runner(("left",))
    runner.faults.store(LoopEvent(5, "fault", 64, "NON_FINITE: force x = nan", "left"))
    assert stored == [("fault", "NON_FINITE: force x = nan")]


def test_the_other_arm_is_recorded_beside_the_task_arm_read_by_name_and_checked(tmp_path: Path) -> None:
    from protocol.storage import StudyReader
    from protocol.storage.recordings import read_segment

    db = tmp_path / "two.db"
    run_study(str(db), participants=1, seed=5, protocol=short_protocol("left"), jobs=1, sim_arms=("left", "right"))
    reader = StudyReader(db)
    try:
        assert reader.arms() == ["right"] and reader.arm_key(1, None) == "" and reader.arm_key(1, "left") == ""
        assert reader.arm_key(1, "right") == "right"
        with pytest.raises(KeyError, match=r"--arm centre: session 1 has no recorded arm .*left, the task arm, right"):
            reader.arm_key(1, "centre")
        task, other = read_segment(reader, 1, 0), read_segment(reader, 1, 0, arm="right")
        # the same ticks from the same snapshot on, on the same session clock; each arm's own force
        assert task.columns["tick"][0] == other.columns["tick"][0] and task.t0_ns == other.t0_ns
        n = min(len(task.columns["tick"]), len(other.columns["tick"]))
        assert abs(len(task.columns["tick"]) - len(other.columns["tick"])) < 100
        assert np.array_equal(task.columns["trial_index"][:n], other.columns["trial_index"][:n])  # the loop's marks
        assert task.columns["force_n"].max() > 0.5 > other.columns["force_n"].max()  # the held stylus never presses
        # the other arm replays through the pipeline bit for bit, as the task arm does
        from pipeline.force.replay import replay

        out = replay(other.replay_inputs())
        assert np.array_equal(out.force_n, other.columns["force_n"]) and other.columns["force_n"].max() > 0
        assert all(np.array_equal(out.column(f"render_{a}"), other.columns[f"render_{a}"]) for a in ("fx", "fy", "fz"))
        n_task = len(list(reader.blocks(1)))
        n_other = len(list(reader.blocks(1, arm="right")))
    finally:
        reader.close()
    conn = sqlite3.connect(db)
    try:
        audit = audit_database(conn, str(db))
        assert audit.problems == [] and audit.blocks_verified == n_task + n_other
    finally:
        conn.close()
    # a flipped bit in the other arm's recording is found by check, naming the arm
    conn = sqlite3.connect(db)
    conn.execute("UPDATE arm_blocks SET data = CAST(zeroblob(length(data)) AS BLOB) WHERE block = 3")
    conn.commit()
    try:
        problems = audit_database(conn, str(db)).problems
        assert len(problems) == 1 and problems[0].startswith("arm right, session 1, recorded run 0, block 3")
    finally:
        conn.close()


def test_a_crash_keeps_the_other_arms_committed_records_and_a_withdrawal_removes_them(tmp_path: Path) -> None:
    from test_storage import FakeClock, _session_args

    from protocol.recording import BLOCK_RECORDS, COLUMNS
    from protocol.storage import Recorder, StudyDatabase
    from protocol.storage.recordings import read_segment
    from protocol.storage.withdrawal import erase_participant, footprint

    def records(first: int, n: int) -> dict[str, np.ndarray]:
        tick = np.arange(first, first + n, dtype=np.int64)
        cols = {c.name: (tick.copy() if c.codec in ("int", "small") else np.sin(tick * 1e-3)) for c in COLUMNS}
        cols["t_ns"] = tick * 1_000_000
        return cols

    path = tmp_path / "crash.db"
    db = StudyDatabase(path)
    sid = db.create_session(**_session_args())
    clock = FakeClock()
    rec = Recorder(db, threaded=False, clock=clock)
    rec.segment(sid, 0, 0.0, 0, {"framework": {}}, {})
    rec.segment(sid, 0, 0.0, 0, {"framework": {}}, {}, arm="left")
    for k in range(0, 1540, 10):
        clock.now = k / 1000
        rec.records(sid, 0, records(k, 10))
        rec.records(sid, 0, records(k, 10), arm="left")
    other = sqlite3.connect(path)
    try:  # a crash now: the other arm's open block is in its chunks, joined by every reader
        task, left = read_segment(other, sid, 0), read_segment(other, sid, 0, arm="left")
        n = len(left.columns["tick"])  # (a commit may fall between the two arms' hand-overs of one block)
        assert n > BLOCK_RECORDS and np.array_equal(left.columns["tick"], np.arange(n))
        assert len(task.columns["tick"]) - 10 <= n <= len(task.columns["tick"])
        assert other.execute("SELECT COUNT(*) FROM arm_chunks").fetchone()[0] > 0
        fp = footprint(other, "P01")
        assert fp is not None and fp.records == n + len(task.columns["tick"]) and fp.segments == 1
    finally:
        other.close()
    db.conn.execute("ROLLBACK")
    erase_participant(db, "P01", "test")
    assert db.conn.execute("SELECT (SELECT COUNT(*) FROM arm_blocks) + (SELECT COUNT(*) FROM arm_chunks) + "
                           "(SELECT COUNT(*) FROM arm_recordings)").fetchone() == (0,)
    db.close()
