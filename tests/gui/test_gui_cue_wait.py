"""Between trials the Trials tab says why the next cue waits, for how long, and offers what ends the wait.

The real window and engine (virtual clock at 4x); nobody presses the stylus, so each trial runs to its cap.
"""

from __future__ import annotations

import pytest
from conftest import SHORT_PROTOCOL, open_ready_window
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QApplication

TIMEOUT_MS = 30_000
# four trials, a 3 s pause between them (0.75 s of real time): long enough to be seen
PROTOCOL = SHORT_PROTOCOL.replace("trials_per_cell = 1", "trials_per_cell = 2").replace("pause_s = 0.3",
                                                                                        "pause_s = 3.0")


@pytest.fixture
def window(qtbot, tmp_path):
    return open_ready_window(qtbot, tmp_path, PROTOCOL, speed=4.0, timeout_ms=TIMEOUT_MS)


def test_the_trials_tab_says_why_the_next_cue_waits_and_ends_the_wait(qtbot, window) -> None:
    w = window
    banner = w.cue_wait
    assert banner.isHidden()  # no session: nothing waits
    w.model.setup.update(code="P01", kind="experiment")
    qtbot.mouseClick(w.start_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.model.session.phase == "active", timeout=TIMEOUT_MS)
    assert banner.isHidden()  # a trial runs: its cue has come

    # the protocol's pause: why, and the seconds left; nothing to press
    qtbot.waitUntil(lambda: w.model.session.phase == "pause" and w.model.cue.wait is not None
                    and w.model.cue.wait.left_s is not None and w.model.cue.wait.left_s < 2.9, timeout=TIMEOUT_MS)
    text = banner.label.text()
    assert text.startswith("Next cue waits: the protocol's 3 s pause between trials · ") and text.endswith(" s left")
    assert not banner.isHidden() and banner.button.isHidden()

    # a fault that only a reset clears, during trial 2: the next cue waits for Reset faults, and the banner has it
    qtbot.waitUntil(lambda: w.model.session.phase == "active", timeout=TIMEOUT_MS)
    w.model.rig_control.inject_fault("device-error", None, 0.0)
    qtbot.waitUntil(lambda: w.model.cue.wait is not None and w.model.cue.wait.action == "reset_faults",
                    timeout=TIMEOUT_MS)
    assert banner.label.text().startswith("Next cue waits: fault latched (HAPTIC_DEVICE")
    # the headline above the plots says the same, never "The next trial is due"
    assert w.progress.label.full_text().startswith("Next trial waits: fault latched (HAPTIC_DEVICE")
    assert w.progress.label.full_text().endswith(" · Reset faults")
    assert banner.button.text() == "Reset faults" and banner.button.isVisible()
    assert "fault log under Devices & health" in banner.help.text()
    # a short Trials tab keeps the table's rows before the explanation, which folds into the headline's tooltip
    # (seen at 1366×768 beside the participant screen: one row left under the banner); a tall one shows it whole
    right = w.tabs.parentWidget()
    w.resize(990, 728)
    right.setSizes([5000, 0])
    QApplication.processEvents()
    assert banner.folded and banner.help.isHidden() and "fault log" in banner.label.toolTip()
    w.resize(990, 1060)  # (a 1920×1080 screen's window)
    right.setSizes([0, 5000])
    QApplication.processEvents()
    assert not banner.folded and banner.help.isVisible() and banner.label.toolTip() == ""
    table = w.trial_table
    assert table.viewport().height() >= 3 * table.verticalHeader().defaultSectionSize()
    qtbot.waitUntil(lambda: "waiting" in banner.label.text(), timeout=TIMEOUT_MS)  # and for how long
    done = w.model.session.completed + w.model.session.aborted
    qtbot.mouseClick(banner.button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.model.session.phase == "active", timeout=TIMEOUT_MS)  # the cue came
    assert w.model.session.completed + w.model.session.aborted == done

    # a pause the experimenter asked for: said so, with Resume
    qtbot.mouseClick(w.pause_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.model.session.state == "paused" and w.model.cue.wait is not None
                    and w.model.cue.wait.action == "resume", timeout=TIMEOUT_MS)
    assert banner.label.text().startswith("Next cue waits: the session is paused")
    assert banner.button.text() == "Resume"
    qtbot.mouseClick(banner.button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.model.session.phase == "active", timeout=TIMEOUT_MS)


def test_abort_session_says_whether_a_trial_is_stored_as_aborted(qtbot, window) -> None:
    """A user trial: paused, no trial running, and Abort session still said "The running trial is stored as
    aborted"."""
    w = window
    asked: list[str] = []
    w.session_actions.confirm = lambda title, text: asked.append(text) and False  # answer No: read the question only
    w.model.setup.update(code="P01", kind="experiment")
    qtbot.mouseClick(w.start_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.model.session.phase == "active", timeout=TIMEOUT_MS)
    w.session_actions.abort_session()
    assert "Trial 1 (" in asked[-1] and "is running: it is stored as aborted" in asked[-1]
    qtbot.mouseClick(w.pause_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.model.session.state == "paused", timeout=TIMEOUT_MS)
    w.session_actions.abort_session()
    assert "No trial is running (the session is paused): none is stored as aborted." in asked[-1]
    assert "is running: it is stored" not in asked[-1] and "not yet done are not run" in asked[-1]
    assert w.model.session.running  # No: nothing was aborted
