"""The questionnaire's page on the participant screen: the question, its scale (or a pair's two choices), Back,
Next and Submit -- answered by mouse or keyboard (:mod:`study_app.models.questionnaire`)."""

from __future__ import annotations

from PySide6.QtCore import QRectF, Qt, Signal
from PySide6.QtGui import QColor, QFont, QKeyEvent, QMouseEvent, QPainter, QPen
from PySide6.QtWidgets import QHBoxLayout, QLabel, QPushButton, QSizePolicy, QVBoxLayout, QWidget

from study_app.models.questionnaire import QuestionnaireModel

__all__ = ["QuestionnaireView", "ScaleWidget", "text_unit_px"]

_BUTTON = ("QPushButton {{ background: #2b2b33; color: #f2f2f2; border: 1px solid #55555f; border-radius: 6px; "
           "padding: {pad}px {wide}px; font-size: {px}px; }} "
           "QPushButton:disabled {{ color: #66666e; border-color: #3a3a42; }}")
_CHOICE = ("QPushButton {{ background: #24324a; color: #f2f2f2; border: 2px solid #4a6a9a; border-radius: 10px; "
           "padding: {pad}px 12px; font-size: {px}px; font-weight: 600; }} "
           "QPushButton:hover {{ background: #2e4466; }}")
#: The text's unit, px: a fortieth of the page's width or a twentieth of its height, whichever is less (the page is
#: a whole monitor in a study, a small window beside the experimenter's in a rehearsal), at least 9 px.
_UNIT_MIN_PX = 9.0


def text_unit_px(width: int, height: int) -> float:
    """The questionnaire's text unit for a page of this size (its sizes are multiples of it)."""
    return max(_UNIT_MIN_PX, min(width / 40.0, height / 20.0))


class ScaleWidget(QWidget):
    """A horizontal scale of marks from ``lo`` to ``hi`` in ``step`` (NASA-TLX: 21 marks; Likert: its points),
    the chosen mark filled; a click picks the nearest mark."""

    picked = Signal(float)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Fixed)
        self.setCursor(Qt.CursorShape.PointingHandCursor)
        self.lo, self.hi, self.step, self.low, self.high = 0, 100, 5, "", ""
        self.value: float | None = None
        self.unit = 18.0
        self.set_unit(self.unit)

    def set_unit(self, unit: float) -> None:
        """The text unit (px): the scale's height and its words follow it."""
        self.unit = unit
        self.setFixedHeight(int(unit * 5.2))
        self.update()

    def mark_y(self) -> float:
        """Where the scale's line runs (px from the top)."""
        return self.unit * 1.6

    def set_scale(self, lo: int, hi: int, step: int, low: str, high: str, value: float | None) -> None:
        self.lo, self.hi, self.step, self.low, self.high, self.value = lo, hi, step, low, high, value
        self.update()

    def _marks(self) -> list[float]:
        return [float(v) for v in range(self.lo, self.hi + 1, self.step)]

    def _x(self, v: float) -> float:
        x0, x1 = 1.5 * self.unit, self.width() - 1.5 * self.unit
        return x0 + (v - self.lo) / max(self.hi - self.lo, 1) * (x1 - x0)

    def mousePressEvent(self, event: QMouseEvent) -> None:  # Qt's name
        x = event.position().x()
        nearest = min(self._marks(), key=lambda v: abs(self._x(v) - x))
        self.picked.emit(nearest)

    def paintEvent(self, event) -> None:  # Qt's name
        p = QPainter(self)
        p.setRenderHint(QPainter.RenderHint.Antialiasing)
        u, y = self.unit, self.mark_y()
        p.setPen(QPen(QColor(200, 200, 210), 2))
        p.drawLine(int(self._x(self.lo)), int(y), int(self._x(self.hi)), int(y))
        marks = self._marks()
        few = len(marks) <= 11  # a Likert scale: every point numbered
        font = QFont(self.font())
        font.setPixelSize(max(8, int(u * 0.75)))
        p.setFont(font)
        for i, v in enumerate(marks):
            x = self._x(v)
            half = u * (0.7 if few or i % 2 == 0 else 0.4)  # NASA-TLX: every other mark long, as on the sheet
            p.drawLine(int(x), int(y - half), int(x), int(y + half))
            if few:
                p.drawText(QRectF(x - u, y + u * 0.8, 2 * u, u), Qt.AlignmentFlag.AlignHCenter, f"{v:g}")
        if self.value is not None:
            r = u * 0.6
            p.setBrush(QColor(127, 176, 255))
            p.setPen(QPen(QColor(240, 240, 255), 2))
            p.drawEllipse(QRectF(self._x(self.value) - r, y - r, 2 * r, 2 * r))
        p.setPen(QPen(QColor(190, 190, 200)))
        font.setPixelSize(max(9, int(u * 0.9)))
        p.setFont(font)
        top = y + u * (2.0 if few else 1.1)
        p.drawText(QRectF(0, top, self.width() / 2, 1.6 * u), Qt.AlignmentFlag.AlignLeft, f" {self.low}")
        p.drawText(QRectF(self.width() / 2, top, self.width() / 2, 1.6 * u), Qt.AlignmentFlag.AlignRight,
                   f"{self.high} ")
        p.end()


class QuestionnaireView(QWidget):
    """One page of the questionnaire; keys: ← / → (or 1 / 2 on a pair, a digit on a Likert item), Enter,
    Backspace."""

    def __init__(self, model: QuestionnaireModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.model = model
        self._room = True  # for the how-to line (set by _fit)
        self.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        self.heading = self._label()
        self.position = self._label()
        self.title = self._label()
        self.question = self._label()
        self.scale = ScaleWidget()
        self.scale.picked.connect(model.set_value)
        self.left, self.right = QPushButton(), QPushButton()
        for side, b in ((-1, self.left), (1, self.right)):
            b.setFocusPolicy(Qt.FocusPolicy.NoFocus)
            b.clicked.connect(lambda _=False, d=side: model.step(d))
        choices = QHBoxLayout()
        choices.addWidget(self.left)
        choices.setContentsMargins(0, 0, 0, 0)
        choices.addWidget(self.right)
        self.choices = QWidget()
        self.choices.setLayout(choices)
        self.instruction = self._label()
        self.back_button, self.next_button, self.submit_button = (QPushButton("Back"), QPushButton("Next"),
                                                                 QPushButton("Submit"))
        for b, slot in ((self.back_button, model.back), (self.next_button, model.next),
                        (self.submit_button, model.submit)):
            b.setFocusPolicy(Qt.FocusPolicy.NoFocus)  # the keys are the view's
            b.clicked.connect(lambda _=False, s=slot: s())
        nav = QHBoxLayout()
        nav.addWidget(self.back_button)
        nav.addStretch(1)
        nav.addWidget(self.next_button)
        nav.addWidget(self.submit_button)
        lay = self.page_layout = QVBoxLayout(self)
        for part in (self.heading, self.position, None, self.title, self.question, self.scale, self.choices,
                     self.instruction):
            if part is None:
                lay.addStretch(1)
            else:
                lay.addWidget(part)
        lay.addStretch(1)
        lay.addLayout(nav)
        model.changed.connect(self._on_changed)
        self._fit()
        self._on_changed()

    @staticmethod
    def _label() -> QLabel:
        label = QLabel()
        label.setWordWrap(True)
        label.setAlignment(Qt.AlignmentFlag.AlignCenter)
        label.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Minimum)
        return label

    def resizeEvent(self, event) -> None:  # Qt's name
        super().resizeEvent(event)
        self._fit()

    def _fit(self) -> None:
        """Every size a multiple of the text unit (:func:`text_unit_px`): legible on a whole monitor and in a small
        window beside the experimenter's; the how-to line only where there is room for it."""
        u = text_unit_px(self.width(), self.height())
        styles = ((self.heading, 0.8, "#b8b8c0", False), (self.position, 0.7, "#8a8a94", False),
                  (self.title, 1.5, "#f2f2f2", True), (self.question, 1.1, "#f2f2f2", False),
                  (self.instruction, 0.7, "#9a9aa4", False))
        for label, scale, colour, bold in styles:
            label.setStyleSheet(f"font-size: {max(9, int(u * scale))}px; color: {colour};"
                                + (" font-weight: 700;" if bold else ""))
        for b in (self.back_button, self.next_button, self.submit_button):
            b.setStyleSheet(_BUTTON.format(pad=int(u * 0.35), wide=int(u * 0.9), px=max(9, int(u * 0.9))))
        for b in (self.left, self.right):
            b.setStyleSheet(_CHOICE.format(pad=int(u * 0.8), px=max(10, int(u * 1.1))))
        self.scale.set_unit(u)
        margin = int(u * 1.2)
        self.page_layout.setContentsMargins(margin, int(u * 0.6), margin, int(u * 0.6))
        self.page_layout.setSpacing(max(2, int(u * 0.3)))
        self._room = self.height() >= 22 * u  # the how-to line too
        self._on_changed()

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
        self.instruction.setVisible(self._room or md.sent)
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
