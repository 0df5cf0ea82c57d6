"""Recovering from a dead study engine or a dead haptic loop, as an experimenter meets it.

The real window, the engine in its own process on the virtual clock.  The engine process is killed
(as a crash would) during a session: the window says so, offers *Restart engine*, and after the restart
lists the interrupted session, selected for resume, with the plots empty.  A haptic loop that died while
its process lives on leads the same way.
"""

from __future__ import annotations

import math
import os
import signal

import pytest
from PySide6.QtCore import QSettings, Qt

from study_app.engine import messages as m
from study_app.engine.setup import HostConfig
from study_app.gui.main_window import ExperimenterWindow

TIMEOUT_MS = 30_000


@pytest.fixture
def window(qtbot, tmp_path, short_protocol):
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    settings.setValue("setup/protocol_path", short_protocol)
    w = ExperimenterWindow(HostConfig(clock="virtual", speed=4.0), settings, str(tmp_path / "study.db"))
    qtbot.addWidget(w, before_close_func=lambda win: setattr(win.session_actions, "confirm", lambda title, text: True))
    w.show()
    qtbot.waitUntil(lambda: w.model.session.state == "ready", timeout=TIMEOUT_MS)
    w.model.rig_control.set_driver("manual")  # nobody presses: each trial runs to its cap
    return w


def start_session(qtbot, w: ExperimenterWindow, code: str) -> int:
    w.model.setup.update(code=code, kind="experiment")
    qtbot.mouseClick(w.start_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.model.session.phase == "active", timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: w.model.tick() >= 0 and len(w.model.plots.t) > 0, timeout=TIMEOUT_MS)
    return w.model.session.session.session_id


def restart_and_find(qtbot, w: ExperimenterWindow, sid: int) -> None:
    assert w.engine_row.isVisible() and w.restart_button.isEnabled()
    old_pid = w.bridge.client.pid
    qtbot.mouseClick(w.restart_button, Qt.MouseButton.LeftButton)
    assert len(w.model.plots.t) == 0 and w.model.plots.ring is None  # the plots start afresh
    assert not w.engine_row.isVisible() and w.model.session.trial is None
    qtbot.waitUntil(lambda: w.model.session.state == "ready", timeout=TIMEOUT_MS)
    assert w.bridge.client.pid != old_pid
    # the interrupted session is listed and selected, ready for Resume selected
    qtbot.waitUntil(lambda: w.setup_panel.resumable.count() >= 1, timeout=TIMEOUT_MS)
    assert w.setup_panel.selected_session() == sid
    assert w.setup_panel.resume_button.isEnabled()
    qtbot.mouseClick(w.setup_panel.resume_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.model.session.running and w.model.session.session.session_id == sid,
                    timeout=TIMEOUT_MS)


def test_an_engine_killed_in_a_session_is_restarted_and_its_session_resumed(qtbot, window) -> None:
    w = window
    sid = start_session(qtbot, w, "P01")
    assert not w.engine_row.isVisible()
    ring = os.path.join("/dev/shm", w.bridge.client.ring_name.lstrip("/"))
    assert os.path.exists(ring)
    os.kill(w.bridge.client.pid, signal.SIGKILL)  # as a crash would
    qtbot.waitUntil(lambda: w.engine_row.isVisible(), timeout=TIMEOUT_MS)
    text = w.engine_label.text()
    # what happened to the engine and to the session, in the same place; the rest in the tooltip
    assert text == f"The study engine exited unexpectedly. Session {sid} was interrupted; its stored trials are kept."
    assert w.restart_button.toolTip().endswith(f"After Restart engine, session {sid} is selected under Interrupted "
                                               "sessions: press Resume selected.")
    assert "exited unexpectedly (killed by SIGKILL (signal 9))" in w.restart_button.toolTip()  # for a bug report
    assert not w.start_button.isEnabled() and not w.abort_trial_button.isEnabled()
    restart_and_find(qtbot, w, sid)
    assert not os.path.exists(ring)  # the dead engine's shared ring is freed, not left until the GUI exits


def test_a_dead_haptic_loop_in_a_live_engine_leads_to_the_same_restart(qtbot, window) -> None:
    w = window
    sid = start_session(qtbot, w, "P02")
    alive_pid = w.bridge.client.pid
    # what a live engine whose loop died says (test_engine_loop_failure checks that the engine says it)
    why = "OSError('Net F/T socket closed')"
    w._on_engine_event(m.SessionEnded(sid, "interrupted", f"the haptic loop died ({why}); the session is "
                                      "interrupted", 0, 0, 0))
    w._on_engine_event(m.Health(1000.0, 1.0, 2.0, 1.0, 0, 0, 1, 0, False, "manual", False, False,
                                loop_dead=why))
    assert w.engine_row.isVisible() and w.engine_label.text().startswith("The haptic loop died; the force is at zero.")
    assert why in w.engine_label.toolTip()
    assert w.bridge.client.alive and w.bridge.client.pid == alive_pid
    assert not w.start_button.isEnabled()
    restart_and_find(qtbot, w, sid)
    assert not math.isnan(w.model.session.latest_t_s)


def test_a_stalled_loop_offers_reset_and_a_restart_that_asks_first(qtbot, window) -> None:
    from PySide6.QtWidgets import QMessageBox

    from pipeline.devices.interfaces import Fault

    w = window
    sid = start_session(qtbot, w, "P03")
    # what a live engine whose loop froze reports (test_engine_loop_failure checks that the engine reports it)
    stalled = m.Health(1000.0, 1.0, 2.0, 1.0, 0, 0, 1, int(Fault.LOOP_STALLED), False, "manual", True, False)
    w.bridge.generation += 1  # nothing more from this engine reaches the window: its next Health would clear it
    w._on_engine_event(stalled)
    assert w.engine_row.isVisible() and w.engine_label.text().startswith("The haptic loop stalled")
    assert "Reset faults" in w.engine_label.text() and w.restart_button.isEnabled()
    assert w.start_button.isEnabled() is False  # a session runs
    qtbot.mouseClick(w.restart_button, Qt.MouseButton.LeftButton)
    q = w.session_actions.questions["restart"]
    assert q.open and q.box.defaultButton() is q.box.button(QMessageBox.StandardButton.No)
    assert f"Session {sid} stops here" in q.box.text()
    q.box.button(QMessageBox.StandardButton.Yes).click()
    qtbot.waitUntil(lambda: w.model.session.state == "ready", timeout=TIMEOUT_MS)
    assert not w.engine_row.isVisible()
    qtbot.waitUntil(lambda: w.setup_panel.selected_session() == sid, timeout=TIMEOUT_MS)


def test_a_rehearsed_kill_is_on_record_as_one_and_no_dead_engine_figure_stays(qtbot, window, tmp_path) -> None:
    """Issue 40, items 6 and 7: the record says the engine's death was a rehearsed kill, stamped when it came (not
    only "planned"); and after it the health panel shows no rate, sample age, loop figure or "next cue waits" of the
    dead engine beside "disconnected"."""
    import sqlite3

    w = window
    sid = start_session(qtbot, w, "P01")
    qtbot.waitUntil(lambda: len(w.model.health.devices) >= 3 and w.model.health.loop is not None, timeout=TIMEOUT_MS)
    w.model.rig_control.inject_fault("kill", None, 0.0)
    qtbot.waitUntil(lambda: w.engine_row.isVisible(), timeout=TIMEOUT_MS)
    h = w.model.health
    assert len(h.devices) >= 3 and {d.state for d in h.devices} == {"disconnected"}
    assert all(math.isnan(d.rate_hz) and math.isnan(d.age_ms) for d in h.devices)
    assert h.loop_text() == "loop: –" and h.waiting_text() == "" and not h.faults
    table = w.health_panel.devices
    assert {table.item(i, 2).text() for i in range(table.rowCount())} == {"–"}
    c = sqlite3.connect(tmp_path / "study.db")
    try:
        (t_s, detail), = c.execute("SELECT t_s, detail FROM events WHERE kind = 'fault_rehearsal'").fetchall()
        # the first cue as stored: the same session clock as the kill's time (the GUI's trial time is the loop's)
        (t_cue,), = c.execute("SELECT MIN(t_s) FROM events WHERE kind = 'cue' AND session_id = ?", (sid,)).fetchall()
    finally:
        c.close()
    assert detail.startswith("kill now: the engine process is killed now, as a crash would kill it -- a rehearsal")
    assert t_s >= t_cue  # when it came, during the trial
    restart_and_find(qtbot, w, sid)
