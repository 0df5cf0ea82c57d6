"""The scripted screenshot tour (``haptic-study gui --screenshot DIR``): every state of the guide, at 1366×768.

A short simulated study driven through the window's own controls, offscreen on one 1366×768 screen (what a lab
laptop gives the window): the calibration chain; a new participant, whose experiment is refused for want of
training and then started with the override; the live view during a trial, the participant screen beside the
window, an aborted trial and its re-run, the pause; the calibration refused during a session and the menus;
a second participant with another seed; a training session with the live gauge; the busy-machine notice; an
engine crash and its restart.

The busy-machine notice is the one state the simulated rig on the virtual clock cannot produce (its loop never
falls behind): the tour shows it by handing the window the events a gap abort sends (the engine's ``gap``
fault and the aborted trial's record, built as the session runner builds them), after the real session ended.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from PySide6.QtCore import QPoint, QRect
from PySide6.QtGui import QColor, QPainter, QPixmap
from PySide6.QtWidgets import QApplication, QMenu, QMessageBox, QWidget

from protocol.study.clock import SessionClock
from protocol.study.design import HapticMode
from protocol.study.records import AbortCause, Outcome, TrialRecord
from protocol.tasks.force_regulation import ForceRegulation
from study_app.engine import messages as m
from study_app.gui.timers import tracked_timer

if TYPE_CHECKING:
    from study_app.gui.main_window import ExperimenterWindow

__all__ = ["SCREEN", "ScreenshotTour"]

#: The screen the tour runs on (the offscreen platform is given one of this size).
SCREEN = QRect(0, 0, 1366, 768)
#: The experimenter window's contents on it: a 1366×768 laptop less a panel and the title bar.
WINDOW = (1280, 728)


class ScreenshotTour:
    """Drives the window through the guide's states and saves a PNG of each.

    The tour is a generator of conditions stepped by a timer: each ``yield`` returns a predicate to wait for
    (with a timeout), so the event loop keeps running and the engine keeps delivering events.
    """

    def __init__(self, win: ExperimenterWindow, out_dir: Path, on_done: Callable[[], None]) -> None:
        self.win = win
        self.out_dir = out_dir
        self.on_done = on_done
        self.saved: list[str] = []
        self.error = ""
        self._steps = self._script()
        self._wait: Callable[[], bool] | None = None
        self._deadline = 0.0
        self._timer = tracked_timer(win, 50, self._step, name="screenshot-tour")

    def start(self) -> None:
        """Begin the tour."""
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self._timer.start()

    def _step(self) -> None:
        try:
            if self._wait is not None and not self._wait():
                if time.monotonic() > self._deadline:
                    raise TimeoutError("screenshot tour: a step did not complete within its timeout")
                return
            self._wait = next(self._steps)
            self._deadline = time.monotonic() + 60.0
        except StopIteration:
            self._finish()
        except Exception as exc:  # reported by run_gui
            self.error = f"{type(exc).__name__}: {exc}"
            self._finish()

    def _finish(self) -> None:
        self._timer.stop()
        self.on_done()

    def _save(self, widget: QWidget, name: str) -> None:
        QApplication.processEvents()
        self._write(widget.grab(), name)

    def _write(self, pixmap: QPixmap, name: str) -> None:
        path = self.out_dir / f"{name}.png"
        if not pixmap.save(str(path)):
            raise OSError(f"cannot write {path}")
        self.saved.append(str(path))

    def _save_screen(self, windows: list[QWidget], name: str) -> None:
        """The whole 1366×768 screen: each window where it is (the offscreen platform draws no title bars)."""
        QApplication.processEvents()
        screen = QPixmap(SCREEN.size())
        screen.fill(QColor(58, 64, 74))
        p = QPainter(screen)
        for w in windows:
            p.drawPixmap(w.geometry().topLeft(), w.grab())
        p.end()
        self._write(screen, name)

    def _save_menu(self, menu: QMenu, name: str) -> None:
        """A menu as it opens under its title (hovering a disabled action shows why in its tooltip)."""
        menu.popup(self.win.mapToGlobal(QPoint(0, 0)))
        QApplication.processEvents()
        self._write(menu.grab(), name)
        menu.hide()

    def _script(self) -> Iterator[Callable[[], bool]]:
        w = self.win
        model = w.model
        w.resize(*WINDOW)
        w.move(0, 0)
        yield lambda: model.session.state == "ready"
        yield from self._calibration()
        yield from self._experiment_without_training()
        yield from self._during_the_session()
        yield from self._second_participant_and_training()
        self._busy_machine()
        yield from self._engine_crash()

    def _calibration(self) -> Iterator[Callable[[], bool]]:
        """The chain in order -- TCP, then the payload's recommended set, accepted."""
        model, wiz = self.win.model, self.win.calibration_wizard
        wiz.resize(720, 640)
        wiz.show()
        wiz.tcp_page.run_button.click()
        yield lambda: model.commissioning.tcp_state == "accepted"
        wiz.steps.setCurrentWidget(wiz.payload_page)
        model.calibration.set_pose_set("recommended")
        wiz.run_button.click()
        yield lambda: model.calibration.state == "accepted"
        self._save(wiz, "calibration-wizard")
        wiz.hide()

    def _experiment_without_training(self) -> Iterator[Callable[[], bool]]:
        """A new participant: training proposed; the experiment refused with the reason; started with the override."""
        w, model = self.win, self.win.model
        self.code = f"DEMO{int(time.time()) % 100000:05d}"
        w.setup_panel.code.setText(self.code)
        model.setup.update(participant_number=1)
        self._save(w, "next-step-training")
        model.setup.update(kind="experiment")
        self._save(w, "training-required")
        w.rig_window.resize(760, 480)
        w.rig_window.show()
        w.untrained_button.click()  # the tour's confirm answers at once ("scripted override")
        yield lambda: model.session.running
        w.open_window(w.participant_window)
        yield lambda: model.session.trial is not None and model.session.trial.position >= 2
        yield lambda: (model.session.phase == "active" and model.session.trial is not None
                       and model.session.latest_t_s - model.session.trial.t_s < 0.6)
        self._save_screen([w, w.participant_window], "participant-beside")
        self._save(w.participant_window, "participant-experiment")

    def _during_the_session(self) -> Iterator[Callable[[], bool]]:
        """The live view, the rig, the health panel; an aborted trial and its re-run; the pause; what is refused."""
        w, model = self.win, self.win.model
        yield lambda: (model.session.phase == "active" and model.session.trial is not None
                       and model.session.trial.position >= 3 and model.rig.indentation_mm > 0.8)
        self._save(w, "experimenter-window")
        self._save(w.rig_window, "sim-rig-view")
        w.rig_window.hide()
        w.tabs.setCurrentWidget(w.health_panel)
        w.health_panel.resize(900, 420)  # all of it (in the window, a short tab scrolls)
        self._save(w.health_panel, "health-panel")
        w.tabs.setCurrentWidget(w.trials_tab)
        trial = model.session.trial
        model.control.abort_trial(None if trial is None else trial.trial_index)  # (the tour's confirm answers Yes)
        yield lambda: model.session.aborted >= 1 and model.session.completed >= 3
        yield lambda: model.session.phase == "active"
        self._save(w, "progress-rerun")
        yield lambda: model.session.phase == "pause"
        self._save(w.participant_window, "participant-rest")
        yield lambda: model.cue.wait is not None and model.cue.wait.left_s is not None and model.cue.wait.left_s < 1.6
        self._save(w.tabs, "trials-cue-wait")
        # not during a session: the calibration steps are disabled, and say why; the menus show the same
        w.open_window(w.calibration_wizard)
        self._save(w.calibration_wizard, "calibration-blocked")
        w.calibration_wizard.hide()
        self._save_menu(w.menus.session, "menu-session")
        self._save_menu(w.menus.file, "menu-file")
        w.abort_session_button.click()
        yield lambda: model.session.state == "ended"

    def _second_participant_and_training(self) -> Iterator[Callable[[], bool]]:
        """Another seed refused in one line; with the study's seed, a training session with the live gauge."""
        w, model = self.win, self.win.model
        yield lambda: model.setup.seed_fixed_by is not None
        w.setup_panel.code.setText(self.code + "B")
        stored = model.setup.values.seed
        model.setup.update(seed=stored + 1)
        self._save(w, "seed-refused")
        model.setup.update(seed=stored, kind="training")
        w.start_button.click()
        yield lambda: (model.session.phase == "active" and model.participant.screen.show_gauge
                       and model.participant.force_n > 0.3)
        self._save(w.participant_window, "participant-training")
        about = QMessageBox(QMessageBox.Icon.Information, "About haptic-study", "", parent=w)
        from study_app.gui.menus import about_text

        about.setText(about_text())
        about.show()
        self._save(about, "help-about")
        about.close()
        w.abort_session_button.click()
        yield lambda: model.session.state == "ended"

    def _busy_machine(self) -> None:
        """The health panel's notice when the loop's falling behind cost trials (see the module docstring)."""
        w, model = self.win, self.win.model
        session = m.SessionStarted(99, self.code + "C", "experiment", 20, 0, ForceRegulation(), 12.0, 2.0, 1.0, False,
                                   seed=0)
        model.health.apply(session)
        model.health.apply(m.Health(998.0, 1000.0, 2800.0, 1900.0, 41, 12, 60_000, 0, False, "autopilot", True,
                                    False, scheduling="normal (Operation not permitted)"))
        for k, gap_ms in ((3, 14.5), (7, 9.2), (8, 22.0)):
            reason = f"gap: no loop record for {gap_ms:.1f} ms (limit 5 ms)"
            model.health.apply(m.EngineFault(k * 15.0, "gap", 0, reason, k * 15.0))
            record = TrialRecord(session_id=99, trial_index=k - 1, target_label="FIRM", target_force_n=1.2,
                                 haptic_mode=HapticMode.ON, outcome=Outcome.ABORTED, clock=SessionClock(0.0, 0),
                                 cue_ns=0,
                                 end_ns=int(3e9), abort_reason=reason, abort_cause=AbortCause.GAP)
            model.health.apply(m.TrialEnded(k * 15.0, record, 23))
        w.tabs.setCurrentWidget(w.health_panel)
        self._save(w, "busy-machine")
        model.health.apply(m.SessionStarted(100, "RESET", "training", 1, 0, ForceRegulation(), 12.0, 2.0, 1.0, False))
        model.health.apply(m.Health(1000.0, 1000.0, 1003.0, 3.0, 0, 0, 60_000, 0, False, "autopilot", False, False))
        w.tabs.setCurrentWidget(w.trials_tab)

    def _engine_crash(self) -> Iterator[Callable[[], bool]]:
        """The engine crashes (the rehearsal's kill): the window says so and offers the restart."""
        w, model = self.win, self.win.model
        w.participant_window.hide()
        model.rig_control.inject_fault("kill", None, 0.0)
        yield lambda: w.engine_row.isVisible()
        self._save(w, "engine-restart")
        w.restart_button.click()
        yield lambda: model.session.state == "ready"
