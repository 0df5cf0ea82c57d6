"""The figures of a pipeline settings sweep (``haptic-study sweep``, :mod:`analysis.planning.sweep`).

* :func:`metrics_figure` -- each measure of the sweep (success rate, TCT in both readings, RMSE, Max AE, the trade's
  phases, ...) against the first swept setting, haptics OFF and ON, each point the mean over studies with its 95 %
  t-interval (none over one study, and the title says so), TCT over successful trials with the successes it rests
  on, the paper's value of the setting marked; a second swept setting is a line per value (its own line style);
* :func:`front_figure` -- the front of the protocol's task's own measures (:data:`FRONTS`, the first whose two
  measures the sweep has): for force regulation the speed–accuracy front in the report's reading, rise time against
  RMSE after reach (parts of the trial apart: docs/science.md §6.1), each point labelled with its success rate; for
  force tracking the lag against the tracking RMSE, each labelled with its gain -- with haptics ON, one point per
  setting (both intervals drawn), the paper's setting starred.

Both carry the sweep's caveat (a model's prediction) along the bottom.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import matplotlib
import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from analysis.planning.setting_labels import setting_formats
from analysis.planning.sim_study import SIMULATED, measure_labels
from analysis.plots.figures import MODE_COLORS, MODE_MARKERS, PAGE_IN, add_note, margins, note_lines, styled
from protocol.metrics import METRICS, TRADE_PHASES, get

__all__ = ["FRONTS", "Front", "front_figure", "front_of", "metrics_figure"]

#: A panel per measure of the sweep (the simulated trials' metrics, :data:`analysis.planning.sweep.METRICS`: those
#: of them the summary has), two to a row.
_PANELS = tuple(measure_labels(SIMULATED).items())
#: The yes/no outcome (the front's success rate) and which panels are means over successful trials only.
_VERDICT = next(m.name for m in METRICS if m.boolean)


@dataclass(frozen=True, slots=True)
class Front:
    """A trade the sweep draws: ``y`` against ``x`` (registry names; lower left is better), each point labelled with
    its ``badge`` measure."""

    y: str
    x: str
    badge: str
    #: The figure's title, before "across SETTING".
    title: str
    #: How the badge reads beside a value (``success 93%``).
    badge_format: Callable[[float], str]

    def words(self) -> str:
        """The front in words (sweep.md's list of files)."""
        name = self.title[:1].lower() + self.title[1:]
        return (f"the {name}: {get(self.y).short} against {get(self.x).short}, haptics ON, each setting's "
                f"{get(self.badge).short} beside it")


#: The fronts a sweep may draw, the first whose two measures its summary has: force regulation's speed–accuracy
#: trade in the report's reading (:data:`protocol.metrics.TRADE_PHASES`), and a moving target's lag against its
#: tracking error (a setting that smooths the force more costs lag before it costs error).
FRONTS: tuple[Front, ...] = (
    Front(TRADE_PHASES[0].name, TRADE_PHASES[1].name, _VERDICT, "Speed–accuracy front",
          lambda v: f"success {v:.0%}"),
    Front("lag_s", "rmse_n", "gain", "Lag–error front", lambda v: f"gain {v:.2f}"),
)


def front_of(summary: pd.DataFrame) -> Front | None:
    """The front of the sweep's measures (None: its task has none of :data:`FRONTS`)."""
    have = set(summary["metric"]) if len(summary) else set()
    return next((f for f in FRONTS if {f.y, f.x} <= have), None)
_SUCCESS_ONLY = {m.name: m.success_only for m in METRICS}
_MODE_NAMES = {"off": "haptics OFF", "on": "haptics ON"}
_DASHES = ("-", "--", ":", "-.")


def _log_x(values: Sequence[float]) -> bool:
    """A log axis when the values are positive and span a factor of 10 or more."""
    return min(values) > 0 and max(values) / min(values) >= 10


def _label(settings: Mapping[str, Any], names: Sequence[str], fmts: Mapping[str, Callable[[Any], str]]) -> str:
    return ", ".join(f"{k}={fmts[k](settings[k])}" for k in names)


def _errorbar(ax: Any, x: Sequence[float], sel: pd.DataFrame, col: str, **kw: Any) -> None:
    y = sel[col].to_numpy(dtype=float)
    lo = (y - sel[f"{col}_ci_low"].to_numpy(dtype=float))
    hi = (sel[f"{col}_ci_high"].to_numpy(dtype=float) - y)
    lo[~(lo == lo)] = 0.0  # no interval (one study): a bare point
    hi[~(hi == hi)] = 0.0
    ax.errorbar(x, y, yerr=[lo, hi], capsize=2, markersize=3.5, **kw)


@styled
def metrics_figure(summary: pd.DataFrame, swept: Sequence[str], paper: Mapping[str, float], note: str) -> Figure:
    """The sweep's measures against the first swept setting (see the module docstring)."""
    x_name, others = swept[0], list(swept[1:])
    xs = sorted({float(v) for v in summary[x_name]})
    lines = note_lines(note, PAGE_IN)
    panels = [p for p in _PANELS if p[0] in set(summary["metric"])]  # the protocol's task's measures
    rows = math.ceil(len(panels) / 2)
    fig = Figure(figsize=(PAGE_IN, 2.6 * rows + 0.11 * lines))
    margins(fig, 0.6, 0.15, 0.55 + 0.11 * lines, 0.3, wspace=0.3, hspace=0.45)
    axes = fig.subplots(rows, 2, squeeze=False)
    for spare in axes.flat[len(panels):]:  # an odd number of measures: the last row's second panel is empty
        spare.set_visible(False)
    groups = (list(summary.groupby(others, sort=True)) if others else [((), summary)])
    fmts = setting_formats(summary, swept)
    for ax, (metric, label) in zip(axes.flat, panels, strict=False):
        for g_i, (g_key, grp) in enumerate(groups):
            sel = grp[grp["metric"] == metric].sort_values(x_name)
            tag = "" if not others else " · " + _label(
                dict(zip(others, g_key if isinstance(g_key, tuple) else (g_key,), strict=True)), others, fmts)
            for mode, dx in (("off", 0.985), ("on", 1.015)):
                x = [float(v) * (dx if _log_x(xs) else 1.0) for v in sel[x_name]]
                _errorbar(ax, x, sel, mode, color=MODE_COLORS[mode], marker=MODE_MARKERS[mode],
                          linestyle=_DASHES[g_i % len(_DASHES)], label=_MODE_NAMES[mode] + tag)
                if _SUCCESS_ONLY.get(metric) and f"n_trials_{mode}" in sel:  # what a mean of successes rests on
                    other = sel["on" if mode == "off" else "off"]
                    for xi, yi, yo, n in zip(x, sel[mode], other, sel[f"n_trials_{mode}"], strict=True):
                        y, y_other = float(yi), float(yo)
                        if math.isfinite(y):
                            # the count on the side away from the other mode's point at this setting (the two
                            # points are often close: labels on facing sides overlapped); a tie: ON above
                            up = y > y_other if y != y_other and math.isfinite(y_other) else mode == "on"
                            ax.annotate(f"n={int(n)}", (xi, y), xytext=(3, 3 if up else -8),
                                        textcoords="offset points", fontsize=5.5, color=MODE_COLORS[mode])
        if _log_x(xs):
            ax.set_xscale("log")
            ax.set_xlim(xs[0] / 1.5, xs[-1] * 1.5)
        elif len(xs) > 1:
            pad = (xs[-1] - xs[0]) * 0.08
            ax.set_xlim(xs[0] - pad, xs[-1] + pad)
        x_lo, x_hi = ax.get_xlim()
        # the paper's setting is marked only inside the axis: a grid far from it (slew near 123456 N/s) would put
        # its label millions of pixels away, beyond what the renderer can draw
        if x_name in paper and x_lo <= float(paper[x_name]) <= x_hi:
            ax.axvline(float(paper[x_name]), color="#777777", linewidth=0.8, linestyle=(0, (2, 2)), zorder=0)
            ax.annotate("paper", (float(paper[x_name]), 1.0), xycoords=("data", "axes fraction"), fontsize=6.5,
                        color="#555555", ha="left", va="top", xytext=(2, -1), textcoords="offset points")
        ax.set_xticks(xs, [fmts[x_name](v) for v in xs])
        ax.minorticks_off()
        ax.set_xlabel(x_name)
        ax.set_ylabel(label)
        ax.spines["top"].set_visible(False)
        ax.spines["right"].set_visible(False)
        ax.grid(axis="y", color="#dddddd", linewidth=0.6)
    axes.flat[0].legend(frameon=False, loc="best")
    one = int(summary["n_studies"].max()) < 2 if len(summary) else True
    fig.suptitle("Pipeline settings sweep: " + ("one study, so no interval (--studies 2 or more gives 95 % "
                                                "t-intervals over the study means)" if one else
                                                "mean over studies, 95 % t-interval over the study means"))
    add_note(fig, note)
    return fig


@styled
def front_figure(summary: pd.DataFrame, swept: Sequence[str], note: str) -> Figure:
    """The front of the sweep's measures with haptics ON (:func:`front_of`), one labelled point per setting (module
    docstring); a task without one: the axes empty, titled so."""
    front = front_of(summary) or FRONTS[0]
    speed, accuracy = get(front.y), get(front.x)
    lines = note_lines(note, PAGE_IN * 0.62)
    fig = Figure(figsize=(PAGE_IN * 0.62, 3.6 + 0.11 * lines))
    margins(fig, 0.6, 0.2, 0.5 + 0.11 * lines, 0.3)
    ax = fig.add_subplot()
    y_rows = summary[summary["metric"] == speed.name].reset_index(drop=True)
    x_rows = summary[summary["metric"] == accuracy.name].reset_index(drop=True)
    ok = summary[summary["metric"] == front.badge].reset_index(drop=True)
    if ok.empty:  # no badge measure: the points unlabelled
        ok = y_rows.assign(on=math.nan)
    if y_rows.empty or x_rows.empty:  # a protocol whose task has no front: none to draw
        y_rows, x_rows, ok = y_rows.iloc[:0], x_rows.iloc[:0], ok.iloc[:0]
    pts: list[tuple[float, float]] = []
    one = len(swept) == 1  # the axis title names the setting: a point is labelled with its value alone
    fmts = setting_formats(summary, swept)
    # each setting its own colour, named in the legend: labels beside points collide where the points crowd
    colours = matplotlib.colormaps["viridis"](np.linspace(0.0, 0.9, max(len(y_rows), 1)))
    for i, ((_, t), (_, r), (_, s)) in enumerate(zip(y_rows.iterrows(), x_rows.iterrows(), ok.iterrows(),
                                                       strict=True)):
        x, y = float(r["on"]), float(t["on"])
        xerr = [[_half(r, "low")], [_half(r, "high")]]
        yerr = [[_half(t, "low")], [_half(t, "high")]]
        star = bool(t["paper"])
        success = f", {front.badge_format(float(s['on']))}" if math.isfinite(float(s["on"])) else ""
        text = (fmts[swept[0]](t[swept[0]]) if one else _label(t, swept, fmts)) + (" (paper)" if star else "") + success
        ax.errorbar([x], [y], xerr=xerr, yerr=yerr, color=colours[i], marker="*" if star else "o",
                    markersize=9 if star else 5, capsize=2, linewidth=0.8, label=text)
        pts.append((x, y))
    for (x0, y0), (x1, y1) in itertools.pairwise(pts) if one else ():
        ax.plot([x0, x1], [y0, y1], color="#bbbbbb", linewidth=0.6, zorder=0)
    ax.margins(x=0.2, y=0.1)
    ax.set_xlabel(f"{accuracy.label}, haptics ON")
    ax.set_ylabel(f"{speed.label}, haptics ON")
    ax.spines["top"].set_visible(False)
    ax.spines["right"].set_visible(False)
    ax.set_title(f"{front.title} across " + (swept[0] if one else "settings") + " (lower left is better)")
    ax.legend(title=(swept[0] if one else "setting") + f": ON {get(front.badge).short}", frameon=False, fontsize=6.5,
              title_fontsize=7, loc="best")
    add_note(fig, note)
    return fig


def _half(row: pd.Series, end: str) -> float:
    """The distance from the ON mean to one end of its interval (0 without one)."""
    v = abs(float(row[f"on_ci_{end}"]) - float(row["on"]))
    return v if math.isfinite(v) else 0.0
