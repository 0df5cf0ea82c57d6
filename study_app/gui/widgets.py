"""Views of the experimenter window, one per model (``Qt<Model>(model)``, napari style)."""

from __future__ import annotations

from collections.abc import Callable

from PySide6.QtCore import QEvent, Qt, Signal
from PySide6.QtGui import QColor
from PySide6.QtWidgets import (
    QAbstractItemView,
    QAbstractScrollArea,
    QComboBox,
    QFileDialog,
    QFormLayout,
    QFrame,
    QGroupBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
    QListWidget,
    QListWidgetItem,
    QPlainTextEdit,
    QProgressBar,
    QPushButton,
    QScrollArea,
    QSizePolicy,
    QSpinBox,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from study_app.models.app import CUE_ACTIONS, AppModel
from study_app.models.cue_wait import headline
from study_app.models.health import HealthModel
from study_app.models.session import TRIAL_COLUMNS, SessionModel, TrialTable
from study_app.models.setup import KINDS, SetupModel, breakable

__all__ = ["ElidedLabel", "FollowNewest", "QtCueWait", "QtHealthPanel", "QtProgress", "QtSetupPanel", "QtTrialTable"]

_OUTCOME_COLOURS = {"success": QColor(215, 245, 215), "timeout": QColor(250, 235, 205),
                    "aborted": QColor(235, 235, 235)}


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


class QtTrialTable(QTableWidget):
    """The trial table, filled as :class:`TrialTable` rows arrive; the newest row stays in view
    (:class:`FollowNewest`)."""

    def __init__(self, table: TrialTable, parent: QWidget | None = None) -> None:
        super().__init__(0, len(TRIAL_COLUMNS), parent)
        self.table = table
        self.setHorizontalHeaderLabels(list(TRIAL_COLUMNS))
        self.verticalHeader().setVisible(False)
        self.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.setTextElideMode(Qt.TextElideMode.ElideRight)
        header = self.horizontalHeader()
        header.setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        header.setSectionResizeMode(3, QHeaderView.ResizeMode.Stretch)
        self.follow = FollowNewest(self)
        table.row_added.connect(self._on_row_added)
        table.cleared.connect(self._on_cleared)

    def _on_cleared(self) -> None:
        self.setRowCount(0)
        self.follow.following = True

    def _on_row_added(self, i: int) -> None:
        row = self.table.rows[i]
        self.insertRow(i)
        colour = _OUTCOME_COLOURS.get(str(row.outcome))
        for j, text in enumerate(TrialTable.cells(row)):
            item = QTableWidgetItem(text)
            item.setToolTip(text)  # an abort's reason may be longer than its column
            if j != 3:
                item.setTextAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
            if colour is not None:
                item.setBackground(colour)
            self.setItem(i, j, item)
        self.follow.to_end()


class QtCueWait(QWidget):
    """Above the trial table: why the next cue waits, for how long, and the button that ends the wait."""

    def __init__(self, model: AppModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.model, self._actions = model, CUE_ACTIONS
        self.label = QLabel()
        self.label.setWordWrap(True)
        self.help = QLabel()
        self.help.setWordWrap(True)
        self.button = QPushButton()
        self.button.setFocusPolicy(Qt.FocusPolicy.NoFocus)  # Space stays Start / Resume
        self.button.clicked.connect(model.end_cue_wait)
        text = QVBoxLayout()
        text.setContentsMargins(0, 0, 0, 0)
        text.setSpacing(0)
        text.addWidget(self.label)
        text.addWidget(self.help)
        lay = QHBoxLayout(self)
        lay.setContentsMargins(6, 3, 6, 3)
        lay.addLayout(text, 1)
        lay.addWidget(self.button, 0, Qt.AlignmentFlag.AlignTop)
        model.cue_wait_changed.connect(self._on_changed)
        self._on_changed()

    def _on_changed(self) -> None:
        w = self.model.cue_wait
        self.setVisible(w is not None)
        if w is None:
            return
        fg, bg = LEVEL_COLOURS.get(w.level, LEVEL_COLOURS["info"])
        self.setAutoFillBackground(True)
        pal = self.palette()
        pal.setColor(self.backgroundRole(), QColor(bg))
        self.setPalette(pal)
        self.label.setText(w.text())
        self.label.setStyleSheet(f"color: {fg}; font-weight: 600;")
        self.help.setStyleSheet(f"color: {fg};")
        self.help.setText(w.help)
        self.help.setVisible(bool(w.help))
        self.button.setText(self._actions.get(w.action, ""))
        self.button.setVisible(bool(w.action))


#: Colours of the levels of health figures and notices (text, background).
LEVEL_COLOURS = {
    "ok": ("#147f28", "#eaf7ec"), "info": ("#1d4f91", "#eaf1fb"), "warn": ("#8a5a00", "#fff4e0"),
    "warning": ("#8a5a00", "#fff4e0"), "bad": ("#b3141b", "#fdecec"), "error": ("#b3141b", "#fdecec"),
    "unknown": ("#555555", "#f2f2f2"),
}


class QtProgress(QWidget):
    """What happens now (the trial and its time left, the pause), the session's count and time left with a bar
    of the designed trials done, and a warning line when the force on the tissue is too high."""

    def __init__(self, session: SessionModel, health: HealthModel | None = None, parent: QWidget | None = None,
                 *, app: AppModel | None = None) -> None:
        super().__init__(parent)
        self.session = session
        self.health = health
        #: Why the next cue waits (the banner's model): the headline says the same (None: the session alone).
        self.app = app
        self.label = ElidedLabel()
        self.label.setStyleSheet("font-size: 15px; font-weight: 600;")
        self.count = ElidedLabel()
        self.count.setStyleSheet("font-size: 13px;")
        self.bar = QProgressBar()
        self.bar.setRange(0, 1000)
        self.bar.setTextVisible(False)
        self.bar.setMaximumHeight(10)
        self.warning = QLabel()
        self.warning.setWordWrap(True)
        fg, bg = LEVEL_COLOURS["bad"]
        self.warning.setStyleSheet(f"color: {fg}; background: {bg}; font-weight: 600; padding: 3px 6px;")
        self.warning.hide()
        lay = QVBoxLayout(self)
        lay.setContentsMargins(4, 2, 4, 2)
        lay.setSpacing(1)
        lay.addWidget(self.label)
        lay.addWidget(self.count)
        lay.addWidget(self.bar)
        lay.addWidget(self.warning)
        session.changed.connect(self._on_changed)
        if health is not None:
            health.changed.connect(self._on_health)
        if app is not None:
            app.cue_wait_changed.connect(self._on_changed)
        self._on_changed()

    def _on_changed(self) -> None:
        self.label.set_full_text(headline(self.session, self.app.cue_wait if self.app is not None else None))
        count = self.session.count_text() if self.session.running else ""
        if count != self.count.full_text():
            self.count.set_full_text(count)
            self.count.setVisible(bool(count))
        self.bar.setValue(int(1000 * self.session.fraction_done()))

    def _on_health(self) -> None:
        text = self.health.force_warning() if self.health is not None else ""
        if text != self.warning.text():
            self.warning.setText(text)
            self.warning.setVisible(bool(text))


class QtHealthPanel(QWidget):
    """Devices (state, rate, sample age), faults with a Reset button, why the next cue waits, the machine's health
    in words, loop timing judged against its limits, and the fault log (newest last, kept in view)."""

    COLUMNS = ("Device", "State", "Rate (Hz)", "Sample age (ms)")
    LOG_LABEL = "Fault log, oldest first and newest last (a fault latches until Reset faults):"

    def __init__(self, health: HealthModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.health = health
        self.devices = QTableWidget(0, len(self.COLUMNS))
        self.devices.setHorizontalHeaderLabels(list(self.COLUMNS))
        self.devices.verticalHeader().setVisible(False)
        self.devices.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.devices.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Stretch)
        # all four devices (the jaw's row when there is one), without a scroll bar
        self.devices.verticalHeader().setDefaultSectionSize(22)
        self.devices.setFixedHeight(4 * 22 + self.devices.horizontalHeader().sizeHint().height() + 4)
        self.faults = QLabel()
        self.arms = QLabel()  # a rig of several arms: one line per arm, the task arm marked
        self.arms.hide()
        self.reset_button = QPushButton("Reset faults")
        self.waiting = QLabel()
        self.waiting.setWordWrap(True)
        self.waiting.hide()
        self.machine = QLabel()
        self.machine.setWordWrap(True)
        fg, bg = LEVEL_COLOURS["warning"]
        self.machine.setStyleSheet(f"color: {fg}; background: {bg}; padding: 4px;")
        self.machine.hide()
        self.loop = QLabel()
        self.loop.setTextFormat(Qt.TextFormat.RichText)
        self.loop.setWordWrap(True)
        self.thermal = QLabel()
        self.thermal.setWordWrap(True)
        self.force = QLabel()
        self.force.setWordWrap(True)
        self.force.hide()
        self.log_label = QLabel(self.LOG_LABEL)
        self.log = QPlainTextEdit()
        self.log.setReadOnly(True)
        self.log.setMinimumHeight(60)
        self.log.setLineWrapMode(QPlainTextEdit.LineWrapMode.WidgetWidth)
        self.log.setPlaceholderText("no fault since the engine started")
        self.log_follow = FollowNewest(self.log)
        row = QHBoxLayout()
        row.addWidget(self.faults, 1)
        row.addWidget(self.reset_button, 0, Qt.AlignmentFlag.AlignTop)
        body = QWidget()
        lay = QVBoxLayout(body)
        lay.setContentsMargins(4, 4, 4, 4)
        lay.addWidget(self.machine)
        lay.addWidget(self.devices)
        lay.addLayout(row)
        lay.addWidget(self.arms)
        lay.addWidget(self.waiting)
        lay.addWidget(self.loop)
        lay.addWidget(self.thermal)
        lay.addWidget(self.force)
        lay.addWidget(self.log_label)
        lay.addWidget(self.log, 1)
        # a short tab (a 768-px screen) scrolls; nothing is squashed or cut
        scroll = QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setFrameShape(QFrame.Shape.NoFrame)
        scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        scroll.setWidget(body)
        outer = QVBoxLayout(self)
        outer.setContentsMargins(0, 0, 0, 0)
        outer.addWidget(scroll)
        health.changed.connect(self._on_changed)
        self._on_changed()

    def loop_html(self) -> str:
        """The loop's figures, each coloured against its limit, and what the colours mean."""
        figures = self.health.loop_figures()
        if not figures:
            return "loop: –"
        line = " · ".join(f'<span style="color:{LEVEL_COLOURS[f.level][0]}">{f.text}</span>' for f in figures)
        limits = "; ".join(f"{f.name} {f.limit}" for f in figures)
        return f"{line}<br><small>green: within the limit, amber: above it, red: far above (limits: {limits})</small>"

    def attention(self) -> bool:
        """Something here needs the experimenter: a latched fault, a held cue or a busy machine (the tab says so)."""
        h = self.health
        return bool(h.faults or h.waiting_text() or h.busy_trials)

    def _on_changed(self) -> None:
        h = self.health
        self.devices.setRowCount(len(h.devices))
        for i, d in enumerate(h.devices):
            cells = (d.name, d.state, "–" if d.rate_hz != d.rate_hz else f"{d.rate_hz:.0f}",
                     "–" if d.age_ms != d.age_ms else f"{d.age_ms:.1f}")
            for j, text in enumerate(cells):
                item = self.devices.item(i, j)
                if item is None:
                    item = QTableWidgetItem()
                    self.devices.setItem(i, j, item)
                item.setText(text)
                item.setToolTip(text)
                if j == 1:
                    level = "ok" if d.state.startswith("ok") else "error"
                    item.setForeground(QColor(LEVEL_COLOURS[level][0]))
        self.faults.setText(f"Faults: {h.faults_text()}")
        # one colour per state, as the Trials tab's banner shows it: a latched fault or a held cue is an error
        level = "error" if h.faults else "ok"
        self.faults.setStyleSheet(f"color: {LEVEL_COLOURS[level][0]}; font-weight: 600;")
        self.reset_button.setEnabled(bool(h.faults))
        self.reset_button.setToolTip("" if h.faults else "No fault is latched")
        arms = h.arms_text()
        if arms != self.arms.text():
            self.arms.setText(arms)
            self.arms.setVisible(bool(arms))
        waiting = h.waiting_text()
        self.waiting.setText(f"The next cue waits: {waiting}" if waiting else "")
        self.waiting.setStyleSheet(f"color: {LEVEL_COLOURS['error'][0]}; font-weight: 600;")
        self.waiting.setVisible(bool(waiting))
        machine = h.machine_notice()
        if machine != self.machine.text():
            self.machine.setText(machine)
            self.machine.setVisible(bool(machine))
        loop = self.loop_html()
        if self.loop.text() != loop:
            self.loop.setText(loop)
        th = h.thermal_figure()
        self.thermal.setText(th.text if th is not None else "")
        if th is not None:
            self.thermal.setStyleSheet(f"color: {LEVEL_COLOURS[th.level][0]};")
        warning = h.force_warning()
        if warning != self.force.text():
            self.force.setText(warning)
            self.force.setStyleSheet(f"color: {LEVEL_COLOURS['bad'][0]}; font-weight: 600;")
            self.force.setVisible(bool(warning))
        log = "\n".join(h.fault_log)
        if log != self.log.toPlainText():
            self.log_follow.keep(lambda: self.log.setPlainText(log))


#: The line a Space typed into a setup field shows instead of starting (or becoming part of the code).
SPACE_WHILE_TYPING = "A code or number has no spaces: press Enter to start (Space starts once you leave the field)."


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
        v = setup.values
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
        self.protocol = QLineEdit(v.protocol_path)
        self.protocol.setPlaceholderText("default: the paper's protocol")
        self.protocol_browse = QPushButton("…")
        self.seed = QSpinBox()
        self.seed.setRange(0, 2**31 - 1)
        self.seed.setValue(v.seed)
        self.errors = QLabel()
        self.errors.setWordWrap(True)
        self.errors.setStyleSheet(f"color: {LEVEL_COLOURS['error'][0]};")
        self.warnings = QLabel()
        self.warnings.setWordWrap(True)
        self.warnings.setStyleSheet(f"color: {LEVEL_COLOURS['warning'][0]};")
        self.hint = QLabel()
        self.hint.setWordWrap(True)
        self.hint.setStyleSheet("color: #555555;")
        form = QFormLayout()
        form.addRow("Database", _row(self.db, self.db_browse))
        form.addRow("Participant", self.code)
        form.addRow("Number", self.number)
        form.addRow("Kind", self.kind)
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
        lay.addWidget(self.errors)
        lay.addWidget(self.warnings)
        lay.addWidget(self.hint)
        self.resumable_label = QLabel()
        lay.addWidget(self.resumable_label)
        lay.addWidget(self.resumable)
        lay.addLayout(_row_layout(self.refresh_button, self.resume_button))
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
        self._on_changed()
        self._on_resumable()

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
        if self.seed.value() != v.seed:
            self.seed.setValue(v.seed)
        if self.number.value() != v.participant_number:
            self.number.setValue(v.participant_number)
        self.errors.setText(breakable("\n".join(self.setup.errors.values())))
        self.warnings.setText(breakable("\n".join(self.setup.warnings.values())))
        idle = self.setup.running_session is None
        self.hint.setText(self.setup.hint or ("" if self.setup.errors or not idle else self.setup.next_step()))
        for label in (self.errors, self.warnings, self.hint):
            label.setVisible(bool(label.text()))
        self._show_seed()

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
            self.hint.setText(SPACE_WHILE_TYPING)
            self.hint.setVisible(True)
            return True
        return super().eventFilter(obj, event)

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
