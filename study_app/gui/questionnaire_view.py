"""The questionnaire's page on the participant screen: the question, its scale (or a pair's two choices), Back,
Next and Submit -- answered by mouse or keyboard (:mod:`study_app.models.questionnaire`)."""

from __future__ import annotations

from PySide6.QtCore import QRectF, Qt, Signal
from PySide6.QtGui import QColor, QFont, QKeyEvent, QMouseEvent, QPainter, QPen
from PySide6.QtWidgets import QHBoxLayout, QLabel, QPushButton, QSizePolicy, QVBoxLayout, QWidget

from study_app.models.questionnaire import QuestionnaireModel

__all__ = ["QuestionnaireView", "ScaleWidget"]

_BUTTON = ("QPushButton { background: #2b2b33; color: #f2f2f2; border: 1px solid #55555f; border-radius: 6px; "
           "padding: 10px 22px; font-size: 18px; } QPushButton:disabled { color: #66666e; border-color: #3a3a42; } "
           "QPushButton:focus { border: 2px solid #7fb0ff; }")
_CHOICE = ("QPushButton { background: #24324a; color: #f2f2f2; border: 2px solid #4a6a9a; border-radius: 10px; "
           "padding: 26px 18px; font-size: 24px; font-weight: 600; } QPushButton:hover { background: #2e4466; }")


class ScaleWidget(QWidget):
    """A horizontal scale of marks from ``lo`` to ``hi`` in ``step`` (NASA-TLX: 21 marks; Likert: its points),
    the chosen mark filled; a click picks the nearest mark."""

    picked = Signal(float)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setMinimumHeight(110)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Fixed)
        self.setCursor(Qt.CursorShape.PointingHandCursor)
        self.lo, self.hi, self.step, self.low, self.high = 0, 100, 5, "", ""
        self.value: float | None = None

    def set_scale(self, lo: int, hi: int, step: int, low: str, high: str, value: float | None) -> None:
        self.lo, self.hi, self.step, self.low, self.high, self.value = lo, hi, step, low, high, value
        self.update()

    def _marks(self) -> list[float]:
        return [float(v) for v in range(self.lo, self.hi + 1, self.step)]

    def _x(self, v: float) -> float:
        x0, x1 = 40.0, self.width() - 40.0
        return x0 + (v - self.lo) / max(self.hi - self.lo, 1) * (x1 - x0)

    def mousePressEvent(self, event: QMouseEvent) -> None:  # Qt's name
        x = event.position().x()
        nearest = min(self._marks(), key=lambda v: abs(self._x(v) - x))
        self.picked.emit(nearest)

    def paintEvent(self, event) -> None:  # Qt's name
        p = QPainter(self)
        p.setRenderHint(QPainter.RenderHint.Antialiasing)
        y = 40.0
        p.setPen(QPen(QColor(200, 200, 210), 2))
        p.drawLine(int(self._x(self.lo)), int(y), int(self._x(self.hi)), int(y))
        marks = self._marks()
        few = len(marks) <= 11  # a Likert scale: every point numbered
        p.setFont(QFont("Sans", 12))
        for i, v in enumerate(marks):
            x = self._x(v)
            tall = few or i % 2 == 0 or i in (0, len(marks) - 1)
            p.drawLine(int(x), int(y - (14 if tall else 8)), int(x), int(y + (14 if tall else 8)))
            if few:
                p.drawText(QRectF(x - 20, y + 16, 40, 20), Qt.AlignmentFlag.AlignHCenter, f"{v:g}")
        if self.value is not None:
            p.setBrush(QColor(127, 176, 255))
            p.setPen(QPen(QColor(240, 240, 255), 2))
            p.drawEllipse(QRectF(self._x(self.value) - 11, y - 11, 22, 22))
        p.setPen(QPen(QColor(190, 190, 200)))
        p.setFont(QFont("Sans", 14))
        bottom = y + (40 if few else 22)
        p.drawText(QRectF(0, bottom, self.width() / 2, 30), Qt.AlignmentFlag.AlignLeft, f"  {self.low}")
        p.drawText(QRectF(self.width() / 2, bottom, self.width() / 2, 30), Qt.AlignmentFlag.AlignRight,
                   f"{self.high}  ")
        p.end()


class QuestionnaireView(QWidget):
    """One page of the questionnaire; keys: ← / → (or 1 / 2 on a pair, a digit on a Likert item), Enter,
    Backspace."""

    def __init__(self, model: QuestionnaireModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.model = model
        self.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        self.heading = self._label(18, "#b8b8c0")
        self.position = self._label(14, "#8a8a94")
        self.title = self._label(30, "#f2f2f2", bold=True)
        self.question = self._label(24, "#f2f2f2")
        self.scale = ScaleWidget()
        self.scale.picked.connect(model.set_value)
        self.left, self.right = QPushButton(), QPushButton()
        for side, b in ((-1, self.left), (1, self.right)):
            b.setStyleSheet(_CHOICE)
            b.setFocusPolicy(Qt.FocusPolicy.NoFocus)
            b.clicked.connect(lambda _=False, d=side: model.step(d))
        choices = QHBoxLayout()
        choices.addWidget(self.left)
        choices.addSpacing(30)
        choices.addWidget(self.right)
        self.choices = QWidget()
        self.choices.setLayout(choices)
        self.instruction = self._label(14, "#9a9aa4")
        self.back_button, self.next_button, self.submit_button = (QPushButton("Back"), QPushButton("Next"),
                                                                 QPushButton("Submit"))
        for b, slot in ((self.back_button, model.back), (self.next_button, model.next),
                        (self.submit_button, model.submit)):
            b.setStyleSheet(_BUTTON)
            b.setFocusPolicy(Qt.FocusPolicy.NoFocus)  # the keys are the view's
            b.clicked.connect(lambda _=False, s=slot: s())
        nav = QHBoxLayout()
        nav.addWidget(self.back_button)
        nav.addStretch(1)
        nav.addWidget(self.next_button)
        nav.addWidget(self.submit_button)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(40, 24, 40, 24)
        for part in (self.heading, self.position, None, self.title, self.question, self.scale, self.choices,
                     self.instruction):
            if part is None:
                lay.addStretch(1)
            else:
                lay.addWidget(part)
        lay.addStretch(1)
        lay.addLayout(nav)
        model.changed.connect(self._on_changed)
        self._on_changed()

    @staticmethod
    def _label(px: int, colour: str, bold: bool = False) -> QLabel:
        label = QLabel()
        label.setWordWrap(True)
        label.setAlignment(Qt.AlignmentFlag.AlignCenter)
        label.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        label.setStyleSheet(f"font-size: {px}px; color: {colour};" + (" font-weight: 700;" if bold else ""))
        return label

    def _on_changed(self) -> None:
        md = self.model
        if not md.active:
            return
        item = md.item
        self.heading.setText(md.heading())
        self.position.setText(md.position())
        self.title.setText(md.title())
        self.title.setVisible(bool(md.title()))
        pair = item is not None and item.pair is not None
        if item is None:
            self.question.setText("Thank you." if not md.sent else "Thank you — your answers are being saved.")
        else:
            self.question.setText("Which contributed more to your workload?" if pair else item.text)
        self.scale.setVisible(item is not None and not pair)
        if item is not None and not pair:
            lo, hi, step, low, high = md.scale()
            v = md.value()
            self.scale.set_scale(lo, hi, step, low, high, v if isinstance(v, float) else None)
        self.choices.setVisible(pair)
        if pair:
            a, b = md.pair_names()
            self.left.setText(f"1  {a}")
            self.right.setText(f"2  {b}")
        self.instruction.setText(md.instruction() if not md.sent else "Please wait.")
        self.back_button.setEnabled(md.page > 0 and not md.sent)
        self.next_button.setVisible(item is not None)
        self.next_button.setEnabled(md.value() is not None)
        self.submit_button.setVisible(item is None)
        self.submit_button.setEnabled(not md.sent)

    def keyPressEvent(self, event: QKeyEvent) -> None:  # Qt's name
        md, key = self.model, event.key()
        item = md.item
        if key in (Qt.Key.Key_Left, Qt.Key.Key_Right):
            md.step(-1 if key == Qt.Key.Key_Left else 1)
        elif key in (Qt.Key.Key_Return, Qt.Key.Key_Enter):
            md.submit() if item is None else md.next()
        elif key == Qt.Key.Key_Backspace:
            md.back()
        elif item is not None and item.pair is not None and key in (Qt.Key.Key_1, Qt.Key.Key_2):
            md.step(-1 if key == Qt.Key.Key_1 else 1)
        elif item is not None and item.scale is not None and Qt.Key.Key_0 <= key <= Qt.Key.Key_9:
            digit = key - Qt.Key.Key_0
            if item.scale.lo <= digit <= item.scale.hi:
                md.set_value(float(digit))
        else:
            super().keyPressEvent(event)
