"""Questions bound to what they were asked about (PsychoPy/PyMeasure users expect No to be the safe default).

A :class:`Confirmation` is a non-blocking question whose default (Enter,
Space, Esc) is **No**, and which closes itself, as No, when what it was asked
about is over: "Abort trial 7?" goes away when trial 7 ends, so a late Yes can
never abort trial 9.  The engine refuses a bound command for a trial that is no
longer running as well (:class:`study_app.engine.messages.AbortTrial`), which covers
the instant between the trial's end and the window hearing of it.
"""

from __future__ import annotations

from collections.abc import Callable

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QGridLayout, QLineEdit, QMessageBox, QWidget

__all__ = ["Confirmation"]


class Confirmation:
    """A Yes/No question, default No, that calls ``on_yes`` only if answered Yes while still open.

    Parameters
    ----------
    parent
        The window the question is about (the dialog is window-modal to it and centred on it).
    title, text
        The question.
    on_yes
        Called once on Yes.
    moot_when
        Called with each engine event while the question is open; True closes it as No.
    on_moot
        Called when it was closed that way (to say so where the experimenter looks).
    reason
        The placeholder of a field for an optional typed reason under the question ("": no field); its text is
        :attr:`reason` when ``on_yes`` is called.
    """

    def __init__(self, parent: QWidget, title: str, text: str, on_yes: Callable[[], object], *,
                 moot_when: Callable[[object], bool] | None = None, on_moot: Callable[[], None] | None = None,
                 reason: str = "") -> None:
        self.on_yes = on_yes
        self.moot_when = moot_when
        self.on_moot = on_moot
        self.box = QMessageBox(QMessageBox.Icon.Question, title, text,
                               QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.No, parent)
        self.reason_field: QLineEdit | None = None
        if reason:
            self._add_reason(reason)
        self.box.setDefaultButton(QMessageBox.StandardButton.No)
        self.box.setEscapeButton(QMessageBox.StandardButton.No)
        self.box.setWindowModality(Qt.WindowModality.WindowModal)
        self.box.button(QMessageBox.StandardButton.No).setFocus()
        self.box.finished.connect(self._on_finished)
        self.open = False

    def _add_reason(self, placeholder: str) -> None:
        """A line for a typed reason between the question and its buttons (Enter in it still answers No)."""
        field = self.reason_field = QLineEdit()
        field.setPlaceholderText(placeholder)
        field.setMinimumWidth(320)
        grid = self.box.layout()
        if isinstance(grid, QGridLayout):  # QMessageBox lays out its icon, text and buttons in a grid
            buttons = grid.itemAtPosition(grid.rowCount() - 1, 0) or grid.itemAtPosition(grid.rowCount() - 1, 1)
            widget = buttons.widget() if buttons is not None else None
            if widget is not None:
                grid.removeWidget(widget)
                grid.addWidget(field, grid.rowCount() - 1, 1, 1, grid.columnCount() - 1)
                grid.addWidget(widget, grid.rowCount(), 0, 1, grid.columnCount())

    @property
    def reason(self) -> str:
        """The reason typed ("" none)."""
        return " ".join(self.reason_field.text().split()) if self.reason_field is not None else ""

    def show(self) -> None:
        """Ask (returns at once; the answer arrives through ``on_yes``)."""
        self.open = True
        self.box.open()
        self.box.button(QMessageBox.StandardButton.No).setFocus()

    def _on_finished(self, result: int) -> None:
        was_open, self.open = self.open, False
        if was_open and result == QMessageBox.StandardButton.Yes:
            self.on_yes()

    def event(self, ev: object) -> None:
        """An engine event: close the question (as No) if it has become moot."""
        if self.open and self.moot_when is not None and self.moot_when(ev):
            self.dismiss()
            if self.on_moot is not None:
                self.on_moot()

    def dismiss(self) -> None:
        """Close as No, and hand the keyboard back to the window (Space and Esc work there again)."""
        if self.open:
            self.open = False
            self.box.done(QMessageBox.StandardButton.No)
            parent = self.box.parentWidget()
            if parent is not None:
                parent.activateWindow()
