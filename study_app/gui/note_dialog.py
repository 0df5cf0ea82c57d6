"""The experimenter's *Note* dialog: what the note is about (the session, the running trial, a trial that ended),
its words, and whether it records a deviation from the protocol (the report lists those).

Window-modal over the experimenter's window, so Space and Esc do not start or abort anything while it is open;
Ctrl+Enter saves.  The note is taken on the session clock when the engine receives it.
"""

from __future__ import annotations

from collections.abc import Callable

from PySide6.QtCore import Qt
from PySide6.QtGui import QKeySequence, QShortcut
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDialog,
    QDialogButtonBox,
    QFormLayout,
    QLabel,
    QPlainTextEdit,
    QVBoxLayout,
    QWidget,
)

__all__ = ["NoteDialog"]


class NoteDialog(QDialog):
    """Asks for a note; ``on_save(text, trial_index or None, deviation)`` is called once, on Save, with words.

    Parameters
    ----------
    parent
        The window it opens over.
    subjects
        What the note may be about: (label, trial index; None: the session), and the one proposed.
    on_save
        Called with the note when it is saved (returns whether it was sent).
    """

    def __init__(self, parent: QWidget, subjects: tuple[list[tuple[str, int | None]], int],
                 on_save: Callable[[str, int | None, bool], bool]) -> None:
        super().__init__(parent)
        self.setWindowTitle("Note")
        self.on_save = on_save
        choices, proposed = subjects
        self.about = QComboBox()
        for label, index in choices:
            self.about.addItem(label, index)
        self.about.setCurrentIndex(proposed)
        self.text = QPlainTextEdit()
        self.text.setPlaceholderText("What happened (no names: the participant is known by their code only)")
        self.text.setTabChangesFocus(True)
        self.text.setMinimumHeight(80)
        self.deviation = QCheckBox("A deviation from the protocol (the study report lists it)")
        self.buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Save | QDialogButtonBox.StandardButton.Cancel)
        self.buttons.accepted.connect(self._save)
        self.buttons.rejected.connect(self.reject)
        self.text.textChanged.connect(self._on_text)
        form = QFormLayout()
        form.addRow("Note on", self.about)
        lay = QVBoxLayout(self)
        lay.addLayout(form)
        lay.addWidget(self.text)
        lay.addWidget(self.deviation)
        hint = QLabel("Stored at once, on the session clock; a note is never changed afterwards (Ctrl+Enter saves).")
        hint.setWordWrap(True)
        hint.setStyleSheet("color: #555555;")
        lay.addWidget(hint)
        lay.addWidget(self.buttons)
        for key in ("Ctrl+Return", "Ctrl+Enter"):
            QShortcut(QKeySequence(key), self).activated.connect(self._save)
        self.setWindowModality(Qt.WindowModality.WindowModal)
        self.resize(460, self.sizeHint().height())
        self._on_text()

    def _on_text(self) -> None:
        self.buttons.button(QDialogButtonBox.StandardButton.Save).setEnabled(bool(self.text.toPlainText().strip()))

    def _save(self) -> None:
        words = self.text.toPlainText().strip()
        if words and self.on_save(words, self.about.currentData(), self.deviation.isChecked()):
            self.accept()
