"""A question asked from an extra window opens over it: the rig view (or a participant screen on the
experimenter's monitor) stays in front, and gets the keyboard back after the answer, which defaults to No.

(Checked in a real X server with a window manager too -- Xvfb + openbox + xdotool: before, the experimenter's
window was raised over the rig view while the question was open.)
"""

from __future__ import annotations

import pytest
from conftest import SHORT_PROTOCOL, open_ready_window
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QApplication, QMessageBox

TIMEOUT_MS = 30_000
PROTOCOL = SHORT_PROTOCOL.replace("max_trial_s = 2.5", "max_trial_s = 60.0")


@pytest.fixture
def window(qtbot, tmp_path):
    return open_ready_window(qtbot, tmp_path, PROTOCOL, speed=1.0, timeout_ms=TIMEOUT_MS)


@pytest.mark.parametrize("which", ["rig_window", "participant_window"])
def test_esc_in_an_extra_window_asks_over_it_and_no_is_the_default(qtbot, window, which) -> None:
    w = window
    w.model.setup.update(code="P01", kind="experiment")
    qtbot.mouseClick(w.start_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.model.session.phase == "active", timeout=TIMEOUT_MS)
    extra = getattr(w, which)
    w.open_window(extra)
    qtbot.waitUntil(lambda: QApplication.activeWindow() is extra, timeout=TIMEOUT_MS)
    qtbot.keyClick(extra.focusWidget() or extra, Qt.Key.Key_Escape)  # bound application-wide
    q = w.session_actions.questions.get("abort_trial")
    assert q is not None and q.open
    assert q.box.parentWidget() is extra  # over the window the experimenter looks at, not the main window
    assert q.box.defaultButton() is q.box.button(QMessageBox.StandardButton.No)
    qtbot.keyClick(q.box, Qt.Key.Key_Return)  # Enter answers No
    assert not q.open and w.model.session.phase == "active" and not w.model.session.table.rows
    qtbot.waitUntil(lambda: QApplication.activeWindow() is extra, timeout=TIMEOUT_MS)
