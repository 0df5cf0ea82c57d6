"""A described participant, a questionnaire after each block, a note and an abort's reason -- through the window.

The protocol asks a required category and an integer about the participant and a weighted NASA-TLX after each
block of one haptic mode.  The form refuses Start until the required covariate is chosen and the number is in its
range (one line naming the covariate, the value and what is allowed); the session runs (the hand on manual, so
trials time out); trial 1 is aborted with a reason typed in the question; a note marked a deviation is saved from
the Note dialog; each questionnaire is answered on the participant screen by keyboard (and one rating by mouse),
and the next cue waits for it.  The database then holds the covariates, both sheets, the notes and the reason.
"""

from __future__ import annotations

import sqlite3

import pytest
from conftest import SHORT_PROTOCOL, open_ready_window
from PySide6.QtCore import QPoint, Qt
from PySide6.QtWidgets import QDialogButtonBox, QMessageBox

TIMEOUT_MS = 60_000
PROTOCOL = SHORT_PROTOCOL.replace("[design]\n", '[design]\nordering = "blocked_by_mode"\n').replace(
    "max_trial_s = 2.5", "max_trial_s = 4.0") + """
[[covariates]]
name = "group"
kind = "category"
levels = ["novice", "resident", "surgeon"]
required = true
label = "Surgical experience"

[[covariates]]
name = "years_experience"
kind = "integer"
min = 0
max = 50
unit = "years"

[[questionnaires]]
name = "workload"
kind = "nasa_tlx"
after = "block"
"""


@pytest.fixture
def window(qtbot, tmp_path):
    return open_ready_window(qtbot, tmp_path, PROTOCOL, speed=4.0, timeout_ms=TIMEOUT_MS)


def _answer_by_keyboard(qtbot, w, mouse_first: bool) -> None:
    """Six ratings (→ sets the middle, → once more: 55; the first by a click when ``mouse_first``), 15 pairs
    (1: the left one), then Enter sends."""
    view = w.participant_window.questions
    md = w.model.questionnaire
    for i in range(6):
        if i == 0 and mouse_first:
            scale = view.scale
            qtbot.mouseClick(scale, Qt.MouseButton.LeftButton, pos=QPoint(int(scale._x(20.0)), int(scale.mark_y())))
            assert md.value() == 20.0
        else:
            qtbot.keyClick(view, Qt.Key.Key_Right)
            qtbot.keyClick(view, Qt.Key.Key_Right)
            assert md.value() == 55.0
        qtbot.keyClick(view, Qt.Key.Key_Return)
    for _ in range(15):
        qtbot.keyClick(view, Qt.Key.Key_1)
    assert md.item is None and "All 21 questions answered" in view.position.text()
    qtbot.keyClick(view, Qt.Key.Key_Return)


def test_covariates_questionnaires_a_note_and_an_aborts_reason_through_the_window(qtbot, window, tmp_path) -> None:
    w = window
    panel = w.setup_panel
    qtbot.keyClicks(panel.code, "P01")
    w.model.setup.update(kind="experiment")
    fields = panel.covariate_fields
    assert fields.isVisibleTo(panel) and set(fields.fields) == {"group", "years_experience"}
    assert not w.start_button.isEnabled()
    # a number's unit and range stay in view in its question once a value is typed (the placeholder goes)
    assert fields.layout_.labelForField(fields.fields["years_experience"]).text() == "Years experience (0–50 years)"
    assert "covariate group = (none): required by the protocol; must be one of novice, resident, surgeon" in \
        panel.errors.text()
    fields.fields["group"].setCurrentIndex(3)  # surgeon
    qtbot.keyClicks(fields.fields["years_experience"], "-3")
    assert "covariate years_experience = '-3': must be a whole number from 0 to 50 years" in panel.errors.text()
    assert not w.start_button.isEnabled()
    fields.fields["years_experience"].clear()
    qtbot.keyClicks(fields.fields["years_experience"], "12")
    assert panel.errors.text() == "" and w.start_button.isEnabled()

    qtbot.mouseClick(w.start_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.model.session.phase == "active", timeout=TIMEOUT_MS)
    first = w.model.session.trial
    assert first is not None and first.trial_index == 0
    # the abort's question offers a reason; Yes aborts with it
    w.session_actions.confirm = None
    w.session_actions.abort_trial()
    q = w.session_actions.questions["abort_trial"]
    assert q.reason_field is not None
    q.reason_field.setText("participant let go of the instrument")
    qtbot.mouseClick(q.box.button(QMessageBox.StandardButton.Yes), Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: any(r.trial_index == 0 for r in w.model.session.table.rows), timeout=TIMEOUT_MS)

    # the first block is over: the questionnaire is on the participant screen, and the next cue waits
    md = w.model.questionnaire
    qtbot.waitUntil(lambda: md.active, timeout=TIMEOUT_MS)
    assert w.participant_window.pages.currentWidget() is w.participant_window.questions
    qtbot.waitUntil(lambda: w.model.cue.wait is not None and "questionnaire" in w.model.cue.wait.reason,
                    timeout=TIMEOUT_MS)
    assert w.model.session.trial is None or w.model.session.phase not in ("active", "cued")
    # a note on the aborted trial, marked a deviation, while the questionnaire waits
    w.session_actions.note(0)
    dlg = w.session_actions.note_dialog
    assert dlg is not None and dlg.about.currentData() == 0
    dlg.text.setPlainText("instrument re-gripped; trial 1 repeated at the end")
    dlg.deviation.setChecked(True)
    qtbot.mouseClick(dlg.buttons.button(QDialogButtonBox.StandardButton.Save), Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: "⚑ instrument re-gripped" in w.model.session.table.note_text(0), timeout=TIMEOUT_MS)
    _answer_by_keyboard(qtbot, w, mouse_first=True)
    qtbot.waitUntil(lambda: not md.active, timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: md.active, timeout=TIMEOUT_MS)  # after the other block
    _answer_by_keyboard(qtbot, w, mouse_first=False)
    qtbot.waitUntil(lambda: w.model.session.state == "ended", timeout=TIMEOUT_MS)

    c = sqlite3.connect(tmp_path / "study.db")
    try:
        assert c.execute("SELECT name, kind, value FROM covariates ORDER BY name").fetchall() == [
            ("group", "category", "surgeon"), ("years_experience", "integer", "12")]
        sheets = c.execute("SELECT block, COUNT(*), SUM(rating IS NOT NULL), MIN(rating), MAX(rating) FROM "
                           "questionnaire_answers GROUP BY block ORDER BY MIN(rowid)").fetchall()
        notes = c.execute("SELECT trial_index, text, deviation, t_s IS NOT NULL FROM notes ORDER BY rowid").fetchall()
        reason = c.execute("SELECT abort_reason FROM trials WHERE trial_index = 0").fetchone()[0]
        status = c.execute("SELECT status FROM sessions").fetchone()[0]
    finally:
        c.close()
    assert [(b, n, r) for b, n, r, _, _ in sheets] == [(first.haptic_mode, 21, 6), (sheets[1][0], 21, 6)]
    assert sheets[0][3:] == (20.0, 55.0) and sheets[1][3:] == (55.0, 55.0)
    assert notes == [(0, "reason for the abort: participant let go of the instrument", 0, 1),
                     (0, "instrument re-gripped; trial 1 repeated at the end", 1, 1)]
    assert reason == "aborted by the experimenter: participant let go of the instrument"
    assert status == "completed"
    note = w.trial_table.item(0, w.trial_table.note_column).text()  # (the last: the task's measures before it)
    assert note.startswith("reason for the abort: participant let go") and "⚑ instrument re-gripped" in note
