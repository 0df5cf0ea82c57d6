"""What a first-day assistant met in the real window (issue 40, items 3, 5 and 8): Space in a read-only field, a
minimised window, the plots squashed by the splitter, a cut jaw line, a one-letter reason, a database without
``.db`` -- each as the assistant would expect it now."""

from __future__ import annotations

import os

from conftest import SHORT_PROTOCOL, open_ready_window
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QApplication, QSplitter

from protocol.tasks.force_regulation import ForceRegulation
from study_app.engine import messages as m
from study_app.gui.force_plots import LOWER_PLOT_MIN_PX, UPPER_PLOT_MIN_PX
from study_app.gui.main_window import TABLE_MIN_HEIGHT
from study_app.gui.setup_panel import SPACE_IN_A_FIELD, SPACE_WHILE_TYPING
from study_app.models.app import AppModel
from study_app.models.calibration import pose_name
from study_app.models.setup import SetupModel

TIMEOUT_MS = 30_000
KNOWN = [{"session_id": 1, "code": "P01", "participant_number": 1, "kind": "training", "status": "completed",
          "seed": 0, "trials_planned": 2, "trials_done": 2, "trials_aborted": 0}]


def test_space_in_a_read_only_field_never_starts(qtbot, tmp_path):
    w = open_ready_window(qtbot, tmp_path, SHORT_PROTOCOL, speed=4.0, timeout_ms=TIMEOUT_MS)
    panel = w.setup_panel
    w.model.setup.set_known(KNOWN)  # the study has a session: its seed is read-only
    w.model.setup.update(code="P02", kind="training")
    assert panel.seed.isReadOnly() and w.start_button.isEnabled()
    w.activateWindow()
    qtbot.waitUntil(lambda: QApplication.activeWindow() is w, timeout=TIMEOUT_MS)
    panel.seed.setFocus()
    qtbot.keyClick(panel.seed, Qt.Key.Key_Space)  # it started the session before
    assert not w.model.session.running and panel.hint.text() == SPACE_WHILE_TYPING
    w.tabs.setCurrentWidget(w.health_panel)
    w.health_panel.log.setFocus()  # the fault log: read-only text
    qtbot.keyClick(w.health_panel.log, Qt.Key.Key_Space)
    assert not w.model.session.running and w.notice.text() == SPACE_IN_A_FIELD
    w.plots.setFocus()  # outside every field, Space starts as it always did
    qtbot.keyClick(w.plots, Qt.Key.Key_Space)
    qtbot.waitUntil(lambda: w.model.session.running, timeout=TIMEOUT_MS)


def test_a_minimised_window_comes_back_by_its_button_and_its_view_action(qtbot, tmp_path):
    w = open_ready_window(qtbot, tmp_path, SHORT_PROTOCOL, speed=4.0, timeout_ms=TIMEOUT_MS)
    rig = w.rig_window
    for bring_back in (w.rig_button.click, w.view_actions["Simulated rig"].trigger):
        w.open_window(rig)
        rig.showMinimized()
        qtbot.waitUntil(rig.isMinimized, timeout=TIMEOUT_MS)
        bring_back()
        assert rig.isVisible() and not rig.isMinimized()


def test_the_splitters_never_squash_the_plots_or_the_table_to_nothing(qtbot, tmp_path):
    w = open_ready_window(qtbot, tmp_path, SHORT_PROTOCOL, speed=4.0, timeout_ms=TIMEOUT_MS)
    right = w.tabs.parentWidget()
    assert isinstance(right, QSplitter)
    w.resize(990, 728)  # a 1366x768 laptop's window beside the participant screen: the legend wraps to 3 lines
    right.setSizes([0, 5000])  # the handle dragged to the top
    QApplication.processEvents()
    # each plot's data area keeps room to be read (the 240 px the column kept left the upper one 20 px tall, its
    # axis title over the lower one's), and nothing of the column is cut to fit
    upper, lower = (p.getViewBox().height() for p in (w.plots.task, w.plots.lower_plot))
    assert upper >= UPPER_PLOT_MIN_PX and lower >= LOWER_PLOT_MIN_PX, (upper, lower)
    for p, height in ((w.plots.task, upper), (w.plots.lower_plot, lower)):  # each axis title whole beside its plot
        assert p.getAxis("left").label.boundingRect().width() <= height, p.getAxis("left").labelText
    bottom = w.plots.lower_plot.sceneBoundingRect().bottom()  # the time axis under the lower plot, not cut off
    assert bottom <= w.plots.view.height() + 1, (bottom, w.plots.view.height())  # (+1: sub-pixel layout)
    # ... by the widget around it either (the wrapped legend above took its room: the view ran past the bottom)
    assert w.plots.view.geometry().bottom() < w.plots.height(), (w.plots.view.geometry(), w.plots.height())
    top = right.widget(0)
    assert top.height() >= top.minimumSizeHint().height()
    w.plots.lower_choice.setCurrentText("none")  # the lower plot hidden: the upper one keeps its time axis
    QApplication.processEvents()
    bottom = w.plots.task.sceneBoundingRect().bottom()
    assert w.plots.task.getViewBox().height() >= UPPER_PLOT_MIN_PX and bottom <= w.plots.view.height() + 1
    right.setSizes([5000, 0])
    QApplication.processEvents()
    assert right.sizes()[1] >= TABLE_MIN_HEIGHT
    assert not right.childrenCollapsible() and not w.centralWidget().childrenCollapsible()


def test_the_jaw_s_last_command_is_shown_whole(qtbot, tmp_path):
    w = open_ready_window(qtbot, tmp_path, SHORT_PROTOCOL, speed=4.0, timeout_ms=TIMEOUT_MS)
    last = ("step_close: 1 mm of rod travel toward closed → 38 % open (1420 µs), from the right stylus's lower "
            "button during trial 3")
    w.model.jaw.apply(m.JawState(0.38, 1420, False, "", last))
    box = w.jaw_box
    assert box.last.text() == f"last: {last}" and box.last.wordWrap()


def test_a_deviation_needs_a_reason_in_words_and_a_database_gets_its_type():
    sent: list[object] = []
    app = AppModel(lambda cmd: sent.append(cmd) or True)
    app.screen.opener = None  # (no window: no participant screen to open)
    for reason in ("x", "  ok  "):
        assert not app.control.start(training_override=reason)
        assert not app.control.start(override_reason=reason)
        assert app.notices.notice.text.startswith(f"Nothing was started: reason = {reason.strip()!r}: say why in a "
                                                  "few words")
    assert not any(isinstance(c, m.StartSession) for c in sent)
    setup = SetupModel()
    setup.update(db_path="study")  # a new database typed without its type
    assert setup.values.db_path == "study.db"
    setup.update(db_path="trial.sqlite")
    assert setup.values.db_path == "trial.sqlite"
    assert os.path.isdir("tests") and SetupModel().values.db_path == ""
    setup.update(db_path="tests")  # an existing folder keeps its name (and is refused as a folder)
    assert setup.values.db_path == "tests" and "is a folder" in setup.errors["db_path"]


def test_calibration_poses_are_not_named_like_participants():
    assert pose_name("P07") == "pose 7" and pose_name("pose 3") == "pose 3" and pose_name("tool-down") == "tool-down"


def test_a_re_run_of_a_re_run_names_the_designed_trial():
    """Issue 40, item 8: "57 (re-run of trial 48)" named the previous attempt; the designed trial is 12."""
    from gui_trials import trial_record

    from protocol.study.records import AbortCause
    from study_app.models.session import SessionModel

    s = SessionModel()
    s.apply(m.SessionStarted(1, "P01", "experiment", 60, 0, ForceRegulation(), 12.0, 2.0, 1.0, False))
    for index, repeat_of in ((11, None), (47, 11)):
        s.apply(m.TrialEnded(1.0, trial_record(trial_index=index, repeat_of=repeat_of, outcome="aborted",
                                               abort_reason="operator", abort_cause=AbortCause.EXPERIMENTER), 60))
    assert s.table.designed_of(47) == 11 and s.table.designed_of(11) == 11
    last = trial_record(trial_index=56, repeat_of=47)
    assert s.table.cells(last, s.table.designed_of(47))[0] == "57 (re-run of 12)"
    s.apply(m.TrialStarted(5.0, 56, 58, 60, "FIRM", 1.2, "on", repeat_of=47))
    s.set_time(6.0)
    assert s.progress_text().startswith("Trial 57 (re-run of trial 12) · FIRM · haptics ON · times out in 11.0 s")


def test_the_fault_log_says_when_one_way_and_whose_session_each_line_is():
    """Issue 40, item 8: the log mixed "session N s" and "t = N s" and kept earlier sessions' lines unnamed."""
    from study_app.models.health import HealthModel

    h = HealthModel()
    h.apply(m.SessionStarted(3, "P01", "experiment", 2, 0, ForceRegulation(), 12.0, 2.0, 1.0, False))
    h.apply(m.EngineFault(10.0, "fault", 1, "SENSOR_STALE", session_t_s=2.5))
    h.apply(m.SessionEnded(3, "completed", "", 2, 0, 1))
    h.apply(m.EngineFault(20.0, "fault", 2, "POSE_STALE"))
    h.apply(m.SessionStarted(4, "P02", "training", 2, 0, ForceRegulation(), 12.0, 2.0, 1.0, True))
    assert h.fault_log == ["— session 3 (P01 experiment) started —", "session 3, 2.500 s  fault: SENSOR_STALE",
                           "no session, engine clock 20.000 s  fault: POSE_STALE",
                           "— session 4 (P02 training) started —"]


def test_the_banner_shows_a_long_reason_whole(qtbot):
    """Seen in the real window at 1366×768: the banner cut the last line of the runner's long reason."""
    from PySide6.QtWidgets import QTableWidget, QVBoxLayout, QWidget

    from study_app.gui.session_views import QtCueWait
    from study_app.models.cue_wait import CueWait

    app = AppModel()
    holder = QWidget()  # the Trials tab: the count, the banner, the table taking the rest
    qtbot.addWidget(holder)
    lay = QVBoxLayout(holder)
    lay.setContentsMargins(0, 0, 0, 0)
    lay.setSpacing(2)
    banner = QtCueWait(app.cue)
    lay.addWidget(banner)
    lay.addWidget(QTableWidget(5, 7), 1)
    holder.resize(620, 190)
    holder.show()
    qtbot.waitExposed(holder)
    app.cue.wait = CueWait("error", "3 trials in a row were not delivered as designed (the last: gap: no loop record "
                           "for 8.8 ms (limit 5 ms)); the rig or the machine cannot hold the designed condition: "
                           "paused — check the machine's load and the devices, then Resume", action="resume",
                           help="Resume (Space) once the cause is dealt with; Devices & health says whether this "
                                "computer is too busy for the loop.")
    app.cue.changed.emit()
    for label in (banner.label, banner.help):
        qtbot.waitUntil(lambda lb=label: lb.height() >= lb.heightForWidth(lb.width()), timeout=5_000)
