"""The experimenter window's small pieces: a one-line label that never widens its column, a scroll area that keeps
its newest row in view, and the colours of the levels (ok, info, warning, error) every view uses."""

from __future__ import annotations

from collections.abc import Callable

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QAbstractScrollArea, QLabel, QSizePolicy, QWidget

__all__ = ["LEVEL_COLOURS", "ElidedLabel", "FollowNewest"]

#: Colours of the levels of health figures and notices (text, background).
LEVEL_COLOURS = {
    "ok": ("#147f28", "#eaf7ec"), "info": ("#1d4f91", "#eaf1fb"), "warn": ("#8a5a00", "#fff4e0"),
    "warning": ("#8a5a00", "#fff4e0"), "bad": ("#b3141b", "#fdecec"), "error": ("#b3141b", "#fdecec"),
    "unknown": ("#555555", "#f2f2f2"),
}


class ElidedLabel(QLabel):
    """One line of text that never wraps or widens its column: what does not fit ends in '…', all of it in the
    tooltip."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._full = ""
        self.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)

    def full_text(self) -> str:
        """The text as set (the label may show it shortened)."""
        return self._full

    def set_full_text(self, text: str) -> None:
        """Show ``text``, shortened to the label's width if it must be."""
        self._full = text
        self.setToolTip(text)
        self._elide()

    def resizeEvent(self, event):  # Qt's name
        super().resizeEvent(event)
        self._elide()

    def _elide(self) -> None:
        one_line = " ".join(self._full.split())  # a message with line breaks (an engine's traceback) is one line here
        self.setText(self.fontMetrics().elidedText(one_line, Qt.TextElideMode.ElideRight, max(0, self.width())))


class FollowNewest:
    """Keep a scroll area's newest (last) row in view -- unless the user scrolled away from it.

    The view follows while its scroll bar is at the end; when rows are added or the view shrinks (a banner
    appears above it), it scrolls to the end again.  Scrolled up by the user, it stays where it was, until
    the user scrolls back to the end.
    """

    def __init__(self, area: QAbstractScrollArea) -> None:
        self.bar = area.verticalScrollBar()
        self.following = True
        self._moving = False
        self.bar.valueChanged.connect(self._on_value)
        self.bar.rangeChanged.connect(self._on_range)

    def _on_value(self, value: int) -> None:
        if not self._moving:
            self.following = value >= self.bar.maximum()

    def _on_range(self, _lo: int, hi: int) -> None:
        if self.following:
            self.to_end()

    def to_end(self) -> None:
        """Show the newest row (when following)."""
        if self.following:
            self._moving = True
            try:
                self.bar.setValue(self.bar.maximum())
            finally:
                self._moving = False

    def keep(self, change: Callable[[], None]) -> None:
        """Apply a change that resets the view (``setPlainText`` scrolls to the top): the newest row stays in view
        if it was, else the user's place is kept."""
        was, value = self.following, self.bar.value()
        self._moving = True
        try:
            change()
        finally:
            self._moving = False
        self.following = was
        if was:
            self.to_end()
        else:
            self.bar.setValue(min(value, self.bar.maximum()))
