"""The live force view: is the force in the band?  Nothing is ever drawn over the data.

Every label and legend sits outside the plots' data areas: the legend of the
upper plot above it, the target band's words and a force above the axis in
the upper plot's title line, the lower plot's legend (each of its curves, by
colour) in its own title line.  The data areas hold only the curves, the
band and the cue's line, so the newest seconds at the right edge are never hidden.

The window holds the last 10 s, so for seconds after a cue it still shows the previous trial's force: the cue
is marked by a vertical line, the target band is drawn from the cue on only, and a force above the axis is
judged on the samples since the cue (:attr:`study_app.models.session.SessionModel.cue_t_s`).
"""

from __future__ import annotations

import html
import math

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QSize, Qt
from PySide6.QtGui import QResizeEvent
from PySide6.QtWidgets import QComboBox, QHBoxLayout, QLabel, QVBoxLayout, QWidget

from study_app.models.plots import TASK_SERIES, PlotModel
from study_app.models.session import SessionModel

__all__ = ["LOWER_CHOICES", "LOWER_PLOT_MIN_PX", "UPPER_PLOT_MIN_PX", "QtForcePlots"]

# Cosmetic 1-px pens: wider ones are stroked as polygons by Qt's raster engine, ~3x the cost per frame.
RAW_COLOUR, RENDER_COLOUR, TASK_COLOUR = "#dc2828", "#14a03c", "#1f4e9c"
AXIS_COLOURS = ("#c83c3c", "#28963c", "#2850c8")
RAW_PEN = pg.mkPen(RAW_COLOUR, width=1)
RENDER_PEN = pg.mkPen(RENDER_COLOUR, width=1)
TASK_PEN = pg.mkPen(TASK_COLOUR, width=1)
AXIS_PENS = tuple(pg.mkPen(c, width=1) for c in AXIS_COLOURS)
#: The other arms' task force (a rig of several arms), one colour per arm after the task arm.
ARM_COLOURS = ("#e07b00", "#8e44ad", "#6b4f2a")
COMP_SERIES = ("comp_fx", "comp_fy", "comp_fz")
#: The lower panel's choices: (series, pens, legend entries (colour, words), axis label).
LOWER_CHOICES: dict[str, tuple[tuple[str, ...], tuple[object, ...], tuple[tuple[str, str], ...], str]] = {
    "raw sensor |F| (tool weight included)": (
        ("raw_n",), (RAW_PEN,), ((RAW_COLOUR, "raw sensor |F| (the tool's weight included)"),), "raw |F| (N)"),
    "compensated x, y, z (sensor frame)": (
        COMP_SERIES, AXIS_PENS, tuple(zip(AXIS_COLOURS, ("compensated Fx", "Fy", "Fz (sensor frame)"), strict=True)),
        "F (N)"),
    "none": ((), (), (), ""),
}
BAND_RGB = (0, 114, 178)
BAND_BRUSH = pg.mkBrush(*BAND_RGB, 60)
BAND_PEN = pg.mkPen(BAND_RGB, width=1, style=Qt.PenStyle.DashLine)
#: Points the band is drawn through from the cue to now (a band that moves is asked of its task at each).
_BAND_POINTS = 121
CUE_COLOUR = "#444444"
#: Dashed: a solid dark line looked like the task force's steep edges.
CUE_PEN = pg.mkPen(CUE_COLOUR, width=1, style=Qt.PenStyle.DashLine)
#: A title line that says nothing still takes its height, so the plots never jump as it fills and empties.
_BLANK = "&nbsp;"


def _swatch(colour: str, text: str, *, block: bool = False) -> str:
    mark = (f'<span style="background:{colour}">&nbsp;&nbsp;&nbsp;&nbsp;</span>' if block
            else f'<span style="color:{colour}; font-weight:900">━━</span>')
    return f"{mark}&nbsp;{html.escape(text)}"


#: The least height of each plot's data area, px: the splitter above the trial table never squashes a plot past
#: reading (its axis title would run into the other plot's, or be cut: "raw |F| (N)" takes 75 px).
UPPER_PLOT_MIN_PX = 100
LOWER_PLOT_MIN_PX = 80


class QtForcePlots(QWidget):
    """The live force view, built for the task: is the force in the band?

    Top: the task force (|compensated, filtered|, what the trial is judged on) and the force rendered on
    the haptic device, with the target band drawn (on a rig of several arms also each other arm's force, one
    colour per arm, the task arm marked in the legend), on an axis set by the target
    (:meth:`study_app.models.plots.PlotModel.task_axis`); the band's words and a force above the axis are
    named in the plot's title line.  Below, on its own axis, the raw sensor force (tool weight included),
    the compensated components (with their legend in the title line), or nothing.
    """

    def __init__(self, plots: PlotModel, session: SessionModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        self.plots, self.session = plots, session
        self.legend = QLabel()
        self.legend.setWordWrap(True)
        self._legend_height = -1  # as last wrapped (minimumSizeHint)
        #: A rig of several arms: each other arm's force curve in the upper plot (name → curve).
        self.arm_curves: dict[str, pg.PlotDataItem] = {}
        self._arms_shown: tuple[str, ...] | None = None
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

        self.task: pg.PlotItem = self.view.addPlot(row=0, col=0)
        self.task.setLabel("left", "force (N)")
        # the band from the current trial's cue to now, where it was at each moment (a tracked target's moves; not
        # across the window: its left part is the last trial): its lower and upper edge, dashed, filled between
        self.band_lo = pg.PlotDataItem(pen=BAND_PEN)
        self.band_hi = pg.PlotDataItem(pen=BAND_PEN)
        self.band = pg.FillBetweenItem(self.band_lo, self.band_hi, brush=BAND_BRUSH)
        self.cue_line = pg.InfiniteLine(angle=90, movable=False, pen=CUE_PEN)
        for item in (self.band, self.band_lo, self.band_hi, self.cue_line):
            item.setZValue(-10)
            item.setVisible(False)
            self.task.addItem(item)
        self.curves = {"force_n": self.task.plot(pen=TASK_PEN), "render_n": self.task.plot(pen=RENDER_PEN)}
        self.lower_plot: pg.PlotItem = self.view.addPlot(row=1, col=0)  # (not "lower": QWidget.lower() exists)
        self.lower_plot.setLabel("bottom", "time (s)")
        self.lower_plot.setXLink(self.task)
        self.view.ci.layout.setRowStretchFactor(0, 3)
        self.view.ci.layout.setRowStretchFactor(1, 1)
        self.task.getViewBox().setMinimumHeight(UPPER_PLOT_MIN_PX)
        self.lower_curves: dict[str, pg.PlotDataItem] = {}
        # No grid and no auto-range: a translucent grid over the whole view and axes re-rendered every frame
        # made each refresh cost 40-60 ms on a loaded 2-core machine (bench gui); the y ranges come from the
        # models instead and change only in steps.  No SI prefix: "(x0.001)" on a force axis misleads.
        for p in (self.task, self.lower_plot):
            p.setXRange(-plots.window_s, 0.0, padding=0)
            p.setMouseEnabled(x=False, y=False)
            p.enableAutoRange(x=False, y=False)
            p.setClipToView(True)
            p.hideButtons()  # pyqtgraph's "A" button sits in the data area's corner
            p.getAxis("left").enableAutoSIPrefix(False)
            p.getAxis("left").setWidth(48)
        self._y: dict[str, tuple[float, float]] = {}
        #: The upper plot's title line as shown (the band's words; a force above the axis).
        self.title_text = ""
        self._title_html = ""
        self.task.setTitle(_BLANK, justify="left", size="9pt")
        self.lower_choice.currentTextChanged.connect(self._set_lower)
        self._set_arms()
        self._set_lower(self.lower_choice.currentText())

    def minimumSizeHint(self) -> QSize:  # Qt's name
        """The layout's least size with the legend as tall as it wraps at its width: the layout counts a wrapped
        label as one line, so a splitter dragged to the top ran the plots' time axis past this widget's bottom."""
        hint = super().minimumSizeHint()
        wrapped = self.legend.heightForWidth(self.legend.width()) if self.legend.width() > 0 else -1
        return QSize(hint.width(), hint.height() + max(0, wrapped - self.legend.minimumSizeHint().height()))

    def resizeEvent(self, event: QResizeEvent) -> None:  # Qt's name
        super().resizeEvent(event)
        self._legend_wrapped()

    def _legend_wrapped(self) -> None:
        """Tell the layouts above when the legend's wrapped height changed (a new width or new words)."""
        height = self.legend.heightForWidth(self.legend.width())
        if height != self._legend_height:
            self._legend_height = height
            self.updateGeometry()

    def legend_entries(self) -> list[str]:
        """The upper plot's legend, in words; on a rig of several arms a second line names each arm's curve, the one
        drawn as the task force marked (the engine's first arm: the protocol's task arm once a session starts, since
        Start puts it first; before that it may be another)."""
        out = ["task force |F| (compensated, filtered)", "rendered on the haptic device", "target band", "cue"]
        if self.plots.arms:
            out += [f"{self.plots.task_arm} (task force)", *self.plots.arms]
        return out

    def _set_arms(self) -> None:
        """One curve per other arm in the upper plot, and the legend naming every arm (when the arms change)."""
        names = tuple(self.plots.arms)
        if names == self._arms_shown:
            return
        self._arms_shown = names
        for c in self.arm_curves.values():
            self.task.removeItem(c)
        colours = dict(zip(names, ARM_COLOURS, strict=False))
        self.arm_curves = {n: self.task.plot(pen=pg.mkPen(colours.get(n, "#555"), width=1)) for n in names}
        words = self.legend_entries()
        text = "  ".join((_swatch(TASK_COLOUR, words[0]), _swatch(RENDER_COLOUR, words[1]),
                          _swatch("rgba(0,114,178,0.35)", words[2], block=True),
                          f'<span style="color:{CUE_COLOUR}; font-weight:900">┆</span>&nbsp;{html.escape(words[3])}'))
        if names:  # each arm's force by its colour: the task arm's is the task force
            marks = [TASK_COLOUR, *(colours.get(n, "#555") for n in names)]
            text += "<br>each arm's |F|: " + "  ".join(_swatch(c, w) for c, w in zip(marks, words[4:], strict=True))
        self.legend.setText(text)
        self._legend_wrapped()

    @property
    def lower_series(self) -> tuple[str, ...]:
        """The series the lower plot shows."""
        return LOWER_CHOICES[self.lower_choice.currentText()][0]

    def lower_legend(self) -> list[str]:
        """The lower plot's legend entries, in the order of its curves (empty when it shows nothing)."""
        return [words for _, words in LOWER_CHOICES[self.lower_choice.currentText()][2]]

    def _set_lower(self, choice: str) -> None:
        for c in self.lower_curves.values():
            self.lower_plot.removeItem(c)
        names, pens, legend, axis = LOWER_CHOICES[choice]
        self.lower_curves = {n: self.lower_plot.plot(pen=pen) for n, pen in zip(names, pens, strict=True)}
        self.lower_plot.setVisible(bool(names))
        self.lower_plot.setMaximumHeight(10_000 if names else 0)
        self.lower_plot.setLabel("left", axis)
        # the legend in the title line, outside the data: every curve by its colour
        self.lower_plot.setTitle("&nbsp;&nbsp;".join(_swatch(c, w) for c, w in legend) or _BLANK, justify="left",
                            size="9pt")
        self.task.setLabel("bottom", "" if names else "time (s)")
        self.task.getAxis("bottom").setStyle(showValues=not names)  # the time axis is read on the lower plot
        self.lower_plot.getViewBox().setMinimumHeight(LOWER_PLOT_MIN_PX if names else 0)
        # the widget asks for what its plots need now (the data areas with their titles and axes), so no splitter
        # or layout gives it less
        self.view.setMinimumHeight(math.ceil(self.view.ci.effectiveSizeHint(Qt.SizeHint.MinimumSize).height()))
        self._y.pop("lower", None)
        self.refresh()

    def _target_n(self) -> float:
        band = self.session.band_for_axis()
        # before the first trial: the scale of the paper's FIRM target
        return 1.2 if band is None else (band[0] + band[1]) / 2

    def _set_y_ranges(self) -> str:
        """Set the axes; returns the words for a force above the upper axis ("" when there is none), judged on the
        samples since the current trial's cue (the window's older samples are the previous trial's)."""
        since = self.session.cue_t_s
        r = self.plots.task_axis(self._target_n(), since)
        if self._y.get("task") != r:
            self._y["task"] = r
            self.task.setYRange(*r, padding=0)
        names = self.lower_series
        if names:
            r = self.plots.y_range(names, floor_zero=names == ("raw_n",))
            if self._y.get("lower") != r:
                self._y["lower"] = r
                self.lower_plot.setYRange(*r, padding=0)
        top = self._y["task"][1]
        peak = self.plots.peak(TASK_SERIES, since)
        over = [f"peak {peak:.1f} N: above the axis"] if bool(np.isfinite(peak) and peak > top) else []
        for name, arm in self.plots.arms.items():
            p = arm.peak(("force_n",), since)
            if bool(np.isfinite(p) and p > top):
                over.append(f"arm {name} peak {p:.1f} N: above the axis")
        return " · ".join(over)

    def refresh(self) -> None:
        """Redraw from the model (the window's 30 Hz timer calls this after a pull)."""
        for name, curve in self.curves.items():
            curve.setData(*self.plots.curve(name), skipFiniteCheck=True)
        for name, curve in self.lower_curves.items():
            curve.setData(*self.plots.curve(name), skipFiniteCheck=True)
        self._set_arms()
        for name, curve in self.arm_curves.items():
            curve.setData(*self.plots.arms[name].curve("force_n"), skipFiniteCheck=True)
        x0 = self.task.viewRange()[0][0]
        if abs(x0 + self.plots.window_s) > 1e-6:  # the x link re-scales the range while the layout settles
            self.task.setXRange(-self.plots.window_s, 0.0, padding=0)
        over = self._set_y_ranges()
        banded = self._set_cue_and_band()
        self._set_title(self.session.band_label() if banded else "", over)

    def _set_cue_and_band(self) -> bool:
        """The cue's line where it is in the window, and the band from it to now, asked of the task at each moment
        drawn; returns whether a band is drawn."""
        cue_x = self.plots.x_of(self.session.cue_t_s)
        self.cue_line.setVisible(cue_x is not None)
        if cue_x is not None:
            self.cue_line.setValue(cue_x)
        x0 = -self.plots.window_s if cue_x is None else cue_x  # a cue scrolled out: the whole window is its
        x = np.linspace(x0, 0.0, _BAND_POINTS)
        band = self.session.band(float(self.plots.t[-1]) + x) if len(self.plots.t) else None
        shown = band is not None
        for item in (self.band, self.band_lo, self.band_hi):
            item.setVisible(shown)
        if band is not None:
            self.band_lo.setData(x, band[0])
            self.band_hi.setData(x, band[1])
        return shown

    def _set_title(self, band_words: str, over: str) -> None:
        """The upper plot's title line: the band in its colour, a force above the axis in red (set on change only:
        a new title re-lays the plot out)."""
        parts = []
        if band_words:
            parts.append(f'<span style="color:#00548c">{html.escape(band_words)}</span>')
        if over:
            parts.append(f'<span style="color:#b3141b; font-weight:600">{html.escape(over)}</span>')
        markup = " &nbsp;·&nbsp; ".join(parts) or _BLANK
        if markup != self._title_html:
            self._title_html = markup
            self.title_text = " · ".join(p for p in (band_words, over) if p)
            self.task.setTitle(markup, justify="left", size="9pt")
