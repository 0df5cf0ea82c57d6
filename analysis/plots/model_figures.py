"""The figures of the within-participant analyses: the speed–accuracy slopes and learning over the session.

* :func:`trade_slopes` -- speed against accuracy per haptic mode (the default reading: rise time against RMSE after
  reaching the band): every trial a dot, every participant's own least-squares line, and the common
  within-participant slope of the repeated-measures correlation;
* :func:`km_curves` -- TCT as a time to event: the Kaplan–Meier curves of P(no success yet) per mode, failures
  censored at the cap, with the Cox model's hazard ratio;
* :func:`learning_curves` -- each metric over the session's trials by mode (blocks of trials, the
  participants' block means averaged), labelled as the secondary analysis it belongs to.

Both are drawn in the report's journal style (:data:`analysis.plots.figures.STYLE`), the page's width.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from analysis.plots.figures import (
    COLUMN_IN,
    MODE_COLORS,
    MODE_MARKERS,
    PAGE_IN,
    _style,
    add_note,
    margins,
    note_lines,
    styled,
)
from analysis.stats.aggregate import METRIC_LABELS, TESTED_METRICS
from protocol.metrics import by_participant_name

__all__ = ["km_curves", "learning_curves", "trade_slopes"]

_DPI = 300
_NAMES = {"off": "haptics OFF", "on": "haptics ON"}


@styled
def trade_slopes(pairs: pd.DataFrame, slopes: pd.DataFrame, common: Mapping[str, tuple[float, str]],
                 speed_label: str, accuracy_label: str, note: str = "") -> Figure:
    """Speed against accuracy, one panel per mode: trials, each participant's own line, the common slope.

    Parameters
    ----------
    pairs
        Trials with ``participant_code``, ``haptic_mode``, ``accuracy`` (N) and ``speed`` (s).
    slopes
        :func:`analysis.stats.trade.participant_slopes`.
    common
        Per mode: (the common within-participant slope in s per N, its caption, e.g. the r_rm with its interval).
    speed_label, accuracy_label
        The axes' labels.
    note
        A caveat printed under the panels.
    """
    extra = 0.12 * note_lines(note, PAGE_IN)
    fig = Figure(figsize=(PAGE_IN, 3.0 + extra), dpi=_DPI)
    margins(fig, 0.5, 0.1, 0.4 + extra, 0.62, wspace=0.12)
    axes = fig.subplots(1, 2, sharey=True)
    for ax, mode in zip(axes, ("off", "on"), strict=True):
        sel = pairs[pairs["haptic_mode"] == mode]
        ax.scatter(sel["accuracy"], sel["speed"], s=7, color=MODE_COLORS[mode], alpha=0.55, linewidths=0,
                   marker=MODE_MARKERS[mode], label="trial", zorder=3)
        first = True
        for r in slopes[slopes["haptic_mode"] == mode].itertuples():
            if not math.isfinite(r.slope_s_per_n):
                continue
            x = np.array([r.accuracy_min_n, r.accuracy_max_n])
            ax.plot(x, r.intercept_s + r.slope_s_per_n * x, color="#555555", linewidth=0.6, alpha=0.8, zorder=2,
                    label="a participant's own line" if first else None)
            first = False
        slope, caption = common.get(mode, (math.nan, "not computable"))
        if len(sel) and math.isfinite(slope):
            x0, y0 = float(sel["accuracy"].mean()), float(sel["speed"].mean())
            x = np.array([float(sel["accuracy"].min()), float(sel["accuracy"].max())])
            ax.plot(x, y0 + slope * (x - x0), color="black", linewidth=1.6, linestyle="--", zorder=4,
                    label="common within-participant slope")
        ax.set_title(f"{_NAMES[mode]}\n{caption}", loc="left")
        ax.set_xlabel(accuracy_label)
        _style(ax)
    axes[0].set_ylabel(speed_label)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, frameon=False, ncols=3, loc="upper right", bbox_to_anchor=(1.0, 1.0))
    add_note(fig, note)
    return fig


@styled
def learning_curves(curve: pd.DataFrame, note: str = "") -> Figure:
    """Each metric over the session by haptic mode: mean ± SE across participants per block of trials.

    Parameters
    ----------
    curve
        :func:`analysis.stats.learning.learning_curve`.
    note
        A caveat printed under the panels (what the points are, what the models say).
    """
    drawn = set(curve["metric"])  # every tested metric of the study, a panel each (learning_curve computes each)
    metrics = [m for m in TESTED_METRICS if m in drawn]
    extra = 0.12 * note_lines(note, PAGE_IN)
    fig = Figure(figsize=(PAGE_IN, 2.4 + extra), dpi=_DPI)
    margins(fig, 0.45, 0.08, 0.42 + extra, 0.72, wspace=0.5)
    axes = fig.subplots(1, len(metrics))
    blocks = curve.drop_duplicates("block").sort_values("block")
    ticks = blocks["block"].to_list()
    names = [f"{a}–{b}" if a != b else str(a) for a, b in zip(blocks["first_trial"], blocks["last_trial"], strict=True)]
    for ax, m in zip(axes, metrics, strict=True):
        for k, mode in enumerate(("off", "on")):
            sel = curve[(curve["metric"] == m) & (curve["haptic_mode"] == mode)].sort_values("block")
            dx = (k - 0.5) * 0.16  # side by side, so equal means and their bars do not hide each other
            ax.errorbar(sel["block"] + dx, sel["mean"], yerr=sel["se"].fillna(0.0), color=MODE_COLORS[mode],
                        marker=MODE_MARKERS[mode], markersize=3.5, linewidth=0.9, capsize=2, elinewidth=0.7,
                        label=_NAMES[mode])
        ax.set_xticks(ticks, names, rotation=0)
        ax.set_xlim(min(ticks, default=0) - 0.4, max(ticks, default=0) + 0.4)
        ax.set_title(METRIC_LABELS.get(m, m))
        ax.set_xlabel("trials")
        if (metric := by_participant_name(m)) is not None and metric.boolean:  # a rate
            ax.set_ylim(-0.05, 1.05)
        _style(ax)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, frameon=False, ncols=2, loc="upper left", bbox_to_anchor=(0.0, 1.0),
               title="secondary analysis: mean ± SE across participants of each participant's block mean",
               alignment="left")
    add_note(fig, note)
    return fig


@styled
def km_curves(km: pd.DataFrame, summary: pd.DataFrame, cox: Any, note: str = "") -> Figure:
    """P(no success yet) against time since the cue, per haptic mode (Kaplan–Meier, failures censored at the cap).

    Parameters
    ----------
    km
        :func:`analysis.stats.survival.kaplan_meier` (its steps and pointwise intervals).
    summary
        :func:`analysis.stats.survival.time_to_event_summary`: the legend's n, successes and median.
    cox
        :func:`analysis.stats.survival.cox_model`: its hazard ratio for haptics ON, in the title.
    note
        A caveat printed under the panel.
    """
    extra = 0.12 * note_lines(note, COLUMN_IN * 1.6)
    fig = Figure(figsize=(COLUMN_IN * 1.6, 3.0 + extra), dpi=_DPI)
    margins(fig, 0.5, 0.1, 0.42 + extra, 0.55)
    ax = fig.add_subplot()
    cap = 0.0
    for mode in ("off", "on"):
        curve = km[km["haptic_mode"] == mode]
        row = summary[summary["haptic_mode"] == mode]
        if curve.empty or row.empty:
            continue
        r = row.iloc[0]
        cap = max(cap, float(r["restricted_mean_s"]) if math.isfinite(r["restricted_mean_s"]) else 0.0)
        med = f"median {r['km_median_s']:.2f} s" if math.isfinite(r["km_median_s"]) else "median not reached"
        label = f"{_NAMES[mode]}: {int(r['n_successes'])} of {int(r['n_trials'])} trials succeeded, {med}"
        ax.step(curve["time_s"], curve["survival"], where="post", color=MODE_COLORS[mode], linewidth=1.2,
                label=label)
        ax.fill_between(curve["time_s"], curve["ci_low"], curve["ci_high"], step="post", color=MODE_COLORS[mode],
                        alpha=0.15, linewidth=0)
    ax.set_ylim(0.0, 1.02)
    ax.set_xlim(left=0.0)
    ax.set_xlabel("time since the cue (s); a trial that did not succeed is censored at the cap")
    ax.set_ylabel("P(no success yet)")
    on = cox.term("haptics_on") if cox.fitted else None
    title = ("Cox model (stratified by participant, clustered SEs): HR ON : OFF = "
             f"{on['hazard_ratio']:.2f} [{on['ci_low']:.2f}, {on['ci_high']:.2f}]" if on is not None else
             f"Cox model {cox.note}")
    ax.set_title(title, loc="left")
    ax.legend(frameon=False, loc="lower left", fontsize=6.5)
    _style(ax)
    add_note(fig, note)
    return fig
