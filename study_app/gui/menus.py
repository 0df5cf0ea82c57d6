"""The experimenter window's menus: File, Session, View, Help -- every action with its shortcut shown, disabled
with a tooltip saying why when it is not allowed now."""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import QFileDialog, QMenu, QMessageBox, QWidget

from study_app.guide_paths import guide

__all__ = ["MAX_RECENT", "PAPER", "WindowMenus", "about_text", "remember_recent"]

#: Databases listed under File → Recent databases.
MAX_RECENT = 8
#: The paper this software implements (Help → About).
PAPER = ("W. Shaker and M. S. Erden, “An Experimental Modular Instrument With a Haptic Feedback Framework for "
         "Robotic Surgery Training” (IEEE conference paper)")


def remember_recent(recent: list[str], path: str) -> list[str]:
    """``recent`` with ``path`` (absolute) first, each once, at most :data:`MAX_RECENT`."""
    path = os.path.abspath(path)
    return [path, *[p for p in recent if p != path]][:MAX_RECENT]


def about_text() -> str:
    """Help → About: what this is, its version and commit, the paper it implements."""
    from study_app.version_info import version_text

    return (f"<b>haptic-study</b> {version_text()}<br><br>"
            "Runs a force-feedback training study end to end: the haptic feedback framework at 1 kHz, the "
            "study protocol and its sessions, the study database and the report.<br><br>"
            f"It implements the system of {PAPER}.<br><br>"
            f"The experimenter's guide: {guide('gui.md')}<br>"
            f"Setting up a real rig: {guide('hardware-setup.md')}")


class WindowMenus:
    """Builds the menus of ``win`` and keeps each action's availability (and its tooltip) current.

    Space and Esc work everywhere in the application (the window's own application-wide shortcuts, which
    also know when a text field or a question has the keyboard); the Session menu shows them next to the
    actions without binding them a second time.
    """

    def __init__(self, win: Any) -> None:  # the ExperimenterWindow (which imports this module: no circle)
        self.win = win
        bar = win.menuBar()
        self.file = bar.addMenu("&File")
        self.session = bar.addMenu("&Session")
        self.view = bar.addMenu("&View")
        self.help = bar.addMenu("&Help")
        for menu in (self.file, self.session, self.view, self.help):
            menu.setToolTipsVisible(True)  # a disabled action says why
        self.open_db = self._add(self.file, "&Open study database…", self.choose_database,
                                 QKeySequence.StandardKey.Open)
        self.recent = self.file.addMenu("&Recent databases")
        self.recent.setToolTipsVisible(True)
        self.file.addSeparator()
        self.quit = self._add(self.file, "&Quit", win.close, QKeySequence.StandardKey.Quit)
        act, control = win.session_actions, win.model.control
        self.start = self._add(self.session, "&Start\tSpace", act.start_session)
        self.start_untrained = self._add(self.session, "Start &without training…", act.start_without_training)
        self.pause = self._add(self.session, "&Pause", control.pause)
        self.resume = self._add(self.session, "&Resume\tSpace", control.resume)
        self.abort_trial = self._add(self.session, "Abort &trial…\tEsc", act.abort_trial)
        self.abort_session = self._add(self.session, "Abort s&ession…", act.abort_session)
        self.note = self._add(self.session, "&Note…", win.note, "Ctrl+N")
        self.session.addSeparator()
        self.reset = self._add(self.session, "Reset &faults", control.reset_faults, "Ctrl+Shift+F")
        self.restart = self._add(self.session, "Restart &engine", act.restart_engine)
        self.windows: dict[str, QAction] = {}
        for text, key, window in (("&Participant screen", "Ctrl+P", win.participant_window),
                                  ("&Simulated rig", "Ctrl+R", win.rig_window),
                                  ("&Calibration wizard", "Ctrl+K", win.calibration_wizard)):
            self.windows[text.replace("&", "")] = self._add(self.view, text, self._opener(window), key)
        self.about = self._add(self.help, "&About haptic-study", self.show_about)
        self.refresh_recent()

    def _opener(self, window: QWidget) -> Callable[[], None]:
        return lambda: self.win.open_window(window)

    def _add(self, menu: QMenu, text: str, slot: Callable[[], object],
             key: QKeySequence.StandardKey | str | None = None) -> QAction:
        act = QAction(text, self.win)
        if key is not None:
            act.setShortcut(QKeySequence(key))
        act.triggered.connect(lambda _=False: slot())
        menu.addAction(act)
        return act

    # -- File --------------------------------------------------------------------------------------------
    def recent_paths(self) -> list[str]:
        """The study databases opened before, newest first (QSettings)."""
        value = self.win.settings.value("recent/databases", [])
        paths = [value] if isinstance(value, str) else list(value) if isinstance(value, (list, tuple)) else []
        return [str(p) for p in paths if p]

    def refresh_recent(self) -> None:
        """Rebuild File → Recent databases (a file that is gone is shown disabled, with why)."""
        self.recent.clear()
        paths = self.recent_paths()
        for i, path in enumerate(paths, start=1):
            act = self.recent.addAction(f"&{i} {path}" if i < 10 else path)
            act.triggered.connect(lambda _=False, p=path: self.open_database(p))
            if not os.path.exists(path):
                act.setEnabled(False)
                act.setToolTip("the file is no longer there")
        self.recent.setEnabled(bool(paths))
        self.recent.setToolTip("" if paths else "no study database opened yet")

    def choose_database(self) -> None:
        """File → Open study database…: pick a file (a new name creates the database at the first Start)."""
        current = self.win.setup_panel.db.text()
        # a save-style dialog, so a new name can be typed (the database is made at the first Start), labelled Open
        dlg = QFileDialog(self.win, "Open study database", current or os.getcwd(),
                          "Study databases (*.db *.sqlite);;All files (*)")
        dlg.setAcceptMode(QFileDialog.AcceptMode.AcceptSave)
        dlg.setOption(QFileDialog.Option.DontConfirmOverwrite)
        dlg.setLabelText(QFileDialog.DialogLabel.Accept, "Open")
        dlg.setDefaultSuffix("db")
        if dlg.exec() and dlg.selectedFiles():
            self.open_database(dlg.selectedFiles()[0])

    def open_database(self, path: str) -> None:
        """Use the study database at ``path`` (refused while a session runs, with why)."""
        win = self.win
        if win.model.session.running:
            win.model.notices.notify("error", "Open study database refused: a session is running; finish or end it "
                                     "first.", "OpenDatabase")
            return
        win.model.setup.update(db_path=path)
        win.model.control.list_sessions()
        win.settings.setValue("recent/databases", remember_recent(self.recent_paths(), path))
        self.refresh_recent()

    # -- Help ----------------------------------------------------------------------------------------------
    def show_about(self) -> None:
        """Help → About: version, commit, the paper."""
        QMessageBox.about(self.win, "About haptic-study", about_text())

    # -- availability --------------------------------------------------------------------------------------
    def refresh(self) -> None:
        """Enable each action only when it is allowed now; a disabled one says why in its tooltip."""
        model, s = self.win.model, self.win.model.session
        can = model.actions.can
        running = "a session is running: finish or end it first"
        no_session = "no session is running"
        for act, allowed, why in (
            (self.start, can("start") or (can("resume") and s.state == "paused"), model.actions.start_refusal()),
            (self.start_untrained, can("start_without_training"),
             "only for an experiment the form refuses for want of training"),
            (self.pause, can("pause"), no_session if not s.running else "a pause is already requested"),
            (self.resume, can("resume"), "the session is not paused"),
            (self.abort_trial, can("abort_trial"), "no trial is running"),
            (self.abort_session, can("abort_session"), no_session),
            (self.note, can("note"), f"{no_session} (haptic-study note adds one to a stored session)"),
            (self.reset, bool(model.health.faults), "no fault is latched"),
            (self.restart, can("restart_engine"), "the study engine runs"),
            (self.open_db, not s.running, running),
            (self.recent.menuAction(), not s.running and bool(self.recent_paths()),
             running if s.running else "no study database opened yet"),
        ):
            act.setEnabled(bool(allowed))
            act.setToolTip("" if allowed else why)
