"""The jaw's controls in the experimenter's window: close, step, open, and where the jaw is (:class:`JawModel`)."""

from __future__ import annotations

from collections.abc import Callable

from PySide6.QtWidgets import QGroupBox, QHBoxLayout, QLabel, QPushButton, QVBoxLayout, QWidget

from study_app.models.commissioning import JawModel

__all__ = ["QtJawBox"]

#: The buttons: (action, text, tooltip).
_BUTTONS = (("close", "Close", "close fully (the firmware's closed limit)"),
            ("step_close", "Step −", "one step (1 mm of rod travel) toward closed"),
            ("step_open", "Step +", "one step (1 mm of rod travel) toward open"),
            ("open", "Open", "open fully (the firmware's open limit)"))


class QtJawBox(QGroupBox):
    """Jaw controls and the jaw's position; hidden until the engine reports a jaw."""

    def __init__(self, jaw: JawModel, on_action: Callable[[str], None], parent: QWidget | None = None) -> None:
        super().__init__("Jaw", parent)
        self.jaw = jaw
        lay = QVBoxLayout(self)
        row = QHBoxLayout()
        self.buttons: dict[str, QPushButton] = {}
        for action, text, tip in _BUTTONS:
            b = QPushButton(text)
            b.setToolTip(tip)
            b.clicked.connect(lambda _=False, a=action: on_action(a))
            row.addWidget(b)
            self.buttons[action] = b
        self.label = QLabel()
        self.label.setWordWrap(True)  # (a fault's text may take two lines)
        # the last command, all of it: wrapped (an elided "last: step_close: 1 mm tow…" said nothing); the left
        # column scrolls on a short screen rather than cut a line
        self.last = QLabel()
        self.last.setWordWrap(True)
        lay.addLayout(row)
        lay.addWidget(self.label)
        lay.addWidget(self.last)
        self.hide()
        jaw.changed.connect(self.refresh)

    def refresh(self) -> None:
        """Show the jaw as the model has it."""
        jaw = self.jaw
        self.setVisible(jaw.available)
        self.label.setText(jaw.text())
        self.last.setText(f"last: {jaw.log[-1]}" if jaw.log else "")
        self.last.setVisible(bool(jaw.log))
        fault = jaw.state is not None and bool(jaw.state.fault)
        self.label.setStyleSheet("color: #c81e1e; font-weight: 600;" if fault else "color: #333;")
