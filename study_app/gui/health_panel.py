"""The Devices & health tab: each device's state, rate and sample age, the faults with their Reset button, why
the next cue waits, the machine's health in words, the loop's timing judged against its limits, and the fault log."""

from __future__ import annotations

import html

from PySide6.QtCore import Qt
from PySide6.QtGui import QColor
from PySide6.QtWidgets import (
    QAbstractItemView,
    QFrame,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QPlainTextEdit,
    QPushButton,
    QScrollArea,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from study_app.gui.widgets import LEVEL_COLOURS, FollowNewest
from study_app.models.health import HealthModel

__all__ = ["QtHealthPanel"]


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
        self.placement = QLabel()  # where the loop runs: its own process, its CPU, its priority
        self.placement.setWordWrap(True)
        self.latency = QLabel()  # the end-to-end latency: its totals, then its stages one a line
        self.latency.setWordWrap(True)
        self.latency.setTextFormat(Qt.TextFormat.RichText)
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
        lay.addWidget(self.placement)
        lay.addWidget(self.latency)
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

    def latency_html(self) -> str:
        """The end-to-end latency: its totals, and below them its breakdown by stage in small type ("" when the
        engine does not say)."""
        total = self.health.latency_text()
        if not total:
            return ""
        stages = "<br>".join(html.escape(line) for line in self.health.latency_stages())
        return f"{html.escape(total)}<br><small>{stages}</small>"

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
        self.placement.setText(h.placement_text())
        latency = self.latency_html()
        if latency != self.latency.text():
            self.latency.setText(latency)
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
