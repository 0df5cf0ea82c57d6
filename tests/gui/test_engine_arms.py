"""The study engine on a simulated rig of two arms: the task arm's session records every arm, as ``run``'s do."""

from __future__ import annotations

import json
import sqlite3

import pytest

from study_app.engine import messages as m
from study_app.engine.host import StudyEngine
from study_app.engine.setup import HostConfig
from tests.gui.conftest import SHORT_PROTOCOL


def _protocol(tmp_path, task_arm: str) -> str:
    p = tmp_path / f"task_{task_arm}.toml"
    p.write_text(SHORT_PROTOCOL.replace("[design]\n", f"[design]\ntask_arm = \"{task_arm}\"\n"), encoding="utf-8")
    return str(p)


@pytest.fixture
def two_arms():
    events: list[object] = []
    e = StudyEngine(HostConfig(clock="virtual", speed=0, sim_arms=("left", "right")), events.append,
                    shared_ring=False)
    e.start()
    yield e, events
    if not e.closed:
        e.close("test over")
    e.release_ring()


def test_a_gui_session_on_two_arms_records_both(two_arms, tmp_path):
    e, events = two_arms
    db = str(tmp_path / "s.db")
    e.handle(m.StartSession(db, "P01", "experiment", _protocol(tmp_path, "left"), 3, 1))
    assert [ev for ev in events if isinstance(ev, m.CommandRefused)] == []
    for _ in range(20_000):
        if e.runner is None:
            break
        e.step()
    assert e.runner is None
    c = sqlite3.connect(db)
    try:
        (cfg,), = c.execute("SELECT config_json FROM sessions").fetchall()
        assert json.loads(cfg)["arms"]["names"] == ["left", "right"]
        # the other arm's records: as many as the task arm's, give or take a block being handed over
        task_n = c.execute("SELECT SUM(n_records) FROM session_blocks").fetchone()[0]
        other_n = c.execute("SELECT SUM(n_records) FROM arm_blocks WHERE arm = 'right'").fetchone()[0]
    finally:
        c.close()
    assert task_n > 2000 and other_n > 2000


def test_a_protocol_whose_task_arm_is_not_the_rigs_first_is_refused_in_one_line(two_arms, tmp_path):
    e, events = two_arms
    e.handle(m.StartSession(str(tmp_path / "s.db"), "P01", "experiment", _protocol(tmp_path, "right"), 3, 1))
    refused = [ev for ev in events if isinstance(ev, m.CommandRefused)]
    assert len(refused) == 1 and "--sim-arms right,left" in refused[0].message
    assert e.runner is None
    e.handle(m.StartSession(str(tmp_path / "s.db"), "P01", "experiment", _protocol(tmp_path, "centre"), 3, 1))
    assert "no such arm" in [ev for ev in events if isinstance(ev, m.CommandRefused)][-1].message


def test_health_names_each_arm_and_a_fault_names_its_arm(two_arms):
    from pipeline.devices.interfaces import Fault
    from pipeline.runtime.loop_messages import LoopEvent
    from study_app.models.health import HealthModel

    e, events = two_arms
    for _ in range(5):
        e.step()
    h = e.health()
    assert [name for name, _, _ in h.arms] == ["left", "right"]
    assert all(force == force and faults == 0 for _, force, faults in h.arms)  # a force (not NaN), no fault
    e._on_loop_event(LoopEvent(1_000_000, "fault", int(Fault.SENSOR_STALE), "sensor stale", arm="right"))
    fault = [ev for ev in events if isinstance(ev, m.EngineFault)][-1]
    assert fault.detail == "arm right: sensor stale"
    model = HealthModel()
    model.apply(h)
    model.apply(fault)
    lines = model.arms_text().splitlines()
    assert lines[0].startswith("left (task): ") and lines[1].startswith("right: ")
    assert "arm right: sensor stale" in model.fault_log[-1]
    one = HealthModel()
    one.apply(m.Health(1000.0, 1000.0, 1000.0, 1.0, 0, 0, 1, 0, False, "autopilot", False, False))
    assert one.arms_text() == ""  # a rig of one arm looks as before
