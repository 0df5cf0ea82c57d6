"""The calibration wizard: the commissioning chain in order -- TCP, payload/bias, frames and signs -- and what is on
record.

Layout and wiring only: the TCP and frame steps and the status are
:class:`study_app.models.commissioning.CommissioningModel`,
the payload step :class:`study_app.models.calibration.CalibrationModel` (and, on the real rig,
:class:`study_app.models.real_calibration.RealCalibrationModel`).
"""

from __future__ import annotations

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QAbstractItemView,
    QComboBox,
    QFormLayout,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QPlainTextEdit,
    QProgressBar,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QTabWidget,
    QVBoxLayout,
    QWidget,
)

from study_app.engine import messages as m
from study_app.models.calibration import CalibrationModel, pose_name
from study_app.models.commissioning import AXIS_WORDS, CommissioningModel
from study_app.models.real_calibration import REAL_POSE_SETS, RealCalibrationModel

__all__ = ["ArmPicker", "CalibrationWizard", "ChainStatus", "FramesPage", "RealPosePanel", "TcpPage"]

_VERDICT_COLOURS = {"accepted": "#147f28", "passed": "#147f28", "refused": "#c81e1e", "failed": "#c81e1e"}


class ChainStatus(QWidget):
    """What is on record for the mounted tool, step by step, and whether a session may start."""

    def __init__(self, model: CommissioningModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.model = model
        self.steps = QLabel()
        self.steps.setTextFormat(Qt.TextFormat.RichText)
        self.gate = QLabel()
        self.gate.setWordWrap(True)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.steps)
        lay.addWidget(self.gate)
        model.changed.connect(self._on_changed)
        self._on_changed()

    def _on_changed(self) -> None:
        mdl = self.model
        st = mdl.status
        arm = f" on {mdl.arm_title()}" if mdl.arm else ""
        head = f"<b>On record for {st.tool!r}{arm}</b>" if st is not None else f"<b>On record{arm}</b>: –"
        rows = [f'<span style="color:{"#147f28" if ok else "#c81e1e"}">{"✔" if ok else "✘"} {n}</span>: {text}'
                for n, ok, text in mdl.status_lines()]
        self.steps.setText(head + ("<br>" + "<br>".join(rows) if rows else ""))
        self.gate.setText(mdl.gate_text())
        blocked = st is not None and st.rig == "real" and bool(st.missing)
        self.gate.setStyleSheet("color: #c81e1e; font-weight: 600;" if blocked else "color: #555;")


class ArmPicker(QWidget):
    """A rig of several arms: the arm the steps commission, and each arm's chain in one line (hidden for one arm).

    ``on_select(name)`` asks for another arm (the model refuses while a step runs; the choice then goes back).
    """

    def __init__(self, model: CommissioningModel, on_select, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.model = model
        self.choice = QComboBox()
        self.choice.setToolTip("The arm whose devices the steps use and whose calibration file they save to — "
                               "as haptic-study calibrate --arm NAME; commission each arm in turn")
        self.overview = QLabel()
        self.overview.setWordWrap(True)
        self.overview.setStyleSheet("color: #555;")
        lay = QHBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        head = QLabel("<b>Arm to commission</b>")
        lay.addWidget(head)
        lay.addWidget(self.choice)
        lay.addWidget(self.overview, 1)
        self._items: tuple[str, ...] = ()
        self.choice.activated.connect(lambda i: on_select(self._items[i]) if 0 <= i < len(self._items) else None)
        model.changed.connect(self._on_changed)
        self._on_changed()

    def _on_changed(self) -> None:
        mdl = self.model
        self.setVisible(bool(mdl.arms))
        if mdl.arms != self._items:
            self._items = mdl.arms
            self.choice.clear()
            self.choice.addItems(list(mdl.arms))
        if mdl.arm in self._items and self.choice.currentIndex() != self._items.index(mdl.arm):
            self.choice.setCurrentIndex(self._items.index(mdl.arm))
        self.choice.setEnabled(not mdl.busy())
        self.overview.setText("    ".join(f"{a}: {what}" for a, what in mdl.arms_overview()))


class TcpPage(QWidget):
    """Step 1: the TCP pivot calibration (automatic on the simulated rig, orientation by orientation on the real
    one)."""

    def __init__(self, model: CommissioningModel, on_run, on_compute, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.model = model
        self.instruction = QLabel()
        self.instruction.setWordWrap(True)
        self.pose_set = QComboBox()
        self.pose_set.addItems(list(m.PIVOT_SETS))
        self.run_button = QPushButton()
        self.compute_button = QPushButton("Compute")
        self.clear_button = QPushButton("Start again")
        self.verdict = QLabel()
        self.verdict.setWordWrap(True)
        self.orientations = QTableWidget(0, 3)
        self.orientations.setHorizontalHeaderLabels(["Orientation", "Flange position (mm)",
                                                     "Moved while recording (mm)"])
        self.orientations.verticalHeader().setVisible(False)
        self.orientations.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.orientations.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Stretch)
        row = QHBoxLayout()
        self.pose_label = QLabel("Orientations")
        row.addWidget(self.pose_label)
        row.addWidget(self.pose_set, 1)
        row.addWidget(self.run_button)
        row.addWidget(self.compute_button)
        row.addWidget(self.clear_button)
        lay = QVBoxLayout(self)
        lay.addWidget(self.instruction)
        lay.addLayout(row)
        lay.addWidget(self.verdict)
        lay.addWidget(self.orientations, 1)
        lay.addStretch(1)  # the simulated rig has no table: keep the rest at the top
        self.pose_set.currentTextChanged.connect(lambda t: setattr(model, "pivot_set", t))
        self.run_button.clicked.connect(on_run)
        self.compute_button.clicked.connect(on_compute)
        self.clear_button.clicked.connect(model.clear_pivots)
        model.changed.connect(self._on_changed)
        self._on_changed()

    def _on_changed(self) -> None:
        mdl = self.model
        real = mdl.real
        self.instruction.setText(mdl.tcp_instruction())
        for w in (self.pose_set, self.pose_label):
            w.setVisible(not real)
        for b in (self.compute_button, self.clear_button, self.orientations):
            b.setVisible(real)
        self.run_button.setText("Record orientation" if real else "Run TCP calibration")
        self.run_button.setEnabled(mdl.tcp_state not in ("running", "recording"))
        why = mdl.compute_refusal()
        self.compute_button.setEnabled(not why)
        self.compute_button.setToolTip(why)
        self.verdict.setText(mdl.tcp_verdict())
        self.verdict.setStyleSheet(f"color: {_VERDICT_COLOURS.get(mdl.tcp_state, '#333')}; font-weight: 600;")
        _grow(self.orientations, len(mdl.pivots))
        for i, p in enumerate(mdl.pivots):
            pos = ", ".join(f"{1e3 * v:+.1f}" for v in p.flange_position_m)
            for j, text in enumerate((p.label, pos, f"{p.moved_mm:.3f}")):
                self.orientations.setItem(i, j, QTableWidgetItem(text))


def _grow(table: QTableWidget, rows: int) -> None:
    """Give ``table`` its rows; one just recorded is scrolled into view (it went below the fold after ten)."""
    added = rows > table.rowCount()
    table.setRowCount(rows)
    if added:
        table.scrollToBottom()


class FramesPage(QWidget):
    """Step 3: the frame and sign check (automatic on the simulated rig, one push per axis on the real one)."""

    def __init__(self, model: CommissioningModel, on_check, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.model = model
        self.instruction = QLabel()
        self.instruction.setWordWrap(True)
        self.run_button = QPushButton("Run frame check")
        self.axis_buttons = {a: QPushButton(f"Record push along {AXIS_WORDS[a]}") for a in AXIS_WORDS}
        self.result = QPlainTextEdit()
        self.result.setReadOnly(True)
        self.result.setPlaceholderText("no check yet")
        row = QHBoxLayout()
        row.addWidget(self.run_button)
        for a, b in self.axis_buttons.items():
            row.addWidget(b)
            b.clicked.connect(lambda _=False, a=a: on_check(a))
        lay = QVBoxLayout(self)
        lay.addWidget(self.instruction)
        lay.addLayout(row)
        lay.addWidget(self.result, 1)
        self.run_button.clicked.connect(lambda: on_check(""))
        model.changed.connect(self._on_changed)
        self._on_changed()

    def _on_changed(self) -> None:
        mdl = self.model
        busy = mdl.frames_state in ("running", "recording")
        self.instruction.setText(mdl.frames_instruction())
        self.run_button.setVisible(not mdl.real)
        self.run_button.setEnabled(not busy)
        for b in self.axis_buttons.values():
            b.setVisible(mdl.real)
            b.setEnabled(not busy)
        text = "\n".join(mdl.frames_display())
        if text != self.result.toPlainText():
            self.result.setPlainText(text)
        colour = _VERDICT_COLOURS.get(mdl.frames_state, "#333")
        self.result.setStyleSheet(f"color: {colour}; font-family: monospace;")


class RealPosePanel(QWidget):
    """Real rig: one target pose at a time, Record pose, the recorded poses, Identify (layout of
    :class:`RealCalibrationModel`)."""

    COLUMNS = ("Pose", "Off target (°)", "|F| (N)", "Force noise (N)")

    def __init__(self, model: RealCalibrationModel, on_record, on_identify, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.model = model
        self.pose_set = QComboBox()
        self.pose_set.addItems(list(REAL_POSE_SETS))
        self.start_button = QPushButton("Start pose set")
        self.instruction = QLabel()
        self.instruction.setWordWrap(True)
        self.instruction.setStyleSheet("font-size: 14px; font-weight: 600;")
        self.message = QLabel()
        self.message.setWordWrap(True)
        self.message.setStyleSheet("color: #a05a00;")
        self.record_button = QPushButton("Record pose")
        self.skip_button = QPushButton("Skip pose")
        self.previous_button = QPushButton("Previous pose")
        self.identify_button = QPushButton("Identify")
        self.poses = QTableWidget(0, len(self.COLUMNS))
        self.poses.setHorizontalHeaderLabels(list(self.COLUMNS))
        self.poses.verticalHeader().setVisible(False)
        self.poses.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.poses.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Stretch)
        self.poses.setMaximumHeight(160)
        top = QHBoxLayout()
        top.addWidget(QLabel("Pose set"))
        top.addWidget(self.pose_set, 1)
        top.addWidget(self.start_button)
        buttons = QHBoxLayout()
        for b in (self.previous_button, self.skip_button, self.record_button, self.identify_button):
            buttons.addWidget(b)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addLayout(top)
        lay.addWidget(self.instruction)
        lay.addWidget(self.message)
        lay.addLayout(buttons)
        lay.addWidget(self.poses)
        self.start_button.clicked.connect(lambda: model.begin(self.pose_set.currentText()))
        self.record_button.clicked.connect(on_record)
        self.identify_button.clicked.connect(on_identify)
        self.skip_button.clicked.connect(model.skip)
        self.previous_button.clicked.connect(lambda: model.go_to(max(0, model.index - 1)))
        model.changed.connect(self._on_changed)
        self._on_changed()

    def _on_changed(self) -> None:
        mdl = self.model
        self.instruction.setText(mdl.instruction())
        self.message.setText(mdl.message if mdl.state != "refused" else "")
        walking = mdl.state == "at_pose"
        self.record_button.setEnabled(mdl.can_record())
        self.skip_button.setEnabled(walking)
        self.previous_button.setEnabled(walking and mdl.index > 0)
        self.start_button.setEnabled(mdl.state not in ("recording", "identifying"))
        why = mdl.identify_refusal() if mdl.steps else "start the pose set first"
        self.identify_button.setEnabled(not why)
        self.identify_button.setToolTip(why)
        rec = mdl.recorded
        _grow(self.poses, len(rec))
        for i, step in enumerate(rec):
            r = step.recorded
            assert r is not None
            f_n = (r.wrench[0] ** 2 + r.wrench[1] ** 2 + r.wrench[2] ** 2) ** 0.5
            for j, text in enumerate((pose_name(step.label), f"{r.off_target_deg:.1f}", f"{f_n:.3f}",
                                      f"{r.force_std_n:.4f}")):
                item = self.poses.item(i, j)
                if item is None:
                    item = QTableWidgetItem()
                    self.poses.setItem(i, j, item)
                item.setText(text)


class CalibrationWizard(QWidget):
    """Layout and wiring of :class:`CalibrationModel`.

    ``hidden`` is emitted when the window closes (its notices in the main window go with it);
    :meth:`set_blocked` disables every step while a calibration may not run (a session runs), saying why.
    """

    hidden = Signal()

    def __init__(self, model: CalibrationModel, on_run, real_panel: RealPosePanel | None = None,
                 parent: QWidget | None = None, chain: CommissioningModel | None = None, on_tcp=None,
                 on_compute_tcp=None, on_frames=None, on_arm=None) -> None:
        super().__init__(parent, Qt.WindowType.Window)
        self.setWindowTitle("Calibration — TCP, payload, frames")
        self.model = model
        intro = QLabel(model.intro())
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
        self.intro = intro
        self.sim_controls = QWidget()
        row = QHBoxLayout(self.sim_controls)
        row.setContentsMargins(0, 0, 0, 0)
        row.addWidget(QLabel("Pose set"))
        row.addWidget(self.pose_set, 1)
        row.addWidget(self.run_button)
        self.real_panel = real_panel
        self.payload_page = QWidget()
        lay = QVBoxLayout(self.payload_page)
        lay.addWidget(intro)
        lay.addWidget(self.sim_controls)
        if real_panel is not None:
            lay.addWidget(real_panel)
            real_panel.setVisible(False)
        lay.addWidget(self.description)
        lay.addWidget(self.progress)
        lay.addWidget(self.verdict)
        lay.addLayout(self.figures)
        lay.addWidget(self.residuals, 1)
        # the chain in order: TCP, payload, frames; what is on record above the steps
        chain = chain if chain is not None else CommissioningModel()
        self.arm_picker = ArmPicker(chain, on_arm or (lambda name: None))
        self.chain_status = ChainStatus(chain)
        self.tcp_page = TcpPage(chain, on_tcp or (lambda: None), on_compute_tcp or (lambda: None))
        self.frames_page = FramesPage(chain, on_frames or (lambda axis: None))
        self.steps = QTabWidget()
        self.steps.addTab(self.tcp_page, "1 · TCP")
        self.steps.addTab(self.payload_page, "2 · Payload && bias")
        self.steps.addTab(self.frames_page, "3 · Frames && signs")
        self.blocked = QLabel()
        self.blocked.setWordWrap(True)
        self.blocked.setStyleSheet("color: #8a5a00; background: #fff4e0; font-weight: 600; padding: 4px;")
        self.blocked.hide()
        outer = QVBoxLayout(self)
        outer.addWidget(self.arm_picker)
        outer.addWidget(self.chain_status)
        outer.addWidget(self.blocked)
        outer.addWidget(self.steps, 1)
        self.pose_set.currentTextChanged.connect(model.set_pose_set)
        self.run_button.clicked.connect(on_run)
        model.changed.connect(self._on_changed)
        self._on_changed()

    def set_blocked(self, why: str) -> None:
        """Disable the steps' actions while no calibration may run (``why``; "" enables them), saying why."""
        pages = [self.tcp_page, self.frames_page, self.sim_controls, self.arm_picker]
        if self.real_panel is not None:
            pages.append(self.real_panel)
        text = f"Calibration is not available now: {why}." if why else ""
        for page in pages:
            page.setEnabled(not why)
            page.setToolTip(text)
        for button in (self.tcp_page.run_button, self.frames_page.run_button, self.run_button):
            button.setToolTip(text)
        if text != self.blocked.text():
            self.blocked.setText(text)
            self.blocked.setVisible(bool(text))

    def hideEvent(self, event) -> None:  # Qt's name
        super().hideEvent(event)
        self.hidden.emit()

    def set_real(self, real: bool) -> None:
        """Show the pose-by-pose panel (real rig) or the automatic run (simulated rig)."""
        self.sim_controls.setVisible(not real)
        self.description.setVisible(not real)
        self.progress.setVisible(not real)
        if self.real_panel is not None:
            self.real_panel.setVisible(real)
        self.intro.setText(self.model.intro())

    def _on_changed(self) -> None:
        mdl = self.model
        if self.pose_set.currentText() != mdl.pose_set:
            self.pose_set.setCurrentText(mdl.pose_set)
        self.description.setText(CalibrationModel.describe(mdl.pose_set))
        self.intro.setText(mdl.intro())
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
            for j, text in enumerate((pose_name(label), f"{f_n:.4f}", f"{t_nm:.5f}")):
                self.residuals.setItem(i, j, QTableWidgetItem(text))
