"""The experimenter's window: layout and wiring of :class:`study_app.models.app.AppModel`."""

from __future__ import annotations

import os

from PySide6.QtCore import QSettings, QSize, Qt, Slot
from PySide6.QtGui import QGuiApplication, QKeySequence, QShortcut
from PySide6.QtWidgets import (
    QAbstractSpinBox,
    QApplication,
    QFrame,
    QLineEdit,
    QMainWindow,
    QPlainTextEdit,
    QScrollArea,
    QSplitter,
    QTabWidget,
    QTextEdit,
    QVBoxLayout,
    QWidget,
)

from study_app.engine import messages as m
from study_app.engine.client import EngineClient
from study_app.engine.setup import HostConfig
from study_app.gui import placement
from study_app.gui.bridge import QtEngineBridge
from study_app.gui.calibration_wizard import CalibrationWizard, RealPosePanel
from study_app.gui.control_box import ControlBox
from study_app.gui.force_plots import QtForcePlots
from study_app.gui.health_panel import QtHealthPanel
from study_app.gui.jaw_box import QtJawBox
from study_app.gui.menus import WindowMenus, remember_recent
from study_app.gui.participant_window import ParticipantWindow
from study_app.gui.qualify_page import attach_qualify
from study_app.gui.rig_view import RigWindow
from study_app.gui.session_actions import SessionActions
from study_app.gui.session_views import QtCueWait, QtProgress, QtSessionNotes, QtTrialTable, TrialsTab
from study_app.gui.setup_panel import SPACE_IN_A_FIELD, QtSetupPanel
from study_app.gui.timers import tracked_timer
from study_app.gui.widgets import ElidedLabel
from study_app.models.app import AppModel
from study_app.models.notices import CALIBRATION_COMMANDS

__all__ = ["ExperimenterWindow"]

#: Plot refresh (pyqtgraph's pull-on-a-timer idiom), ms.
PLOT_INTERVAL_MS = 33
#: Preferred sizes, shrunk to fit the screen (the experimenter's window fits a 1366×768 laptop).
MAIN_SIZE = QSize(1280, 800)
PARTICIPANT_SIZE = QSize(900, 560)
#: The participant screen beside this window on a one-monitor machine (a rehearsal): small enough to leave room.
PARTICIPANT_BESIDE_SIZE = QSize(640, 400)
RIG_SIZE = QSize(760, 480)
#: The least the plot/table splitter leaves the trial table's tabs, px (the plots ask for their own least).
TABLE_MIN_HEIGHT = 120
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
        self.bridge = QtEngineBridge(EngineClient(host), self)
        self.model = AppModel(self.bridge.send)
        self.model.engine.restarter = self.bridge.restart
        self._restore_settings(db_path)
        self._shut_down = False

        self.setup_panel = QtSetupPanel(self.model.setup)
        #: Start, abort, restart, quit: each destructive one asked first (``session_actions.confirm`` answers at once
        #: in scripted runs).
        self.session_actions = SessionActions(self, self.model, self.setup_panel, self.question_parent,
                                              self._save_settings)
        left = self._build_left_column()
        right = self._build_right_column()
        split = QSplitter(Qt.Orientation.Horizontal)
        split.addWidget(left)
        split.addWidget(right)
        split.setStretchFactor(1, 1)
        split.setChildrenCollapsible(False)  # neither the controls nor the plots can be dragged away to nothing
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
            placement.leave_room_beside(self, PARTICIPANT_BESIDE_SIZE)  # one monitor: the participant screen's room
        self.bridge.start()
        self.plot_timer.start()

    # -- building the window (the order of creation is the keyboard focus order) -----------------------
    def _build_left_column(self) -> QWidget:
        """Session setup, the controls and the jaw, top to bottom."""
        controls = self._build_controls()
        self.jaw_box = QtJawBox(self.model.jaw, self.model.rig_control.jaw_action)
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
        self.note_button, self.skip_questionnaire_button = c.note_button, c.skip_questionnaire_button
        self.calibrate_button, self.participant_button, self.rig_button = c.calibrate_button, c.participant_button, \
            c.rig_button
        self.engine_row, self.engine_label, self.restart_button = c.engine_row, c.engine_label, c.restart_button
        self.notice_row, self.notice, self.notice_close = c.notice_row, c.notice, c.notice_close
        return c

    def _build_right_column(self) -> QSplitter:
        """Progress and live plots above; the trial table and device health in tabs below."""
        self.progress = QtProgress(self.model.session, self.model.health, cue=self.model.cue)
        self.plots = QtForcePlots(self.model.plots, self.model.session)
        self.trial_table = QtTrialTable(self.model.session.table)
        self.session_notes = QtSessionNotes(self.model.session.table)
        self.cue_wait = QtCueWait(self.model.cue)
        self.trials_count = ElidedLabel()  # the session's count, as the progress line above reads it
        self.trials_count.setContentsMargins(6, 2, 6, 0)
        self.trials_count.hide()
        self.trials_tab = TrialsTab(self.trials_count, self.cue_wait, self.session_notes, self.trial_table)
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
        # the splitter's handle never squashes the plots (or the table) to nothing: each keeps room to be read (the
        # plots: what their layout asks for, each plot's data area readable -- QtForcePlots)
        right.setChildrenCollapsible(False)
        self.tabs.setMinimumHeight(TABLE_MIN_HEIGHT)
        right.setSizes([520, 220])
        right.setStretchFactor(0, 3)  # a taller window gives the plots the room
        right.setStretchFactor(1, 1)
        return right

    def _build_windows(self) -> None:
        """The participant screen, the simulated rig view, the calibration wizard and the menu."""
        self.participant_window = ParticipantWindow(self.model.participant, questionnaire=self.model.questionnaire)
        rig, steps = self.model.rig_control, self.model.steps
        self.rig_window = RigWindow(self.model.rig, rig.set_driver, rig.inject_fault)
        self.calibration_wizard = CalibrationWizard(
            self.model.calibration, steps.calibrate,
            RealPosePanel(self.model.real_calibration, steps.record_pose, steps.identify),
            chain=self.model.commissioning, on_tcp=steps.run_tcp, on_compute_tcp=steps.compute_tcp,
            on_frames=steps.check_frames, on_arm=steps.select_arm,
        )
        self.calibration_wizard.hidden.connect(lambda: self.model.notices.clear(CALIBRATION_COMMANDS))
        self.qualify_page = attach_qualify(self, self.bridge.client.config.hardware_path if
                                           self.bridge.client.config.rig == "real" else None)
        # no trial is cued to a participant screen nobody sees: the engine hears each change, a start opens it
        self.participant_window.seen_changed.connect(self.model.screen.shown)
        self.model.screen.opener = self.open_participant_screen
        app = QGuiApplication.instance()
        if isinstance(app, QGuiApplication):  # a monitor unplugged or added: is the participant screen still seen?
            app.screenAdded.connect(lambda _s: self.participant_window.report_soon())
            app.screenRemoved.connect(lambda _s: self.participant_window.report_soon())
        self.menus = WindowMenus(self)
        self.view_actions = self.menus.windows

    def _wire_signals(self) -> None:
        """Buttons, keys and the model's signals to the window's slots."""
        act = self.session_actions
        self.start_button.clicked.connect(act.start_session)
        self.pause_button.clicked.connect(self.model.control.pause)
        self.resume_button.clicked.connect(self.model.control.resume)
        self.abort_trial_button.clicked.connect(act.abort_trial)
        self.abort_session_button.clicked.connect(act.abort_session)
        self.note_button.clicked.connect(self.note)
        self.skip_questionnaire_button.clicked.connect(act.skip_questionnaire)
        self.model.questionnaire.changed.connect(self._on_questionnaire_changed)
        self.calibrate_button.clicked.connect(lambda: self.open_window(self.calibration_wizard))
        self.participant_button.clicked.connect(lambda: self.open_window(self.participant_window))
        self.rig_button.clicked.connect(lambda: self.open_window(self.rig_window))
        self.notice_close.clicked.connect(self.model.notices.clear)
        self.restart_button.clicked.connect(act.restart_engine)
        self.model.engine.changed.connect(self._on_engine_changed)
        self.override_button.clicked.connect(act.start_with_override)
        self.untrained_button.clicked.connect(act.start_without_training)
        self.health_panel.health.changed.connect(self._on_health_changed)
        self.model.commissioning.changed.connect(self._on_actions_changed)
        self.setup_panel.start_requested.connect(act.start_session)
        self.health_panel.reset_button.clicked.connect(self.model.control.reset_faults)
        self.setup_panel.refresh_button.clicked.connect(self.model.control.list_sessions)
        self.setup_panel.resume_button.clicked.connect(act.resume_selected)
        self.setup_panel.db.editingFinished.connect(self.model.control.list_sessions)
        # application-wide: the experimenter may have the rig view or the participant screen focused
        for key, slot in ((Qt.Key.Key_Space, self._on_space), (Qt.Key.Key_Escape, act.abort_trial)):
            sc = QShortcut(QKeySequence(key), self)
            sc.setContext(Qt.ShortcutContext.ApplicationShortcut)
            sc.activated.connect(slot)
        self.model.actions.changed.connect(self._on_actions_changed)
        self.model.session.changed.connect(self._on_session_changed)
        self.model.notices.changed.connect(self._on_notice)
        self.bridge.event_received.connect(self._on_engine_event, Qt.ConnectionType.QueuedConnection)

    # -- engine events (GUI thread, queued from the monitor thread) -------------------------------------
    @Slot(object)
    def _on_engine_event(self, ev: object) -> None:
        if isinstance(ev, m.EngineReady) and self.bridge.client.ring is not None:
            client = self.bridge.client
            self.model.attach_ring(client.ring, client.task_arm, dict(client.arm_rings))
            self.model.control.list_sessions()
        self.model.apply(ev)
        self.session_actions.event(ev)
        if isinstance(ev, m.EngineReady):
            self._on_rig_known(ev.rig)

    def note(self) -> None:
        """The Note dialog, the trial selected in the table proposed when none runs."""
        row = self.trial_table.currentRow()
        rows = self.model.session.table.rows
        self.session_actions.note(rows[row].trial_index if 0 <= row < len(rows) else None)

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

    def _on_space(self) -> None:
        """Space: Start (or Resume) -- but not from a text field.  An editable field takes its Space as a character
        (the setup form's code, number and seed refuse it, saying how to start); a read-only one (the study's seed
        once fixed, the fault log, a calibration result) would pass it on to this shortcut, and a Space meant for the
        field would start a session: it is refused with the same line."""
        focus = QApplication.focusWidget()
        if isinstance(focus, (QLineEdit, QAbstractSpinBox, QPlainTextEdit, QTextEdit)):
            if self.setup_panel.isAncestorOf(focus):
                self.setup_panel.refuse_space()
            else:
                self.model.notices.notify("info", SPACE_IN_A_FIELD)
            return
        self.session_actions.start_session()

    def _on_plot_timer(self) -> None:
        if self.model.tick():  # nothing new (engine paused or gone): nothing to redraw
            self.plots.refresh()

    # -- questions -----------------------------------------------------------------------------------------
    def question_parent(self) -> QWidget:
        """The window a question opens over: the one the experimenter is looking at (Esc pressed in the rig
        view asks over the rig view, which so stays in front), never the participant's own monitor."""
        active = QApplication.activeWindow()
        if active in (self.rig_window, self.calibration_wizard):
            return active
        if active is self.participant_window and active.screen() is self.screen():
            return active  # one monitor: the experimenter sees the participant view too
        return self

    def open_participant_screen(self) -> str:
        """Open the participant screen where it was (first: beside this window, or on its own monitor), brought
        onto a monitor and out of its minimised state; returns how the participant still cannot see it ("")."""
        w, before = self.participant_window, QApplication.activeWindow()
        self.open_window(w, activate=False)
        if before is not None and before is not w and QApplication.activeWindow() is not before:
            before.activateWindow()  # the experimenter's keys stay where they were (a platform may have moved them)
        w.report()  # at once: the engine hears it is open before the start that follows
        return w.unseen()

    def open_window(self, w: QWidget, activate: bool = True) -> None:
        """Show one of the extra windows: where it was last (brought onto a monitor if it is off every one), else at
        a size that fits, on the right screen; in front, and with the keyboard if ``activate``."""
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
                    placement.place_over(w, size, self)  # over this window, not the participant screen beside
        if w is self.participant_window:
            placement.keep_above(w, self)
        _show(w, activate)
        placement.onto_a_screen(w)

    # -- views of state ------------------------------------------------------------------------------------
    def _on_actions_changed(self) -> None:
        actions = self.model.actions
        can = actions.can
        self.start_button.setEnabled(can("start"))
        self.start_button.setToolTip("" if can("start") else f"Start is not available: {actions.start_refusal()}")
        untrained = bool(self.model.setup.training_missing)
        self.untrained_button.setVisible(untrained)
        self.untrained_button.setEnabled(can("start_without_training"))
        self.untrained_button.setToolTip("Asks for the reason; it is stored with the session as a deviation from "
                                         "the protocol, and the report lists it")
        self.calibration_wizard.set_blocked(self.model.actions.calibration_refusal())
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
        self.note_button.setEnabled(can("note"))
        self.setup_panel.resume_button.setEnabled(can("resume_session"))
        self.setup_panel.setEnabled(not self.model.session.running)
        missing = self.model.actions.calibration_missing()
        self.override_button.setVisible(bool(missing))
        self.override_button.setEnabled(bool(missing) and can("start"))
        self.override_button.setToolTip(missing)

    def _on_questionnaire_changed(self) -> None:
        """Skip questionnaire…: shown while one waits for the participant's answers (not once they are sent)."""
        q = self.model.questionnaire
        self.skip_questionnaire_button.setVisible(q.active and not q.sent)

    def _on_engine_changed(self) -> None:
        trouble, detail = self.model.engine.notice()
        self.controls.show_engine(trouble, detail, self.model.actions.can("restart_engine"))

    def _on_session_changed(self) -> None:
        s = self.model.session
        count = s.count_text() if s.running else ""
        self.status.set_full_text(s.message + (f" — {count}" if count else ""))
        if count != self.trials_count.full_text():
            self.trials_count.set_full_text(count)
            self.trials_count.setVisible(bool(count))
        if hasattr(self.rig_window, "fault_trial"):
            self.rig_window.set_trials(self.model.rig_control.rehearsal_trials())

    def _on_health_changed(self) -> None:
        """The health tab's title says when something there needs the experimenter (a fault, a busy machine)."""
        i = self.tabs.indexOf(self.health_panel)
        text = "Devices && health" + ("  ⚠" if self.health_panel.attention() else "")
        if self.tabs.tabText(i) != text:
            self.tabs.setTabText(i, text)
        if hasattr(self, "menus"):
            self.menus.refresh()

    def _on_notice(self) -> None:
        self.controls.show_notice(self.model.notices.notice)

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
        self.model.screen.opener = None
        self.participant_window.seen_changed.disconnect(self.model.screen.shown)  # closing it is no news to the engine
        self.plot_timer.stop()
        self.model.plots.detach()
        self.bridge.shutdown()
        for w in (self.participant_window, self.rig_window, self.calibration_wizard):
            w.close()
            w.deleteLater()

    def closeEvent(self, event) -> None:  # Qt's name
        if not self.session_actions.may_quit():  # a session runs: asked (or refused by a scripted run)
            event.ignore()
            return
        self.session_actions.dismiss()
        self._save_settings()
        self.shutdown()
        event.accept()


def _show(w: QWidget, activate: bool = True) -> None:
    """Show ``w`` in front -- also out of its minimised state (``show`` alone leaves a minimised window an icon),
    keeping full screen or maximised as it was -- with the keyboard if ``activate``."""
    if w.isMinimized():
        w.setWindowState(w.windowState() & ~Qt.WindowState.WindowMinimized)
    w.setAttribute(Qt.WidgetAttribute.WA_ShowWithoutActivating, not activate)
    w.show()
    w.raise_()
    if activate:
        w.activateWindow()
