"""Composition root of the GUI: QApplication, the experimenter window, and the scripted screenshot tour."""

from __future__ import annotations

import os
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from PySide6.QtCore import QSettings, QtMsgType, qInstallMessageHandler
from PySide6.QtWidgets import QApplication, QWidget

from study_app.engine_setup import HostConfig
from study_app.gui.main_window import ExperimenterWindow
from study_app.gui.timers import tracked_timer

__all__ = ["ScreenshotTour", "run_gui"]


def run_gui(host: HostConfig, *, db_path: str | None = None, screenshot_dir: str | None = None) -> int:
    """Open the experimenter window (or run the screenshot tour) and return the exit status."""
    if screenshot_dir is not None:
        os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
        qInstallMessageHandler(_quiet_offscreen)
    app = QApplication.instance() or QApplication(["haptic-study"])
    app.setApplicationName("haptic-study")
    tmp: tempfile.TemporaryDirectory[str] | None = None
    if screenshot_dir is not None:
        # a throwaway database and settings, so the tour never touches real study data or preferences
        tmp = tempfile.TemporaryDirectory(prefix="haptic-study-shots-")
        settings = QSettings(os.path.join(tmp.name, "settings.ini"), QSettings.Format.IniFormat)
        win = ExperimenterWindow(host, settings, db_path or os.path.join(tmp.name, "screenshots.db"))
        win.confirm = lambda title, text: True
        tour = ScreenshotTour(win, Path(screenshot_dir), on_done=app.quit)
        win.show()
        tour.start()
    else:
        win = ExperimenterWindow(host, None, db_path)
        win.show()
    try:
        status = app.exec()
    finally:
        if screenshot_dir is not None:
            win.close()
        if tmp is not None:
            tmp.cleanup()
    if screenshot_dir is not None:
        qInstallMessageHandler(None)
        if tour.error:
            raise RuntimeError(tour.error)
    return int(status)


def _quiet_offscreen(mode: QtMsgType, context: object, message: str) -> None:
    """Qt messages of a scripted run: drop what the offscreen platform says it cannot do (raise a window,
    pass size hints to a window manager it does not have), pass on everything else."""
    if "This plugin does not support" in message:
        return
    print(f"Qt: {message}", file=sys.stderr)


class ScreenshotTour:
    """Drives a short simulated session through the window's own controls and saves a PNG of every main view.

    The tour is a generator of conditions stepped by a timer: each ``yield``
    returns a predicate to wait for (with a timeout), so the event loop keeps
    running and the engine keeps delivering events.
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
            if self._wait is not None:
                if not self._wait():
                    if time.monotonic() > self._deadline:
                        raise TimeoutError("screenshot tour: a step did not complete within its timeout")
                    return
            self._wait = next(self._steps)
            self._deadline = time.monotonic() + 60.0
        except StopIteration:
            self._finish()
        except Exception as exc:  # noqa: BLE001 - reported by run_gui
            self.error = str(exc)
            self._finish()

    def _finish(self) -> None:
        self._timer.stop()
        self.on_done()

    def _save(self, widget: QWidget, name: str) -> None:
        QApplication.processEvents()
        path = self.out_dir / f"{name}.png"
        if not widget.grab().save(str(path)):
            raise OSError(f"cannot write {path}")
        self.saved.append(str(path))

    def _script(self) -> Iterator[Callable[[], bool]]:
        w = self.win
        model = w.model
        w.resize(1280, 728)  # what the window gets on a 1366×768 laptop (the offscreen screen is smaller)
        yield lambda: model.session.state == "ready"
        # calibration wizard: the chain in order -- TCP, then the payload's recommended set, accepted
        wiz = w.calibration_wizard
        wiz.resize(720, 640)
        wiz.show()
        wiz.tcp_page.run_button.click()
        yield lambda: model.commissioning.tcp_state == "accepted"
        wiz.steps.setCurrentWidget(wiz.payload_page)
        model.calibration.set_pose_set("recommended")
        wiz.run_button.click()
        yield lambda: model.calibration.state == "accepted"
        self._save(wiz, "calibration-wizard")
        w.calibration_wizard.hide()
        # an experiment session, driven by the simulated participant
        code = f"DEMO{int(time.time()) % 100000:05d}"
        model.setup.update(code=code, kind="experiment", participant_number=1, seed=7)
        w.participant_window.resize(900, 520)
        w.participant_window.show()
        w.rig_window.resize(760, 480)
        w.rig_window.show()
        w.start_button.click()
        yield lambda: model.session.trial is not None and model.session.trial.position >= 2
        yield lambda: model.session.phase == "active" and model.session.latest_t_s - model.session.trial.t_s < 0.6
        self._save(w.participant_window, "participant-experiment")
        yield lambda: (model.session.phase == "active" and model.session.trial is not None
                       and model.session.trial.position >= 3 and model.rig.indentation_mm > 0.8)
        self._save(w, "experimenter-window")
        self._save(w.rig_window, "sim-rig-view")
        w.tabs.setCurrentWidget(w.health_panel)
        w.health_panel.resize(900, 360)
        self._save(w.health_panel, "health-panel")
        w.tabs.setCurrentWidget(w.trials_tab)
        yield lambda: model.session.phase == "pause"
        self._save(w.participant_window, "participant-rest")
        yield lambda: model.cue_wait is not None and model.cue_wait.left_s is not None and model.cue_wait.left_s < 1.6
        self._save(w.tabs, "trials-cue-wait")
        w.abort_session_button.click()
        yield lambda: model.session.state == "ended"
        # a training session: the participant screen shows the live force gauge
        model.setup.update(code=code + "T", kind="training")
        w.start_button.click()
        yield lambda: (model.session.phase == "active" and model.participant.screen.show_gauge
                       and model.participant.force_n > 0.3)
        self._save(w.participant_window, "participant-training")
        # the engine crashes (the rehearsal's kill): the window says so and offers the restart
        w.participant_window.hide()
        w.rig_window.hide()
        model.inject_fault("kill", None, 0.0)
        yield lambda: w.engine_row.isVisible()
        self._save(w, "engine-restart")
        w.restart_button.click()
        yield lambda: model.session.state == "ready" and w.setup_panel.selected_session() is not None
