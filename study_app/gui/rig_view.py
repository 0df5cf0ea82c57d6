"""The simulated rig's 2-D side view, the choice of who drives the stylus, and fault rehearsal."""

from __future__ import annotations

import time

from PySide6.QtCore import QPointF, QRectF, QSignalBlocker, Qt
from PySide6.QtGui import QBrush, QColor, QFont, QLinearGradient, QPainter, QPainterPath, QPen, QPolygonF
from PySide6.QtWidgets import (
    QButtonGroup,
    QComboBox,
    QDoubleSpinBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QRadioButton,
    QVBoxLayout,
    QWidget,
)

from study_app.models.rig import RigViewModel
from study_app.models.rig_control import REHEARSAL_KINDS

__all__ = ["RigCanvas", "RigWindow"]

#: Shown span: x ±30 mm, z from −12 mm (tissue) to +24 mm (above the surface).
_X_MM = 30.0
_Z_LO, _Z_HI = -12.0, 24.0
#: Shortest interval between manual targets sent to the engine (the loop needs no more).
_SEND_INTERVAL_S = 0.02
#: The readout's strip above the drawing: its lines (always two, so the drawing's scale never jumps), line height.
_READOUT_LINES, _LINE_PX, _READOUT_PAD_PX = 2, 18, 6
_BACKGROUND = QColor(238, 242, 247)
_READOUT_BACKGROUND = QColor(250, 251, 253)


class RigCanvas(QWidget):
    """Paints tissue and instrument; in manual mode the mouse sets where the tip should go."""

    def __init__(self, model: RigViewModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.model = model
        self.setMinimumSize(480, 320)
        self.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        self._last_send = 0.0
        model.changed.connect(self.update)

    # -- geometry --------------------------------------------------------------------------------
    def readout_rect(self) -> QRectF:
        """The strip at the top that holds the readout: nothing of the drawing enters it (the shaft passes under
        a readout drawn over the scene, which made the contact force unreadable)."""
        return QRectF(0, 0, self.width(), 2 * _READOUT_PAD_PX + _LINE_PX * _READOUT_LINES)

    def drawing_rect(self) -> QRectF:
        """Where tissue and instrument are drawn: below the readout."""
        top = self.readout_rect().bottom()
        return QRectF(0, top, self.width(), max(1.0, self.height() - top))

    def _scale(self) -> float:
        return min(self.width() / (2 * _X_MM), self.drawing_rect().height() / (_Z_HI - _Z_LO))

    def to_px(self, x_mm: float, z_mm: float) -> QPointF:
        s = self._scale()
        return QPointF(self.width() / 2 + x_mm * s, self.height() - (z_mm - _Z_LO) * s)

    def to_z_mm(self, y_px: float) -> float:
        return _Z_LO + (self.height() - y_px) / self._scale()

    # -- painting --------------------------------------------------------------------------------
    def paintEvent(self, event) -> None:  # Qt's name
        m = self.model
        p = QPainter(self)
        p.setRenderHint(QPainter.RenderHint.Antialiasing)
        p.fillRect(self.rect(), _BACKGROUND)
        p.setClipRect(self.drawing_rect())  # the shaft reaches up past the top of the scene
        s = self._scale()
        half_mm = max(_X_MM, self.width() / 2 / s) + 5  # the tissue reaches both edges, however wide the view
        x, z = m.surface_profile(half_mm, n=61)
        # one vectorised transform, not 61 Python calls of to_px (this paints at 30 Hz)
        px = self.width() / 2 + x * s
        py = self.height() - (z - _Z_LO) * s
        poly = QPolygonF([QPointF(a, b) for a, b in zip(px.tolist(), py.tolist(), strict=True)])
        poly.append(self.to_px(half_mm, _Z_LO - 2))
        poly.append(self.to_px(-half_mm, _Z_LO - 2))
        top = self.to_px(0, 0).y()
        grad = QLinearGradient(0, top, 0, self.height())
        grad.setColorAt(0.0, QColor(214, 120, 120))
        grad.setColorAt(1.0, QColor(150, 60, 70))
        p.setBrush(QBrush(grad))
        p.setPen(QPen(QColor(120, 40, 50), 2))
        p.drawPolygon(poly)
        # the instrument: a shaft down to the tip, jaws closed
        tip = self.to_px(0.0, max(m.tip_z_mm, -m.indentation_mm))
        shaft = QPainterPath()
        shaft.addRoundedRect(QRectF(tip.x() - 2.5 * s, tip.y() - 60 * s, 5 * s, 57 * s), 2, 2)
        p.setBrush(QColor(150, 155, 165))
        p.setPen(QPen(QColor(70, 70, 80), 1.5))
        p.drawPath(shaft)
        jaw = QPolygonF([QPointF(tip.x() - 2.5 * s, tip.y() - 4 * s), QPointF(tip.x() + 2.5 * s, tip.y() - 4 * s), tip])
        p.setBrush(QColor(90, 95, 105))
        p.drawPolygon(jaw)
        if m.driver == "manual":
            target_z = m.manual_y_m * 1e3 + (m.home_z_m - m.surface_z_m) * 1e3
            ty = self.to_px(0, target_z).y()
            p.setPen(QPen(QColor(30, 90, 220), 1.5, Qt.PenStyle.DashLine))
            p.drawLine(QPointF(tip.x() - 12 * s, ty), QPointF(tip.x() + 12 * s, ty))
        self._paint_readout(p)
        p.end()

    def readout_lines(self) -> list[str]:
        """The readout: where the tip is and the ground-truth force; then how the stylus is driven."""
        m = self.model
        return [f"tip {m.tip_z_mm:+5.1f} mm · indentation {m.indentation_mm:4.2f} mm · "
                f"contact force {m.contact_force_n:4.2f} N (ground truth)",
                "manual: drag vertically to move the tip · ↑/↓ 0.5 mm steps · Home: lift off"
                if m.driver == "manual" else "driven by the simulated participant (autopilot)"]

    def _paint_readout(self, p: QPainter) -> None:
        """The readout in its own strip, above the drawing: never over the shaft."""
        p.setClipping(False)
        strip = self.readout_rect()
        p.fillRect(strip, _READOUT_BACKGROUND)
        p.setPen(QPen(QColor(200, 205, 215), 1))
        p.drawLine(strip.bottomLeft(), strip.bottomRight())
        p.setFont(QFont("Sans", 10))
        for k, text in enumerate(self.readout_lines()):
            p.setPen(QColor(40, 40, 50) if k == 0 else QColor(90, 95, 110))
            p.drawText(QRectF(8, _READOUT_PAD_PX + _LINE_PX * k, self.width() - 16, _LINE_PX),
                       Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignVCenter, text)

    # -- manual driving --------------------------------------------------------------------------
    def _target_from_mouse(self, y_px: float, force: bool = False) -> None:
        if self.model.driver != "manual":
            return
        now = time.monotonic()
        if not force and now - self._last_send < _SEND_INTERVAL_S:
            return
        self._last_send = now
        self.model.set_manual_target(self.model.target_for_tip_mm(self.to_z_mm(y_px)))
        self.update()

    def mousePressEvent(self, event) -> None:  # Qt's name
        self._target_from_mouse(event.position().y(), force=True)

    def mouseMoveEvent(self, event) -> None:  # Qt's name
        if event.buttons() & Qt.MouseButton.LeftButton:
            self._target_from_mouse(event.position().y())

    def keyPressEvent(self, event) -> None:  # Qt's name
        if self.model.driver == "manual" and event.key() in (Qt.Key.Key_Up, Qt.Key.Key_Down, Qt.Key.Key_Home):
            if event.key() == Qt.Key.Key_Home:
                self.model.set_manual_target(0.0)
            else:
                self.model.step_manual(1 if event.key() == Qt.Key.Key_Up else -1)
            self.update()
            return
        super().keyPressEvent(event)


class RigWindow(QWidget):
    """Side view plus the driver choice."""

    def __init__(self, model: RigViewModel, on_driver, on_inject=None,
                 parent: QWidget | None = None) -> None:
        super().__init__(parent, Qt.WindowType.Window)
        self.setWindowTitle("Simulated rig — side view")
        self.model = model
        self.canvas = RigCanvas(model)
        self.autopilot = QRadioButton("Simulated participant (autopilot)")
        self.manual = QRadioButton("Me — mouse / keyboard")
        self.group = QButtonGroup(self)
        self.group.addButton(self.autopilot)
        self.group.addButton(self.manual)
        self.autopilot.setChecked(model.driver == "autopilot")
        self.manual.setChecked(model.driver == "manual")
        # ↑/↓ move the stylus, not the choice: the radio buttons never take the keyboard focus
        for b in (self.autopilot, self.manual):
            b.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        self.autopilot.toggled.connect(lambda on: on and on_driver("autopilot"))
        self.manual.toggled.connect(lambda on: on and on_driver("manual"))
        self.manual.toggled.connect(lambda on: on and self.canvas.setFocus())
        row = QHBoxLayout()
        row.addWidget(QLabel("Stylus driven by:"))
        row.addWidget(self.autopilot)
        row.addWidget(self.manual)
        row.addStretch(1)
        lay = QVBoxLayout(self)
        lay.addLayout(row)
        lay.addWidget(self.canvas, 1)
        if on_inject is not None:
            lay.addLayout(self._rehearsal_row(on_inject))
        model.changed.connect(self._on_changed)

    def _rehearsal_row(self, on_inject) -> QHBoxLayout:
        """Rehearse a fault: what, and when (now, or seconds after a trial's cue)."""
        self.fault_kind = QComboBox()
        for kind, text in REHEARSAL_KINDS.items():
            self.fault_kind.addItem(text, kind)
        # "now", or one of the running session's trials still to come (numbered from 1, as everywhere)
        self.fault_trial = QComboBox()
        self.fault_trial.addItem("now", None)
        self.fault_trial.setToolTip("now, or a trial of the running session not yet begun (numbered from 1), "
                                    "whose cue the fault follows")
        self.fault_trial.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToContents)
        self.fault_seconds = QDoubleSpinBox()
        self.fault_seconds.setRange(0.0, 600.0)
        self.fault_seconds.setDecimals(1)
        self.fault_seconds.setValue(3.0)
        self.fault_seconds.setSuffix(" s after its cue")
        self.fault_trial.currentIndexChanged.connect(
            lambda _i: self.fault_seconds.setEnabled(self.fault_trial.currentData() is not None))
        self.fault_seconds.setEnabled(False)
        self.inject_button = QPushButton("Inject")
        self.inject_button.setToolTip("a real fault of the simulated rig, stored with the running session like any "
                                      "fault: it latches, a trial it hits is stored as aborted and run again, and "
                                      "the next cue waits for Reset faults")
        self.inject_button.setFocusPolicy(Qt.FocusPolicy.NoFocus)  # Space in the side view never injects
        self.inject_button.clicked.connect(lambda: on_inject(
            self.fault_kind.currentData(), self.fault_trial.currentData(), self.fault_seconds.value()))
        row = QHBoxLayout()
        row.addWidget(QLabel("Rehearse a fault:"))
        row.addWidget(self.fault_kind)
        row.addWidget(self.fault_trial)
        row.addWidget(self.fault_seconds)
        row.addWidget(self.inject_button)
        row.addStretch(1)
        return row

    def set_trials(self, trials: range) -> None:
        """Offer these trials (the session's trials not yet begun).  A chosen trial that has begun gives way to
        the next one still to come, never silently to "now"."""
        have = [self.fault_trial.itemData(i) for i in range(1, self.fault_trial.count())]
        if have == list(trials):
            return
        chosen = self.fault_trial.currentData()
        with QSignalBlocker(self.fault_trial):
            while self.fault_trial.count() > 1:
                self.fault_trial.removeItem(1)
            for k in trials:
                self.fault_trial.addItem(f"trial {k}", k)
            if chosen is None or not len(trials):
                index = 0
            else:
                index = 1 + next((i for i, k in enumerate(trials) if k >= chosen), len(trials) - 1)
            self.fault_trial.setCurrentIndex(index)
        self.fault_seconds.setEnabled(self.fault_trial.currentData() is not None)

    def showEvent(self, event) -> None:  # Qt's name
        super().showEvent(event)
        self.canvas.setFocus()

    def _on_changed(self) -> None:
        want = self.model.driver == "manual"
        if self.manual.isChecked() != want:
            # showing the engine's state is not a choice: sending it back would undo the experimenter's
            # own switch whenever a health report from before it arrives
            with QSignalBlocker(self.autopilot), QSignalBlocker(self.manual):
                (self.manual if want else self.autopilot).setChecked(True)
