"""The commissioning view's Qualify step: ``haptic-study qualify`` run from the window (docs/gui.md).

Layout and wiring only: :class:`study_app.models.qualify.QualifyModel` builds the command, reads its progress and its
record; this page runs it as a child process (:class:`QProcess`: the window stays responsive), after the window's
study engine has let the devices go, and restarts the engine when it ends.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from PySide6.QtCore import QProcess, Qt
from PySide6.QtWidgets import (
    QAbstractItemView,
    QDoubleSpinBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QProgressBar,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from pipeline.commissioning.qualification import CHECKS
from study_app.models.qualify import QualifyModel

__all__ = ["QualifyPage", "attach_qualify"]

_COLOURS = {"PASS": "#147f28", "FAIL": "#c81e1e", "NOT CHECKED": "#8a5a00"}
_INTRO = ("Qualify the arm before its first participant: the Touch goes to zero when our process dies, a held force "
          "is derated within the thermal budget, the end-to-end latency is within its budget, and the 1 kHz loop "
          "holds on this computer as the lab uses it (keep open what runs beside a session). Stand clear: the "
          "Touch renders 0.44 N for a moment. The study engine stops while it runs (qualify opens the devices "
          "itself) and restarts after. The record is written beside the arm's calibration file, as "
          "haptic-study qualify writes it (docs/qualify.md).")


class QualifyPage(QWidget):
    """The Qualify tab: seconds of the loop check, Run, the progress, each check's verdict, the record."""

    def __init__(self, model: QualifyModel, release_engine: Callable[[], None],
                 restore_engine: Callable[[], None], arm: Callable[[], str],
                 refusal: Callable[[], str], parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.model = model
        self._release, self._restore, self._arm, self._refusal = release_engine, restore_engine, arm, refusal
        self.proc: QProcess | None = None
        intro = QLabel(_INTRO)
        intro.setWordWrap(True)
        self.seconds = QDoubleSpinBox()
        self.seconds.setRange(1.0, 3600.0)
        self.seconds.setDecimals(0)
        self.seconds.setSuffix(" s")
        self.seconds.setValue(model.seconds)
        self.seconds.setToolTip("How long the loop-under-load check measures the loop")
        self.run_button = QPushButton("Run qualification")
        row = QHBoxLayout()
        row.addWidget(QLabel("Loop measured for"))
        row.addWidget(self.seconds)
        row.addStretch(1)
        row.addWidget(self.run_button)
        self.progress = QProgressBar()
        self.progress.setRange(0, len(CHECKS))
        self.summary = QLabel()
        self.summary.setWordWrap(True)
        self.summary.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.table = QTableWidget(len(CHECKS), 3)
        self.table.setHorizontalHeaderLabels(["Check", "Verdict", "Measured, or why"])
        self.table.verticalHeader().setVisible(False)
        self.table.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.setWordWrap(True)
        head = self.table.horizontalHeader()
        head.setSectionResizeMode(0, QHeaderView.ResizeMode.ResizeToContents)
        head.setSectionResizeMode(1, QHeaderView.ResizeMode.ResizeToContents)
        head.setSectionResizeMode(2, QHeaderView.ResizeMode.Stretch)
        lay = QVBoxLayout(self)
        lay.addWidget(intro)
        lay.addLayout(row)
        lay.addWidget(self.progress)
        lay.addWidget(self.summary)
        lay.addWidget(self.table, 1)
        self.run_button.clicked.connect(self.run)
        model.changed.connect(self._on_changed)
        self._on_changed()

    def refresh(self) -> None:
        """Run enabled or not, saying why (the window's state changed)."""
        why = self.model.refusal(self._refusal())
        self.run_button.setEnabled(not why)
        self.run_button.setToolTip(f"Not available now: {why}." if why else "")

    def run(self) -> None:
        """Stop the engine, run ``haptic-study qualify`` on the chosen arm, restart the engine when it ends."""
        if self.model.refusal(self._refusal()):
            self.refresh()
            return
        self.model.start(self._arm(), self.seconds.value())
        cmd = self.model.command()
        self._release()
        proc = self.proc = QProcess(self)
        proc.setProgram(cmd[0])
        proc.setArguments(cmd[1:])
        proc.readyReadStandardError.connect(self._read_progress)
        proc.finished.connect(self._finished)
        proc.errorOccurred.connect(self._failed_to_start)
        proc.start()

    def _read_progress(self) -> None:
        if self.proc is not None:
            for line in bytes(self.proc.readAllStandardError().data()).decode("utf-8", "replace").splitlines():
                self.model.progress(line)

    def _finished(self, exit_code: int, _status: Any = None) -> None:
        proc = self.proc
        if proc is None:
            return
        self._read_progress()
        out = bytes(proc.readAllStandardOutput().data()).decode("utf-8", "replace")
        self.proc = None
        self.model.finish(exit_code, out)
        self._restore()

    def _failed_to_start(self, error: QProcess.ProcessError) -> None:
        if error == QProcess.ProcessError.FailedToStart and self.proc is not None:
            self.proc = None
            self.model.progress(f"haptic-study qualify could not be started ({error.name})")
            self.model.finish(-1, "")
            self._restore()

    def _on_changed(self) -> None:
        mdl = self.model
        self.progress.setValue(mdl.done_checks if mdl.state != "idle" else 0)
        self.summary.setText(mdl.summary())
        colour = "#c81e1e" if mdl.state == "failed" or (mdl.record or {}).get("verdict") == "FAIL" else "#333"
        self.summary.setStyleSheet(f"color: {colour}; font-weight: 600;")
        for i, (name, verdict, text) in enumerate(mdl.rows()):
            items = [QTableWidgetItem(name), QTableWidgetItem(verdict), QTableWidgetItem(text)]
            if verdict in _COLOURS:
                items[1].setForeground(Qt.GlobalColor.white)
                items[1].setBackground(_qcolor(_COLOURS[verdict]))
            items[2].setToolTip(text)
            for j, item in enumerate(items):
                self.table.setItem(i, j, item)
        self.table.resizeRowsToContents()
        self.refresh()


def _qcolor(hex_colour: str) -> Any:
    from PySide6.QtGui import QColor

    return QColor(hex_colour)


def attach_qualify(win: Any, hardware: str | None) -> QualifyPage:
    """Give the window's calibration wizard its Qualify tab, wired to the window's engine and arm picker."""
    model = QualifyModel(hardware)

    def release() -> None:  # nothing of the stopped engine is read (its ring goes with it); no Start meanwhile
        mdl = win.model
        mdl.plots.detach()
        mdl.session.reset("qualifying the rig: the study engine is stopped until haptic-study qualify ends …")
        mdl.health.engine_restarted()  # its faults (a latched stall) are the stopped engine's, not news
        win.bridge.release()
        mdl.engine.changed.emit()

    page = QualifyPage(model, release, win.model.engine.restart,
                       lambda: win.model.commissioning.arm, win.model.actions.calibration_refusal)
    win.calibration_wizard.steps.addTab(page, "4 · Qualify")
    win.model.actions.changed.connect(page.refresh)
    return page
