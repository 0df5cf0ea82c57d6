"""Views of the experimenter window, one per model (``Qt<Model>(model)``, napari style)."""

from __future__ import annotations

import pyqtgraph as pg
from PySide6.QtCore import Qt
from PySide6.QtGui import QColor
from PySide6.QtWidgets import (
    QAbstractItemView, QComboBox, QFileDialog, QFormLayout, QGroupBox, QHBoxLayout, QHeaderView, QLabel, QLineEdit,
    QListWidget, QListWidgetItem, QPlainTextEdit, QProgressBar, QPushButton, QSpinBox, QTableWidget, QTableWidgetItem,
    QVBoxLayout, QWidget,
)

from study_app.models.health import HealthModel
from study_app.models.plots import PlotModel
from study_app.models.session import TRIAL_COLUMNS, SessionModel, TrialTable
from study_app.models.setup import KINDS, SetupModel

__all__ = ["QtForcePlots", "QtHealthPanel", "QtProgress", "QtSetupPanel", "QtTrialTable"]

# Cosmetic 1-px pens: wider ones are stroked as polygons by Qt's raster engine, ~3x the cost per frame.
RAW_PEN = pg.mkPen((220, 40, 40), width=1)
COMP_PEN = pg.mkPen((30, 90, 220), width=1)
RENDER_PEN = pg.mkPen((20, 160, 60), width=1)
AXIS_PENS = (pg.mkPen((200, 60, 60), width=1), pg.mkPen((40, 150, 60), width=1), pg.mkPen((40, 80, 200), width=1))
#: Series on each plot, and whether its axis starts at zero (magnitudes).
MAG_SERIES = ("raw_n", "comp_n", "render_n")
COMP_SERIES = ("comp_fx", "comp_fy", "comp_fz")
_OUTCOME_COLOURS = {"success": QColor(215, 245, 215), "timeout": QColor(250, 235, 205), "aborted": QColor(235, 235, 235)}


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
        colour = _OUTCOME_COLOURS.get(str(row["outcome"]))
        for j, text in enumerate(TrialTable.cells(row)):
            item = QTableWidgetItem(text)
            if j != 3:
                item.setTextAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
            if colour is not None:
                item.setBackground(colour)
            self.setItem(i, j, item)
        self.scrollToBottom()


class QtProgress(QWidget):
    """Progress line and bar of the running session."""

    def __init__(self, session: SessionModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.session = session
        self.label = QLabel()
        self.label.setStyleSheet("font-size: 15px; font-weight: 600;")
        self.bar = QProgressBar()
        self.bar.setRange(0, 1000)
        self.bar.setTextVisible(False)
        self.bar.setMaximumHeight(10)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(4, 2, 4, 2)
        lay.addWidget(self.label)
        lay.addWidget(self.bar)
        session.changed.connect(self._on_changed)
        self._on_changed()

    def _on_changed(self) -> None:
        self.label.setText(self.session.progress_text())
        self.bar.setValue(int(1000 * self.session.fraction_done()))


class QtForcePlots(pg.GraphicsLayoutWidget):
    """Fig. 6-style force magnitudes and the compensated components, redrawn from :class:`PlotModel`."""

    def __init__(self, plots: PlotModel, session: SessionModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setBackground("w")
        self.plots, self.session = plots, session
        self.mag = self.addPlot(row=0, col=0)
        self.mag.setTitle("Force magnitude", size="10pt")
        self.mag.setLabel("left", "|F| (N)")
        self.mag.addLegend(offset=(-10, 10))
        self.band = pg.LinearRegionItem(orientation="horizontal", movable=False, brush=pg.mkBrush(255, 190, 0, 70),
                                        pen=pg.mkPen(None))
        self.band.setZValue(-10)
        self.band.setVisible(False)
        self.mag.addItem(self.band)
        self.curves = {
            "raw_n": self.mag.plot(pen=RAW_PEN, name="raw (sensor)"),
            "comp_n": self.mag.plot(pen=COMP_PEN, name="compensated"),
            "render_n": self.mag.plot(pen=RENDER_PEN, name="rendered (haptic)"),
        }
        self.comp = self.addPlot(row=1, col=0)
        self.comp.setTitle("Compensated force, sensor frame", size="10pt")
        self.comp.setLabel("left", "F (N)")
        self.comp.setLabel("bottom", "time (s)")
        self.comp.addLegend(offset=(-10, 10))
        self.comp.setXLink(self.mag)
        for name, pen, label in zip(("comp_fx", "comp_fy", "comp_fz"), AXIS_PENS, ("x", "y", "z")):
            self.curves[name] = self.comp.plot(pen=pen, name=label)
        # No grid and no auto-range: a translucent grid over the whole view and axes re-rendered every frame
        # made each refresh cost 40-60 ms on a loaded 2-core machine (bench gui); the y range comes from the
        # model instead, snapped so it changes only when the data crosses a step.
        self._y: dict[str, tuple[float, float]] = {}
        for p in (self.mag, self.comp):
            p.setXRange(-plots.window_s, 0.0, padding=0)
            p.setMouseEnabled(x=False, y=False)
            p.enableAutoRange(x=False, y=False)
            p.setClipToView(True)
        self._set_y_ranges()

    def _set_y_ranges(self) -> None:
        band = self.session.band() or ()
        for key, plot, names, zero, extra in (("mag", self.mag, MAG_SERIES, True, band),
                                              ("comp", self.comp, COMP_SERIES, False, ())):
            r = self.plots.y_range(names, floor_zero=zero, include=extra)
            if self._y.get(key) != r:
                self._y[key] = r
                plot.setYRange(*r, padding=0)

    def refresh(self) -> None:
        """Redraw from the model (the window's 30 Hz timer calls this after a pull)."""
        for name, curve in self.curves.items():
            t, y = self.plots.curve(name)
            curve.setData(t, y, skipFiniteCheck=True)
        self._set_y_ranges()
        band = self.session.band()
        self.band.setVisible(band is not None)
        if band is not None:
            self.band.setRegion(band)


class QtHealthPanel(QWidget):
    """Devices (state, rate, sample age), faults with a Reset button, loop timing."""

    COLUMNS = ("Device", "State", "Rate (Hz)", "Sample age (ms)")

    def __init__(self, health: HealthModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.health = health
        self.devices = QTableWidget(0, len(self.COLUMNS))
        self.devices.setHorizontalHeaderLabels(list(self.COLUMNS))
        self.devices.verticalHeader().setVisible(False)
        self.devices.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.devices.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Stretch)
        self.devices.setMaximumHeight(120)
        self.faults = QLabel()
        self.reset_button = QPushButton("Reset faults")
        self.loop = QLabel()
        self.log = QPlainTextEdit()
        self.log.setReadOnly(True)
        self.log.setMaximumHeight(80)
        row = QHBoxLayout()
        row.addWidget(self.faults, 1)
        row.addWidget(self.reset_button)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(4, 4, 4, 4)
        lay.addWidget(self.devices)
        lay.addLayout(row)
        lay.addWidget(self.loop)
        lay.addWidget(self.log)
        health.changed.connect(self._on_changed)
        self._on_changed()

    def _on_changed(self) -> None:
        h = self.health
        self.devices.setRowCount(len(h.devices))
        for i, d in enumerate(h.devices):
            cells = (d.name, d.state, f"{d.rate_hz:.0f}", f"{d.age_ms:.1f}")
            for j, text in enumerate(cells):
                item = self.devices.item(i, j)
                if item is None:
                    item = QTableWidgetItem()
                    self.devices.setItem(i, j, item)
                item.setText(text)
                if j == 1:
                    item.setForeground(QColor(20, 130, 40) if d.state == "ok" else QColor(200, 30, 30))
        text = h.faults_text()
        self.faults.setText(f"Faults: {text}")
        self.faults.setStyleSheet("color: #c81e1e; font-weight: 600;" if h.faults else "color: #147f28;")
        self.reset_button.setEnabled(bool(h.faults))
        self.loop.setText(h.loop_text())
        log = "\n".join(h.fault_log)
        if log != self.log.toPlainText():
            self.log.setPlainText(log)


class QtSetupPanel(QGroupBox):
    """Session setup form and the list of interrupted sessions to resume."""

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
        self.errors.setStyleSheet("color: #c81e1e;")
        form = QFormLayout()
        form.addRow("Database", _row(self.db, self.db_browse))
        form.addRow("Participant", self.code)
        form.addRow("Number", self.number)
        form.addRow("Kind", self.kind)
        form.addRow("Protocol", _row(self.protocol, self.protocol_browse))
        form.addRow("Seed", self.seed)
        self.resumable = QListWidget()
        self.resumable.setMaximumHeight(90)
        self.refresh_button = QPushButton("Refresh")
        self.resume_button = QPushButton("Resume selected")
        lay = QVBoxLayout(self)
        lay.addLayout(form)
        lay.addWidget(self.errors)
        lay.addWidget(QLabel("Interrupted sessions"))
        lay.addWidget(self.resumable)
        lay.addLayout(_row_layout(self.refresh_button, self.resume_button))
        self.db.editingFinished.connect(lambda: setup.update(db_path=self.db.text()))
        self.code.textChanged.connect(lambda t: setup.update(code=t))
        self.number.valueChanged.connect(lambda n: setup.update(participant_number=int(n)))
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

    def _on_resumable(self) -> None:
        self.resumable.clear()
        for s in self.setup.resumable:
            item = QListWidgetItem(SetupModel.describe_resumable(s))
            item.setData(Qt.ItemDataRole.UserRole, int(s["session_id"]))  # type: ignore[arg-type]
            self.resumable.addItem(item)

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
