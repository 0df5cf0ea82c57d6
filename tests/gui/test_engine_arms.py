"""The study engine on a simulated rig of two arms: the task arm's session records every arm, as ``run``'s do."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

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


def test_the_real_rigs_gate_needs_every_arms_chain(tmp_path):
    from types import SimpleNamespace

    from pipeline.commissioning.rig_calibration import RigCalibrationFile
    from study_app.engine.start_gate import other_arms_missing
    from tests.pipeline.test_commissioning import _chain

    full = _chain("grasper")
    frameworks = {n: SimpleNamespace(config=SimpleNamespace(rot_tip_sensor=full.frames.rot_tip_sensor,
                                                            rot_haptic_base=full.frames.rot_haptic_base))
                  for n in ("right", "left")}
    good = tmp_path / "left.json"
    f = RigCalibrationFile.load(good)
    f.tools["grasper"] = full
    f.save()

    def arm(name, file, tool="grasper"):
        return SimpleNamespace(name=name, calibration_file=file, calibration_tool=tool)

    first = arm("right", None)
    assert other_arms_missing(SimpleNamespace(arms=(first, arm("left", str(good)))), frameworks) == ""
    assert other_arms_missing(SimpleNamespace(arms=(first, arm("left", None))), frameworks).startswith(
        "arm left: no TCP calibration on record for tool 'grasper'")
    assert other_arms_missing(SimpleNamespace(arms=(first, arm("left", str(good), "scissors"))), frameworks
                              ).startswith("arm left: no TCP calibration on record for tool 'scissors'")
    bad = tmp_path / "bad.json"
    bad.write_text("{", encoding="utf-8")
    assert other_arms_missing(SimpleNamespace(arms=(first, arm("left", str(bad)))), frameworks).startswith("arm left: ")


def _interrupted_two_arm_session(tmp_path, db: str) -> int:
    """P01's experiment session on a two-arm GUI engine, 50 steps in, then the engine closed: its session id."""
    events: list[object] = []
    e = StudyEngine(HostConfig(clock="virtual", speed=0, sim_arms=("left", "right")), events.append,
                    shared_ring=False)
    e.start()
    e.handle(m.StartSession(db, "P01", "experiment", _protocol(tmp_path, "left"), 3, 1))
    for _ in range(50):
        e.step()
    sid = e.sessions.opened.session_id
    e.close("interrupted")
    e.release_ring()
    return sid


def test_a_two_arm_session_resumes_on_two_arms_only(tmp_path):
    db = str(tmp_path / "s.db")
    sid = _interrupted_two_arm_session(tmp_path, db)
    from study_app.engine.sessions import list_resumable

    assert [r["arms"] for r in list_resumable(db)] == [["left", "right"]]  # the window rearranges a rig by it
    one: list[object] = []
    e1 = StudyEngine(HostConfig(clock="virtual", speed=0), one.append, shared_ring=False)
    e1.start()
    try:
        e1.handle(m.ResumeSession(db, sid))
        refused = [ev for ev in one if isinstance(ev, m.CommandRefused)]
        assert len(refused) == 1 and "ran on the arms left, right" in refused[0].message
        assert "--sim-arms left,right" in refused[0].message
    finally:
        e1.close("test over")
        e1.release_ring()
    two: list[object] = []
    e2 = StudyEngine(HostConfig(clock="virtual", speed=0, sim_arms=("left", "right")), two.append, shared_ring=False)
    e2.start()
    try:
        e2.handle(m.ResumeSession(db, sid))
        assert [ev for ev in two if isinstance(ev, m.CommandRefused)] == []
        assert e2.sessions.runner is not None and e2.sessions.runner.arms == ("left", "right")
    finally:
        e2.close("test over")
        e2.release_ring()


def test_a_new_participant_of_a_two_arm_study_is_refused_on_a_one_arm_gui(tmp_path):
    """Issue 42, class 5, in the GUI: ``run`` refused it, the GUI's engine gave the next participant a one-arm rig."""
    db = str(tmp_path / "s.db")
    _interrupted_two_arm_session(tmp_path, db)
    before = Path(db).read_bytes()
    one: list[object] = []
    e1 = StudyEngine(HostConfig(clock="virtual", speed=0), one.append, shared_ring=False)
    e1.start()
    try:
        e1.handle(m.StartSession(db, "P02", "experiment", _one_arm_protocol(tmp_path), 3, 2))
        refused = [ev for ev in one if isinstance(ev, m.CommandRefused)]
        assert len(refused) == 1 and "ran on the arms left,right" in refused[0].message, refused
        assert "one study runs on one rig" in refused[0].message and e1.sessions.runner is None
    finally:
        e1.close("test over")
        e1.release_ring()
    assert Path(db).read_bytes() == before  # refused on the read-only look: nothing stored touched


def _one_arm_protocol(tmp_path) -> str:
    p = tmp_path / "one_arm.toml"
    p.write_text(SHORT_PROTOCOL, encoding="utf-8")
    return str(p)


def test_a_gui_session_with_other_pipeline_settings_than_the_studys_is_refused(tmp_path):
    """One pipeline per study, from the GUI as from run: a stored study's settings against gui --set's; and a ramp-in
    no ON trial can hold."""
    db = tmp_path / "s.db"
    from protocol.study.config import load_protocol
    from study_app.headless import run_study

    run_study(str(db), participants=1, seed=3, protocol=load_protocol(_protocol(tmp_path, "right")), jobs=1)
    for settings, says in (((("filter_window", 50),), "ran with the pipeline settings: the paper's; this command's: "
                            "filter_window=50"),
                           ((("ramp_in_s", 30.0),), "must be at least trial.hold_s")):
        events: list[object] = []
        e = StudyEngine(HostConfig(clock="virtual", speed=0, sim_settings=settings), events.append, shared_ring=False)
        e.start()
        try:
            e.handle(m.StartSession(str(db), "P02", "experiment", _protocol(tmp_path, "right"), 3, 2,
                                    override_reason="test"))
            refused = [ev for ev in events if isinstance(ev, m.CommandRefused)]
            assert len(refused) == 1 and says in refused[0].message and "\n" not in refused[0].message
        finally:
            e.close("test over")
            e.release_ring()


def _last(events: list[object], kind: type) -> object:
    return [ev for ev in events if isinstance(ev, kind)][-1]


def _status(events: list[object], arm: str) -> m.CalibrationStatus:
    return [ev for ev in events if isinstance(ev, m.CalibrationStatus) and ev.arm == arm][-1]


def test_each_arm_is_commissioned_on_its_own_as_calibrate_arm_does(two_arms, capsys):
    """TCP, payload and frames on the second arm: its devices, its force path, its record; the first arm's untouched.
    The TCP result is the one ``calibrate tcp --sim-arms left,right --arm right`` prints (one service, one rig)."""
    from study_app.cli.main import main

    e, events = two_arms
    assert {ev.arm for ev in events if isinstance(ev, m.CalibrationStatus)} == {"left", "right"}
    left_cal = e.calibration
    e.handle(m.CalibrateTcp("recommended", arm="right"))
    done = _last(events, m.TcpCalibrationDone)
    assert done.accepted and done.error_mm <= 0.5
    assert main(["calibrate", "tcp", "--sim-arms", "left,right", "--arm", "right", "--json"]) == 0
    cli = json.loads(capsys.readouterr().out)
    assert done.result["tip_in_flange_m"] == pytest.approx(cli["tip_in_flange_m"], abs=1e-12)
    right = {name: ok for name, ok, _ in _status(events, "right").steps}
    left = {name: ok for name, ok, _ in _status(events, "left").steps}
    assert right["TCP"] and not left["TCP"]

    e.handle(m.Calibrate("quick", arm="right"))
    assert _last(events, m.CalibrationDone).accepted
    new = e.eng.calibrations["right"]
    assert e.calibration is left_cal and e.eng.calibrations["left"] is left_cal
    for _ in range(3):
        e.step()
    # installed in the right arm's path only (the bias then refines online: compare the payload)
    assert new.mass_kg != left_cal.mass_kg
    assert e.loop.arm("right").framework.calibration.mass_kg == new.mass_kg
    assert e.loop.arm("left").framework.calibration.mass_kg == left_cal.mass_kg

    e.handle(m.CheckFrames(arm="right"))
    assert _last(events, m.FrameCheckDone).passed
    right = {name: ok for name, ok, _ in _status(events, "right").steps}
    assert right["frames"] and not {name: ok for name, ok, _ in _status(events, "left").steps}["frames"]
    assert set(e.commissioning.provenance()["arms_rig_calibration"]) == {"left", "right"}

    e.handle(m.CalibrateTcp("recommended", arm="centre"))
    refused = _last(events, m.CommandRefused)
    assert refused.message == "arm = 'centre': this rig has no such arm; its arms: left, right"


def test_each_arms_stylus_buttons_drive_its_own_jaw(two_arms, tmp_path):
    """The right Touch's open button opens the right jaw, not the left; the command is stored with the session, the
    arm named."""
    import time

    e, _ = two_arms
    arms = e.eng.rig
    assert e.jaws.first is not None and set(e.jaws.others) == {"right"}
    assert arms.rig("left").on_buttons == e.jaws.first.buttons
    assert arms.rig("right").on_buttons == e.jaws.others["right"].buttons
    db = str(tmp_path / "s.db")
    e.handle(m.StartSession(db, "P01", "experiment", _protocol(tmp_path, "left"), 3, 1))
    e.step()
    left_open, right_open = arms.rig("left").jaw.status.fraction_open, arms.rig("right").jaw.status.fraction_open
    arms.rig("right").haptic.buttons = 2  # a short press of the right stylus' open button (the jaws start closed)
    e.step()
    arms.rig("right").haptic.buttons = 0
    end = time.monotonic() + 5.0
    while arms.rig("right").jaw.status.fraction_open == right_open and time.monotonic() < end:
        e.step()  # the jaw's own thread carries the command out (wall time, as the actuator moves)
    e.step()
    assert arms.rig("right").jaw.status.fraction_open > right_open
    assert arms.rig("left").jaw.status.fraction_open == left_open
    e.handle(m.AbortSession("done"))
    for _ in range(1000):
        if e.runner is None:
            break
        e.step()
    c = sqlite3.connect(db)
    try:
        stored = [d for (d,) in c.execute("SELECT detail FROM events WHERE kind = 'jaw' ORDER BY rowid")]
    finally:
        c.close()
    assert stored == ["arm right: stylus: step 50 µs toward open → 1150 µs (6% open)"]
