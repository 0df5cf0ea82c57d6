"""A first-day lab assistant cannot run an invalid session: the real window, its real dialogs, a real engine.

Training before the experiment (refused with the reason; an override with a typed reason runs and is stored as
a deviation), one seed per study (read-only after the first session, another one refused in one line), and one
count of progress that reads the same in every panel through an aborted trial, its re-run, a quit and a resume.
The stylus is held by "me" (manual driving) and never pressed: every trial runs to its cap, so what happens
depends on the order of events, never on how fast this machine is.
"""

from __future__ import annotations

import os
import sqlite3

from conftest import SHORT_PROTOCOL, open_ready_window
from PySide6.QtCore import Qt, QTimer
from PySide6.QtWidgets import QApplication, QInputDialog, QMessageBox

from study_app.engine import messages as m

TIMEOUT_MS = 30_000
#: The short protocol as a study protocol: it requires training before the experiment (the default); a 6 s cap
#: leaves time to answer a question within a trial.
PROTOCOL = SHORT_PROTOCOL.replace("required = false", "required = true").replace("max_trial_s = 2.5",
                                                                                 "max_trial_s = 6.0")
assert "required = true" in PROTOCOL and "max_trial_s = 6.0" in PROTOCOL


def rows(db: str, sql: str) -> list[tuple]:
    c = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        return c.execute(sql).fetchall()
    finally:
        c.close()


def answer_input(text: str) -> None:
    """Type ``text`` into the next input dialog and press OK (the dialog runs its own event loop)."""
    def fill() -> None:
        dlg = QApplication.activeModalWidget()
        if not isinstance(dlg, QInputDialog):
            QTimer.singleShot(20, fill)
            return
        dlg.setTextValue(text)
        dlg.accept()
    QTimer.singleShot(20, fill)


def panels(w) -> dict[str, str]:
    """The session's count as each panel shows it: the progress line, the status bar, the Trials tab."""
    status = w.status.full_text()
    return {"progress": w.progress.count.full_text(), "status bar": status.split(" — ", 1)[-1],
            "trials tab": w.trials_count.full_text()}


def test_training_rule_seed_rule_and_one_count_through_a_rerun_quit_and_resume(qtbot, tmp_path):
    db = str(tmp_path / "study.db")
    w = open_ready_window(qtbot, tmp_path, PROTOCOL, speed=4.0)
    untrained_refused_then_overridden(qtbot, w, db)
    count = one_count_through_a_rerun_then_quit(qtbot, w, db)
    # the next day: the interrupted session is listed with the same count the resumed session shows
    w2 = open_ready_window(qtbot, tmp_path, PROTOCOL, speed=4.0)
    qtbot.waitUntil(lambda: w2.setup_panel.resumable.count() == 1, timeout=TIMEOUT_MS)
    assert w2.setup_panel.resumable.item(0).text().startswith(f"session 1: P01 experiment, {count}, started ")
    another_seed_refused_then_trained(qtbot, w2, db)
    # P01 resumed: the progress line counts as the list did (the interrupted re-run's own re-run is left)
    qtbot.waitUntil(lambda: w2.setup_panel.resumable.count() == 1, timeout=TIMEOUT_MS)
    w2.setup_panel.resumable.setCurrentRow(0)
    qtbot.mouseClick(w2.setup_panel.resume_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w2.model.session.running, timeout=TIMEOUT_MS)
    assert all(text.startswith(count) for text in panels(w2).values()), panels(w2)
    assert [(k, s) for k, s in rows(db, "SELECT kind, status FROM sessions ORDER BY session_id")] == [
        ("experiment", "running"), ("training", "completed")]


def untrained_refused_then_overridden(qtbot, w, db: str) -> None:
    """A new participant: training proposed; the experiment refused with the reason; the override runs it."""
    panel = w.setup_panel
    # the menus: each shortcut shown, and what may not be done now disabled, saying why
    assert w.menus.abort_trial.text().endswith("\tEsc") and not w.menus.abort_trial.isEnabled()
    assert w.menus.abort_trial.toolTip() == "no trial is running" and w.menus.open_db.isEnabled()
    qtbot.keyClicks(panel.code, "P01")
    assert panel.kind.currentText() == "training"
    assert panel.hint.text() == "Next for P01: training (required before the experiment), then the experiment."
    # the assistant picks the experiment anyway: Start is refused, with the reason where the form is
    w.model.setup.update(kind="experiment")
    assert not w.start_button.isEnabled()
    reason = "P01 has no training session; the protocol requires a completed one before the experiment"
    assert panel.errors.text().startswith(reason) and "Start without training…" in panel.errors.text()
    assert reason in w.start_button.toolTip() and reason in w.menus.start.toolTip()
    w.plots.setFocus()
    qtbot.keyClick(w.plots, Qt.Key.Key_Space)  # Space anyway: nothing starts, the line under Start says why
    assert not w.model.session.running and w.notice.text().startswith(f"Cannot start: {reason}")
    assert not os.path.exists(db)  # nothing was stored, not even an empty database
    # the override: a typed reason in the real dialog; the session runs
    assert w.untrained_button.isVisible() and w.untrained_button.isEnabled()
    answer_input("pilot participant, trained on the rig yesterday")
    qtbot.mouseClick(w.untrained_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.model.session.running, timeout=TIMEOUT_MS)
    assert w.notice.text() == "P01: started without training, stored as a deviation with your reason."
    (_, detail), = rows(db, "SELECT kind, detail FROM events WHERE kind = 'deviation'")
    assert detail.startswith("training skipped: P01's experiment started without a completed training session")
    assert detail.endswith("Reason given: pilot participant, trained on the rig yesterday")
    assert not w.menus.open_db.isEnabled() and w.menus.open_db.toolTip().startswith("a session is running")
    assert w.calibration_wizard.blocked.text().startswith("Calibration is not available now: not during a session")
    # the seed is the study's now: read-only, and the tooltip says why
    assert panel.seed.isReadOnly() and "fixed by the database's first session (session 1, P01)" in panel.seed.toolTip()


def one_count_through_a_rerun_then_quit(qtbot, w, db: str) -> str:
    """Trial 1 aborted (Esc, Yes), trial 2 done, the re-run cut short by Quit; returns the count left."""
    qtbot.waitUntil(lambda: w.model.session.phase == "active", timeout=TIMEOUT_MS)
    seen = panels(w)
    assert len(set(seen.values())) == 1 and seen["progress"].startswith("0 of 2 trials done · at most "), seen
    w.activateWindow()  # (the dialog had the keyboard)
    qtbot.waitUntil(lambda: QApplication.activeWindow() is w, timeout=TIMEOUT_MS)
    qtbot.keyClick(w.plots, Qt.Key.Key_Escape)
    w.session_actions.questions["abort_trial"].box.button(QMessageBox.StandardButton.Yes).click()
    qtbot.waitUntil(lambda: w.trial_table.rowCount() == 2, timeout=TIMEOUT_MS)  # trial 2 ended too
    seen = panels(w)  # the same in every panel, and never grown by the re-run
    assert len(set(seen.values())) == 1, seen
    assert seen["progress"].startswith("1 of 2 trials done · 1 aborted · 1 re-run left · about ")
    assert w.progress.bar.value() == 500
    # the re-run says which trial it repeats; quitting mid-trial stores it aborted
    qtbot.waitUntil(lambda: w.model.session.trial is not None and w.model.session.trial.repeat_of == 0
                    and w.model.session.phase == "active", timeout=TIMEOUT_MS)
    assert w.progress.label.full_text().startswith("Trial 3 (re-run of trial 1) · GENTLE")
    w.session_actions.confirm = lambda title, text: True
    w.close()
    qtbot.waitUntil(lambda: not w.bridge.client.alive, timeout=TIMEOUT_MS)
    assert [r[0] for r in rows(db, "SELECT outcome FROM trials ORDER BY trial_index")] == [
        "aborted", "timeout", "aborted"]
    return "1 of 2 trials done · 2 aborted · 1 re-run left"


def another_seed_refused_then_trained(qtbot, w2, db: str) -> None:
    """A second participant with another seed: refused in the form and by the engine; with the study's seed, the
    training runs and the experiment is proposed and allowed."""
    p2 = w2.setup_panel
    qtbot.keyClicks(p2.code, "P02")
    assert p2.seed.value() == 0 and p2.seed.isReadOnly() and p2.kind.currentText() == "training"
    w2.model.setup.update(seed=5)
    one_line = "seed = 5: this study's seed is 0, fixed by its first session (session 1, P01)"
    assert p2.errors.text().startswith(one_line) and not w2.start_button.isEnabled()
    assert not p2.seed.isReadOnly()  # (so the assistant can put it back)
    w2.model.commands(m.StartSession(db, "P02", "training", w2.model.setup.values.protocol_path, 5, 2))
    qtbot.waitUntil(lambda: w2.notice_row.isVisible(), timeout=TIMEOUT_MS)
    assert w2.notice.text().startswith(f"Start refused: {one_line}") and "\n" not in w2.notice.text()
    assert rows(db, "SELECT COUNT(*) FROM sessions") == [(1,)]
    w2.model.setup.update(seed=0)
    qtbot.mouseClick(w2.start_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w2.model.session.state == "ended", timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: p2.kind.currentText() == "experiment" and w2.start_button.isEnabled(), timeout=TIMEOUT_MS)
    assert p2.code.text() == "P02" and not p2.errors.isVisible() and not w2.untrained_button.isVisible()
