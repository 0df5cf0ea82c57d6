"""The schedule of a returning participant in the real window: their first visit made days ago, the form shows each
visit's state and dates and proposes the next (visit, part); an overdue visit starts only with the experimenter's
reason (asked by Start, stored as the session's deviation exactly as ``run --visit`` stores it), as its own session
of that visit."""

from __future__ import annotations

import re
import sqlite3

from conftest import open_ready_window
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QMessageBox
from schedule_study import VISITS, first_visit_days_ago

TIMEOUT_MS = 60_000


def _stored(db) -> list[tuple[str, str, str]]:
    """Each stored session's (visit, part, status)."""
    c = sqlite3.connect(db)
    try:
        return [tuple(r) for r in c.execute(
            "SELECT json_extract(s.protocol_json, '$.part.visit.name'), json_extract(s.protocol_json, '$.part.name'), "
            "s.status FROM sessions s ORDER BY s.session_id")]
    finally:
        c.close()


def _events(db, session_id: int) -> list[tuple[str, str]]:
    c = sqlite3.connect(db)
    try:
        return [tuple(r) for r in c.execute("SELECT kind, detail FROM events WHERE session_id = ? AND kind IN "
                                            "('visit', 'deviation') ORDER BY rowid", (session_id,))]
    finally:
        c.close()


def _lines(shown: str) -> list[str]:
    """The schedule's lines as the label shows them (each visit coloured by its state)."""
    return [re.sub("<[^>]+>", "", line) for line in shown.split("<br>")]


def test_an_overdue_visit_of_a_returning_participant(qtbot, tmp_path, monkeypatch) -> None:
    proto = tmp_path / "visits.toml"
    proto.write_text(VISITS, encoding="utf-8")
    db = tmp_path / "study.db"
    first_visit_days_ago(monkeypatch, db, proto, days=12)  # the post-test (day 7 ± 1) is overdue
    w = open_ready_window(qtbot, tmp_path, VISITS, speed=8.0, timeout_ms=TIMEOUT_MS)
    setup, panel = w.model.setup, w.setup_panel
    qtbot.waitUntil(lambda: len(setup.known) == 2, timeout=TIMEOUT_MS)
    qtbot.keyClicks(panel.code, "P01")
    assert (setup.values.visit, setup.values.part) == ("post", "test")
    assert panel.visit.isVisible() and panel.visit.currentText() == "post" and panel.part.currentText() == "test"
    lines = _lines(panel.plan.text())
    assert lines[1].startswith("✓ 1. baseline, day 0 (") and lines[1].endswith("): done — practice done, test done")
    assert lines[2].startswith("▶ 2. post, day 7 ± 1 (") and lines[2].endswith("): overdue — test to do")
    assert "not yet" in lines[3] and "today study day 12" in panel.hint.text()
    assert "font-weight: bold\">▶ 2. post" in panel.plan.text()  # the overdue visit stands out
    assert panel.off_schedule.isVisible() and "outside its window: held on study day 12" in panel.off_schedule.text()
    # Start asks for the reason; No starts nothing
    qtbot.mouseClick(w.start_button, Qt.MouseButton.LeftButton)
    q = w.session_actions.questions["visit_deviation"]
    assert q.open and "The schedule refuses it: visit 'post' is outside its window" in q.box.text()
    qtbot.mouseClick(q.box.button(QMessageBox.StandardButton.No), Qt.MouseButton.LeftButton)
    assert len(_stored(db)) == 2 and not w.model.session.running
    # with the reason: the post visit's test runs as its own session, the deviation stored with it
    qtbot.mouseClick(w.start_button, Qt.MouseButton.LeftButton)
    q = w.session_actions.questions["visit_deviation"]
    qtbot.keyClicks(q.reason_field, "participant was ill on days 6-8")
    qtbot.mouseClick(q.box.button(QMessageBox.StandardButton.Yes), Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.model.session.running, timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: not w.model.session.running and setup.running_session is None, timeout=TIMEOUT_MS)
    assert _stored(db) == [("baseline", "practice", "completed"), ("baseline", "test", "completed"),
                           ("post", "test", "completed")]
    assert _events(db, 3) == [
        ("visit", "post (visit 2): held on study day 12, planned day 7 ± 1 (started in the GUI)"),
        ("deviation", "visit 'post' is outside its window: held on study day 12, planned for day 7 ± 1: participant "
                      "was ill on days 6-8")]
    # the visit done, the participant comes back for the retention test: the next participant's turn now
    qtbot.waitUntil(lambda: setup.values.code == "" and len(setup.known) == 3, timeout=TIMEOUT_MS)
    qtbot.keyClicks(panel.code, "P01")
    assert _lines(panel.plan.text())[2].startswith("✓ 2. post")
    assert (setup.values.visit, setup.schedule.rows()[2].visit.state) == ("retention", "not yet")
