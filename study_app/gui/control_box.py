"""The experimenter window's "Control" box: the session's buttons, and the two rows that say what went wrong.

Layout only (the window wires the buttons to the model, :mod:`study_app.gui.main_window`): start (and the two
starts that need a typed reason, hidden until they apply), pause/resume, abort, a note, calibration, the extra
windows' buttons; above them the dead-engine row (what happened and *Restart engine*) and the notices' row (a refusal, a
question that became moot), each hidden until there is something to say.
"""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QGroupBox, QHBoxLayout, QLabel, QPushButton, QToolButton, QVBoxLayout, QWidget

from study_app.gui.widgets import LEVEL_COLOURS
from study_app.models.notices import Notice

__all__ = ["ControlBox"]


class ControlBox(QGroupBox):
    """Start, pause/resume, abort, the windows' buttons; the engine's and the notices' rows above them."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__("Control", parent)
        self.start_button = QPushButton("Start  [Space]")
        self.pause_button = QPushButton("Pause")
        self.resume_button = QPushButton("Resume")
        self.abort_trial_button = QPushButton("Abort trial  [Esc]")
        self.abort_session_button = QPushButton("Abort session")
        self.note_button = QPushButton("Note…  [Ctrl+N]")
        # a questionnaire waits for the participant: the experimenter may skip it (stored as skipped, a deviation)
        self.skip_questionnaire_button = QPushButton("Skip questionnaire…")
        self.skip_questionnaire_button.setToolTip("The participant does not answer it: stored as skipped, a "
                                                  "deviation from the protocol the study report lists")
        self.skip_questionnaire_button.hide()
        self.note_button.setToolTip("A note on the session or one of its trials, stored on the session clock (mark "
                                    "it a deviation and the study report lists it)")
        self.calibrate_button = QPushButton("Calibration…")
        self.participant_button = QPushButton("Participant screen")
        self.rig_button = QPushButton("Simulated rig view")
        self.start_button.setStyleSheet("font-weight: 700; padding: 6px;")
        # an experiment the form refuses for want of training: only with a typed reason, stored as a deviation
        self.untrained_button = QPushButton("Start without training…")
        self.untrained_button.hide()
        grid = QVBoxLayout(self)
        grid.addWidget(self._build_engine_row())
        grid.addWidget(self.start_button)
        grid.addWidget(self.untrained_button)
        grid.addWidget(self._build_notice_row())
        pr = QHBoxLayout()
        pr.addWidget(self.pause_button)
        pr.addWidget(self.resume_button)
        grid.addLayout(pr)
        ab = QHBoxLayout()
        ab.addWidget(self.abort_trial_button)
        ab.addWidget(self.abort_session_button)
        grid.addLayout(ab)
        grid.addWidget(self.note_button)
        grid.addWidget(self.skip_questionnaire_button)
        grid.addWidget(self.calibrate_button)
        # real rig: start although the calibration chain is incomplete -- only with a reason, which is stored
        self.override_button = QPushButton("Start without calibration…")
        self.override_button.hide()
        grid.addWidget(self.override_button)
        wr = QHBoxLayout()
        wr.addWidget(self.participant_button)
        wr.addWidget(self.rig_button)
        grid.addLayout(wr)

    def _build_engine_row(self) -> QWidget:
        """A dead engine or haptic loop: what happened and the way out (hidden until then)."""
        self.engine_label = QLabel()
        self.engine_label.setWordWrap(True)
        self.restart_button = QPushButton("Restart engine")
        self.restart_button.setStyleSheet("font-weight: 700; padding: 6px;")
        self.engine_row = QWidget()
        er = QVBoxLayout(self.engine_row)
        er.setContentsMargins(4, 4, 4, 4)
        er.addWidget(self.engine_label)
        er.addWidget(self.restart_button)
        fg, bg = LEVEL_COLOURS["error"]
        self.engine_row.setStyleSheet(f"background: {bg};")
        self.engine_label.setStyleSheet(f"color: {fg}; font-weight: 600;")
        self.engine_row.hide()
        return self.engine_row

    def _build_notice_row(self) -> QWidget:
        """Refusals and questions that became moot, with a dismiss button (hidden until there is one)."""
        self.notice = QLabel()
        self.notice.setWordWrap(True)
        self.notice.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.notice_close = QToolButton()
        self.notice_close.setText("×")
        self.notice_close.setToolTip("Dismiss")
        self.notice_row = QWidget()
        nr = QHBoxLayout(self.notice_row)
        nr.setContentsMargins(0, 0, 0, 0)
        nr.addWidget(self.notice, 1)
        nr.addWidget(self.notice_close, 0, Qt.AlignmentFlag.AlignTop)
        self.notice_row.hide()
        return self.notice_row

    def show_engine(self, trouble: str, detail: str, can_restart: bool) -> None:
        """Show what is wrong with the engine ("" hides the row) and whether it can be restarted now."""
        self.engine_label.setText(trouble)
        self.engine_label.setToolTip(detail)
        self.restart_button.setToolTip(detail)
        self.engine_row.setVisible(bool(trouble))
        self.restart_button.setEnabled(can_restart)

    def show_notice(self, n: Notice | None) -> None:
        """Show the model's notice in its level's colours (None hides the row)."""
        self.notice_row.setVisible(n is not None)
        if n is not None:
            fg, bg = LEVEL_COLOURS.get(n.level, LEVEL_COLOURS["info"])
            self.notice.setText(n.text)
            self.notice_row.setStyleSheet(f"background: {bg}; color: {fg};")
            self.notice.setStyleSheet(f"color: {fg}; font-weight: 600; padding: 4px;")
