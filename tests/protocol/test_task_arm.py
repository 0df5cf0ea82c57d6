"""The task arm: the protocol names it, a study on the two-arm simulated rig runs on it and recomputes clean, the
other arm's events are stored with its name and do not stand for the trial's fault."""

from __future__ import annotations

import dataclasses
import json
import sqlite3
from pathlib import Path

import pytest

from analysis.load import load_study
from analysis.metrics import compute_trials
from pipeline.runtime.loop_messages import LoopEvent
from protocol.audit import audit_database
from protocol.config import ProtocolError, default_protocol, protocol_from_dict
from protocol.design import build_schedule
from protocol.session import SessionRunner
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
    runner = SessionRunner(protocol=proto, schedule=build_schedule(proto, 1, 1), session_id=1,
                           recorder=Recorder(), submit=lambda cmd: None, arms=arms)  # type: ignore[arg-type]
    return runner, stored


def test_another_arms_fault_is_stored_with_its_arm_and_does_not_name_the_task_trials_fault() -> None:
    runner, stored = _runner(("left", "right"))
    runner._store_loop_event(LoopEvent(5, "fault", 64, "NON_FINITE: force x = nan", "right"))
    runner._store_loop_event(LoopEvent(6, "fault", 512, "OTHER_ARM: arm right faulted", "left"))
    assert stored == [("fault", "arm right: NON_FINITE: force x = nan"),
                      ("fault", "arm left: OTHER_ARM: arm right faulted")]
    assert runner._fault_detail == "OTHER_ARM: arm right faulted"  # the task arm's own fault names the trial's


def test_a_one_arm_rig_stores_its_events_as_before() -> None:
    runner, stored = _runner(("left",))
    runner._store_loop_event(LoopEvent(5, "fault", 64, "NON_FINITE: force x = nan", "left"))
    assert stored == [("fault", "NON_FINITE: force x = nan")]
