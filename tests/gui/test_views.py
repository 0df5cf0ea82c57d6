"""Models drive views: change the model, assert the widget (no engine)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from gui_trials import trial_record
from PySide6.QtCore import QPoint, Qt

from protocol.tasks.force_regulation import ForceRegulation
from study_app.engine import messages as m
from study_app.gui.calibration_wizard import CalibrationWizard
from study_app.gui.force_plots import QtForcePlots
from study_app.gui.health_panel import QtHealthPanel
from study_app.gui.participant_window import ParticipantWindow
from study_app.gui.rig_view import RigWindow
from study_app.gui.session_views import QtProgress, QtTrialTable
from study_app.gui.setup_panel import QtSetupPanel
from study_app.models.calibration import CalibrationModel
from study_app.models.health import HealthModel
from study_app.models.participant import ParticipantScreenModel
from study_app.models.plots import PlotModel
from study_app.models.rig import RigViewModel
from study_app.models.session import SessionModel, TrialTable
from study_app.models.setup import SetupModel

READY = m.EngineReady("", "sim", "virtual", {}, 0.10, (0.3, 0.0, 0.115), "autopilot")


def test_trial_table_view_fills_from_the_model(qtbot):
    table = TrialTable()
    view = QtTrialTable(table)
    qtbot.addWidget(view)
    table.add(trial_record(trial_index=0, target_label="FIRM", target_force_n=1.2, haptic_mode="on",
                           outcome="success", tct_s=2.5, rmse_n=0.2, max_ae_n=0.4))
    assert view.rowCount() == 1
    assert [view.item(0, j).text() for j in range(7)] == ["1", "FIRM 1.2 N", "haptics ON", "success", "2.50", "0.200",
                                                          "0.400"]
    table.clear()
    assert view.rowCount() == 0


def test_progress_view_follows_the_session(qtbot):
    s = SessionModel()
    view = QtProgress(s)
    qtbot.addWidget(view)
    s.apply(READY)
    s.apply(m.SessionStarted(1, "P01", "experiment", 20, 0, ForceRegulation(), 12.0, 2.0, 1.0, False))
    s.apply(m.TrialStarted(1.0, 0, 1, 20, "GENTLE", 0.6, "off"))
    s.set_time(4.0)
    assert view.label.full_text() == "Trial 1 · GENTLE · haptics OFF · times out in 9.0 s"
    assert view.count.full_text() == "0 of 20 trials done · at most 5 min left"


def test_health_panel_shows_faults_and_enables_reset(qtbot):
    h = HealthModel()
    view = QtHealthPanel(h)
    qtbot.addWidget(view)
    h.apply(READY)
    assert view.faults.text() == "Faults: none" and not view.reset_button.isEnabled()
    h.apply(m.EngineFault(2.0, "fault", 64, "OPERATOR_STOP"))
    assert view.faults.text() == "Faults: OPERATOR_STOP" and view.reset_button.isEnabled()
    h.apply(m.Health(1000.0, 1000.0, 1003.0, 12.0, 1, 0, 5000, 0, True, "autopilot", True, False))
    text = view.loop.text()
    assert '<span style="color:#147f28">p99 |period − 1 ms| 12 µs</span>' in text  # within its limit: green
    assert '<span style="color:#8a5a00">periods over 2 ms: 1 of 5,000 (0.02 %)</span>' in text  # above: amber
    assert "limits: rate 1000 ± 5 Hz; p99 ≤ 100 µs" in text
    assert view.log_label.text().startswith("Fault log") and view.force.isHidden()
    h.update_force(18.0, in_trial=False)
    assert not view.force.isHidden() and "18.0 N on the tissue while no trial is running" in view.force.text()
    assert not view.reset_button.isEnabled()


def test_health_panel_says_where_the_loop_runs_and_the_latency_stage_by_stage(qtbot):
    from pipeline.assembly.latency import Latency, Stage

    h = HealthModel()
    view = QtHealthPanel(h)
    qtbot.addWidget(view)
    h.apply(READY)
    assert view.placement.text() == "" and view.latency.text() == ""  # nothing said before the engine says it
    lat = Latency((Stage("force", "moving average (10 samples)", 4.0, "measured on the simulated rig"),
                   Stage("force", "F/T sensor: sampling and transport", float("nan"), "a tap test"),
                   Stage("motion", "robot: servoL look-ahead 0.03 s", 34.0, "UR client library #86")))
    h.apply(m.Health(1000.0, 1000.0, 1003.0, 12.0, 1, 0, 5000, 0, True, "autopilot", True, False,
                     scheduling="SCHED_FIFO/20 on CPU 1 of 0-1", loop_pid=4242, latency=lat.to_dict()))
    assert view.placement.text() == "The 1 kHz loop: alone in its own process (pid 4242), SCHED_FIFO/20 on CPU 1 of 0-1"
    text = view.latency.text()
    assert text.startswith("End-to-end latency: tip → hand 4.0 ms · hand → tip 34.0 ms · round trip 38.0 ms")
    # every stage on a line of its own, the one not measured said so (not a zero)
    assert "tip → hand: 4.0 ms  moving average (10 samples) (measured on the simulated rig)" in text
    assert "tip → hand: –  F/T sensor: sampling and transport (a tap test)" in text
    assert "hand → tip: 34.0 ms  robot: servoL look-ahead 0.03 s (UR client library #86)" in text


def test_setup_panel_shows_validation_errors(qtbot, tmp_path):
    s = SetupModel()
    view = QtSetupPanel(s)
    qtbot.addWidget(view)
    s.update(db_path=str(tmp_path / "s.db"))
    assert view.hint.text().startswith("Enter the participant's code") and view.errors.isHidden()
    started = []
    view.start_requested.connect(lambda: started.append(1))
    qtbot.keyClicks(view.code, "P 1")  # Space in the code field: neither a character of the code nor Start
    assert s.values.code == "P1" and started == []
    qtbot.keyClick(view.code, Qt.Key.Key_Return)  # Enter is Start
    assert started == [1]
    qtbot.keyClick(view.kind, Qt.Key.Key_Space)  # outside the typing fields Space is Start, as in the whole window
    assert started == [1, 1]
    view.code.setText("P-1!")
    assert view.errors.text().startswith("participant code = 'P-1!'")
    view.code.clear()
    qtbot.keyClicks(view.code, "P01")
    assert view.errors.text() == "" and s.valid
    # the protocol path is checked as it is typed: the old path's refusal does not stay while a new one is typed
    qtbot.keyClicks(view.protocol, "nope.toml")
    assert "nope.toml" in view.errors.text()
    view.protocol.selectAll()
    qtbot.keyClick(view.protocol, Qt.Key.Key_Backspace)
    assert view.errors.text() == "" and s.valid and s.values.protocol_path == ""
    view.resize(340, 700)  # the left column's narrowest
    view.show()
    qtbot.waitExposed(view)
    # a long pasted code: its refusal wraps inside the column (a label wraps only between words)
    view.code.setText("P" + "0123456789" * 4)
    assert "\u200b" in view.errors.text() and view.errors.minimumSizeHint().width() <= view.width()
    view.code.setText("P01")
    s.set_resumable([{"session_id": 4, "code": "P02", "kind": "experiment", "started_at": "2026-01-02T10:11:12",
                      "trials_planned": 20, "trials_done": 7, "trials_aborted": 2, "reruns_run": 1,
                      "trials_total": 22},
                     {"session_id": 9, "code": "PARTICIPANT-0042-LONG", "kind": "training",
                      "started_at": "2026-01-03T09:00:00", "trials_planned": 12, "trials_done": 0,
                      "trials_total": 12}])
    assert view.resumable.count() == 2
    # counted as the running session's progress line counts (designed trials, aborted attempts, re-runs left)
    full = "session 4: P02 experiment, 7 of 20 trials done · 2 aborted · 1 re-run left, started 2026-01-02 10:11"
    assert view.resumable.item(0).toolTip() == full and view.resumable.item(0).text() == full
    assert view.selected_session() == 4  # the first row is selected: Resume selected works at once
    # long rows wrap within the list: nothing runs out of sight to the right
    width = view.resumable.viewport().width()
    for i in range(view.resumable.count()):
        assert view.resumable.visualItemRect(view.resumable.item(i)).right() <= width
    assert view.resumable.horizontalScrollBar().maximum() == 0


def test_participant_window_experiment_word_then_blank_never_a_gauge(qtbot):
    p = ParticipantScreenModel()
    view = ParticipantWindow(p)
    qtbot.addWidget(view)
    p.apply(m.SessionStarted(1, "P01", "experiment", 2, 0, ForceRegulation(), 12.0, 2.0, 1.0, True))
    p.apply(m.TrialStarted(1.0, 0, 1, 2, "FIRM", 1.2, "on"))
    p.update(1.2, 1.1)
    assert view.headline.text() == "FIRM" and view.gauge.isHidden()
    p.update(2.5, 1.1)
    assert view.headline.text() == "" and view.gauge.isHidden()
    p.apply(m.PhaseEntered(5.0, 0, "pause"))
    assert view.headline.text() == "Rest"


def test_participant_window_training_gauge(qtbot):
    p = ParticipantScreenModel()
    view = ParticipantWindow(p)
    qtbot.addWidget(view)
    p.apply(m.SessionStarted(1, "P01", "training", 4, 0, ForceRegulation(), 20.0, 2.0, 1.0, True))
    p.apply(m.TrialStarted(1.0, 0, 1, 4, "GENTLE", 0.6, "off"))
    p.update(3.0, 0.55)
    assert not view.gauge.isHidden()
    # the band the task judges: its edges carry the 1e-9 relative slack that makes them inclusive
    assert view.gauge.force_n == 0.55 and math.isclose(view.gauge.band[0], 0.54, rel_tol=1e-8) \
        and math.isclose(view.gauge.band[1], 0.66, rel_tol=1e-8)


def test_calibration_wizard_shows_refusal_and_figures(qtbot):
    c = CalibrationModel()
    runs = []
    view = CalibrationWizard(c, lambda: runs.append(1))
    qtbot.addWidget(view)
    view.pose_set.setCurrentText("quick")
    assert c.pose_set == "quick"
    qtbot.mouseClick(view.run_button, Qt.MouseButton.LeftButton)
    assert runs == [1]
    c.command()
    assert not view.run_button.isEnabled()
    c.apply(m.CalibrationDone(False, "rank 6 of 10: add tilted poses", "quick", 6, 3.1e17, math.nan, math.nan, [],
                              None))
    assert view.verdict.text() == ("Refused — the previous calibration stays in use. Reason: rank 6 of 10: "
                                   "add tilted poses")
    assert view.run_button.isEnabled() and view.residuals.rowCount() == 0
    c.apply(m.CalibrationDone(True, "", "quick", 2, 9.7, 0.0015, 0.0003,
                              [("P01", 0.001, 0.0002), ("P02", 0.002, 0.0004)],
                              {"mass_kg": 0.65, "model": "affine"}))
    assert view.verdict.text().startswith("Accepted")
    assert view.residuals.rowCount() == 2 and view.residuals.item(1, 1).text() == "0.0020"
    assert view.figures.rowCount() == 6


def test_rig_view_manual_driving_with_mouse_and_keys(qtbot):
    r = RigViewModel()
    r.apply(READY)
    drivers, targets = [], []
    r.target_changed.connect(targets.append)
    view = RigWindow(r, drivers.append)
    qtbot.addWidget(view)
    view.resize(600, 400)
    view.show()
    qtbot.waitExposed(view)
    qtbot.mouseClick(view.canvas, Qt.MouseButton.LeftButton, pos=QPoint(300, 200))
    assert targets == []  # autopilot: the mouse does nothing
    view.manual.setChecked(True)
    assert drivers == ["manual"]
    r.driver = "manual"
    canvas = view.canvas
    y_px = int(canvas.to_px(0.0, -2.0).y())
    qtbot.mouseClick(canvas, Qt.MouseButton.LeftButton, pos=QPoint(canvas.width() // 2, y_px))
    assert len(targets) == 1 and abs(targets[0] - r.target_for_tip_mm(-2.0)) < 2e-4
    canvas.setFocus()
    qtbot.keyClick(canvas, Qt.Key.Key_Up)
    assert abs(targets[-1] - (targets[0] + 0.0005)) < 1e-12
    qtbot.keyClick(canvas, Qt.Key.Key_Home)
    assert targets[-1] == 0.0
    # ↑/↓ move the stylus, never the choice of driver: the radio buttons take no keyboard focus
    assert view.manual.focusPolicy() == Qt.FocusPolicy.NoFocus == view.autopilot.focusPolicy()
    qtbot.mouseClick(view.manual, Qt.MouseButton.LeftButton)
    assert view.focusWidget() is not view.manual
    # the engine's report of the driver is shown, never sent back as a choice
    r.driver = "autopilot"
    r.changed.emit()
    assert view.autopilot.isChecked() and drivers == ["manual"]


def _live_view_in_trial_1(qtbot, t_s: np.ndarray) -> tuple[SessionModel, PlotModel, QtForcePlots]:
    """The live view of a session whose trial 1 (GENTLE, haptics OFF) was cued at 1 s; samples at ``t_s``, all 0."""
    s = SessionModel()
    plots = PlotModel(window_s=10.0)
    view = QtForcePlots(plots, s)
    qtbot.addWidget(view)
    s.apply(READY)
    s.apply(m.SessionStarted(1, "P01", "experiment", 2, 0, ForceRegulation(), 12.0, 2.0, 1.0, False))
    s.apply(m.TrialStarted(1.0, 0, 1, 2, "GENTLE", 0.6, "off"))
    plots.t = t_s
    for k in plots.data:
        plots.data[k] = np.zeros(len(t_s))
    return s, plots, view


def test_the_live_view_scales_to_the_target_and_names_a_force_above_it(qtbot):
    _, plots, view = _live_view_in_trial_1(qtbot, np.linspace(0, 5, 500))
    plots.data["raw_n"][:] = 7.6  # the tool's weight: on the lower plot's own axis, never the task axis
    plots.data["force_n"][:] = 0.6
    view.refresh()
    assert view.task.viewRange()[1] == pytest.approx([0.0, 1.5])
    x, lo = view.band_lo.getData()  # from the cue (t = 1 s, 4 s before the newest sample) to now
    _, hi = view.band_hi.getData()
    assert (x[0], x[-1]) == pytest.approx((-4.0, 0.0))
    assert list(lo) == pytest.approx([0.54] * len(x)) and list(hi) == pytest.approx([0.66] * len(x))
    assert view.cue_line.isVisible() and view.cue_line.value() == pytest.approx(-4.0)
    # the band's words in the title line, outside the data area: nothing is drawn over the trace
    assert view.title_text == "GENTLE: target 0.6 N ± 10 % (0.54–0.66 N)"
    assert view.task.titleLabel.isVisible() and not view.task.vb.sceneBoundingRect().intersects(
        view.task.titleLabel.sceneBoundingRect())
    in_data = [i for i in view.task.vb.addedItems if i.isVisible()]
    # curves, the band and the cue's line only
    assert set(map(type, in_data)) <= {type(view.band), type(view.band_lo), type(view.cue_line),
                                       type(view.curves["force_n"])}
    assert view.lower_plot.viewRange()[1][1] >= 7.6
    assert view.lower_legend() == ["raw sensor |F| (the tool's weight included)"]
    plots.data["force_n"][-1] = 18.0
    view.refresh()
    assert view.task.viewRange()[1] == pytest.approx([0.0, 2.4])
    assert view.title_text.endswith("peak 18.0 N: above the axis")
    assert not view.task.getAxis("left").autoSIPrefix  # "(x0.001)" never appears on a force axis
    # the newest 2 s are in the data area, up to its right edge, on both plots
    view.resize(900, 500)
    view.show()
    qtbot.waitExposed(view)
    view.refresh()  # (the window's 30 Hz timer)
    for p in (view.task, view.lower_plot):
        assert p.viewRange()[0] == pytest.approx([-10.0, 0.0], abs=0.02)
    # a legend on every plot with more than one line: the compensated x, y, z
    view.lower_choice.setCurrentText("compensated x, y, z (sensor frame)")
    assert len(view.lower_curves) == 3 and view.lower_legend() == ["compensated Fx", "Fy", "Fz (sensor frame)"]
    assert all(w in view.lower_plot.titleLabel.text for w in ("Fx", "Fy", "Fz"))
    view.lower_choice.setCurrentText("none")
    assert not view.lower_plot.isVisible() and view.task.getAxis("bottom").style["showValues"]


def test_after_a_cue_the_live_view_marks_it_and_leaves_the_last_trials_force_alone(qtbot):
    """A user trial: right after a cue the window still showed the previous trial's 2.7 N, the new trial's band
    across the whole window and "peak 2.7 N: above the axis", read as the participant overshooting now."""
    s, plots, view = _live_view_in_trial_1(qtbot, np.linspace(0.0, 10.0, 1001))
    plots.data["force_n"][plots.t < 8.0] = 2.7  # trial 1, pressed hard, ended at 7 s
    s.apply(m.TrialEnded(7.0, trial_record(trial_index=0, target_label="GENTLE", target_force_n=0.6,
                                           haptic_mode="off", outcome="timeout"), 2))
    s.apply(m.PhaseEntered(7.0, 0, "pause"))
    view.refresh()
    assert "peak 2.7 N: above the axis" in view.title_text  # between trials: the trial just ended is the last
    assert not view.band.isVisible()
    s.apply(m.TrialStarted(9.0, 1, 2, 2, "GENTLE", 0.6, "off"))  # the cue, 1 s before the newest sample
    view.refresh()
    assert "above the axis" not in view.title_text  # the previous trial's force is not this trial's
    assert view.task.viewRange()[1] == pytest.approx([0.0, 1.5])
    assert view.cue_line.isVisible() and view.cue_line.value() == pytest.approx(-1.0)
    x, _ = view.band_lo.getData()
    assert view.band.isVisible() and (x[0], x[-1]) == pytest.approx((-1.0, 0.0))
    plots.data["force_n"][-1] = 2.7  # this trial overshoots: said at once
    view.refresh()
    assert view.title_text.endswith("peak 2.7 N: above the axis")
    plots.t = plots.t + 20.0  # the cue has scrolled out: the band spans the whole window, no line
    view.refresh()
    assert not view.cue_line.isVisible() and view.band_lo.getData()[0][0] == pytest.approx(-10.0)


def test_rig_view_rehearses_a_fault_now_or_at_a_trial(qtbot):
    r = RigViewModel()
    r.apply(READY)
    sent: list[tuple] = []
    view = RigWindow(r, lambda mode: None, lambda *a: sent.append(a))
    qtbot.addWidget(view)
    view.show()
    qtbot.waitExposed(view)
    assert not view.fault_seconds.isEnabled() and view.fault_trial.currentText() == "now"
    assert view.fault_trial.count() == 1  # no session: now, or nothing
    view.fault_kind.setCurrentIndex(view.fault_kind.findData("nan-burst"))
    qtbot.mouseClick(view.inject_button, Qt.MouseButton.LeftButton)
    view.set_trials(range(3, 9))  # trials 1 and 2 have begun, of 8
    assert [view.fault_trial.itemText(i) for i in range(view.fault_trial.count())] == \
        ["now"] + [f"trial {k}" for k in range(3, 9)]
    view.fault_trial.setCurrentIndex(view.fault_trial.findData(4))
    assert view.fault_seconds.isEnabled()
    view.fault_seconds.setValue(2.5)
    view.fault_kind.setCurrentIndex(view.fault_kind.findData("sensor-stall"))
    qtbot.mouseClick(view.inject_button, Qt.MouseButton.LeftButton)
    assert sent == [("nan-burst", None, 3.0), ("sensor-stall", 4, 2.5)]
    assert view.inject_button.focusPolicy() == Qt.FocusPolicy.NoFocus
    view.set_trials(range(5, 9))  # trial 4 began before Inject: the next one still to come, not "now"
    assert view.fault_trial.currentData() == 5 and view.fault_seconds.isEnabled()
    view.set_trials(range(0))
    assert view.fault_trial.currentText() == "now" and not view.fault_seconds.isEnabled()


def test_the_app_model_sends_the_rehearsal_and_says_what_will_happen():
    from study_app.models.app import AppModel

    sent: list[object] = []
    app = AppModel(send=lambda cmd: sent.append(cmd) or True)
    app.apply(READY)
    app.rig_control.inject_fault("stale-pose", 3, 1.5)  # no session: refused here, saying why
    assert not sent and app.notices.notice.text == ("Fault rehearsal refused: a fault at trial 3 needs a running "
                                                    "session: start or resume one, or inject it now.")
    app.apply(m.SessionStarted(session_id=3, code="P01", kind="experiment", trials_total=8, start_position=0,
                               task=ForceRegulation(), max_trial_s=12.0, pause_s=2.0, cue_s=1.0, live_force_aid=False))
    app.apply(m.TrialStarted(1.0, 0, 1, 8, "FIRM", 1.2, "on"))
    assert app.rig_control.rehearsal_trials() == range(2, 9)
    app.apply(m.TrialStarted(9.0, 1, 2, 8, "FIRM", 1.2, "on"))
    app.rig_control.inject_fault("stale-pose", 2, 1.5)
    assert not sent and app.notices.notice.text == ("Fault rehearsal refused: trial 2 has already begun; the trials "
                                                    "still to come are 3 to 8.")
    app.rig_control.inject_fault("stale-pose", 9, 1.5)
    assert app.notices.notice.text.endswith("trial 9: the session has 8 trials; the trials still to come are 3 to 8.")
    app.rig_control.inject_fault("stale-pose", 3, 1.5)
    assert sent == [m.InjectFault("stale-pose", 3, 1.5)]
    app.apply(m.FaultInjected("stale-pose", "trial 3 + 1.5 s"))
    assert app.notices.notice is not None and app.notices.notice.level == "info"
    assert app.notices.notice.text == (
        "Rehearsal planned: robot pose stops (100 ms), 1.5 s after the cue of trial 3 (if trial 3 ends sooner, nothing "
        "is injected). It is a real fault of the simulated rig in this session, stored with it like any fault, and "
        "the record says it was rehearsed (a fault_rehearsal event, listed among the report's deviations): trial 3 "
        "is stored as aborted (cause: fault), does not count, and is run again later. The fault latches: the next "
        "cue waits for Reset faults.")
    app.apply(m.FaultInjected("nan-burst", "now"))
    assert "Rehearsal: F/T sensor sends NaN (5 ms), now: a real fault of the simulated rig. It is stored with the " \
        "running session" in app.notices.notice.text
    app.apply(m.SessionEnded(3, "aborted", "", 0, 1, 0))
    app.apply(m.FaultInjected("nan-burst", "now"))
    assert app.notices.notice.text.endswith("No session is running: nothing is stored. The fault latches until Reset "
                                            "faults.")


def test_a_placed_window_fits_with_its_title_bar(qtbot):
    """``move`` places the frame and ``resize`` sizes the contents: centring the contents put the bottom of the
    experimenter's window 5 px below a 1366×768 screen under a window manager (Xvfb + openbox)."""
    from PySide6.QtCore import QSize
    from PySide6.QtGui import QGuiApplication
    from PySide6.QtWidgets import QWidget

    from study_app.gui import placement

    w = QWidget()
    qtbot.addWidget(w)
    screen = QGuiApplication.primaryScreen()
    avail = screen.availableGeometry()
    placement.place(w, QSize(5000, 5000), screen)  # larger than any screen: shrunk to fit
    extra = placement.FRAME_ALLOWANCE
    assert w.y() >= avail.y() and w.y() + extra.height() + w.height() <= avail.y() + avail.height()
    assert w.x() >= avail.x() and w.x() + extra.width() + w.width() <= avail.x() + avail.width()


def test_the_rig_views_readout_is_never_drawn_over_the_instrument(qtbot):
    """A user trial: "contact force 1.61 N" was drawn over the grey stylus shaft, unreadable."""
    r = RigViewModel()
    r.apply(READY)
    r.update(r.surface_z_m - 0.0028, 1.61)  # the tip 2.8 mm into the tissue: the shaft reaches the top
    view = RigWindow(r, lambda mode: None)
    qtbot.addWidget(view)
    view.resize(760, 480)
    view.show()
    qtbot.waitExposed(view)
    canvas = view.canvas
    assert "contact force 1.61 N (ground truth)" in canvas.readout_lines()[0]
    strip, scene = canvas.readout_rect(), canvas.drawing_rect()
    assert strip.bottom() <= scene.top() and strip.height() >= 40  # the readout's strip is its own
    image = canvas.grab().toImage()
    dpr = image.devicePixelRatio()
    shaft = (150, 155, 165)  # the shaft's fill
    x_mid = int(canvas.width() / 2 * dpr)
    below = image.pixelColor(x_mid, int((scene.top() + 20) * dpr))
    assert (below.red(), below.green(), below.blue()) == shaft  # the shaft is drawn in the scene, up to its top
    for y in range(int(strip.bottom() * dpr)):  # and nowhere in the readout's strip
        for x in range(x_mid - int(10 * dpr), x_mid + int(10 * dpr)):
            c = image.pixelColor(x, y)
            assert (c.red(), c.green(), c.blue()) != shaft, (x, y)
