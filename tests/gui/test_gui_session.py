"""A whole short session on the simulated rig, driven through the GUI's own controls (engine in its own process)."""

from __future__ import annotations

import json
import re
import sqlite3

import pytest
from PySide6.QtCore import QSettings, Qt
from PySide6.QtWidgets import QApplication

from study_app.engine.setup import HostConfig
from study_app.gui.main_window import ExperimenterWindow

TIMEOUT_MS = 30_000


@pytest.fixture
def window(qtbot, tmp_path):
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    # virtual clock at 3x real time: the 2-trial protocol takes a few seconds
    w = ExperimenterWindow(HostConfig(clock="virtual", speed=3.0), settings, str(tmp_path / "study.db"))
    w.session_actions.confirm = lambda title, text: True
    qtbot.addWidget(w)  # closed at teardown: the engine is shut down and joined
    w.show()
    qtbot.waitUntil(lambda: w.model.session.state == "ready", timeout=TIMEOUT_MS)
    return w


def rows(path, sql):
    c = sqlite3.connect(path)
    try:
        return c.execute(sql).fetchall()
    finally:
        c.close()


def test_whole_session_through_the_gui(window, qtbot, tmp_path, short_protocol):
    w = window
    db = str(tmp_path / "study.db")
    seen_screens: list[tuple[bool, str, str]] = []

    def record_screen() -> None:
        pw = w.participant_window
        seen_screens.append((not pw.gauge.isHidden(), pw.headline.text(), pw.subline.text()))

    w.model.participant.changed.connect(record_screen)

    # calibration wizard: a degenerate set is refused with the reason, a good one accepted
    qtbot.mouseClick(w.calibrate_button, Qt.MouseButton.LeftButton)
    wiz = w.calibration_wizard
    assert wiz.isVisible()
    wiz.pose_set.setCurrentText("tool-down only")
    qtbot.mouseClick(wiz.run_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.model.calibration.state == "refused", timeout=TIMEOUT_MS)
    assert "do not determine the payload" in wiz.verdict.text()
    wiz.pose_set.setCurrentText("quick")
    qtbot.mouseClick(wiz.run_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.model.calibration.state == "accepted", timeout=TIMEOUT_MS)
    accepted = w.model.calibration.active
    wiz.close()

    # setup through the form
    panel = w.setup_panel
    assert not w.start_button.isEnabled()  # no participant code yet
    qtbot.keyClicks(panel.code, "P07")
    panel.protocol.setText(short_protocol)
    panel.protocol.editingFinished.emit()
    assert panel.kind.currentText() == "training"  # the proposed next step of a new participant
    w.model.setup.update(kind="experiment")  # (this protocol does not require it: its tests are elsewhere)
    assert w.start_button.isEnabled()
    qtbot.mouseClick(w.participant_button, Qt.MouseButton.LeftButton)

    # Space starts (focus away from the text fields, where Space is a character)
    w.activateWindow()
    qtbot.waitUntil(lambda: QApplication.activeWindow() is w, timeout=TIMEOUT_MS)
    w.plots.setFocus()
    qtbot.keyClick(w.plots, Qt.Key.Key_Space)
    qtbot.waitUntil(lambda: w.model.session.running, timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: w.model.session.trial is not None, timeout=TIMEOUT_MS)
    assert not w.start_button.isEnabled() and w.abort_session_button.isEnabled()

    # Esc aborts the running trial (after confirmation): stored as aborted and run again at the end
    qtbot.waitUntil(lambda: w.abort_trial_button.isEnabled(), timeout=TIMEOUT_MS)
    qtbot.keyClick(w.plots, Qt.Key.Key_Escape)
    qtbot.waitUntil(lambda: w.trial_table.rowCount() == 1, timeout=TIMEOUT_MS)
    assert w.trial_table.item(0, 3).text().startswith("aborted")

    qtbot.waitUntil(lambda: w.model.session.state == "ended", timeout=TIMEOUT_MS)
    assert w.trial_table.rowCount() == 3
    assert w.progress.label.text() == "session 1 completed"
    # ready for the next participant: the code cleared, the next number suggested from the database
    qtbot.waitUntil(lambda: w.setup_panel.number.value() == 2, timeout=TIMEOUT_MS)
    assert panel.code.text() == "" and not w.start_button.isEnabled()
    qtbot.keyClicks(panel.code, "P07")  # the same code again: refused before Start, where the form is
    assert not w.start_button.isEnabled() and "already has a completed experiment session" in panel.errors.text()
    panel.code.clear()
    qtbot.keyClicks(panel.code, "P08")
    assert w.start_button.isEnabled()

    stored = rows(db, "SELECT trial_index, outcome, repeat_of FROM trials ORDER BY trial_index")
    assert [r[0] for r in stored] == [0, 1, 2] and stored[0][1] == "aborted" and stored[2][2] == 0
    (status, cal_json), = rows(db, "SELECT status, calibration_json FROM sessions")
    assert status == "completed" and json.loads(cal_json) == accepted
    # the plots were fed from the shared ring
    assert len(w.model.plots.t) > 1000

    # the participant never saw force: no gauge, no number on any screen of the experiment session
    assert seen_screens, "the participant screen never changed"
    assert not any(gauge for gauge, _, _ in seen_screens)
    assert not any(re.search(r"\d", head + sub) for _, head, sub in seen_screens)
    assert ("GENTLE" in {h for _, h, _ in seen_screens}) and ("Rest" in {h for _, h, _ in seen_screens})
    # settings remembered for next time
    assert w.settings.value("setup/protocol_path") == short_protocol


def test_closing_the_window_mid_trial_leaves_complete_records(window, qtbot, tmp_path, short_protocol):
    w = window
    db = str(tmp_path / "study.db")
    w.model.setup.update(code="P08", protocol_path=short_protocol)
    qtbot.mouseClick(w.start_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.model.session.trial is not None and
                    w.model.session.latest_t_s > w.model.session.trial.t_s + 0.3, timeout=TIMEOUT_MS)
    asked = []
    w.session_actions.confirm = lambda title, text: asked.append(title) or True
    w.close()
    assert asked == ["Quit"]
    assert not w.bridge.client.alive
    assert rows(db, "SELECT trial_index, outcome, abort_reason FROM trials") == [
        (0, "aborted", "the experimenter GUI closed")]
    assert rows(db, "SELECT status FROM sessions") == [("running",)]  # resumable from the list
