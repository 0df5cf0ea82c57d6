"""The experimenter's window: layout and wiring of :class:`study_app.models.app.AppModel`."""

from __future__ import annotations

import os
from collections.abc import Callable

from PySide6.QtCore import QSettings, QSize, Qt, Slot
from PySide6.QtGui import QGuiApplication, QKeySequence, QShortcut
from PySide6.QtWidgets import (
    QApplication,
    QFrame,
    QInputDialog,
    QMainWindow,
    QScrollArea,
    QSplitter,
    QTabWidget,
    QVBoxLayout,
    QWidget,
)

from study_app.engine import messages as m
from study_app.engine.client import EngineClient
from study_app.engine.setup import HostConfig
from study_app.gui import placement
from study_app.gui.bridge import QtEngineBridge
from study_app.gui.calibration_wizard import CalibrationWizard, RealPosePanel
from study_app.gui.confirm import Confirmation
from study_app.gui.control_box import ControlBox
from study_app.gui.force_plots import QtForcePlots
from study_app.gui.jaw_box import QtJawBox
from study_app.gui.menus import WindowMenus, remember_recent
from study_app.gui.participant_window import ParticipantWindow
from study_app.gui.rig_view import RigWindow
from study_app.gui.timers import tracked_timer
from study_app.gui.widgets import ElidedLabel, QtCueWait, QtHealthPanel, QtProgress, QtSetupPanel, QtTrialTable
from study_app.models.app import CALIBRATION_COMMANDS, AppModel

__all__ = ["ExperimenterWindow"]

#: Plot refresh (pyqtgraph's pull-on-a-timer idiom), ms.
PLOT_INTERVAL_MS = 33
#: Preferred sizes, shrunk to fit the screen (the experimenter's window fits a 1366×768 laptop).
MAIN_SIZE = QSize(1280, 800)
PARTICIPANT_SIZE = QSize(900, 560)
#: The participant screen beside this window on a one-monitor machine (a rehearsal): small enough to leave room.
PARTICIPANT_BESIDE_SIZE = QSize(640, 400)
RIG_SIZE = QSize(760, 480)
WIZARD_SIZE = QSize(720, 640)


class ExperimenterWindow(QMainWindow):
    """Session setup and control, live plots, trial table, progress, device health.

    Parameters
    ----------
    host
        What the study engine builds (it is spawned in its own process).
    settings
        Where last-used settings live (QSettings).
    db_path
        Study database to preselect (else the last used one).
    """

    def __init__(self, host: HostConfig, settings: QSettings | None = None, db_path: str | None = None) -> None:
        super().__init__()
        self.setWindowTitle("haptic-study — experimenter")
        self.settings = settings if settings is not None else QSettings("haptic-study", "gui")
        #: None: destructive actions ask in a dialog bound to what it asks about (default No).  Scripted runs
        #: (the screenshot tour, benchmarks, tests) set a function that answers at once instead.
        self.confirm: Callable[[str, str], bool] | None = None
        self.questions: dict[str, Confirmation] = {}
        self._quit_confirmed = False
        self.bridge = QtEngineBridge(EngineClient(host), self)
        self.model = AppModel(self.bridge.send)
        self.model.restarter = self.bridge.restart
        self._restore_settings(db_path)
        self._shut_down = False

        self.setup_panel = QtSetupPanel(self.model.setup)
        left = self._build_left_column()
        right = self._build_right_column()
        split = QSplitter(Qt.Orientation.Horizontal)
        split.addWidget(left)
        split.addWidget(right)
        split.setStretchFactor(1, 1)
        self.setCentralWidget(split)
        self.status = ElidedLabel()
        self.statusBar().addWidget(self.status, 1)
        self.setMinimumSize(self.minimumSizeHint().boundedTo(QSize(1000, 640)))

        self._build_windows()
        self._wire_signals()
        self.plot_timer = tracked_timer(self, PLOT_INTERVAL_MS, self._on_plot_timer, name="plot-refresh")
        self._on_actions_changed()
        self._on_session_changed()
        if not placement.restore(self, self.settings, "experimenter"):
            placement.place(self, MAIN_SIZE, QGuiApplication.primaryScreen())
        self.bridge.start()
        self.plot_timer.start()

    # -- building the window (the order of creation is the keyboard focus order) -----------------------
    def _build_left_column(self) -> QWidget:
        """Session setup, the controls and the jaw, top to bottom."""
        controls = self._build_controls()
        self.jaw_box = QtJawBox(self.model.jaw, self.model.jaw_action)
        left = QWidget()
        ll = QVBoxLayout(left)
        ll.addWidget(self.setup_panel)
        ll.addWidget(controls)
        ll.addWidget(self.jaw_box)
        ll.addStretch(1)
        left.setMinimumWidth(340)
        left.setMaximumWidth(460)
        # a column taller than the screen scrolls; nothing in it is squashed or cut
        scroll = QScrollArea()
        scroll.setWidget(left)
        scroll.setWidgetResizable(True)
        scroll.setFrameShape(QFrame.Shape.NoFrame)
        scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        bar = scroll.verticalScrollBar().sizeHint().width()
        scroll.setMinimumWidth(340 + bar)
        scroll.setMaximumWidth(460 + bar)
        self.left_column = scroll
        return scroll

    def _build_controls(self) -> ControlBox:
        """The "Control" box (:mod:`study_app.gui.control_box`); its widgets are the window's to wire."""
        c = self.controls = ControlBox()
        self.start_button, self.untrained_button, self.override_button = c.start_button, c.untrained_button, \
            c.override_button
        self.pause_button, self.resume_button = c.pause_button, c.resume_button
        self.abort_trial_button, self.abort_session_button = c.abort_trial_button, c.abort_session_button
        self.calibrate_button, self.participant_button, self.rig_button = c.calibrate_button, c.participant_button, \
            c.rig_button
        self.engine_row, self.engine_label, self.restart_button = c.engine_row, c.engine_label, c.restart_button
        self.notice_row, self.notice, self.notice_close = c.notice_row, c.notice, c.notice_close
        return c

    def _build_right_column(self) -> QSplitter:
        """Progress and live plots above; the trial table and device health in tabs below."""
        self.progress = QtProgress(self.model.session, self.model.health, app=self.model)
        self.plots = QtForcePlots(self.model.plots, self.model.session)
        self.trial_table = QtTrialTable(self.model.session.table)
        self.cue_wait = QtCueWait(self.model)
        self.trials_tab = QWidget()
        self.trials_count = ElidedLabel()  # the session's count, as the progress line above reads it
        self.trials_count.setContentsMargins(6, 2, 6, 0)
        self.trials_count.hide()
        tt = QVBoxLayout(self.trials_tab)
        tt.setContentsMargins(0, 0, 0, 0)
        tt.setSpacing(2)
        tt.addWidget(self.trials_count)
        tt.addWidget(self.cue_wait)
        tt.addWidget(self.trial_table, 1)
        self.health_panel = QtHealthPanel(self.model.health)
        self.tabs = QTabWidget()
        self.tabs.addTab(self.trials_tab, "Trials")
        self.tabs.addTab(self.health_panel, "Devices && health")
        right = QSplitter(Qt.Orientation.Vertical)
        top = QWidget()
        tl = QVBoxLayout(top)
        tl.setContentsMargins(0, 0, 0, 0)
        tl.addWidget(self.progress)
        tl.addWidget(self.plots, 1)
        right.addWidget(top)
        right.addWidget(self.tabs)
        right.setSizes([520, 220])
        right.setStretchFactor(0, 3)  # a taller window gives the plots the room
        right.setStretchFactor(1, 1)
        return right

    def _build_windows(self) -> None:
        """The participant screen, the simulated rig view, the calibration wizard and the menu."""
        self.participant_window = ParticipantWindow(self.model.participant)
        self.rig_window = RigWindow(self.model.rig, self.model.set_driver, self.model.inject_fault)
        self.calibration_wizard = CalibrationWizard(
            self.model.calibration, self.model.calibrate,
            RealPosePanel(self.model.real_calibration, self.model.record_pose, self.model.identify),
            chain=self.model.commissioning, on_tcp=self.model.run_tcp, on_compute_tcp=self.model.compute_tcp,
            on_frames=self.model.check_frames, on_arm=self.model.select_calibration_arm,
        )
        self.calibration_wizard.hidden.connect(lambda: self.model.clear_notice(CALIBRATION_COMMANDS))
        self.menus = WindowMenus(self)
        self.view_actions = self.menus.windows

    def _wire_signals(self) -> None:
        """Buttons, keys and the model's signals to the window's slots."""
        self.start_button.clicked.connect(self.start_session)
        self.pause_button.clicked.connect(self.model.pause)
        self.resume_button.clicked.connect(self.model.resume)
        self.abort_trial_button.clicked.connect(self.abort_trial)
        self.abort_session_button.clicked.connect(self.abort_session)
        self.calibrate_button.clicked.connect(lambda: self.open_window(self.calibration_wizard))
        self.participant_button.clicked.connect(lambda: self.open_window(self.participant_window))
        self.rig_button.clicked.connect(lambda: self.open_window(self.rig_window))
        self.notice_close.clicked.connect(self.model.clear_notice)
        self.restart_button.clicked.connect(self.restart_engine)
        self.model.engine_changed.connect(self._on_engine_changed)
        self.override_button.clicked.connect(self.start_with_override)
        self.untrained_button.clicked.connect(self.start_without_training)
        self.health_panel.health.changed.connect(self._on_health_changed)
        self.model.commissioning.changed.connect(self._on_actions_changed)
        self.setup_panel.start_requested.connect(self.start_session)
        self.health_panel.reset_button.clicked.connect(self.model.reset_faults)
        self.setup_panel.refresh_button.clicked.connect(self.model.list_sessions)
        self.setup_panel.resume_button.clicked.connect(self.resume_selected)
        self.setup_panel.db.editingFinished.connect(self.model.list_sessions)
        # application-wide: the experimenter may have the rig view or the participant screen focused
        for key, slot in ((Qt.Key.Key_Space, self.start_session), (Qt.Key.Key_Escape, self.abort_trial)):
            sc = QShortcut(QKeySequence(key), self)
            sc.setContext(Qt.ShortcutContext.ApplicationShortcut)
            sc.activated.connect(slot)
        self.model.actions_changed.connect(self._on_actions_changed)
        self.model.session.changed.connect(self._on_session_changed)
        self.model.notice_changed.connect(self._on_notice)
        self.bridge.event_received.connect(self._on_engine_event, Qt.ConnectionType.QueuedConnection)

    def start_with_override(self) -> None:
        """Real rig, calibration incomplete: ask for a reason, then start anyway (the reason is stored)."""
        missing = self.model.calibration_missing()
        if not missing or not self.model.can("start"):
            return
        self.model.setup.update(db_path=self.setup_panel.db.text(), protocol_path=self.setup_panel.protocol.text())
        prompt = self.model.commissioning.override_prompt()
        if self.confirm is not None:  # a scripted run answers at once
            reason = "scripted override" if self.confirm("Start without calibration", prompt) else ""
        else:
            reason, ok = QInputDialog.getText(self, "Start without calibration", prompt)
            reason = reason if ok else ""
        if reason.strip() and self.model.start(override_reason=reason):
            self._save_settings()

    # -- engine events (GUI thread, queued from the monitor thread) -------------------------------------
    @Slot(object)
    def _on_engine_event(self, ev: object) -> None:
        if isinstance(ev, m.EngineReady) and self.bridge.client.ring is not None:
            client = self.bridge.client
            self.model.attach_ring(client.ring, client.task_arm, dict(client.arm_rings))
            self.model.list_sessions()
        self.model.apply(ev)
        for q in list(self.questions.values()):
            q.event(ev)
        if isinstance(ev, m.EngineReady):
            self._on_rig_known(ev.rig)

    def _on_rig_known(self, rig: str) -> None:
        """On the real rig a person holds the stylus: no simulated rig view, no autopilot, pose-by-pose calibration."""
        real = rig == "real"
        self.calibration_wizard.set_real(real)
        why = ("real rig: a person holds the stylus — the simulated rig view and the simulated participant "
               "(autopilot) exist on the simulated rig only")
        for w in (self.rig_button, self.view_actions["Simulated rig"]):
            w.setEnabled(not real)
            w.setToolTip(why if real else "")
        if real:
            self.rig_window.hide()

    def _on_plot_timer(self) -> None:
        if self.model.tick():  # nothing new (engine paused or gone): nothing to redraw
            self.plots.refresh()

    # -- questions -----------------------------------------------------------------------------------------
    def ask(self, key: str, title: str, text: str, on_yes: Callable[[], object], *,
            moot_when: Callable[[object], bool] | None = None, moot_text: str = "") -> None:
        """Ask before a destructive action: default No, closed as No when ``moot_when`` an engine event."""
        if self.confirm is not None:
            if self.confirm(title, text):
                on_yes()
            return
        old = self.questions.pop(key, None)
        if old is not None:
            old.dismiss()
            old.box.deleteLater()
        say = (lambda: self.model.notify("info", moot_text)) if moot_text else None
        q = Confirmation(self.question_parent(), title, text, on_yes, moot_when=moot_when, on_moot=say)
        self.questions[key] = q
        q.show()

    def question_parent(self) -> QWidget:
        """The window a question opens over: the one the experimenter is looking at (Esc pressed in the rig
        view asks over the rig view, which so stays in front), never the participant's own monitor."""
        active = QApplication.activeWindow()
        if active in (self.rig_window, self.calibration_wizard):
            return active
        if active is self.participant_window and active.screen() is self.screen():
            return active  # one monitor: the experimenter sees the participant view too
        return self

    # -- actions -----------------------------------------------------------------------------------------
    def start_without_training(self) -> None:
        """An experiment for a participant without the completed training the protocol requires: only with a
        typed reason, which the engine stores as a ``deviation`` event (listed in the report)."""
        missing = self.model.setup.training_missing
        if not missing or not self.model.can("start_without_training"):
            return
        code = self.model.setup.values.code
        prompt = (f"{missing.split('. ')[0]}.\n\nStart {code}'s experiment anyway? The session is stored with "
                  "this deviation from the protocol and your reason; the study report lists it.\n\nReason:")
        if self.confirm is not None:  # a scripted run answers at once
            reason = "scripted override" if self.confirm("Start without training", prompt) else ""
        else:
            reason, ok = QInputDialog.getText(self, "Start without training", prompt)
            reason = reason if ok else ""
        if not reason.strip():
            self.model.notify("info", "Nothing was started: a start without training needs a reason.",
                              "StartSession")
            return
        if self.model.start(training_override=reason):
            self._save_settings()

    def start_session(self) -> None:
        """Space: start a session from the setup form (or resume a paused one); asks first on a warning."""
        if self.model.can("resume") and self.model.session.state == "paused":
            self.model.resume()
            return
        if self.model.session.running:
            return
        self.model.setup.update(db_path=self.setup_panel.db.text(), protocol_path=self.setup_panel.protocol.text())
        warnings = self.model.setup.warnings
        if warnings and self.model.can("start"):
            self.ask("start", "Start anyway?", "\n\n".join(warnings.values()) + "\n\nStart the session anyway?",
                     self._start, moot_when=lambda ev: isinstance(ev, (m.SessionStarted, m.EngineStopped)))
        else:
            self._start()

    def _start(self) -> None:
        if self.model.start():
            self._save_settings()

    def abort_trial(self) -> None:
        """Esc: abort the running trial after confirmation -- that trial only, however late the answer."""
        tr = self.model.session.trial
        if not self.model.can("abort_trial") or tr is None:
            return
        k = tr.trial_index

        def moot(ev: object) -> bool:
            return ((isinstance(ev, m.TrialEnded) and ev.record.trial_index == k)
                    or (isinstance(ev, m.TrialStarted) and ev.trial_index != k)
                    or isinstance(ev, (m.SessionEnded, m.EngineStopped)))

        self.ask("abort_trial", "Abort trial",
                 f"Abort trial {k + 1} ({tr.target_label}, haptics {tr.haptic_mode.upper()})? It is stored as aborted "
                 "and run again later.\n\nIf the trial ends before you answer, this question closes and nothing is "
                 "aborted.", lambda: self.model.abort_trial(k), moot_when=moot,
                 moot_text=f"Trial {k + 1} ended before you answered: nothing was aborted.")

    def abort_session(self) -> None:
        """Abort the session after confirmation (that session only)."""
        s = self.model.session.session
        if not self.model.can("abort_session") or s is None:
            return
        sid = s.session_id
        self.ask("abort_session", "Abort session", self.model.session.abort_session_question(),
                 lambda: self.model.abort_session(sid),
                 moot_when=lambda ev: isinstance(ev, (m.SessionEnded, m.EngineStopped)),
                 moot_text=f"Session {sid} ended before you answered: nothing was aborted.")

    def restart_engine(self) -> None:
        """Restart engine: at once if it is dead; asks first if it still runs a session (a stalled loop)."""
        s = self.model.session.session
        if not self.model.can("restart_engine"):
            return
        if self.model.session.running and s is not None:
            sid = s.session_id
            self.ask("restart", "Restart engine",
                     f"Restart the study engine? Session {sid} stops here: the running trial is stored as aborted if "
                     "the engine can still store it, and the session can be resumed after the restart.",
                     self.model.restart_engine,
                     moot_when=lambda ev: isinstance(ev, (m.SessionEnded, m.EngineStopped)))
        else:
            self.model.restart_engine()

    def open_window(self, w: QWidget) -> None:
        """Show one of the extra windows: where it was last, else at a size that fits, on the right screen."""
        if not w.property("placed"):
            w.setProperty("placed", True)
            key, size = {id(self.participant_window): ("participant", PARTICIPANT_SIZE),
                         id(self.rig_window): ("rig", RIG_SIZE)}.get(id(w), ("calibration", WIZARD_SIZE))
            if not placement.restore(w, self.settings, key):
                other = placement.other_screen(self) if w is self.participant_window else None
                if other is not None:  # the participant's own monitor: the whole of it
                    placement.place(w, size, other)
                    w.showFullScreen()
                elif w is self.participant_window:  # one monitor: beside this window, never over its controls
                    placement.place_beside(w, self, self.left_column, PARTICIPANT_BESIDE_SIZE)
                else:
                    placement.place(w, size, self.screen())
        if w is self.participant_window:
            placement.keep_above(w, self)
        _show(w)

    def resume_selected(self) -> None:
        """Continue the interrupted session selected in the list."""
        sid = self.setup_panel.selected_session()
        if sid is not None and self.model.can("resume_session"):
            self.model.resume_session(sid)

    # -- views of state ------------------------------------------------------------------------------------
    def _on_actions_changed(self) -> None:
        can = self.model.can
        self.start_button.setEnabled(can("start"))
        self.start_button.setToolTip("" if can("start") else f"Start is not available: {self.model.start_refusal()}")
        untrained = bool(self.model.setup.training_missing)
        self.untrained_button.setVisible(untrained)
        self.untrained_button.setEnabled(can("start_without_training"))
        self.untrained_button.setToolTip("Asks for the reason; it is stored with the session as a deviation from "
                                         "the protocol, and the report lists it")
        self.calibration_wizard.set_blocked(self.model.calibration_refusal())
        db = self.model.setup.values.db_path
        title = f"{os.path.basename(db)} — haptic-study experimenter" if db else "haptic-study — experimenter"
        if title != self.windowTitle():
            self.setWindowTitle(title)
            self.setWindowFilePath(os.path.abspath(db) if db else "")
        if hasattr(self, "menus"):
            self.menus.refresh()
        self.pause_button.setEnabled(can("pause"))
        pending = self.model.session.running and self.model.session.paused_requested
        self.pause_button.setText("Pause requested…" if pending and self.model.session.state == "running" else "Pause")
        self.pause_button.setToolTip("The session pauses when the running trial ends; Resume cancels" if pending
                                     else "Hold before the next trial (the running trial finishes first)")
        self.resume_button.setEnabled(can("resume"))
        self.abort_trial_button.setEnabled(can("abort_trial"))
        self.abort_session_button.setEnabled(can("abort_session"))
        self.setup_panel.resume_button.setEnabled(can("resume_session"))
        self.setup_panel.setEnabled(not self.model.session.running)
        missing = self.model.calibration_missing()
        self.override_button.setVisible(bool(missing))
        self.override_button.setEnabled(bool(missing) and can("start"))
        self.override_button.setToolTip(missing)

    def _on_engine_changed(self) -> None:
        trouble, detail = self.model.engine_notice()
        self.controls.show_engine(trouble, detail, self.model.can("restart_engine"))

    def _on_session_changed(self) -> None:
        s = self.model.session
        count = s.count_text() if s.running else ""
        self.status.set_full_text(s.message + (f" — {count}" if count else ""))
        if count != self.trials_count.full_text():
            self.trials_count.set_full_text(count)
            self.trials_count.setVisible(bool(count))
        if hasattr(self.rig_window, "fault_trial"):
            self.rig_window.set_trials(self.model.rehearsal_trials())

    def _on_health_changed(self) -> None:
        """The health tab's title says when something there needs the experimenter (a fault, a busy machine)."""
        i = self.tabs.indexOf(self.health_panel)
        text = "Devices && health" + ("  ⚠" if self.health_panel.attention() else "")
        if self.tabs.tabText(i) != text:
            self.tabs.setTabText(i, text)
        if hasattr(self, "menus"):
            self.menus.refresh()

    def _on_notice(self) -> None:
        self.controls.show_notice(self.model.notice)

    # -- settings and closing --------------------------------------------------------------------------------
    def _restore_settings(self, db_path: str | None) -> None:
        s = self.settings
        self.model.setup.update(
            db_path=db_path or str(s.value("setup/db_path", "") or ""),
            protocol_path=str(s.value("setup/protocol_path", "") or ""),
            seed=int(s.value("setup/seed", 0) or 0),  # type: ignore[call-overload]  # QSettings.value is typed object
        )

    def _save_settings(self) -> None:
        v = self.model.setup.values
        s = self.settings
        s.setValue("setup/db_path", v.db_path)
        s.setValue("setup/protocol_path", v.protocol_path)
        s.setValue("setup/seed", v.seed)
        if v.db_path:
            s.setValue("recent/databases", remember_recent(self.menus.recent_paths(), v.db_path))
            self.menus.refresh_recent()
        placement.save(self, s, "experimenter")
        for key, w in (("participant", self.participant_window), ("rig", self.rig_window),
                       ("calibration", self.calibration_wizard)):
            if w.property("placed"):
                placement.save(w, s, key)
        s.sync()

    def shutdown(self) -> None:
        """Stop refreshing, let the engine close the session's records and exit, close every window."""
        if self._shut_down:
            return
        self._shut_down = True
        self.plot_timer.stop()
        self.model.plots.detach()
        self.bridge.shutdown()
        for w in (self.participant_window, self.rig_window, self.calibration_wizard):
            w.close()
            w.deleteLater()

    def closeEvent(self, event) -> None:  # Qt's name
        if self.model.session.running and not self._quit_confirmed:
            title = "Quit"
            text = ("A session is running. Quit anyway? A trial still running is stored as aborted and the session "
                    "can be resumed later.")
            if self.confirm is not None:  # a scripted run answers at once
                if not self.confirm(title, text):
                    event.ignore()
                    return
            else:
                event.ignore()
                self.ask("quit", title, text, self._quit,
                         moot_when=lambda ev: isinstance(ev, (m.SessionEnded, m.EngineStopped)))
                return
        for q in self.questions.values():
            q.dismiss()
        self._save_settings()
        self.shutdown()
        event.accept()

    def _quit(self) -> None:
        self._quit_confirmed = True
        self.close()


def _show(w: QWidget) -> None:
    w.show()
    w.raise_()
    w.activateWindow()
