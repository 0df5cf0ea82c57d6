"""A study of several parts in the GUI: the form shows the participant's plan and proposes the next part (its kind
follows), each part started from the window is a session of its own, and the plan follows what is stored."""

from __future__ import annotations

import sqlite3

import pytest
from conftest import SHORT_PROTOCOL, open_ready_window
from PySide6.QtCore import Qt

from study_app.engine import messages as m
from study_app.engine.sessions import part_to_run
from study_app.models.setup import SetupModel

TIMEOUT_MS = 60_000
#: Practice, then the experiment: a two-part plan over the short protocol (training required before it).
PLAN = SHORT_PROTOCOL.replace("required = false", "required = true") + """
[[parts]]
name = "practice"
session = "training"
[[parts]]
name = "regulation"
"""


@pytest.fixture
def window(qtbot, tmp_path):
    return open_ready_window(qtbot, tmp_path, PLAN, speed=8.0, timeout_ms=TIMEOUT_MS)


def _parts(db) -> list[tuple[str, str, str]]:
    c = sqlite3.connect(db)
    try:
        return [(code, kind, status) for code, kind, status in c.execute(
            "SELECT p.code, s.kind, json_extract(s.protocol_json, '$.part.name') FROM sessions s "
            "JOIN participants p USING (participant_id) ORDER BY s.session_id")]
    finally:
        c.close()


def _run_part(qtbot, w) -> None:
    qtbot.mouseClick(w.start_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.model.session.running, timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: not w.model.session.running and w.model.setup.running_session is None,
                    timeout=TIMEOUT_MS)


def test_the_plan_is_shown_and_each_part_runs_as_its_own_session(qtbot, window, tmp_path) -> None:
    w = window
    setup = w.model.setup
    setup.update(code="P01")
    panel = w.setup_panel
    assert (setup.values.part, setup.values.kind) == ("practice", "training")
    assert panel.plan.isVisible() and not panel.kind.isEnabled()
    assert "▶ 1. practice — force regulation, training: to do" in panel.plan.text()
    assert "P01's plan: 0 of 2 parts done; next: practice" in panel.hint.text()
    _run_part(qtbot, w)
    qtbot.waitUntil(lambda: setup.values.part == "regulation", timeout=TIMEOUT_MS)
    assert setup.values.kind == "experiment" and setup.values.code == "P01"  # the same participant's next part
    qtbot.waitUntil(lambda: "1. practice — force regulation, training: done (session 1)" in panel.plan.text(),
                    timeout=TIMEOUT_MS)
    assert "▶ 2. regulation" in panel.plan.text()
    _run_part(qtbot, w)
    qtbot.waitUntil(lambda: setup.values.code == "", timeout=TIMEOUT_MS)  # the plan done: the next participant
    assert _parts(tmp_path / "study.db") == [("P01", "training", "practice"), ("P01", "experiment", "regulation")]


def test_the_form_refuses_a_part_run_before_its_training(tmp_path) -> None:
    proto = tmp_path / "p.toml"
    proto.write_text(PLAN, encoding="utf-8")
    setup = SetupModel()
    setup.update(db_path=str(tmp_path / "s.db"), protocol_path=str(proto), code="P01")
    assert setup.values.part == "practice"
    setup.update(part="regulation")
    assert setup.values.kind == "experiment"
    assert "P01 has no training part 'practice' session" in setup.errors["training"]
    setup.update(part="nothing")
    assert "part = 'nothing': this protocol's parts are practice, regulation" in setup.errors["part"]


def test_the_engine_runs_a_part_of_the_participants_order(tmp_path) -> None:
    from protocol.study.config import load_protocol

    proto = tmp_path / "p.toml"
    proto.write_text(PLAN, encoding="utf-8")
    protocol = load_protocol(proto)
    cmd = m.StartSession(str(tmp_path / "s.db"), "P01", "experiment", str(proto), 0, 1, part="regulation")
    part = part_to_run(cmd, protocol)
    assert part.part is not None and (part.part.name, part.part.position) == ("regulation", 2)
    with pytest.raises(ValueError, match="'practice' is a training part, not experiment"):
        part_to_run(m.StartSession(str(tmp_path / "s.db"), "P01", "experiment", str(proto), 0, 1, part="practice"),
                    protocol)
    with pytest.raises(ValueError, match="part = '': no part ''"):
        part_to_run(m.StartSession(str(tmp_path / "s.db"), "P01", "experiment", str(proto), 0, 1), protocol)
