"""The participant's screen (a second monitor): target word, rest screen, in training a force gauge, and between two
trials the protocol's questionnaires (:mod:`study_app.gui.questionnaire_view`)."""

from __future__ import annotations

from PySide6.QtCore import QEvent, QPointF, QRectF, Qt, QTimer, Signal
from PySide6.QtGui import QColor, QFont, QFontMetricsF, QKeySequence, QPainter, QPen, QPolygonF, QShortcut
from PySide6.QtWidgets import QHBoxLayout, QLabel, QPushButton, QSizePolicy, QStackedLayout, QVBoxLayout, QWidget

from study_app.gui.placement import centre_on_a_screen
from study_app.gui.questionnaire_view import QuestionnaireView
from study_app.models.participant import ParticipantScreen, ParticipantScreenModel
from study_app.models.questionnaire import QuestionnaireModel

__all__ = ["ForceGauge", "ParticipantWindow"]


class ForceGauge(QWidget):
    """A horizontal bar 0–3 N with the target band; the force only ever shown in training sessions (a moving
    target's band alone in experiments).  A trace ahead (force tracking's ``display = "trace_ahead"``) is drawn above
    the bar: the band's course over the next seconds rising from the bar (now) to the top (the trace's end), as a
    road seen ahead."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setMinimumHeight(90)
        self.force_n: float | None = 0.0
        self.band: tuple[float, float] | None = None
        self.trace: tuple[tuple[float, float, float], ...] = ()
        self.ahead_s = 0.0
        self.max_n = 3.0

    def set_state(self, force_n: float | None, band: tuple[float, float] | None, max_n: float,
                  trace: tuple[tuple[float, float, float], ...] = (), ahead_s: float = 0.0) -> None:
        """The force (None: not shown, the band alone), the band, the scale and the trace ahead (() none) with
        how far ahead it reaches, s."""
        self.force_n, self.band, self.max_n, self.trace, self.ahead_s = force_n, band, max_n, trace, ahead_s
        self.update()

    def paintEvent(self, event) -> None:  # Qt's name
        p = QPainter(self)
        p.setRenderHint(QPainter.RenderHint.Antialiasing)
        w, h = self.width(), self.height()
        x0, x1, y0, bar_h = 40.0, w - 40.0, 20.0, h - 50.0
        scale = (x1 - x0) / self.max_n
        if self.trace:  # the road ahead over the upper part, the bar (now) below it
            bar_h = min(70.0, 0.3 * (h - 30.0))
            y0 = h - 30.0 - bar_h
            self._paint_trace(p, x0, x1, scale, 10.0, y0)
        p.fillRect(QRectF(x0, y0, x1 - x0, bar_h), QColor(45, 45, 52))
        if self.band is not None:
            lo, hi = self.band
            p.fillRect(QRectF(x0 + lo * scale, y0, (hi - lo) * scale, bar_h), QColor(60, 170, 90))
        if self.force_n is not None:
            f = min(max(self.force_n, 0.0), self.max_n)
            inside = self.band is not None and self.band[0] <= self.force_n <= self.band[1]
            p.fillRect(QRectF(x0, y0 + bar_h * 0.3, f * scale, bar_h * 0.4),
                       QColor(250, 250, 250) if inside else QColor(240, 180, 40))
        p.setPen(QPen(QColor(200, 200, 200), 1))
        p.setFont(QFont("Sans", 11))
        for k in range(int(self.max_n) + 1):
            x = x0 + k * scale
            p.drawLine(int(x), int(y0 + bar_h), int(x), int(y0 + bar_h + 6))
            p.drawText(int(x - 15), int(y0 + bar_h + 8), 30, 20, Qt.AlignmentFlag.AlignHCenter, f"{k} N")
        p.end()


    def _paint_trace(self, p: QPainter, x0: float, x1: float, scale: float, top: float, bottom: float) -> None:
        """The band's course ahead: its edges from ``bottom`` (now) up to ``top`` (the trace's end), filled."""
        p.fillRect(QRectF(x0, top, x1 - x0, bottom - top), QColor(30, 30, 38))
        left = [QPointF(x0 + lo * scale, bottom - a * (bottom - top)) for a, lo, _ in self.trace]
        right = [QPointF(x0 + hi * scale, bottom - a * (bottom - top)) for a, _, hi in reversed(self.trace)]
        p.setPen(QPen(QColor(60, 170, 90), 1.5))
        p.setBrush(QColor(60, 170, 90, 110))
        p.drawPolygon(QPolygonF(left + right))
        p.setBrush(Qt.BrushStyle.NoBrush)
        p.setPen(QPen(QColor(170, 170, 180), 1))  # the time axis of the trace: now at the bar, later above
        p.setFont(QFont("Sans", 11))
        p.drawText(QRectF(x0 + 6, top + 4, 200, 20), Qt.AlignmentFlag.AlignLeft, f"in {self.ahead_s:g} s")
        p.drawText(QRectF(x0 + 6, bottom - 22, 200, 20), Qt.AlignmentFlag.AlignLeft, "now")


#: The cue word's largest size, px (a full HD monitor); it shrinks with the window, never the other way round.
HEADLINE_MAX_PX = 96
#: Words the headline shows at most: the cue is sized so the longest of these fits (the targets' labels added).
_HEADLINE_WORDS = ("Thank you", "GENTLE", "FIRM", "Rest")


#: The keys that answer a trial's question, by the name the model takes (``Left``/``Right``: the first/second answer).
_ANSWER_KEYS = {Qt.Key.Key_1: "1", Qt.Key.Key_2: "2", Qt.Key.Key_Left: "Left", Qt.Key.Key_Right: "Right"}


class ParticipantWindow(QWidget):
    """Layout of the participant screen; F11 or double-click toggles full screen.

    The window keeps the size the experimenter gives it: its text never asks for more room (the labels
    ignore their text's width), and the cue word is scaled to the window instead.

    ``seen_changed`` says whether the participant can see it -- shown, not minimised, its middle on a monitor --
    each time that changes (:meth:`unseen` says how it is not): no trial is cued to a screen nobody sees
    (:class:`study_app.models.screen_guard.ScreenGuard`).
    """

    #: (seen, how it is not: "closed", "minimised" or "off every monitor"; "" when seen).
    seen_changed = Signal(bool, str)

    def __init__(self, model: ParticipantScreenModel, parent: QWidget | None = None,
                 questionnaire: QuestionnaireModel | None = None) -> None:
        super().__init__(parent, Qt.WindowType.Window)
        self.model = model
        self.questionnaire = questionnaire or QuestionnaireModel()
        self.setWindowTitle("Participant")
        self.setStyleSheet("background-color: #16161a; color: #f2f2f2;")
        self.setMinimumSize(320, 240)
        self.headline = QLabel()
        self.headline.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.headline.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.subline = QLabel()
        self.subline.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.subline.setWordWrap(True)
        self.subline.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self._words: tuple[str, ...] = _HEADLINE_WORDS
        self.headline_px = HEADLINE_MAX_PX
        self.gauge = ForceGauge()
        self._scale_text()
        cue = self.cue_page = QWidget()
        lay = QVBoxLayout(cue)
        lay.addStretch(2)
        lay.addWidget(self.headline)
        lay.addWidget(self.subline)
        lay.addStretch(1)
        lay.addWidget(self.gauge)
        # a trial's question (force discrimination): a button per answer, and the keys that give them
        self.answer_box = QWidget()
        self.answer_row = QHBoxLayout(self.answer_box)
        self.answer_row.setSpacing(48)  # two answers far enough apart not to be pressed one for the other
        self.answer_row.addStretch(1)
        self.answer_row.addStretch(1)  # the buttons go between the two: centred
        self.answer_buttons: list[QPushButton] = []
        self.answer_box.setVisible(False)
        lay.addWidget(self.answer_box)
        lay.addStretch(1)

        # the cue (and rest) screen, or a questionnaire between two trials
        self.questions = QuestionnaireView(self.questionnaire)
        self.pages = QStackedLayout(self)
        self.pages.addWidget(cue)
        self.pages.addWidget(self.questions)
        QShortcut(QKeySequence(Qt.Key.Key_F11), self).activated.connect(self.toggle_fullscreen)
        model.changed.connect(self._on_changed)
        self.questionnaire.changed.connect(self._on_questionnaire)
        self._on_changed()
        self._reported: str | None = None  # what was last said (None: nothing yet)

    # -- whether the participant sees it ---------------------------------------------------------------
    def unseen(self) -> str:
        """How the participant cannot see this window now: closed, minimised, off every monitor ("" when they can)."""
        if not self.isVisible():
            return "closed"
        if self.isMinimized():
            return "minimised"
        if not centre_on_a_screen(self):
            return "off every monitor"
        return ""

    def report(self) -> None:
        """Say whether it is seen, if that changed since it was last said (at once: before a start is sent)."""
        why = self.unseen()
        if why != self._reported:
            self._reported = why
            self.seen_changed.emit(not why, why)

    def report_soon(self) -> None:
        """:meth:`report` once the event loop has settled (a change of window flags hides and shows it again)."""
        QTimer.singleShot(0, self, self.report)

    def showEvent(self, event) -> None:  # Qt's name
        super().showEvent(event)
        self.report_soon()

    def hideEvent(self, event) -> None:  # Qt's name
        super().hideEvent(event)
        self.report_soon()

    def moveEvent(self, event) -> None:  # Qt's name
        super().moveEvent(event)
        self.report_soon()

    def changeEvent(self, event) -> None:  # Qt's name
        super().changeEvent(event)
        if event.type() == QEvent.Type.WindowStateChange:
            self.report_soon()

    def headline_size_px(self, width: int, height: int) -> int:
        """The cue word's size for a window of this size: the longest word fits 85 % of the width, and the word
        a third of the height (at most :data:`HEADLINE_MAX_PX`, at least 16 px)."""
        font = QFont(self.font())
        font.setPixelSize(100)
        font.setBold(True)
        font.setLetterSpacing(QFont.SpacingType.AbsoluteSpacing, 6.0)
        metrics = QFontMetricsF(font)
        widest = max(metrics.horizontalAdvance(w) for w in self._words)
        px = min(100.0 * 0.85 * width / max(widest, 1.0), height / 3.0, float(HEADLINE_MAX_PX))
        return max(16, int(px))

    def _scale_text(self) -> None:
        px = self.headline_size_px(self.width(), self.height())
        self.headline_px = px
        self.headline.setStyleSheet(f"font-size: {px}px; font-weight: 700; letter-spacing: 6px;")
        sub = max(12, min(22, px // 4))
        self.subline.setStyleSheet(f"font-size: {sub}px; color: #b8b8c0;")
        self._size_gauge()

    def _size_gauge(self) -> None:
        """A gauge with a trace ahead takes half the window's height (the road ahead readable); else its own."""
        self.gauge.setMinimumHeight(max(260, self.height() // 2) if self.gauge.trace else 90)

    def resizeEvent(self, event) -> None:  # Qt's name
        super().resizeEvent(event)
        self._scale_text()

    def toggle_fullscreen(self) -> None:
        """Full screen on the participant's monitor, or back."""
        self.showNormal() if self.isFullScreen() else self.showFullScreen()

    def keyPressEvent(self, event) -> None:  # Qt's name
        """An answer's key (1, 2) or ←/→ (the first, the second) answers the open question; any other key is Qt's."""
        name = _ANSWER_KEYS.get(Qt.Key(event.key()))
        if name is None or not self.model.answer(name):
            super().keyPressEvent(event)

    def mouseDoubleClickEvent(self, event) -> None:  # Qt's name
        self.toggle_fullscreen()

    def _on_questionnaire(self) -> None:
        """A questionnaire due: its pages (the keyboard theirs); answered: the cue screen again."""
        page = self.questions if self.questionnaire.active else self.cue_page
        if self.pages.currentWidget() is not page:
            self.pages.setCurrentWidget(page)
            if page is self.questions:
                self.questions.setFocus()

    def _on_changed(self) -> None:
        s: ParticipantScreen = self.model.screen
        if s.headline and s.headline not in self._words:  # a protocol's own target word: sized to fit as well
            self._words = (*self._words, s.headline)
            self._scale_text()
        self.headline.setText(s.headline)
        self.subline.setText(s.subline)
        # the force only where a gauge is allowed; the band alone where the target moves (force tracking)
        force = s.gauge_force_n if self.model.gauge_allowed else None
        show = s.show_gauge and (force is not None or s.band_n is not None)
        self.gauge.setVisible(show)
        if show:
            had = bool(self.gauge.trace)
            self.gauge.set_state(force, s.band_n, s.gauge_max_n, s.trace, s.ahead_s)
            if had != bool(s.trace):
                self._size_gauge()
        self._show_answers(s.answers)

    def _show_answers(self, answers: tuple[tuple[str, str], ...]) -> None:
        """A button per answer of the open question (none: the row empty)."""
        if [b.property("key") for b in self.answer_buttons] == [k for k, _ in answers]:
            return
        for b in self.answer_buttons:
            self.answer_row.removeWidget(b)
            b.deleteLater()
        self.answer_buttons = []
        self.answer_box.setVisible(bool(answers))
        for i, (key, words) in enumerate(answers):
            b = QPushButton(f"{words}  ({key})")
            b.setProperty("key", key)
            b.setMinimumSize(220, 72)
            b.setStyleSheet("font-size: 26px; background-color: #2c2c36; border: 2px solid #8a8aa0; "
                            "border-radius: 8px; padding: 8px 24px;")
            b.clicked.connect(lambda _=False, k=key: self.model.answer(k))
            self.answer_row.insertWidget(1 + i, b)
            self.answer_buttons.append(b)
