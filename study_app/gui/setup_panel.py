"""The Session box of the experimenter window: the setup form (database, participant, number, kind, protocol,
seed, and what the protocol asks about a new participant) and the interrupted sessions to resume."""

from __future__ import annotations

import html

from PySide6.QtCore import QEvent, Qt, Signal
from PySide6.QtWidgets import (
    QComboBox,
    QFileDialog,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QListWidget,
    QListWidgetItem,
    QPushButton,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from study_app.gui.covariate_fields import QtCovariateFields
from study_app.gui.widgets import LEVEL_COLOURS
from study_app.models.setup import KINDS, SetupModel, breakable

__all__ = ["SPACE_IN_A_FIELD", "SPACE_WHILE_TYPING", "QtSetupPanel"]

#: How a visit of the schedule is shown by its state: what needs the experimenter today stands out.
_STATE_STYLES = {"overdue": f"color: {LEVEL_COLOURS['error'][0]}; font-weight: bold", "due": "font-weight: bold",
                 "done": "color: #555555", "not yet": ""}

#: The line a Space typed into a setup field shows instead of starting (or becoming part of the code).
SPACE_WHILE_TYPING = "A code or number has no spaces: press Enter to start (Space starts once you leave the field)."
#: The line a Space pressed in another text field (read-only: a log, a result) shows instead of starting.
SPACE_IN_A_FIELD = "Space in a text field does not start: click outside the field (or press Start) to start."


class QtSetupPanel(QGroupBox):
    """Session setup form and the list of interrupted sessions to resume.

    Enter in the code, number, kind or seed field starts (``start_requested``), as a form is submitted; Space
    starts from the kind field as everywhere else in the window, but not while typing: a Space typed into a code
    ("P 07") would start the session for "P", so there it is refused with a line saying how to start.  A number
    field whose text is no number it takes (empty, "0") is an error until it is one again, so Start never uses a
    value that is not on screen.
    """

    start_requested = Signal()

    def __init__(self, setup: SetupModel, parent: QWidget | None = None) -> None:
        super().__init__("Session", parent)
        self.setup = setup
        self._build_fields()
        self._build_layout()
        self._wire()
        self._on_changed()
        self._on_resumable()

    def _build_fields(self) -> None:
        """The form's fields, filled from the model, and the lines of its errors, warnings and hints."""
        v = self.setup.values
        self.db = QLineEdit(v.db_path)
        self.db_browse = QPushButton("…")
        self.code = QLineEdit(v.code)
        self.code.setPlaceholderText("e.g. P07 (pseudonymous)")
        self.number = QSpinBox()
        self.number.setRange(1, 9999)
        self.number.setValue(v.participant_number)
        self.kind = QComboBox()
        self.kind.addItems(list(KINDS))
        self.kind.setCurrentText(v.kind)
        self.visit = QComboBox()  # a schedule of visits: which visit (its parts in the Part field)
        self.part = QComboBox()  # a study of several parts: which part (its kind follows)
        self.plan = QLabel()  # the participant's plan: each part in their order, done or not, the next marked
        self.plan.setWordWrap(True)
        self.plan.setTextFormat(Qt.TextFormat.RichText)  # a schedule's visit coloured by its state
        self.protocol = QLineEdit(v.protocol_path)
        self.protocol.setPlaceholderText("default: the paper's protocol")
        self.protocol_browse = QPushButton("…")
        self.seed = QSpinBox()
        self.seed.setRange(0, 2**31 - 1)
        self.seed.setValue(v.seed)
        self.covariate_fields = QtCovariateFields(self.setup.covariates, self.setup.validate)
        self.errors = QLabel()
        self.errors.setWordWrap(True)
        self.errors.setStyleSheet(f"color: {LEVEL_COLOURS['error'][0]};")
        self.off_schedule = QLabel()  # why the form's visit starts only with a reason (out of order, out of window)
        self.off_schedule.setWordWrap(True)
        self.off_schedule.setStyleSheet(f"color: {LEVEL_COLOURS['error'][0]};")
        self.warnings = QLabel()
        self.warnings.setWordWrap(True)
        self.warnings.setStyleSheet(f"color: {LEVEL_COLOURS['warning'][0]};")
        self.hint = QLabel()
        self.hint.setWordWrap(True)
        self.hint.setStyleSheet("color: #555555;")

    def _build_layout(self) -> None:
        """The form above its messages, then the interrupted sessions with their buttons."""
        form = QFormLayout()
        form.addRow("Database", _row(self.db, self.db_browse))
        form.addRow("Participant", self.code)
        form.addRow("Number", self.number)
        form.addRow("Kind", self.kind)
        form.addRow("Visit", self.visit)
        form.addRow("Part", self.part)
        self._form = form
        form.addRow("Protocol", _row(self.protocol, self.protocol_browse))
        form.addRow("Seed", self.seed)
        self.resumable = QListWidget()
        self.resumable.setMaximumHeight(90)
        # a row longer than the column wraps (all of it in the tooltip too); nothing hides to the right
        self.resumable.setWordWrap(True)
        self.resumable.setTextElideMode(Qt.TextElideMode.ElideNone)
        self.resumable.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.resumable.setResizeMode(QListWidget.ResizeMode.Adjust)
        self.refresh_button = QPushButton("Refresh")
        self.resume_button = QPushButton("Resume selected")
        lay = QVBoxLayout(self)
        lay.addLayout(form)
        lay.addWidget(self.plan)
        lay.addWidget(self.off_schedule)
        lay.addWidget(self.covariate_fields)
        lay.addWidget(self.errors)
        lay.addWidget(self.warnings)
        lay.addWidget(self.hint)
        self.resumable_label = QLabel()
        lay.addWidget(self.resumable_label)
        lay.addWidget(self.resumable)
        lay.addLayout(_row_layout(self.refresh_button, self.resume_button))

    def _wire(self) -> None:
        """Each field to the model as the experimenter types or chooses; the model's changes back to the form."""
        setup = self.setup
        self.db.editingFinished.connect(lambda: setup.update(db_path=self.db.text()))
        self.code.textChanged.connect(lambda t: setup.update(code=t))
        self.number.valueChanged.connect(lambda n: setup.set_number(int(n)))
        self.number.setToolTip("Sets the counterbalanced trial order: suggested from the database (the code's own "
                               "number, or the next free one) until you change it")
        for w in (self.code, self.number, self.kind, self.seed):
            w.installEventFilter(self)
        for name, spin in (("participant_number", self.number), ("seed", self.seed)):
            # typed text, and a value set (Qt then rewrites the text without a signal) or restored on leaving
            for signal in (spin.lineEdit().textChanged, spin.valueChanged, spin.editingFinished):
                signal.connect(lambda *_a, n=name, b=spin: self._check_entry(n, b))
        # the experimenter's choice only (textActivated): the form's own proposal of the next step is set from the model
        self.kind.textActivated.connect(lambda k: setup.update(kind=k))
        self.part.textActivated.connect(lambda p: setup.update(part=p))
        self.visit.textActivated.connect(lambda name: setup.update(visit=name))
        self.visit.setToolTip("The visit of the participant's schedule: the form proposes their next visit and part "
                              "until you choose; a visit out of order or outside its window starts only with your "
                              "reason (stored as a deviation)")
        self.part.setToolTip("The part of the study to run: the form proposes the participant's next part in their "
                             "(counterbalanced) order until you choose; its kind follows the part")
        self.kind.setToolTip("Training (practice with the live force gauge) or the experiment. The form proposes "
                             "the participant's next step — training, then the experiment — until you choose")
        # checked as typed (a refusal of the path before stays on screen no longer than that path), and when left
        self.protocol.textEdited.connect(lambda t: setup.update(protocol_path=t))
        self.protocol.editingFinished.connect(lambda: setup.update(protocol_path=self.protocol.text()))
        self.seed.valueChanged.connect(lambda n: setup.update(seed=int(n)))
        self.db_browse.clicked.connect(self._browse_db)
        self.protocol_browse.clicked.connect(self._browse_protocol)
        setup.changed.connect(self._on_changed)
        setup.resumable_changed.connect(self._on_resumable)

    def _browse_db(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self, "Study database", self.db.text(),
                                              "SQLite (*.db *.sqlite);;All files (*)",
                                              options=QFileDialog.Option.DontConfirmOverwrite)
        if path:
            self.db.setText(path)
            self.setup.update(db_path=path)

    def _browse_protocol(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Protocol", self.protocol.text(), "TOML (*.toml)")
        if path:
            self.protocol.setText(path)
            self.setup.update(protocol_path=path)

    def _on_changed(self) -> None:
        v = self.setup.values
        for widget, text in ((self.db, v.db_path), (self.code, v.code), (self.protocol, v.protocol_path)):
            if widget.text() != text:
                widget.setText(text)
        if self.kind.currentText() != v.kind:
            self.kind.setCurrentText(v.kind)
        self._show_plan()
        if self.seed.value() != v.seed:
            self.seed.setValue(v.seed)
        if self.number.value() != v.participant_number:
            self.number.setValue(v.participant_number)
        self.errors.setText(breakable("\n".join(self.setup.errors.values())))
        self.warnings.setText(breakable("\n".join(self.setup.warnings.values())))
        idle = self.setup.running_session is None
        self.hint.setText(self.setup.hint or ("" if self.setup.errors or not idle else self.setup.next_step()))
        why = self.setup.schedule.refusal
        self.off_schedule.setText(breakable(f"Out of schedule: {why}. Start asks for your reason (stored as a "
                                            "deviation)." if why else ""))
        for label in (self.errors, self.off_schedule, self.warnings, self.hint):
            label.setVisible(bool(label.text()))
        self._show_seed()

    def _show_plan(self) -> None:
        """A study of several parts: the Part field (the kind follows it) and the participant's plan; with a schedule
        of visits, the Visit field (the Part field lists its parts) and the participant's schedule."""
        protocol, v, sched = self.setup.protocol, self.setup.values, self.setup.schedule
        visits = list(protocol.visit_names) if protocol is not None else []
        names = list(protocol.part_names) if protocol is not None else []
        _choices(self.visit, visits, v.visit)
        _choices(self.part, list(sched.parts_of.get(v.visit, ())) if visits else names, v.part)
        self._form.setRowVisible(self.visit, bool(visits))
        self._form.setRowVisible(self.part, bool(names))
        self.kind.setEnabled(not names)
        if visits:
            head = "Schedule (each visit: its day, dates, state, parts):"
            lines = [f'<span style="{_STATE_STYLES[r.visit.state]}">{_html(r.text())}</span>' for r in sched.rows()]
        else:
            head, lines = "Plan (this participant's order):", [_html(r.text()) for r in self.setup.plan()]
        self.plan.setText("<br>".join([head, *lines]) if lines else "")
        self.plan.setVisible(bool(lines))

    def _show_seed(self) -> None:
        """The study's seed: read-only once the database has a session, with a tooltip saying why."""
        first = self.setup.seed_fixed_by
        fixed = first is not None and "seed" not in self.setup.errors
        self.seed.setReadOnly(fixed)
        self.seed.setButtonSymbols(QSpinBox.ButtonSymbols.NoButtons if fixed else QSpinBox.ButtonSymbols.UpDownArrows)
        self.seed.setToolTip(
            f"The study's seed, {first.seed}: fixed by the database's first session (session {first.session_id}, "
            f"{first.code}). Every session of a study uses one seed, so its schedules can be reproduced; a new "
            "study needs a new database." if first is not None else
            "The study's seed (schedules, simulated rigs and participants derive from it): fixed when this database "
            "gets its first session, read-only after that")

    def eventFilter(self, obj, event) -> bool:  # Qt's name
        if event.type() != QEvent.Type.KeyPress or event.modifiers() & ~Qt.KeyboardModifier.KeypadModifier:
            return super().eventFilter(obj, event)
        key = event.key()
        if key in (Qt.Key.Key_Return, Qt.Key.Key_Enter) or (key == Qt.Key.Key_Space and obj is self.kind):
            self.start_requested.emit()
            return True
        if key == Qt.Key.Key_Space:  # typing: not part of a code or a number, and not Start either
            self.refuse_space()
            return True
        return super().eventFilter(obj, event)

    def refuse_space(self) -> None:
        """A Space typed into a field of the form (the seed too, read-only once the study has one) neither becomes
        part of it nor starts: the line under the form says how to start."""
        self.hint.setText(SPACE_WHILE_TYPING)
        self.hint.setVisible(True)

    def _check_entry(self, name: str, spin: QSpinBox) -> None:
        """Tell the form when a number field's text is no value it takes (Qt would keep the last one that was)."""
        ok = spin.hasAcceptableInput()
        self.setup.set_entry_problem(name, spin.text(), None if ok else
                                     f"must be a whole number from {spin.minimum()} to {spin.maximum()}")

    def _on_resumable(self) -> None:
        # an empty list takes one line, not the list's height: the column must fit a 768-px screen
        n = len(self.setup.resumable)
        self.resumable_label.setText("Interrupted sessions" if n else "Interrupted sessions: none")
        self.resumable.setVisible(bool(n))
        self.resume_button.setToolTip("" if n else "no interrupted session in this database")
        self.resumable.clear()
        for s in self.setup.resumable:
            text = self.setup.describe_resumable(s)
            item = QListWidgetItem(text)
            item.setToolTip(text)
            item.setData(Qt.ItemDataRole.UserRole, int(s["session_id"]))  # type: ignore[call-overload]  # an int in an untyped row
            self.resumable.addItem(item)
            if int(s["session_id"]) == self.setup.default_resume():  # type: ignore[call-overload]  # as above
                self.resumable.setCurrentItem(item)

    def selected_session(self) -> int | None:
        """The session id selected in the resume list."""
        item = self.resumable.currentItem()
        return None if item is None else int(item.data(Qt.ItemDataRole.UserRole))


def _html(text: str) -> str:
    return html.escape(text, quote=False)


def _choices(box: QComboBox, items: list[str], current: str) -> None:
    """A combo box's items (replaced only when they change) and its current one."""
    if [box.itemText(i) for i in range(box.count())] != items:
        box.clear()
        box.addItems(items)
    if box.currentText() != current:
        box.setCurrentText(current)


def _row(*widgets: QWidget) -> QWidget:
    w = QWidget()
    w.setLayout(_row_layout(*widgets))
    return w


def _row_layout(*widgets: QWidget) -> QHBoxLayout:
    lay = QHBoxLayout()
    lay.setContentsMargins(0, 0, 0, 0)
    for i, x in enumerate(widgets):
        lay.addWidget(x, 1 if i == 0 else 0)
    return lay
