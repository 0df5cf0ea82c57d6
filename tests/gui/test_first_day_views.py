"""What a first-day assistant meets, view by view (no engine): the newest row kept in view, the participant screen
beside the controls and keeping its size, the busy machine in words, notices that go with their cause."""

from __future__ import annotations

from pathlib import Path

import pytest
from gui_trials import trial_record
from PySide6.QtCore import QRect, QSize
from PySide6.QtWidgets import QApplication

from protocol.study.records import AbortCause
from protocol.tasks.force_regulation import ForceRegulation
from study_app.engine import messages as m
from study_app.gui.health_panel import QtHealthPanel
from study_app.gui.participant_window import HEADLINE_MAX_PX, ParticipantWindow
from study_app.gui.placement import BESIDE_MIN, onto_a_screen, over_the_older_plots, side_by_side
from study_app.gui.session_views import QtTrialTable
from study_app.models.app import AppModel
from study_app.models.health import HealthModel
from study_app.models.participant import ParticipantScreenModel
from study_app.models.session import TrialCount, TrialTable, time_left_text
from study_app.models.setup import SetupModel

FRAME = QSize(8, 34)  # a window manager's borders and title bar


def test_the_participant_screen_goes_beside_the_window_never_over_it():
    # issue 40, item 4: on one 1366-px monitor it covered the plots' newest seconds and the table's outcome columns
    laptop = QRect(0, 0, 1366, 768)
    main = QRect(40, 5, 1288, 762)  # the experimenter's window, its frame: no room beside it
    got = side_by_side(laptop, main, 790, QSize(640, 400), FRAME)
    assert got is not None
    main_after, r = got
    assert not r.intersects(main_after) and laptop.contains(r) and laptop.contains(main_after)
    assert main_after.left() == 0 and main_after.width() >= 790  # moved to the edge and narrowed to leave the room
    assert r.width() - FRAME.width() >= BESIDE_MIN.width() and r.left() == main_after.right() + 1
    wide = QRect(0, 0, 1920, 1080)
    main_after, r = side_by_side(wide, QRect(316, 159, 1288, 762), 790, QSize(640, 400), FRAME)
    assert main_after == QRect(0, 159, 1288, 762)  # centred, no room on either side: moved, not narrowed
    assert (r.left(), r.width(), r.height()) == (1288, 632, 424) and wide.contains(r)  # the room there is
    main_after, r = side_by_side(wide, QRect(0, 0, 1288, 762), 790, QSize(640, 400), FRAME)
    assert main_after == QRect(0, 0, 1288, 762) and r.left() == 1288  # room already: the main window stays
    tiny = QRect(0, 0, 800, 600)  # too narrow for both: over the older plots, clear of the controls
    assert side_by_side(tiny, QRect(0, 0, 800, 600), 790, QSize(640, 400), FRAME) is None
    controls = QRect(0, 40, 350, 500)
    r = over_the_older_plots(tiny, controls, QSize(640, 400), FRAME)
    assert r.left() > controls.right() and tiny.contains(r) and r.right() < 350 + (800 - 350) // 2 + 10


def test_a_participant_screen_off_every_monitor_is_brought_back(qtbot):
    w = ParticipantWindow(ParticipantScreenModel())
    qtbot.addWidget(w)
    w.resize(400, 260)
    w.show()
    qtbot.waitExposed(w)
    avail = w.screen().availableGeometry()
    w.move(avail.right() - 100, avail.bottom() + 20)  # reopened 20 px below the screen's edge
    assert w.unseen() == "off every monitor"
    onto_a_screen(w)
    assert avail.contains(w.frameGeometry()) and w.unseen() == ""


def test_the_participant_screen_keeps_the_size_given_and_scales_the_cue(qtbot):
    p = ParticipantScreenModel()
    w = ParticipantWindow(p)
    qtbot.addWidget(w)
    w.resize(400, 260)
    w.show()
    qtbot.waitExposed(w)
    p.apply(m.SessionStarted(1, "P01", "experiment", 2, 0, ForceRegulation(), 12.0, 2.0, 1.0, False))
    p.apply(m.TrialStarted(1.0, 0, 1, 2, "VERYLONGTARGET", 0.6, "off"))  # a protocol's own, long target word
    p.update(1.2, 0.0)
    p.apply(m.SessionEnded(1, "completed", "", 2, 0, 0))
    QApplication.processEvents()
    assert (w.width(), w.height()) == (400, 260)  # it never grows to fit its text
    small = w.headline_px
    assert 16 <= small < HEADLINE_MAX_PX and w.headline.text() == "Thank you"
    w.resize(1200, 700)
    qtbot.waitUntil(lambda: w.headline_px > small)


def test_the_trial_table_keeps_the_newest_row_in_view_unless_scrolled_away(qtbot):
    table = TrialTable()
    view = QtTrialTable(table)
    qtbot.addWidget(view)
    view.resize(600, 150)
    view.show()
    qtbot.waitExposed(view)
    bar = view.verticalScrollBar()
    for i in range(12):
        table.add(trial_record(trial_index=i))
    qtbot.waitUntil(lambda: bar.maximum() > 0)  # (the range follows the layout)
    assert bar.value() == bar.maximum()
    view.resize(600, 100)  # a banner appears above the table: the newest row stays in view
    qtbot.waitUntil(lambda: bar.value() == bar.maximum())
    bar.setValue(0)  # the assistant scrolls up to read an older row: it stays there
    table.add(trial_record(trial_index=12, repeat_of=3, outcome="aborted", abort_reason="operator",
                           abort_cause=AbortCause.EXPERIMENTER))
    QApplication.processEvents()
    assert bar.value() == 0
    assert view.item(12, 0).text() == "13 (re-run of 4)"
    bar.setValue(bar.maximum())  # back to the end: it follows again
    table.add(trial_record(trial_index=13))
    qtbot.waitUntil(lambda: bar.value() == bar.maximum() and view.rowViewportPosition(13) < view.viewport().height())


def test_the_fault_log_reads_oldest_first_and_keeps_the_newest_in_view(qtbot):
    h = HealthModel()
    view = QtHealthPanel(h)
    qtbot.addWidget(view)
    view.resize(700, 420)
    view.show()
    qtbot.waitExposed(view)
    assert "oldest first and newest last" in view.log_label.text()
    for k in range(30):
        h.apply(m.EngineFault(float(k), "fault" if k % 2 else "fault_cleared", 1, f"SENSOR_STALE event {'ab'[k % 2]}",
                              float(k)))
    bar = view.log.verticalScrollBar()
    assert bar.maximum() > 0 and bar.value() == bar.maximum()
    assert view.log.toPlainText().splitlines()[-1].startswith("session clock, 29.000 s")
    h.apply(m.EngineFault(30.0, "faults_reset", 0, "", 30.0))  # Reset faults: the view stays at the newest line
    assert bar.value() == bar.maximum()


def test_a_computer_too_busy_for_the_loop_is_said_in_words():
    h = HealthModel()
    h.apply(m.SessionStarted(1, "P01", "experiment", 20, 0, ForceRegulation(), 12.0, 2.0, 1.0, False))
    assert h.machine_notice() == ""
    h.apply(m.Health(990.0, 1000.0, 2000.0, 900.0, 30, 5, 20_000, 0, True, "autopilot", True, False,
                     scheduling="normal (Operation not permitted)"))
    gap = trial_record(trial_index=6, outcome="aborted", abort_reason="gap: no loop record for 14.5 ms (limit 5 ms)",
                       abort_cause=AbortCause.GAP)
    h.apply(m.TrialEnded(3.0, gap, 21))
    h.apply(m.TrialEnded(4.0, trial_record(trial_index=7, outcome="aborted", abort_reason="operator",
                                           abort_cause=AbortCause.EXPERIMENTER), 22))
    text = h.machine_notice()
    assert text.startswith("This computer is too busy for the 1 kHz haptic loop: 1 trial of this session (trial 7) "
                           "was aborted because the loop fell behind")
    assert "What helps: close other programs" in text
    assert "did not get it (Operation not permitted)" in text and "allow real-time scheduling" in text
    # the guide by a path that exists here (a lab that installed the wheel has no docs/ folder of its own)
    assert text.endswith(f"for this user ({Path(__file__).resolve().parents[2] / 'docs' / 'gui.md'}, Machine health).")
    h.apply(m.Health(990.0, 1000.0, 2000.0, 900.0, 30, 5, 20_000, 0, True, "autopilot", True, False,
                     scheduling="SCHED_FIFO/20"))
    assert h.machine_notice().endswith("The loop asked for real-time priority and got it (SCHED_FIFO/20).")
    for k in (8, 9, 10, 11, 12, 13, 14):  # eight lost: the newest five are named, the older ones elided before them
        h.apply(m.TrialEnded(5.0 + k, trial_record(trial_index=k, outcome="aborted", abort_cause=AbortCause.GAP,
                                                   abort_reason="gap: no loop record for 9.1 ms (limit 5 ms)"), 30))
    assert "8 trials of this session (trials …, 11, 12, 13, 14, 15) were aborted" in h.machine_notice()


def test_the_fault_log_names_an_aborted_trial_s_cause_once():
    h = HealthModel()
    h.apply(m.EngineFault(3.0, "gap", 0, "gap: no loop record for 14.5 ms (limit 5 ms)", 3.0))
    h.apply(m.EngineFault(4.0, "feedback", 0, "feedback: the force was not rendered as designed", 4.0))
    assert h.fault_log == ["session clock, 3.000 s  gap: no loop record for 14.5 ms (limit 5 ms)",
                           "session clock, 4.000 s  feedback: the force was not rendered as designed"]


def test_notices_go_with_their_cause_and_the_form_speaks_plainly(tmp_path):
    app = AppModel()
    app.apply(m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot"))
    app.apply(m.SessionStarted(1, "P01", "experiment", 2, 0, ForceRegulation(), 12.0, 2.0, 1.0, False))
    assert app.actions.calibration_refusal().startswith("not during a session")
    app.apply(m.CommandRefused("CalibrateTcp", "a session is running"))
    assert app.notices.notice is not None and app.notices.notice.text == "TCP calibration refused: a session is running"
    app.apply(m.SessionEnded(1, "completed", "", 2, 0, 0))
    # the cause has gone: so has the notice
    assert app.notices.notice is None and app.actions.calibration_refusal() == ""
    app.apply(m.EngineStopped("the study engine exited unexpectedly", {}))
    # the calibration window (over the main window) says so too: its buttons would send into nothing
    assert app.actions.calibration_refusal() == ("the study engine is not running: press Restart engine in the main "
                                                 "window")
    app.apply(m.CommandRefused("CheckFrames", "no payload"))
    app.notices.clear(("Calibrate",))
    assert app.notices.notice is not None  # another command's notice stays
    s = SetupModel()
    s.update(db_path=str(tmp_path / "s.db"))
    s.set_known([{"session_id": 3, "code": "P01", "participant_number": 1, "kind": "experiment", "status": "aborted",
                  "seed": 0, "trials_done": 2, "trials_planned": 20}])
    s.update(code="P01", kind="experiment")
    assert "P01 already has an aborted experiment session (session 3)" in s.errors["code"]


@pytest.mark.parametrize(("seconds", "bound", "text"), [
    (4.0, False, "about 10 s left"), (41.0, False, "about 40 s left"), (90.0, False, "about 2 min left"),
    (280.0, True, "at most 5 min left"), (0.0, False, "about 10 s left"), (12.3, False, "about 10 s left"),
    (16.0, False, "about 20 s left"), (12.3, True, "at most 20 s left"),  # issue 40: an estimate is not rounded up
])
def test_time_left_is_said_as_people_say_it(seconds, bound, text):
    assert time_left_text(seconds, bound=bound) == text


def test_one_count_never_grows_with_re_runs():
    assert TrialCount(20).text() == "0 of 20 trials done"
    c = TrialCount(20, done=7, aborted=2, reruns_run=1)
    assert c.text() == "7 of 20 trials done · 2 aborted · 1 re-run left"
    assert c.fraction == pytest.approx(0.35, rel=1e-15)  # 7/20, up to the division's rounding
    assert TrialCount(20, 20, 3, 3).text() == "20 of 20 trials done · 3 aborted"


def test_help_about_names_the_version_the_commit_and_the_paper():
    from study_app.gui.menus import about_text
    from study_app.version_info import version_text

    text = about_text()
    assert version_text() in text and "Shaker and M. S. Erden" in text and "Robotic Surgery Training" in text


def test_the_experimenter_s_other_windows_open_over_its_window_not_the_participant_screen(qtbot):
    """Seen at 1920×1080: the rig view opened centred on the screen, over the participant screen beside the window."""
    from PySide6.QtWidgets import QWidget

    from study_app.gui.placement import place_over

    main, rig = QWidget(), QWidget()
    qtbot.addWidget(main)
    qtbot.addWidget(rig)
    avail = main.screen().availableGeometry()
    main.resize(avail.width() // 2, avail.height() // 2)
    main.move(avail.topLeft())
    main.show()
    qtbot.waitExposed(main)
    place_over(rig, QSize(avail.width() // 4, avail.height() // 4), main)
    assert main.frameGeometry().contains(rig.frameGeometry().center()) and avail.contains(rig.frameGeometry())
