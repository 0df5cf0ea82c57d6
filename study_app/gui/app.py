"""Composition root of the GUI: QApplication, the experimenter window, and the scripted screenshot tour."""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

from PySide6.QtCore import QSettings, QtMsgType, qInstallMessageHandler
from PySide6.QtWidgets import QApplication

from study_app.engine.setup import HostConfig
from study_app.gui.main_window import ExperimenterWindow
from study_app.gui.tour import SCREEN, ScreenshotTour

__all__ = ["ScreenshotTour", "run_gui"]


def run_gui(host: HostConfig, *, db_path: str | None = None, screenshot_dir: str | None = None) -> int:
    """Open the experimenter window (or run the screenshot tour) and return the exit status."""
    tmp: tempfile.TemporaryDirectory[str] | None = None
    if screenshot_dir is not None:
        # a throwaway database and settings, so the tour never touches real study data or preferences
        tmp = tempfile.TemporaryDirectory(prefix="haptic-study-shots-")
        # offscreen, on one screen the size of a lab laptop's (the windows are placed on it as on the laptop)
        screens = os.path.join(tmp.name, "screens.json")
        with open(screens, "w", encoding="utf-8") as f:
            json.dump({"screens": [{"name": "laptop", "x": 0, "y": 0, "width": SCREEN.width(),
                                    "height": SCREEN.height(), "logicalDpi": 96, "logicalBaseDpi": 96,
                                    "dpr": 1}]}, f)
        os.environ.setdefault("QT_QPA_PLATFORM", f"offscreen:configfile={screens}")
        qInstallMessageHandler(_quiet_offscreen)
    app = QApplication.instance() or QApplication(["haptic-study"])
    app.setApplicationName("haptic-study")
    if screenshot_dir is not None and tmp is not None:
        settings = QSettings(os.path.join(tmp.name, "settings.ini"), QSettings.Format.IniFormat)
        win = ExperimenterWindow(host, settings, db_path or os.path.join(tmp.name, "screenshots.db"))
        win.session_actions.confirm = lambda title, text: True
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
