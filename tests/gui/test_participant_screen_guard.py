"""No trial is cued to an empty screen (issue 40, item 1): Start and Resume open the participant screen first (or
refuse, saying why), and a participant screen closed mid-trial aborts that trial with its cause, stored, and pauses
the session until the experimenter resumes -- which opens it again."""

from __future__ import annotations

import sqlite3

from conftest import SHORT_PROTOCOL, open_ready_window

from protocol.study.records import AbortCause
from study_app.engine import messages as m
from study_app.models.app import AppModel

TIMEOUT_MS = 60_000
#: Long trials (the stylus is on manual, so each runs to its cap), a short pause.
PROTOCOL = SHORT_PROTOCOL.replace("max_trial_s = 2.5", "max_trial_s = 20.0")
READY = m.EngineReady("ring", "sim", "virtual", {}, 0.0, (0.0, 0.0, 0.0), "autopilot")


def test_start_and_resume_open_the_participant_screen_or_are_refused():
    sent: list[object] = []
    app = AppModel(lambda cmd: sent.append(cmd) or True)
    app.apply(READY)
    app.setup.update(db_path="", code="P01", kind="experiment")
    app.setup.errors.clear()  # (no database here: only the screen is in question)
    opened: list[str] = []
    app.screen.opener = lambda: opened.append("open") or "off every monitor"  # it cannot be shown on any monitor
    for act in (lambda: app.control.resume_session(3), app.control.resume):
        sent.clear()
        act()
        assert opened and not [c for c in sent if isinstance(c, (m.ResumeSession, m.Resume))]
        assert "participant screen is off every monitor" in app.notices.notice.text
    app.screen.opener = lambda: ""  # opened: now it may
    app.control.resume_session(3)
    assert isinstance(sent[-1], m.ResumeSession)
    app.screen.shown(False, "closed")  # the engine hears each change, and a new engine hears it again
    assert sent[-1] == m.ParticipantScreenState(False, "closed")
    sent.clear()
    app.apply(READY)
    assert m.ParticipantScreenState(False, "closed") in sent


def test_a_participant_screen_closed_mid_trial_aborts_it_and_pauses_until_resumed(qtbot, tmp_path):
    w = open_ready_window(qtbot, tmp_path, PROTOCOL, speed=4.0, timeout_ms=TIMEOUT_MS)
    model, pw = w.model, w.participant_window
    assert not pw.isVisible()
    model.setup.update(code="P01", kind="experiment")
    w.session_actions.start_session()  # the participant screen closed: Start opens it
    assert pw.isVisible() and pw.unseen() == ""
    qtbot.waitUntil(lambda: model.session.trial is not None
                    and model.session.latest_t_s > model.session.trial.t_s + 0.5, timeout=TIMEOUT_MS)
    pw.close()  # the assistant closes the participant's window mid-trial
    qtbot.waitUntil(lambda: len(model.session.table.rows) == 1, timeout=TIMEOUT_MS)
    row = model.session.table.rows[0]
    assert row.abort_cause is AbortCause.PARTICIPANT_SCREEN and "participant screen was closed" in row.abort_reason
    qtbot.waitUntil(lambda: model.session.state == "paused", timeout=TIMEOUT_MS)
    assert model.cue.wait is not None and "participant screen was closed" in model.cue.wait.reason
    assert model.cue.wait.action == "resume"
    t0 = model.session.latest_t_s
    qtbot.waitUntil(lambda: model.session.latest_t_s > t0 + 2.0, timeout=TIMEOUT_MS)  # past the 0.3 s pause
    assert model.session.trial is None or model.session.trial.trial_index == 0  # no cue while it is closed
    w.session_actions.start_session()  # Space resumes: the screen opens again first
    assert pw.isVisible()
    qtbot.waitUntil(lambda: model.session.trial is not None and model.session.trial.trial_index == 1,
                    timeout=TIMEOUT_MS)
    c = sqlite3.connect(tmp_path / "study.db")
    try:
        assert c.execute("SELECT abort_cause FROM trials").fetchall() == [("participant_screen",)]
        assert c.execute("SELECT count(*) FROM events WHERE kind = 'participant_screen'").fetchone() == (1,)
    finally:
        c.close()
