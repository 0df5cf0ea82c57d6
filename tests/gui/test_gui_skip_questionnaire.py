"""The experimenter skips a questionnaire that waits for the participant -- through the window (issue 44).

A weighted NASA-TLX after each block of one haptic mode.  After the first block it waits on the participant screen
and the next cue with it; the experimenter window shows *Skip questionnaire…*, whose question offers a reason; Yes
stores it as skipped (an event of kind ``questionnaire_skipped``, one of the deviations the report lists, with the
reason), the participant screen closes it and the session goes on.  The second block's is answered as usual.  A
resume would not ask the skipped one again (``answered_blocks``).
"""

from __future__ import annotations

import sqlite3

import pytest
from conftest import SHORT_PROTOCOL, open_ready_window
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QMessageBox

from protocol.runner.study_rules import DEVIATION_KINDS
from protocol.storage.annotations import answered_blocks
from protocol.study.questionnaires import QUESTIONNAIRE_SKIPPED_EVENT

TIMEOUT_MS = 60_000
PROTOCOL = SHORT_PROTOCOL.replace("[design]\n", '[design]\nordering = "blocked_by_mode"\n') + """
[[questionnaires]]
name = "workload"
kind = "nasa_tlx"
weighted = false
after = "block"
"""


@pytest.fixture
def window(qtbot, tmp_path):
    return open_ready_window(qtbot, tmp_path, PROTOCOL, speed=4.0, timeout_ms=TIMEOUT_MS)


def test_the_experimenter_skips_a_waiting_questionnaire_stored_as_a_deviation(qtbot, window, tmp_path) -> None:
    w = window
    qtbot.keyClicks(w.setup_panel.code, "P01")
    w.model.setup.update(kind="experiment")
    assert not w.skip_questionnaire_button.isVisibleTo(w)
    qtbot.mouseClick(w.start_button, Qt.MouseButton.LeftButton)
    md = w.model.questionnaire
    qtbot.waitUntil(lambda: md.active, timeout=TIMEOUT_MS)
    first = md.block
    qtbot.waitUntil(lambda: w.model.cue.wait is not None and "questionnaire" in w.model.cue.wait.reason,
                    timeout=TIMEOUT_MS)
    assert w.skip_questionnaire_button.isVisibleTo(w)
    w.session_actions.confirm = None
    qtbot.mouseClick(w.skip_questionnaire_button, Qt.MouseButton.LeftButton)
    q = w.session_actions.questions["skip_questionnaire"]
    assert '"workload" after the haptics ' + first.upper() + " block" in q.box.text()
    assert q.reason_field is not None
    q.reason_field.setText("participant felt unwell; asked to continue")
    qtbot.mouseClick(q.box.button(QMessageBox.StandardButton.Yes), Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: not md.active, timeout=TIMEOUT_MS)  # the participant screen closes it
    assert not w.skip_questionnaire_button.isVisibleTo(w)
    qtbot.waitUntil(lambda: md.active, timeout=TIMEOUT_MS)  # the next block ran: its questionnaire, answered
    assert md.block != first
    for _ in range(6):
        qtbot.keyClick(w.participant_window.questions, Qt.Key.Key_Right)
        qtbot.keyClick(w.participant_window.questions, Qt.Key.Key_Return)
    qtbot.keyClick(w.participant_window.questions, Qt.Key.Key_Return)
    qtbot.waitUntil(lambda: w.model.session.state == "ended", timeout=TIMEOUT_MS)

    c = sqlite3.connect(tmp_path / "study.db")
    try:
        skipped = c.execute("SELECT detail FROM events WHERE kind = ?", (QUESTIONNAIRE_SKIPPED_EVENT,)).fetchall()
        sheets = c.execute("SELECT block, COUNT(*) FROM questionnaire_answers GROUP BY block").fetchall()
        (sid,) = c.execute("SELECT session_id FROM sessions").fetchone()
        asked = sorted(answered_blocks(c, sid))
        status = c.execute("SELECT status FROM sessions").fetchone()[0]
    finally:
        c.close()
    assert QUESTIONNAIRE_SKIPPED_EVENT in DEVIATION_KINDS  # the report lists it with the deviations
    assert skipped == [(f"workload/{first}: workload (NASA-TLX) after the haptics {first.upper()} block skipped by "
                        "the experimenter, not answered (reason: participant felt unwell; asked to continue)",)]
    assert len(sheets) == 1 and sheets[0][0] != first and sheets[0][1] == 6  # the other block's six ratings
    assert asked == sorted([("workload", first), ("workload", sheets[0][0])])  # a resume asks neither again
    assert status == "completed"
