"""Views of the running session in the experimenter window, one per model (``Qt<Model>(model)``, napari style):
what happens now and how far the session is, why the next cue waits, and the trial table."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtGui import QColor
from PySide6.QtWidgets import (
    QAbstractItemView,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QProgressBar,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from protocol.study.records import Outcome
from study_app.gui.widgets import LEVEL_COLOURS, ElidedLabel, FollowNewest
from study_app.models.cue_wait import CUE_ACTIONS, CueWaitModel, headline
from study_app.models.health import HealthModel
from study_app.models.session import TRIAL_COLUMNS, SessionModel, TrialTable

__all__ = ["QtCueWait", "QtProgress", "QtSessionNotes", "QtTrialTable"]

_OUTCOME_COLOURS = {"success": QColor(215, 245, 215), "timeout": QColor(250, 235, 205),
                    "aborted": QColor(235, 235, 235)}
#: What the Outcome column must show whole: its header and each outcome.
_OUTCOME_WORDS = ("Outcome", *(str(o) for o in Outcome))


class QtTrialTable(QTableWidget):
    """The trial table, filled as :class:`TrialTable` rows arrive; the newest row stays in view
    (:class:`FollowNewest`)."""

    def __init__(self, table: TrialTable, parent: QWidget | None = None) -> None:
        super().__init__(0, len(TRIAL_COLUMNS), parent)
        self.table = table
        self._set_columns()
        self.verticalHeader().setVisible(False)
        self.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.setTextElideMode(Qt.TextElideMode.ElideRight)
        self.setWordWrap(False)  # one line per trial: more rows in view; a long cell is elided, its tooltip whole
        self.follow = FollowNewest(self)
        table.row_added.connect(self._on_row_added)
        table.cleared.connect(self._on_cleared)
        table.note_added.connect(self._on_note_added)

    @property
    def note_column(self) -> int:
        """The column of the experimenter's notes (the last: the columns are the session's task's)."""
        return len(self.table.columns) - 1

    def _set_columns(self) -> None:
        """The session's task's columns (:func:`study_app.models.session.trial_columns`)."""
        cols = self.table.columns
        self.setColumnCount(len(cols))
        self.setHorizontalHeaderLabels(list(cols))
        header = self.horizontalHeader()
        header.setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        # The outcome is as wide as its header and its longest word, not its text (an abort's reason is elided; its
        # tooltip has it), and the notes at least 16 letters wide, taking the room left: stretched, both were
        # squeezed below their headers ("utcom") in a narrow window; now the table scrolls sideways instead.
        em = header.fontMetrics().horizontalAdvance("M")
        for j, width in ((3, max(header.fontMetrics().horizontalAdvance(w) for w in _OUTCOME_WORDS) + 3 * em),
                         (len(cols) - 1, 16 * em)):
            header.setSectionResizeMode(j, QHeaderView.ResizeMode.Interactive)
            header.resizeSection(j, width)
        header.setStretchLastSection(True)

    def _on_cleared(self) -> None:
        self.setRowCount(0)
        self._set_columns()
        self.follow.following = True

    def _on_row_added(self, i: int) -> None:
        row = self.table.rows[i]
        self.insertRow(i)
        colour = _OUTCOME_COLOURS.get(str(row.outcome))
        designed = None if row.repeat_of is None else self.table.designed_of(row.repeat_of)
        for j, text in enumerate(self.table.cells(row, designed)):
            item = QTableWidgetItem(text)
            item.setToolTip(text)  # an abort's reason may be longer than its column
            if j not in (3, self.note_column):
                item.setTextAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
            if colour is not None:
                item.setBackground(colour)
            self.setItem(i, j, item)
        self.follow.to_end()

    def _on_note_added(self, i: int | None) -> None:
        """A note on a trial that has its row: the row's Note shows it (a session's notes are above the table)."""
        if i is None or i >= self.rowCount():
            return
        item = self.item(i, self.note_column)
        text = self.table.note_text(self.table.rows[i].trial_index)
        if item is not None:
            item.setText(text)
            item.setToolTip(text)


class QtSessionNotes(QLabel):
    """Above the trial table: the experimenter's notes on the session itself (hidden while there is none)."""

    def __init__(self, table: TrialTable, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.table = table
        self.setWordWrap(True)
        self.setContentsMargins(6, 0, 6, 0)
        self.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        table.note_added.connect(lambda _i: self._show())
        table.cleared.connect(self._show)
        self._show()

    def _show(self) -> None:
        text = self.table.note_text(None)
        self.setText(f"Notes on the session: {text}" if text else "")
        self.setVisible(bool(text))


class QtCueWait(QWidget):
    """Above the trial table: why the next cue waits, for how long, and the button that ends the wait."""

    def __init__(self, model: CueWaitModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.model, self._actions = model, CUE_ACTIONS
        #: The explanation folded into the headline's tooltip (:meth:`fold`): the tab is too short for it and rows.
        self.folded = False
        self.label = QLabel()
        self.label.setWordWrap(True)
        self.help = QLabel()
        self.help.setWordWrap(True)
        self.button = QPushButton()
        self.button.setFocusPolicy(Qt.FocusPolicy.NoFocus)  # Space stays Start / Resume
        self.button.clicked.connect(model.end)
        text = QVBoxLayout()
        text.setContentsMargins(0, 0, 0, 0)
        text.setSpacing(0)
        text.addWidget(self.label)
        text.addWidget(self.help)
        lay = QHBoxLayout(self)
        lay.setContentsMargins(6, 3, 6, 3)
        lay.addLayout(text, 1)
        lay.addWidget(self.button, 0, Qt.AlignmentFlag.AlignTop)
        model.changed.connect(self._on_changed)
        self._on_changed()

    def _on_changed(self) -> None:
        w = self.model.wait
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
        self.help.setVisible(bool(w.help) and not self.folded)
        self.label.setToolTip(w.help if self.folded else "")
        self.button.setText(self._actions.get(w.action, ""))
        self.button.setVisible(bool(w.action))
        self._fit()

    def resizeEvent(self, event) -> None:  # Qt's name
        super().resizeEvent(event)
        self._fit()

    def fold(self, folded: bool) -> None:
        """Show the explanation under the headline, or keep it in the headline's tooltip (the headline, the seconds
        left and the button stay)."""
        if folded != self.folded:
            self.folded = folded
            self._on_changed()

    def unfolded_height(self) -> int:
        """The banner's height with its explanation shown, at its width."""
        extra = 0 if not self.folded or not self.help.text() else self.help.heightForWidth(max(1, self.label.width()))
        return self.sizeHint().height() + extra

    def _fit(self) -> None:
        """Each wrapped line as tall as its text at its width: a nested layout sized a long reason for a wider
        label and cut its last line ("… check the machine's load and the" without "devices, then Resume")."""
        for label in (self.label, self.help):
            height = label.heightForWidth(label.width()) if label.isVisibleTo(self) and label.width() > 0 else 0
            if height != label.minimumHeight():
                label.setMinimumHeight(max(0, height))


class QtProgress(QWidget):
    """What happens now (the trial and its time left, the pause), the session's count and time left with a bar
    of the designed trials done, and a warning line when the force on the tissue is too high."""

    def __init__(self, session: SessionModel, health: HealthModel | None = None, parent: QWidget | None = None,
                 *, cue: CueWaitModel | None = None) -> None:
        super().__init__(parent)
        self.session = session
        self.health = health
        #: Why the next cue waits (the banner's model): the headline says the same (None: the session alone).
        self.cue = cue
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
        if cue is not None:
            cue.changed.connect(self._on_changed)
        self._on_changed()

    def _on_changed(self) -> None:
        self.label.set_full_text(headline(self.session, self.cue.wait if self.cue is not None else None))
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


class TrialsTab(QWidget):
    """The Trials tab: the session's count, why the next cue waits, the session's notes and the trial table.

    Seen at 1366×768 with the participant screen beside the window: the waiting banner's explanation (three lines)
    left the table one row, the trial just aborted half under it.  When the tab cannot hold the banner whole and
    the table's header and three rows, the banner folds its explanation into its headline's tooltip."""

    #: Rows of the table kept in view before the banner's explanation is.
    ROWS_KEPT = 3

    def __init__(self, count: QWidget, cue_wait: QtCueWait, notes: QWidget, table: QtTrialTable) -> None:
        super().__init__()
        self.count, self.cue_wait, self.notes, self.table = count, cue_wait, notes, table
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.setSpacing(2)
        for w in (count, cue_wait, notes):
            lay.addWidget(w)
        lay.addWidget(table, 1)
        cue_wait.model.changed.connect(self._fold)

    def resizeEvent(self, event) -> None:  # Qt's name
        super().resizeEvent(event)
        self._fold()

    def _fold(self) -> None:
        table = self.table
        row_px = table.verticalHeader().defaultSectionSize()
        rows = table.horizontalHeader().sizeHint().height() + self.ROWS_KEPT * row_px
        above = sum(w.sizeHint().height() + 2 for w in (self.count, self.notes) if w.isVisibleTo(self))
        room = self.height() - above - rows - 2 * table.frameWidth()
        self.cue_wait.fold(self.cue_wait.isVisibleTo(self) and self.cue_wait.unfolded_height() > room)
