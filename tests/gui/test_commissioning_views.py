"""The wizard's chain (status, TCP, frames), the jaw controls and the health panel's thermal and jaw rows: models
drive views, events drive models (no engine)."""

from __future__ import annotations

import math

import numpy as np
from PySide6.QtWidgets import QApplication

from pipeline.core.tick_record import TICK_DTYPE
from pipeline.force.frames import axis_angle, mat_mul
from pipeline.sim.robot import TOOL_DOWN
from study_app.engine import messages as m
from study_app.gui.calibration_wizard import CalibrationWizard
from study_app.gui.health_panel import QtHealthPanel
from study_app.models.app import AppModel
from study_app.models.calibration import CalibrationModel
from study_app.models.commissioning import CommissioningModel, JawModel
from study_app.models.health import HealthModel
from study_app.models.real_calibration import RealCalibrationModel

REAL = m.EngineReady("", "real", "real", {}, math.nan, (math.nan,) * 3, "participant")
SIM = m.EngineReady("", "sim", "virtual", {}, 0.10, (0.3, 0.0, 0.115), "autopilot")
MISSING = ("no TCP calibration on record for tool 'grasper': run haptic-study calibrate tcp --rig real --hardware "
           "FILE (or the calibration wizard's TCP step)")
STATUS = m.CalibrationStatus("real", "grasper", "/lab/calibration.json",
                             [("TCP", False, "not on record"), ("payload", True, "0.650 kg (2026-01-01 10:00:00 UTC)"),
                              ("frames", False, "not on record")], MISSING)


def test_the_real_tcp_step_records_orientations_warns_on_a_repeat_and_computes(qtbot) -> None:
    chain = CommissioningModel()
    sent: list[object] = []
    wiz = CalibrationWizard(CalibrationModel(), lambda: None, chain=chain,
                            on_tcp=lambda: sent.append(chain.tcp_command()),
                            on_compute_tcp=lambda: sent.append(chain.compute_command()))
    qtbot.addWidget(wiz)
    for ev in (REAL, STATUS):
        chain.apply(ev)
    assert wiz.chain_status.gate.text() == f"A session cannot start yet: {MISSING}."
    page = wiz.tcp_page
    assert page.run_button.text() == "Record orientation" and not page.compute_button.isEnabled()
    assert page.compute_button.toolTip() == "record at least 4 orientations first (0 so far)"
    page.run_button.click()
    assert sent == [m.RecordPivot("O1")] and not page.run_button.isEnabled()
    chain.apply(m.PivotRecorded("O1", TOOL_DOWN, (0.3, -0.1, 0.2), 0.01))
    chain.apply(m.PivotRecorded("O2", mat_mul(axis_angle((1.0, 0.0, 0.0), math.radians(1.0)), TOOL_DOWN),
                                (0.3, -0.1, 0.2), 0.01))
    assert page.orientations.rowCount() == 2 and page.orientations.item(1, 1).text() == "+300.0, -100.0, +200.0"
    # kept (there is nothing to undo): the advice is for the next one, not "record again"
    assert page.verdict.text() == ("O2 is only 1.0° from O1: kept, but it adds little — turn the instrument further "
                                   "before the next one (at least 20° between orientations, in two directions)")
    for k, deg in ((3, 30.0), (4, -30.0)):
        chain.apply(m.PivotRecorded(f"O{k}", mat_mul(axis_angle((0.0, 1.0, 0.0), math.radians(deg)), TOOL_DOWN),
                                    (0.3, -0.1, 0.2), 0.01))
    assert page.compute_button.isEnabled()
    page.compute_button.click()
    assert isinstance(sent[-1], m.IdentifyTcp) and [p[0] for p in sent[-1].poses] == ["O1", "O2", "O3", "O4"]
    chain.apply(m.TcpCalibrationDone(True, "", "recorded", 4, {"tip_in_flange_m": [0.001, -0.001, 0.25],
                                                               "rms_residual_m": 4e-5}))
    # what `calibrate tcp` says too: the pendant's TCP and the file's offset (docs/hardware-setup.md: "as it says")
    assert page.verdict.text() == ("Accepted: tip (+1.00, -1.00, +250.00) mm in the flange frame, RMS residual 0.040 "
                                   "mm over 4 orientations — saved for the tool. Set the TCP on the pendant to (+1.00, "
                                   "-1.00, +250.00) mm and robot.tcp_offset_m to [0.00100, -0.00100, 0.25000] (until "
                                   "then the app corrects the poses itself).")


def test_the_real_frames_step_records_one_axis_at_a_time(qtbot) -> None:
    chain = CommissioningModel()
    sent: list[object] = []
    wiz = CalibrationWizard(CalibrationModel(), lambda: None, chain=chain,
                            on_frames=lambda axis: sent.append(chain.frames_command(axis)))
    qtbot.addWidget(wiz)
    chain.apply(REAL)
    page = wiz.frames_page
    assert page.run_button.isHidden() and not page.axis_buttons["+z"].isHidden()
    page.axis_buttons["+z"].click()
    assert sent == [m.RecordFrameAxis("+z")]
    assert page.instruction.text().startswith("Recording 3 s: push the tip gently (about 1 N) along base +z (up)")
    chain.apply(m.FrameAxisChecked("+z", False, "+z  peak 1.02 N · base force  89.4° from +z · FAIL", {}))
    chain.apply(m.FrameCheckDone(False, "Frames and signs: FAIL on +z (89.4° off): ...", []))
    assert page.result.toPlainText().splitlines() == ["+z  FAIL · peak 1.02 N", "    base force  89.4° from +z",
                                                      "Frames and signs: FAIL on +z (89.4° off): ..."]
    # the window is narrower than a terminal: every axis's verdict comes first, its parts beneath it
    chain.apply(m.FrameAxisChecked("+x", True, "+x  peak 1.03 N · base force   0.2° from +x · rendered force   0.2° "
                                   "from haptic +x (right) · PASS", {}))
    assert page.result.toPlainText().splitlines()[:3] == [
        "+x  PASS · peak 1.03 N", "    base force   0.2° from +x", "    rendered force   0.2° from haptic +x (right)"]
    assert chain.frames_view()[0].endswith("· PASS")  # (what the terminal prints is unchanged)


def test_a_new_push_replaces_an_old_verdict_and_a_restarted_engine_starts_the_pushes_afresh() -> None:
    chain = CommissioningModel()
    chain.apply(REAL)
    for axis in ("+x", "+y", "+z"):
        chain.frames_command(axis)
        chain.apply(m.FrameAxisChecked(axis, axis != "+z", f"{axis}  peak 1.00 N · PASS", {}))
    chain.apply(m.FrameCheckDone(False, "Frames and signs: FAIL on +z (180.0° off): …", []))
    chain.frames_command("+z")
    chain.apply(m.CommandRefused("RecordFrameAxis", "the force sensor stalled while recording — record again"))
    assert chain.frames_view()[-1] == "the force sensor stalled while recording — record again"
    chain.frames_command("+z")
    chain.apply(m.FrameAxisChecked("+z", True, "+z  peak 1.00 N · PASS", {}))
    # the refusal (and the old FAIL) were about earlier pushes: not shown under the new one
    assert chain.frames_view() == ["+x  peak 1.00 N · PASS", "+y  peak 1.00 N · PASS", "+z  peak 1.00 N · PASS"]
    chain.apply(m.FrameCheckDone(True, "Frames and signs: PASS (3 of 3 axes)", []))
    assert chain.frames_view()[-1] == "Frames and signs: PASS (3 of 3 axes)"
    chain.apply(REAL)  # the engine was restarted: it holds none of these pushes
    assert chain.frames_view() == [] and chain.frames_instruction().endswith("(still to do: +x, +y, +z).")


def test_the_real_payload_step_names_its_buttons_and_says_when_every_pose_is_recorded() -> None:
    cal = CalibrationModel()
    real = RealCalibrationModel(seconds=1.0)
    for mdl in (cal, real):
        mdl.apply(REAL)
    # the button is "Start pose set" (the window's own Start starts a session)
    assert real.instruction() == "Choose a pose set and press Start pose set: the wizard shows one pose at a time."
    real.begin("quick")
    for step in list(real.steps):
        real.record_command()
        real.apply(m.PoseRecorded(step.label, 1000, (0.0, 0.0, 2.0, 0.0, 0.0, 0.0), step.target_rot_base_sensor,
                                  (0.3, -0.1, 0.2), 0.0, 0.001))
    # no target is left: not "move the TCP to … then press Record pose" for a pose already recorded
    assert real.instruction() == ("All 6 poses are recorded: press Identify (Previous pose goes back to record one "
                                  "again).")
    assert real.message == ""  # not said twice
    real.identify_command()
    done = m.CalibrationDone(True, "", "quick", 6, 9.7, 2e-4, 3e-4, [], {"mass_kg": 0.4, "model": "affine"})
    for mdl in (cal, real):
        mdl.apply(done)
    # saved for the mounted tool, as the TCP step says, not only "stored with the next session"
    assert real.instruction() == "Accepted: installed in the force path and saved for the tool (on record above)."
    assert cal.verdict() == "Accepted: installed in the force path, saved for the tool and stored with every session."


def test_start_without_calibration_asks_with_every_step_missing_and_what_the_override_does_not_waive() -> None:
    chain = CommissioningModel()
    chain.apply(REAL)
    nothing = m.CalibrationStatus("real", "scalpel", "/lab/calibration.json",
                                  [("TCP", False, "not on record"), ("payload", False, "not on record"),
                                   ("frames", False, "not on record")], MISSING.replace("grasper", "scalpel"))
    chain.apply(nothing)
    # it named the TCP only; the payload's absence is what refuses the start (the tool's weight at rest)
    assert chain.override_prompt() == (
        f"{MISSING.replace('grasper', 'scalpel')}.\n\nNot on record for 'scalpel': TCP, payload, frames.\n\nStart "
        "anyway? The session stores this override and your reason.\nThe force at rest is still measured for 2 s and "
        "must be below 0.1 N;\nwith no payload on record the tool's own weight counts as force, and the start is "
        "refused.\n\nReason:")
    chain.apply(STATUS)  # the payload on record: only the TCP and the frames are missing
    assert "Not on record for 'grasper': TCP, frames." in chain.override_prompt()
    assert "own weight" not in chain.override_prompt()


def test_the_simulated_rig_runs_each_step_at_once(qtbot) -> None:
    chain = CommissioningModel()
    sent: list[object] = []
    wiz = CalibrationWizard(CalibrationModel(), lambda: None, chain=chain,
                            on_tcp=lambda: sent.append(chain.tcp_command()),
                            on_frames=lambda axis: sent.append(chain.frames_command(axis)))
    qtbot.addWidget(wiz)
    chain.apply(SIM)
    wiz.tcp_page.pose_set.setCurrentText("minimal")
    wiz.tcp_page.run_button.click()
    wiz.frames_page.run_button.click()
    assert sent == [m.CalibrateTcp("minimal"), m.CheckFrames()]
    # the check is under way (no answer yet): the page says so
    assert wiz.frames_page.instruction.text().startswith("Checking … the simulated experimenter pushes")
    assert not wiz.frames_page.run_button.isEnabled()
    assert wiz.tcp_page.orientations.isHidden() and wiz.tcp_page.run_button.text() == "Run TCP calibration"


def test_the_app_offers_an_override_only_on_an_incomplete_real_rig_and_sends_the_reason() -> None:
    sent: list[object] = []
    app = AppModel(lambda cmd: sent.append(cmd) or True)
    app.apply(REAL)
    assert app.actions.calibration_missing() == ""
    app.apply(STATUS)
    assert app.actions.calibration_missing() == MISSING
    app.setup.update(db_path="/tmp/x.db", code="R01")
    app.session.state = "ready"
    assert app.control.start(override_reason="  rehearsal  ")
    assert isinstance(sent[-1], m.StartSession) and sent[-1].override_reason == "rehearsal"


def test_the_jaw_and_the_touch_motors_in_the_health_panel(qtbot) -> None:
    h = HealthModel()
    panel = QtHealthPanel(h)
    qtbot.addWidget(panel)
    h.apply(SIM)
    h.apply(m.JawState(0.4, 1420, False, "", "experimenter: step 50 µs toward open → 1420 µs (40% open)"))
    h.apply(m.Health(1000.0, 1000, 1010, 10, 0, 0, 5000, 0, True, "autopilot", True, False,
                     haptic_heat_fraction=0.62, haptic_force_limit_n=2.52, haptic_peak_force_n=3.3,
                     haptic_continuous_force_n=0.88))
    rows = np.zeros(300, dtype=TICK_DTYPE)
    rows["t_s"] = np.arange(300) * 1e-3
    h.update_from_rows(rows)
    names = [panel.devices.item(i, 0).text() for i in range(panel.devices.rowCount())]
    states = [panel.devices.item(i, 1).text() for i in range(panel.devices.rowCount())]
    assert names[-1] == "Jaw actuator" and states[-1] == "ok, 40% open (1420 µs)"
    assert states[names.index("Haptic device")] == "ok, derating: at most 2.52 N"
    assert panel.thermal.text() == ("Touch motors at 62 % of their heat budget: derating — it may render at most "
                                    "2.52 N now (its 3.3 N peak, lowered toward its 0.88 N continuous rating as the "
                                    "motors heat; back to the peak when they cool)")
    # below the onset: no derating, whatever the fraction says about a near-peak limit
    h.apply(m.Health(1000.0, 1000, 1010, 10, 0, 0, 5000, 0, True, "autopilot", True, False,
                     haptic_heat_fraction=0.45, haptic_force_limit_n=3.3, haptic_peak_force_n=3.3,
                     haptic_continuous_force_n=0.88))
    assert panel.thermal.text() == "Touch motors at 45 % of their heat budget" and not h.derating()
    h.apply(m.Health(1000.0, 1000, 1010, 10, 0, 0, 5000, 0, True, "autopilot", True, False,
                     haptic_heat_fraction=0.62, haptic_force_limit_n=2.52, haptic_peak_force_n=3.3,
                     haptic_continuous_force_n=0.88))
    h.apply(m.JawState(0.4, 1420, False, "serial port /dev/ttyACM0 lost: [Errno 5]",
                       "experimenter: open fully: refused"))
    assert panel.devices.item(3, 1).text() == "FAULT: serial port /dev/ttyACM0 lost: [Errno 5]"
    jaw = JawModel()
    jaw.apply(m.JawState(1.0, 1900, False, "", "stylus: open fully → 1900 µs (100% open)"))
    assert jaw.text() == "100% open (1900 µs)" and jaw.log == ["stylus: open fully → 1900 µs (100% open)"]
    assert JawModel.command("step_open") == m.JawCommand("step_open")


def test_a_row_just_recorded_is_scrolled_into_view(qtbot) -> None:
    chain = CommissioningModel()
    wiz = CalibrationWizard(CalibrationModel(), lambda: None, chain=chain, on_tcp=lambda: None,
                            on_compute_tcp=lambda: None)
    qtbot.addWidget(wiz)
    wiz.resize(900, 500)
    wiz.show()
    for ev in (REAL, STATUS):
        chain.apply(ev)
    table = wiz.tcp_page.orientations
    for k in range(1, 31):
        chain.apply(m.PivotRecorded(f"O{k}", mat_mul(axis_angle((0.0, 1.0, 0.0), math.radians(3.0 * k)), TOOL_DOWN),
                                    (0.3, -0.1, 0.2), 0.01))
        QApplication.processEvents()  # Qt lays the table out
    bar = table.verticalScrollBar()
    assert table.rowCount() == 30 and bar.maximum() > 0 and bar.value() == bar.maximum()
