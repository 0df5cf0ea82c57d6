"""A force-discrimination block run by hand in the GUI on the simulated rig (issue 43): the participant screen says
which force is presented (first, second), then asks which was stronger with a button per answer; the keys (←/→,
1/2) and the buttons answer once per question; the answer is stored with the trial and shown in the trial table,
whose columns are the task's; a key the task does not allow is refused in one line."""

from __future__ import annotations

from pathlib import Path

from conftest import open_ready_window
from PySide6.QtCore import Qt

from protocol.storage.schema import connect_readonly
from protocol.storage.trial_answers import trial_answers
from study_app.engine import messages as m

TIMEOUT_MS = 60_000
EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "discrimination.toml"


def test_a_discrimination_block_answered_by_keys_and_buttons(qtbot, tmp_path):
    protocol = EXAMPLE.read_text(encoding="utf-8").replace("trials = 60", "trials = 10").replace(
        "pause_s = 1.0", "pause_s = 0.3")
    w = open_ready_window(qtbot, tmp_path, protocol, speed=8.0, timeout_ms=TIMEOUT_MS)
    headlines: list[str] = []
    w.model.participant.changed.connect(lambda: headlines.append(w.participant_window.headline.text()))
    qtbot.keyClicks(w.setup_panel.code, "P01")
    w.model.setup.update(kind="experiment")
    qtbot.mouseClick(w.participant_button, Qt.MouseButton.LeftButton)
    qtbot.mouseClick(w.start_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.model.session.running, timeout=TIMEOUT_MS)
    assert w.trial_table.columnCount() == 6  # #, Target, Mode, Outcome, Answer, Note: the task's, not the paper's
    pw, model = w.participant_window, w.model.participant

    qtbot.waitUntil(lambda: model.phase == "answer", timeout=TIMEOUT_MS)
    assert pw.headline.text() == "Which was stronger?" and [b.text() for b in pw.answer_buttons] == [
        "first  (1)", "second  (2)"]
    assert "first" in headlines and "second" in headlines  # each force named while it was presented
    pw.activateWindow()
    qtbot.keyClick(pw, Qt.Key.Key_Right)  # → : the second
    qtbot.waitUntil(lambda: len(w.model.session.table.rows) == 1, timeout=TIMEOUT_MS)
    assert w.model.session.table.rows[0].answer == "2"
    assert w.trial_table.item(0, 4).text() in ("2 ✓", "2 ✗")

    qtbot.waitUntil(lambda: model.phase == "answer" and bool(pw.answer_buttons), timeout=TIMEOUT_MS)
    qtbot.mouseClick(pw.answer_buttons[0], Qt.MouseButton.LeftButton)  # the button "first"
    qtbot.waitUntil(lambda: len(w.model.session.table.rows) == 2, timeout=TIMEOUT_MS)
    assert w.model.session.table.rows[1].answer == "1"

    session_id = model.session_id
    assert session_id is not None
    w.model.commands(m.AnswerTrial(session_id, "3"), clear=False)
    qtbot.waitUntil(lambda: "answer = '3'" in w.notice.text(), timeout=TIMEOUT_MS)  # the engine's one line
    assert "answers are '1', '2'" in w.notice.text()
    w.close()
    conn = connect_readonly(tmp_path / "study.db")
    try:
        stored = trial_answers(conn)
    finally:
        conn.close()
    assert [a.answer for a in stored[:2]] == ["2", "1"]
