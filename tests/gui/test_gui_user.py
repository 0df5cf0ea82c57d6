"""The experimenter's window as a user meets it: keyboard, confirmations bound to their trial, pause, resume.

The real window and real dialogs (no ``confirm`` stand-in), the engine in its own process on the virtual
clock.  The stylus is held by "me" (manual driving) and never pressed, so every trial runs to its cap:
what happens depends on the order of events, never on how fast this machine is.
"""

from __future__ import annotations

import sqlite3

import pytest
from conftest import SHORT_PROTOCOL
from PySide6.QtCore import QSettings, Qt
from PySide6.QtWidgets import QApplication, QMessageBox

from study_app.engine.setup import HostConfig
from study_app.gui.main_window import ExperimenterWindow
from study_app.gui.setup_panel import SPACE_WHILE_TYPING

TIMEOUT_MS = 30_000

# the short GUI protocol with two trials per cell and a 6 s cap (time to answer a question within a trial)
PROTOCOL = SHORT_PROTOCOL.replace("trials_per_cell = 1", "trials_per_cell = 2").replace("max_trial_s = 2.5",
                                                                                        "max_trial_s = 6.0")
assert "trials_per_cell = 2" in PROTOCOL and "max_trial_s = 6.0" in PROTOCOL


@pytest.fixture
def setup(tmp_path):
    proto = tmp_path / "user.toml"
    proto.write_text(PROTOCOL, encoding="utf-8")
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    settings.setValue("setup/protocol_path", str(proto))
    return settings, str(tmp_path / "study.db")


def open_window(qtbot, settings, db) -> ExperimenterWindow:
    # virtual clock at 4x real time: a 6 s trial takes 1.5 s
    w = ExperimenterWindow(HostConfig(clock="virtual", speed=4.0), settings, db)
    # at teardown (also of a failed test) quit without asking, so the engine is shut down and joined
    qtbot.addWidget(w, before_close_func=lambda win: setattr(win.session_actions, "confirm", lambda title, text: True))
    w.show()
    qtbot.waitUntil(lambda: w.model.session.state == "ready", timeout=TIMEOUT_MS)
    w.model.rig_control.set_driver("manual")  # nobody presses: each trial times out at its cap
    return w


def question(w: ExperimenterWindow, key: str) -> QMessageBox | None:
    q = w.session_actions.questions.get(key)
    return q.box if q is not None and q.open else None


def active_trial(w: ExperimenterWindow, index: int):
    return lambda: (w.model.session.trial is not None and w.model.session.trial.trial_index == index
                    and w.model.session.phase == "active")


def test_keyboard_late_yes_pause_and_resume_as_a_user_meets_them(qtbot, setup):
    settings, db = setup
    w = open_window(qtbot, settings, db)
    panel = w.setup_panel
    assert (w.width() <= 1366 and w.height() <= 768) or w.screen().availableGeometry().height() > 768
    assert panel.number.value() == 1 and panel.hint.text().startswith("Enter the participant's code")

    # the experiment (the protocol does not require training: that rule is test_gui_study_rules.py's)
    w.model.setup.update(kind="experiment")
    # the code, then a Space typed into it: neither part of the code nor Start ("P 11" would start "P")
    panel.code.setFocus()
    qtbot.keyClicks(panel.code, "P1")
    qtbot.keyClick(panel.code, Qt.Key.Key_Space)
    assert panel.hint.text() == SPACE_WHILE_TYPING and panel.hint.isVisible()  # until the next change
    qtbot.keyClicks(panel.code, "1")
    assert panel.code.text() == "P11" and not w.model.session.running
    # a number field showing no number it takes ("0", or empty) is an error: Start would use a value not on screen
    panel.number.lineEdit().selectAll()
    qtbot.keyClicks(panel.number, "0")
    assert panel.number.text() == "0" and panel.number.value() != 0
    assert panel.errors.text() == "participant number = '0': must be a whole number from 1 to 9999"
    qtbot.keyClick(panel.number, Qt.Key.Key_Return)
    assert not w.model.session.running and w.notice.text().startswith("Cannot start: participant number = '0'")
    qtbot.keyClick(panel.number, Qt.Key.Key_Backspace)
    qtbot.keyClicks(panel.number, "1")
    assert panel.errors.text() == "" and panel.number.value() == 1
    # Enter in the code field: Start, as a form is submitted
    qtbot.keyClick(panel.code, Qt.Key.Key_Return)
    qtbot.waitUntil(lambda: w.model.session.running, timeout=TIMEOUT_MS)
    assert panel.code.text() == "P11" and w.model.session.session.code == "P11"

    # Esc during trial 1; the question stays open while trial 1 ends: it closes itself, nothing is aborted
    qtbot.waitUntil(active_trial(w, 0), timeout=TIMEOUT_MS)
    qtbot.keyClick(w.plots, Qt.Key.Key_Escape)
    box = question(w, "abort_trial")
    assert box is not None and "trial 1 " in box.text()
    assert box.defaultButton() is box.button(QMessageBox.StandardButton.No)
    qtbot.waitUntil(lambda: question(w, "abort_trial") is None, timeout=TIMEOUT_MS)
    assert w.trial_table.item(0, 3).text() == "timeout"
    assert w.notice.text() == "Trial 1 ended before you answered: nothing was aborted." and w.notice_row.isVisible()
    # a Yes that left the window just before it heard of the end: the engine refuses it for the next trial
    qtbot.waitUntil(active_trial(w, 1), timeout=TIMEOUT_MS)
    w.model.control.abort_trial(0)
    qtbot.waitUntil(lambda: w.notice.text() == "trial 1 had already ended: nothing was aborted", timeout=TIMEOUT_MS)

    # Esc during trial 2 and Yes in time: trial 2, and only trial 2, is aborted
    # (a click back into the window: offscreen, a closing question gives the keyboard to the window shown last, the
    # participant screen Start opened; a window manager gives it back to the question's parent, this window)
    w.activateWindow()
    qtbot.waitUntil(lambda: QApplication.activeWindow() is w, timeout=TIMEOUT_MS)
    qtbot.keyClick(w.plots, Qt.Key.Key_Escape)
    box = question(w, "abort_trial")
    assert box is not None and "trial 2 " in box.text()
    box.button(QMessageBox.StandardButton.Yes).click()
    qtbot.waitUntil(lambda: w.trial_table.rowCount() == 2, timeout=TIMEOUT_MS)
    assert w.trial_table.item(1, 3).text().startswith("aborted")

    # Pause during trial 3: shown as pending until the trial ends, then paused
    qtbot.waitUntil(active_trial(w, 2), timeout=TIMEOUT_MS)
    qtbot.mouseClick(w.pause_button, Qt.MouseButton.LeftButton)
    assert w.pause_button.text() == "Pause requested…" and not w.pause_button.isEnabled()
    assert w.progress.label.full_text().endswith("pause requested: pausing after this trial")
    qtbot.waitUntil(lambda: w.model.session.state == "paused", timeout=TIMEOUT_MS)
    assert w.progress.label.full_text() == "Paused · Resume (Space) to continue"
    count = "2 of 4 trials done · 1 aborted · 1 re-run left"  # the re-run is no fifth designed trial
    assert w.progress.count.full_text().startswith(count)
    fraction = w.progress.bar.value()
    assert fraction == 500  # 2 of the 4 designed trials

    # quitting asks, and Enter means No
    w.close()
    box = question(w, "quit")
    assert box is not None and w.isVisible()
    qtbot.keyClick(box, Qt.Key.Key_Return)
    assert question(w, "quit") is None and w.isVisible() and w.bridge.client.alive
    w.close()
    question(w, "quit").button(QMessageBox.StandardButton.Yes).click()
    qtbot.waitUntil(lambda: not w.bridge.client.alive, timeout=TIMEOUT_MS)
    size = w.size()

    # the next day: the same database; the interrupted session is resumed with its table and progress
    w2 = open_window(qtbot, settings, db)
    assert w2.size() == size  # the window opens where and as it was left
    qtbot.waitUntil(lambda: w2.setup_panel.resumable.count() == 1, timeout=TIMEOUT_MS)
    assert w2.setup_panel.number.value() == 2  # the next free number is suggested
    w2.setup_panel.resumable.setCurrentRow(0)
    qtbot.mouseClick(w2.setup_panel.resume_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w2.model.session.running, timeout=TIMEOUT_MS)
    assert w2.trial_table.rowCount() == 3
    assert [w2.trial_table.item(i, 3).text()[:7] for i in range(3)] == ["timeout", "aborted", "timeout"]
    assert w2.progress.bar.value() == fraction  # 2 of 4, not 0 of 2
    assert w2.progress.count.full_text().startswith(count)
    assert (w2.setup_panel.code.text(), w2.setup_panel.number.value()) == ("P11", 1)
    assert w2.setup_panel.errors.isHidden()
    # the participant screen opens at a usable size on the screen, beside the controls, never over them
    w2.open_window(w2.participant_window)
    pw = w2.participant_window
    assert pw.width() >= 320 and pw.height() >= 240  # (an 800×600 screen here; on 1366×768: test_views)
    assert w2.screen().availableGeometry().contains(pw.frameGeometry())
    controls = w2.left_column
    assert pw.frameGeometry().left() > controls.mapToGlobal(controls.rect().topRight()).x()

    c = sqlite3.connect(db)
    try:
        stored = c.execute("SELECT trial_index, outcome FROM trials ORDER BY trial_index").fetchall()
    finally:
        c.close()
    assert stored[:3] == [(0, "timeout"), (1, "aborted"), (2, "timeout")]
