"""The power-curve figure of :mod:`analysis.planning.power`: power against the number of participants.

One panel per scope (overall, then each target); one line per metric with its
Monte Carlo interval as a band, the Holm family-wise power of all the primary
metrics as a dashed black line, and the 80 % and 90 % targets.  Power is
directional (:mod:`analysis.planning.power`): a rejection in the pool's direction.  Colours are
Okabe–Ito, distinguishable with every common colour-vision deficiency, and
each metric also has its own marker, so the figure reads in grey too.
"""

from __future__ import annotations

import math

from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import NullLocator, PercentFormatter

from analysis.planning.power import FAMILY_ANY, PowerResult, is_family_row, metric_label
from analysis.plots.figures import _style
from analysis.stats.aggregate import TESTED_METRICS

__all__ = ["METRIC_COLORS", "power_curves"]

#: Okabe–Ito colours and markers, one per tested metric in the registry's order.
_PALETTE = ("#009E73", "#D55E00", "#0072B2", "#CC79A7", "#E69F00", "#56B4E9", "#F0E442")
_MARKER_CYCLE = ("o", "s", "^", "D", "v", "P", "X")
METRIC_COLORS = {m: _PALETTE[i % len(_PALETTE)] for i, m in enumerate(TESTED_METRICS)}
_MARKERS = {m: _MARKER_CYCLE[i % len(_MARKER_CYCLE)] for i, m in enumerate(TESTED_METRICS)}


def power_curves(result: PowerResult) -> Figure:
    """Power of each metric's test (and of all the primary ones under Holm) against n, one panel per scope.

    Parameters
    ----------
    result
        :func:`analysis.planning.power.estimate_power`'s result.

    Returns
    -------
    matplotlib.figure.Figure
    """
    f = result.frame
    scopes = list(dict.fromkeys(f["scope"]))
    fig = Figure(figsize=(4.2 * len(scopes) + 0.6, 4.6), layout="constrained")
    axes = fig.subplots(1, len(scopes), sharey=True, squeeze=False)[0]
    handles: dict[str, Line2D] = {}
    for ax, scope in zip(axes, scopes, strict=True):
        sel = f[f["scope"] == scope]
        for level, style in ((0.8, (0, (4, 3))), (0.9, (0, (1, 2)))):
            ax.axhline(level, color="#555555", linewidth=0.9, linestyle=style, zorder=1)
        ns = sorted(set(sel["n"]))
        # a wide range of n (6 … 200) reads on a log axis; the default 6 … 30 on a linear one
        log = ns[-1] > 6 * ns[0]
        span = math.log(ns[-1] / ns[0]) if log else float(max(ns[-1] - ns[0], 4))
        # curves that coincide (e.g. several at 100 %) stay visible: each metric is shifted a hair sideways
        dodge = 0.007 * span
        shown = [m for m in dict.fromkeys(sel["metric"]) if m != FAMILY_ANY]  # the family row: Holm rejects all
        for k, metric in enumerate(shown):
            m = sel[sel["metric"] == metric].sort_values("n")
            shift = (k - (len(shown) - 1) / 2) * dodge
            x = m["n"] * math.exp(shift) if log else m["n"] + shift
            family = is_family_row(metric)
            color = "#000000" if family else METRIC_COLORS.get(metric, "#666666")
            col, lo, hi = ("power_holm", "holm_ci_low", "holm_ci_high") if family else ("power", "ci_low", "ci_high")
            ax.fill_between(x, m[lo], m[hi], color=color, alpha=0.15, linewidth=0, zorder=2)
            (line,) = ax.plot(x, m[col], color=color, linewidth=2.0 if family else 1.6,
                              linestyle="--" if family else "-", marker=None if family else _MARKERS.get(metric, "o"),
                              markersize=4.5, zorder=3, label=metric_label(metric))
            handles.setdefault(metric_label(metric), line)
        _style(ax)
        ax.set_title("overall" if scope == "overall" else f"within {scope}", fontsize=11)
        ax.set_xlabel("participants in the planned study, n")
        if log:
            ax.set_xscale("log")
            ax.xaxis.set_minor_locator(NullLocator())
            ax.set_xlim(ns[0] * math.exp(-0.03 * span), ns[-1] * math.exp(0.03 * span))
        else:
            pad = max(0.5, 0.03 * span)
            ax.set_xlim(ns[0] - pad, ns[-1] + pad)
        ax.set_xticks(ns, _thinned_labels(ns, log))
        ax.set_ylim(-0.02, 1.03)
        ax.yaxis.set_major_formatter(PercentFormatter(1.0, decimals=0))
        ax.grid(axis="x", color="#eeeeee", linewidth=0.6)
    axes[0].set_ylabel(f"power (p < {result.alpha:g}, in the pool's direction)")
    for level in (0.8, 0.9):
        axes[-1].annotate(f"{level:.0%}", xy=(1.0, level), xycoords=("axes fraction", "data"), xytext=(3, 0),
                          textcoords="offset points", va="center", fontsize=8, color="#555555")
    band = f"band: {result.interval_level:.0%} Monte Carlo interval of {result.resamples} resampled studies per n"
    # the caveat belongs on the figure it qualifies, not only in the text beside it
    band += (f"\ncaveat: resampling {result.n_pool} participants leaves out their own sampling error; a small pilot "
             "overstates power" + (", more so where all its participants change the same way"
                                   if any("overstates the power" in n for n in result.notes) else ""))
    fig.legend(list(handles.values()), list(handles.keys()), loc="outside lower center", ncol=len(handles),
               frameon=False, fontsize=9, title=band, title_fontsize=8)
    size = "" if "participants" in result.source else f" ({result.n_pool} participants)"
    fig.suptitle(f"Power of the ON-vs-OFF Wilcoxon tests to detect the effect in the pool's direction, against "
                 f"study size\nresampling {result.source}{size}",
                 fontsize=10.5)
    return fig


def _thinned_labels(ns: list[int], log: bool, min_gap: float = 0.06) -> list[str]:
    """Tick labels for the n tried, leaving out any closer than ``min_gap`` of the axis to the last one shown."""
    pos = [math.log(n) if log else float(n) for n in ns]
    width = (pos[-1] - pos[0]) or 1.0
    labels, last = [], -math.inf
    for n, p in zip(ns, pos, strict=True):
        need = min_gap * max(2, len(str(n))) / 2  # three-digit labels need more room than two-digit ones
        show = (p - last) / width >= need or (n == ns[-1] and (p - last) / width >= need / 2)
        labels.append(str(n) if show else "")
        last = p if show else last
    return labels

