"""Views of the experimenter window, one per model (``Qt<Model>(model)``, napari style)."""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QEvent, Qt, Signal
from PySide6.QtGui import QColor
from PySide6.QtWidgets import (
    QAbstractItemView, QComboBox, QFileDialog, QFormLayout, QGroupBox, QHBoxLayout, QHeaderView, QLabel, QLineEdit,
    QListWidget, QListWidgetItem, QPlainTextEdit, QProgressBar, QPushButton, QSizePolicy, QSpinBox, QTableWidget,
    QTableWidgetItem, QVBoxLayout, QWidget,
)

from study_app.models.app import CUE_ACTIONS, AppModel
from study_app.models.health import HealthModel
from study_app.models.plots import TASK_SERIES, PlotModel
from study_app.models.session import TRIAL_COLUMNS, SessionModel, TrialTable
from study_app.models.setup import KINDS, SetupModel

__all__ = ["ElidedLabel", "QtCueWait", "QtForcePlots", "QtHealthPanel", "QtProgress", "QtSetupPanel", "QtTrialTable"]

# Cosmetic 1-px pens: wider ones are stroked as polygons by Qt's raster engine, ~3x the cost per frame.
RAW_PEN = pg.mkPen((220, 40, 40), width=1)
RENDER_PEN = pg.mkPen((20, 160, 60), width=1)
AXIS_PENS = (pg.mkPen((200, 60, 60), width=1), pg.mkPen((40, 150, 60), width=1), pg.mkPen((40, 80, 200), width=1))
COMP_SERIES = ("comp_fx", "comp_fy", "comp_fz")
_OUTCOME_COLOURS = {"success": QColor(215, 245, 215), "timeout": QColor(250, 235, 205), "aborted": QColor(235, 235, 235)}


class ElidedLabel(QLabel):
    """One line of text that never wraps or widens its column: what does not fit ends in '…', all of it in the tooltip."""

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

    def resizeEvent(self, event):  # noqa: N802 - Qt's name
        super().resizeEvent(event)
        self._elide()

    def _elide(self) -> None:
        self.setText(self.fontMetrics().elidedText(self._full, Qt.TextElideMode.ElideRight, max(0, self.width())))


class QtTrialTable(QTableWidget):
    """The trial table, filled as :class:`TrialTable` rows arrive."""

    def __init__(self, table: TrialTable, parent: QWidget | None = None) -> None:
        super().__init__(0, len(TRIAL_COLUMNS), parent)
        self.table = table
        self.setHorizontalHeaderLabels(list(TRIAL_COLUMNS))
        self.verticalHeader().setVisible(False)
        self.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        header = self.horizontalHeader()
        header.setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        header.setSectionResizeMode(3, QHeaderView.ResizeMode.Stretch)
        table.row_added.connect(self._on_row_added)
        table.cleared.connect(lambda: self.setRowCount(0))

    def _on_row_added(self, i: int) -> None:
        row = self.table.rows[i]
        self.insertRow(i)
        colour = _OUTCOME_COLOURS.get(str(row.outcome))
        for j, text in enumerate(TrialTable.cells(row)):
            item = QTableWidgetItem(text)
            if j != 3:
                item.setTextAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
            if colour is not None:
                item.setBackground(colour)
            self.setItem(i, j, item)
        self.scrollToBottom()


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
    """Progress line and bar of the running session, and a warning line when the force on the tissue is too high."""

    def __init__(self, session: SessionModel, health: HealthModel | None = None, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.session = session
        self.health = health
        self.label = QLabel()
        self.label.setStyleSheet("font-size: 15px; font-weight: 600;")
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
        lay.addWidget(self.label)
        lay.addWidget(self.bar)
        lay.addWidget(self.warning)
        session.changed.connect(self._on_changed)
        if health is not None:
            health.changed.connect(self._on_health)
        self._on_changed()

    def _on_changed(self) -> None:
        self.label.setText(self.session.progress_text())
        self.bar.setValue(int(1000 * self.session.fraction_done()))

    def _on_health(self) -> None:
        text = self.health.force_warning() if self.health is not None else ""
        if text != self.warning.text():
            self.warning.setText(text)
            self.warning.setVisible(bool(text))


#: The task panel's curve; the lower panel's choices (series, pens).
TASK_PEN = pg.mkPen((31, 78, 156), width=1)
LOWER_CHOICES = {
    "raw sensor |F| (tool weight included)": (("raw_n",), (RAW_PEN,)),
    "compensated x, y, z (sensor frame)": (COMP_SERIES, AXIS_PENS),
    "none": ((), ()),
}
BAND_BRUSH = pg.mkBrush(0, 114, 178, 60)
BAND_PEN = pg.mkPen((0, 114, 178), width=1, style=Qt.PenStyle.DashLine)


def _swatch(colour: str, text: str, *, block: bool = False) -> str:
    mark = (f'<span style="background:{colour}">&nbsp;&nbsp;&nbsp;&nbsp;</span>' if block
            else f'<span style="color:{colour}; font-weight:900">━━</span>')
    return f"{mark}&nbsp;{text}"


class QtForcePlots(QWidget):
    """The live force view, built for the task: is the force in the band?

    Top: the task force (|compensated, filtered|, what the trial is judged on) and the force rendered on
    the haptic device, with the target band drawn, on an axis set by the target
    (:meth:`study_app.models.plots.PlotModel.task_axis`); a force above the axis is named.  Below, on its
    own axis, the raw sensor force (tool weight included), the compensated components, or nothing.  The
    legend sits above the plots, never over the data.
    """

    def __init__(self, plots: PlotModel, session: SessionModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        self.plots, self.session = plots, session
        self.legend = QLabel("  ".join((
            _swatch("#1f4e9c", "task force |F| (compensated, filtered)"),
            _swatch("#14a03c", "rendered on the haptic device"),
            _swatch("rgba(0,114,178,0.35)", "target band", block=True),
        )))
        self.lower_choice = QComboBox()
        self.lower_choice.addItems(list(LOWER_CHOICES))
        self.lower_choice.setToolTip("What the lower plot shows, on an axis of its own")
        head = QHBoxLayout()
        head.setContentsMargins(4, 0, 4, 0)
        head.addWidget(self.legend, 1)
        head.addWidget(QLabel("Lower plot:"))
        head.addWidget(self.lower_choice)
        self.view = pg.GraphicsLayoutWidget()
        self.view.setBackground("w")
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.setSpacing(2)
        lay.addLayout(head)
        lay.addWidget(self.view, 1)

        self.task = self.view.addPlot(row=0, col=0)
        self.task.setLabel("left", "force (N)")
        self.band = pg.LinearRegionItem(orientation="horizontal", movable=False, brush=BAND_BRUSH, pen=BAND_PEN)
        self.band.setZValue(-10)
        self.band.setVisible(False)
        self.task.addItem(self.band)
        # on a pale backing, above the traces: a force held just above the band runs through the label
        backing = pg.mkBrush(255, 255, 255, 215)
        self.band_label = pg.TextItem(color=(0, 84, 140), anchor=(1, 1), fill=backing)
        self.clip_label = pg.TextItem(color=(179, 20, 27), anchor=(1, 0), fill=backing)
        for item in (self.band_label, self.clip_label):
            item.setVisible(False)
            item.setZValue(10)
            self.task.addItem(item, ignoreBounds=True)
        self.curves = {"force_n": self.task.plot(pen=TASK_PEN), "render_n": self.task.plot(pen=RENDER_PEN)}
        self.lower = self.view.addPlot(row=1, col=0)
        self.lower.setLabel("bottom", "time (s)")
        self.lower.setXLink(self.task)
        self.view.ci.layout.setRowStretchFactor(0, 3)
        self.view.ci.layout.setRowStretchFactor(1, 1)
        self.lower_curves: dict[str, pg.PlotDataItem] = {}
        # No grid and no auto-range: a translucent grid over the whole view and axes re-rendered every frame
        # made each refresh cost 40-60 ms on a loaded 2-core machine (bench gui); the y ranges come from the
        # models instead and change only in steps.  No SI prefix: "(x0.001)" on a force axis misleads.
        for p in (self.task, self.lower):
            p.setXRange(-plots.window_s, 0.0, padding=0)
            p.setMouseEnabled(x=False, y=False)
            p.enableAutoRange(x=False, y=False)
            p.setClipToView(True)
            p.getAxis("left").enableAutoSIPrefix(False)
            p.getAxis("left").setWidth(48)
        self._y: dict[str, tuple[float, float]] = {}
        self._band: tuple[float, float] | None = None
        self.lower_choice.currentTextChanged.connect(self._set_lower)
        self._set_lower(self.lower_choice.currentText())

    @property
    def lower_series(self) -> tuple[str, ...]:
        """The series the lower plot shows."""
        return LOWER_CHOICES[self.lower_choice.currentText()][0]

    def _set_lower(self, choice: str) -> None:
        for c in self.lower_curves.values():
            self.lower.removeItem(c)
        names, pens = LOWER_CHOICES[choice]
        self.lower_curves = {n: self.lower.plot(pen=pen) for n, pen in zip(names, pens)}
        self.lower.setVisible(bool(names))
        self.lower.setMaximumHeight(10_000 if names else 0)
        self.lower.setLabel("left", "raw |F| (N)" if names == ("raw_n",) else "F (N)")
        self.task.setLabel("bottom", "" if names else "time (s)")
        self.task.getAxis("bottom").setStyle(showValues=not names)  # the time axis is read on the lower plot
        self._y.pop("lower", None)
        self.refresh()

    def _target_n(self) -> float:
        band = self.session.band_for_axis()
        # before the first trial: the scale of the paper's FIRM target
        return 1.2 if band is None else (band[0] + band[1]) / 2

    def _set_y_ranges(self) -> None:
        r = self.plots.task_axis(self._target_n())
        if self._y.get("task") != r:
            self._y["task"] = r
            self.task.setYRange(*r, padding=0)
        names = self.lower_series
        if names:
            r = self.plots.y_range(names, floor_zero=names == ("raw_n",))
            if self._y.get("lower") != r:
                self._y["lower"] = r
                self.lower.setYRange(*r, padding=0)
        top = self._y["task"][1]
        peak = self.plots.peak(TASK_SERIES)
        over = bool(np.isfinite(peak) and peak > top)
        if over:
            self.clip_label.setText(f"peak {peak:.1f} N: above the axis")
            self.clip_label.setPos(0.0, top)
        if over != self.clip_label.isVisible():
            self.clip_label.setVisible(over)

    def refresh(self) -> None:
        """Redraw from the model (the window's 30 Hz timer calls this after a pull)."""
        for name, curve in self.curves.items():
            curve.setData(*self.plots.curve(name), skipFiniteCheck=True)
        for name, curve in self.lower_curves.items():
            curve.setData(*self.plots.curve(name), skipFiniteCheck=True)
        self._set_y_ranges()
        band = self.session.band()
        if band != self._band:
            self._band = band
            self.band.setVisible(band is not None)
            self.band_label.setVisible(band is not None)
            if band is not None:
                self.band.setRegion(band)
                self.band_label.setText(self.session.band_label())
                self.band_label.setPos(0.0, band[1])


class QtHealthPanel(QWidget):
    """Devices (state, rate, sample age), faults with a Reset button, loop timing judged against its limits."""

    COLUMNS = ("Device", "State", "Rate (Hz)", "Sample age (ms)")

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
        self.reset_button = QPushButton("Reset faults")
        self.loop = QLabel()
        self.loop.setTextFormat(Qt.TextFormat.RichText)
        self.loop.setWordWrap(True)
        self.thermal = QLabel()
        self.force = QLabel()
        self.force.setWordWrap(True)
        self.force.hide()
        self.log_label = QLabel("Fault log (newest last; a fault latches until Reset faults):")
        self.log = QPlainTextEdit()
        self.log.setReadOnly(True)
        self.log.setMaximumHeight(80)
        self.log.setPlaceholderText("no fault since the engine started")
        row = QHBoxLayout()
        row.addWidget(self.faults, 1)
        row.addWidget(self.reset_button)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(4, 4, 4, 4)
        lay.addWidget(self.devices)
        lay.addLayout(row)
        lay.addWidget(self.loop)
        lay.addWidget(self.thermal)
        lay.addWidget(self.force)
        lay.addWidget(self.log_label)
        lay.addWidget(self.log)
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
                if j == 1:
                    item.setForeground(QColor(20, 130, 40) if d.state.startswith("ok") else QColor(200, 30, 30))
        text = h.faults_text()
        waiting = h.waiting_text()
        self.faults.setText(f"Faults: {text}" + (f" — the next cue waits: {waiting}" if waiting else ""))
        self.faults.setStyleSheet("color: #c81e1e; font-weight: 600;" if h.faults else "color: #147f28;")
        self.reset_button.setEnabled(bool(h.faults))
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
            self.log.setPlainText(log)


class QtSetupPanel(QGroupBox):
    """Session setup form and the list of interrupted sessions to resume.

    Space in the code, number, kind or seed field starts (``start_requested``), as everywhere else in the
    window: a code has no spaces, so a Space typed there can only mean Start.
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
        lay.addWidget(QLabel("Interrupted sessions"))
        lay.addWidget(self.resumable)
        lay.addLayout(_row_layout(self.refresh_button, self.resume_button))
        self.db.editingFinished.connect(lambda: setup.update(db_path=self.db.text()))
        self.code.textChanged.connect(lambda t: setup.update(code=t))
        self.number.valueChanged.connect(lambda n: setup.set_number(int(n)))
        self.number.setToolTip("Sets the counterbalanced trial order: suggested from the database (the code's own "
                               "number, or the next free one) until you change it")
        for w in (self.code, self.number, self.kind, self.seed):
            w.installEventFilter(self)
        self.kind.currentTextChanged.connect(lambda k: setup.update(kind=k))
        self.protocol.editingFinished.connect(lambda: setup.update(protocol_path=self.protocol.text()))
        self.seed.valueChanged.connect(lambda n: setup.update(seed=int(n)))
        self.db_browse.clicked.connect(self._browse_db)
        self.protocol_browse.clicked.connect(self._browse_protocol)
        setup.changed.connect(self._on_changed)
        setup.resumable_changed.connect(self._on_resumable)
        self._on_changed()

    def _browse_db(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self, "Study database", self.db.text(), "SQLite (*.db *.sqlite);;All files (*)",
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
        self.errors.setText("\n".join(self.setup.errors.values()))
        self.warnings.setText("\n".join(self.setup.warnings.values()))
        self.hint.setText(self.setup.hint)
        for label in (self.errors, self.warnings, self.hint):
            label.setVisible(bool(label.text()))

    def eventFilter(self, obj, event) -> bool:  # noqa: N802 - Qt's name
        if (event.type() == QEvent.Type.KeyPress and event.key() == Qt.Key.Key_Space
                and not event.modifiers() & ~Qt.KeyboardModifier.KeypadModifier):
            self.start_requested.emit()
            return True
        return super().eventFilter(obj, event)

    def _on_resumable(self) -> None:
        self.resumable.clear()
        for s in self.setup.resumable:
            text = SetupModel.describe_resumable(s)
            item = QListWidgetItem(text)
            item.setToolTip(text)
            item.setData(Qt.ItemDataRole.UserRole, int(s["session_id"]))  # type: ignore[arg-type]
            self.resumable.addItem(item)
            if int(s["session_id"]) == self.setup.default_resume():  # type: ignore[call-overload]
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
