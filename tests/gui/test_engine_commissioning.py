"""The study engine on the simulated rig: a derated ON trial is not counted as full feedback; every jaw command is
stored with the session; the wizard's steps run and report (virtual clock)."""

from __future__ import annotations

import sqlite3
import time

import pytest

from pipeline.devices.touch_output import HapticLimits
from pipeline.sim.touch import SimTouch
from protocol.study.trial import TrialPhase
from study_app.engine import messages as m
from study_app.engine.host import StudyEngine
from study_app.engine.setup import HostConfig


@pytest.fixture
def engine():
    events: list[object] = []
    e = StudyEngine(HostConfig(clock="virtual", speed=0), events.append, shared_ring=False)
    e.start()
    try:
        yield e, events
    finally:
        if not e.closed:
            e.close("test over")
        e.release_ring()


def rows(db: str, sql: str) -> list[tuple]:
    c = sqlite3.connect(db)
    try:
        return c.execute(sql).fetchall()
    finally:
        c.close()


def steps_until(e: StudyEngine, pred, n: int = 40_000) -> None:
    for _ in range(n):
        if pred():
            return
        e.step()
    raise AssertionError("condition not reached")


def test_a_thermally_derated_on_trial_is_aborted_as_feedback_not_delivered(engine, tmp_path, short_protocol) -> None:
    e, events = engine
    # a Touch whose motors are hot and whose continuous rating is low: its derated limit (~0.02 N) cuts any press
    hot = SimTouch(HapticLimits(peak_force_n=3.3, continuous_force_n=0.01, thermal_budget_n2s=1.0))
    hot.output.heat.heat_n2s = 0.999
    e.eng.rig.haptic = hot  # the physics' device ...
    e.eng.loop.arms[0].haptic = hot  # ... and the one the loop's arm reads and commands
    db = str(tmp_path / "s.db")
    e.handle(m.StartSession(db, "P01", "experiment", short_protocol, 3, 1))
    steps_until(e, lambda: any(isinstance(ev, m.TrialEnded) and ev.record.haptic_mode == "on" for ev in events))
    on = next(ev.record for ev in events if isinstance(ev, m.TrialEnded) and ev.record.haptic_mode == "on")
    assert on.outcome == "aborted"
    assert on.abort_reason.startswith("feedback: the haptic device's thermal derating rendered ")
    assert on.abort_reason.endswith("% of the designed force in a haptics-ON trial")
    e.close("test over")
    (cause,) = rows(db, "SELECT abort_cause FROM trials WHERE haptic_mode = 'on' AND outcome = 'aborted' LIMIT 1")[0]
    assert cause == "feedback"
    kinds = [k for (k,) in rows(db, "SELECT kind FROM events")]
    assert "derating" in kinds  # the derating itself is in the record


def test_every_jaw_command_is_stored_with_the_running_session(engine, tmp_path, short_protocol) -> None:
    e, events = engine
    db = str(tmp_path / "s.db")
    e.handle(m.StartSession(db, "P01", "experiment", short_protocol, 3, 1))
    steps_until(e, lambda: e.runner is not None and e.runner.machine.phase is TrialPhase.ACTIVE)
    e.handle(m.JawCommand("open"))
    e.handle(m.JawCommand("step_close"))
    e.eng.rig.haptic.buttons = 1  # a short press of the stylus' front button: one step toward closed
    e.step()
    e.eng.rig.haptic.buttons = 0
    end = time.monotonic() + 5.0
    while len([ev for ev in events if isinstance(ev, m.JawState) and ev.last]) < 3 and time.monotonic() < end:
        e.step()  # the jaw's own thread carries the commands out (wall time, as the actuator moves)
    states = [ev for ev in events if isinstance(ev, m.JawState) and ev.last]
    assert [s.last for s in states][:3] == [
        "experimenter: open fully → 1900 µs (100% open)",
        "experimenter: step 50 µs toward closed → 1850 µs (94% open)",
        "stylus: step 50 µs toward closed → 1800 µs (88% open)",
    ]
    e.handle(m.AbortSession("done"))
    steps_until(e, lambda: e.runner is None)
    stored = [d for (d,) in rows(db, "SELECT detail FROM events WHERE kind = 'jaw' ORDER BY rowid")]
    assert stored == [s.last for s in states][:3]


def test_the_wizard_steps_on_the_simulated_rig(engine) -> None:
    e, events = engine
    e.handle(m.CalibrateTcp("minimal"))
    e.handle(m.CheckFrames())
    (tcp,) = [ev for ev in events if isinstance(ev, m.TcpCalibrationDone)]
    assert tcp.accepted and tcp.n_poses == 4 and tcp.error_mm < 0.5
    (fc,) = [ev for ev in events if isinstance(ev, m.FrameCheckDone)]
    assert fc.passed and len(fc.lines) == 3
    status = [ev for ev in events if isinstance(ev, m.CalibrationStatus)][-1]
    assert status.rig == "sim" and status.missing == "" and all(ok for _, ok, _ in status.steps)
    for cmd in (m.RecordPivot("O1"), m.RecordFrameAxis("+x"), m.CalibrateTcp("sideways")):
        e.handle(cmd)
    refused = [ev.message for ev in events if isinstance(ev, m.CommandRefused)]
    assert refused == ["simulated rig: the orientations run automatically (Run TCP calibration)",
                       "simulated rig: the pushes run automatically (Run frame check)",
                       "pose set = 'sideways': allowed values are recommended, minimal, roll only"]


def test_the_gui_s_mount_error_makes_the_wizard_s_frame_check_fail_naming_the_axes() -> None:
    events: list[object] = []
    e = StudyEngine(HostConfig(clock="virtual", speed=0, sim_mount_error_deg=90.0), events.append, shared_ring=False)
    e.start()
    try:
        e.handle(m.CheckFrames())
    finally:
        e.close("test over")
        e.release_ring()
    (fc,) = [ev for ev in events if isinstance(ev, m.FrameCheckDone)]
    assert not fc.passed and fc.summary.startswith("Frames and signs: FAIL on +x (")
    off = [float(s.split("(")[1].split("°")[0]) for s in fc.summary.split(":")[1].split(",")[:2]]
    assert all(abs(a - 90.0) < 3.0 for a in off), fc.summary
    status = [ev for ev in events if isinstance(ev, m.CalibrationStatus)][-1]
    assert [(n, ok) for n, ok, _ in status.steps][2] == ("frames", False)
