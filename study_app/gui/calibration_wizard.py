"""The calibration wizard: choose a pose set, run it, see condition number and residuals, accept or refuse."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QAbstractItemView, QComboBox, QFormLayout, QHBoxLayout, QHeaderView, QLabel, QProgressBar, QPushButton,
    QTableWidget, QTableWidgetItem, QVBoxLayout, QWidget,
)

from study_app import messages as m
from study_app.models.calibration import CalibrationModel

__all__ = ["CalibrationWizard"]


class CalibrationWizard(QWidget):
    """Layout and wiring of :class:`CalibrationModel`."""

    def __init__(self, model: CalibrationModel, on_run, parent: QWidget | None = None) -> None:  # type: ignore[no-untyped-def]
        super().__init__(parent, Qt.WindowType.Window)
        self.setWindowTitle("Gravity and bias calibration")
        self.model = model
        intro = QLabel(
            "The wrist sensor reads the instrument's weight and its own offsets as well as the contact force. "
            "The rig holds the tool clear of the tissue in a set of orientations; a least-squares fit identifies "
            "the payload and the bias. On the simulated rig the poses run automatically."
        )
        intro.setWordWrap(True)
        self.pose_set = QComboBox()
        self.pose_set.addItems(list(m.POSE_SETS))
        self.pose_set.setCurrentText(model.pose_set)
        self.description = QLabel()
        self.description.setWordWrap(True)
        self.description.setStyleSheet("color: #555;")
        self.run_button = QPushButton("Run calibration")
        self.progress = QProgressBar()
        self.verdict = QLabel()
        self.verdict.setWordWrap(True)
        self.figures = QFormLayout()
        self.residuals = QTableWidget(0, 3)
        self.residuals.setHorizontalHeaderLabels(["Pose", "Force residual (N)", "Torque residual (N·m)"])
        self.residuals.verticalHeader().setVisible(False)
        self.residuals.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.residuals.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Stretch)
        row = QHBoxLayout()
        row.addWidget(QLabel("Pose set"))
        row.addWidget(self.pose_set, 1)
        row.addWidget(self.run_button)
        lay = QVBoxLayout(self)
        lay.addWidget(intro)
        lay.addLayout(row)
        lay.addWidget(self.description)
        lay.addWidget(self.progress)
        lay.addWidget(self.verdict)
        lay.addLayout(self.figures)
        lay.addWidget(self.residuals, 1)
        self.pose_set.currentTextChanged.connect(model.set_pose_set)
        self.run_button.clicked.connect(on_run)
        model.changed.connect(self._on_changed)
        self._on_changed()

    def _on_changed(self) -> None:
        mdl = self.model
        if self.pose_set.currentText() != mdl.pose_set:
            self.pose_set.setCurrentText(mdl.pose_set)
        self.description.setText(CalibrationModel.describe(mdl.pose_set))
        self.run_button.setEnabled(mdl.state != "running")
        self.progress.setRange(0, max(1, mdl.total))
        self.progress.setValue(mdl.done if mdl.state == "running" else (mdl.total if mdl.result else 0))
        self.verdict.setText(mdl.verdict())
        colour = {"accepted": "#147f28", "refused": "#c81e1e"}.get(mdl.state, "#333")
        self.verdict.setStyleSheet(f"color: {colour}; font-weight: 600;")
        while self.figures.rowCount():
            self.figures.removeRow(0)
        for label, value in mdl.summary():
            self.figures.addRow(label, QLabel(value))
        res = mdl.result.residuals if mdl.result is not None else []
        self.residuals.setRowCount(len(res))
        for i, (label, f_n, t_nm) in enumerate(res):
            for j, text in enumerate((label, f"{f_n:.4f}", f"{t_nm:.5f}")):
                self.residuals.setItem(i, j, QTableWidgetItem(text))
