"""The paper's figures, drawn with matplotlib's object API (no pyplot state, no display).

* :func:`mode_bars` -- a metric per target and overall, haptics OFF vs ON,
  the median across participants with its interquartile range (the summary the signed-rank test is about; the
  paper's figures show mean ± SD, which skewed per-participant values misrepresent), each participant a dot, the
  number of participants under each bar and the test's significance mark (the paper's Figs. 8 and 9);
* :func:`paired_lines` -- every participant's OFF → ON change per metric;
* :func:`pipeline_trace` -- one trial's task force (blue) against its target
  band with the rendered force (green), and the raw sensor force (red) on an
  axis of its own, contact shaded (the paper's Fig. 6); the error window and,
  for an aborted trial, the abort with its time and cause marked.

The speed–accuracy and learning figures are in :mod:`analysis.plots.model_figures`.
Every function returns a :class:`matplotlib.figure.Figure` sized for a journal
page (:data:`COLUMN_IN` one column, :data:`PAGE_IN` the full width) in the
fonts of :data:`STYLE`; :func:`save` writes it as a 300 dpi PNG, a PDF and an
SVG with real (selectable) text.
"""

from __future__ import annotations

import functools
import io
import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar, cast

import numpy as np
import numpy.typing as npt
import pandas as pd
from matplotlib.figure import Figure

from analysis.reading.recorded import read_trial_samples
from analysis.stats.aggregate import METRIC_LABELS, by_mode
from analysis.stats.wilcoxon import WilcoxonResult
from protocol.metrics import by_participant_name
from protocol.study.display import task_axis_top_n
from protocol.study.labels import fault_names
from protocol.tasks.base import Task, TrialScreen, TrialTarget
from protocol.tasks.window import CONTACT_THRESHOLD_N

__all__ = [
    "COLUMN_IN",
    "MODE_COLORS",
    "MODE_MARKERS",
    "PAGE_IN",
    "STYLE",
    "mode_bars",
    "paired_lines",
    "peak_downsample",
    "pipeline_trace",
    "render",
    "save",
    "save_one",
    "significance_mark",
    "stored_trial_figure",
    "styled",
    "trial_trace",
]

#: Okabe–Ito colours, distinguishable with every common colour-vision deficiency.
MODE_COLORS = {"off": "#E69F00", "on": "#0072B2"}
#: A marker per mode too, so the modes stay apart in grey print and where lines overlap.
MODE_MARKERS = {"off": "o", "on": "s"}
_MODE_NAMES = {"off": "haptics OFF", "on": "haptics ON"}
#: Widths of a journal's single column and full page, inches (89 and 183 mm).
COLUMN_IN, PAGE_IN = 3.5, 7.2
#: Fonts a journal accepts at the printed size: 8 pt text, 7 pt ticks and legends, never below 6 pt.
STYLE: dict[str, Any] = {"font.family": "DejaVu Sans", "font.size": 8, "axes.titlesize": 8, "axes.labelsize": 8,
         "xtick.labelsize": 7, "ytick.labelsize": 7, "legend.fontsize": 7, "legend.title_fontsize": 7,
         "figure.titlesize": 8, "axes.linewidth": 0.6, "xtick.major.width": 0.6, "ytick.major.width": 0.6,
         "lines.linewidth": 1.0}
_F = TypeVar("_F", bound=Callable[..., Figure])


def styled(builder: _F) -> _F:
    """Build the figure in :data:`STYLE` (fonts are fixed when the text is made, so the style wraps the build)."""
    import matplotlib

    @functools.wraps(builder)
    def build(*args: Any, **kwargs: Any) -> Figure:
        with matplotlib.rc_context(cast(Any, STYLE)):
            return builder(*args, **kwargs)

    return build  # type: ignore[return-value]  # functools.wraps keeps the signature; mypy cannot see it
#: Print resolution of the PNGs.
_DPI = 300
#: Text stays text in SVG and PDF (selectable, searchable, editable in a journal's tools).
_VECTOR_RC: dict[str, Any] = {"svg.fonttype": "none", "pdf.fonttype": 42}
#: No dates in vector files: the same data give the same files.
_NO_DATE: dict[str, dict[str, None]] = {"svg": {"Date": None}, "pdf": {"CreationDate": None}}


def significance_mark(result: WilcoxonResult | None, *, adjusted: bool = True, p_holm: float | None = None) -> str:
    """``***`` p < 0.001, ``**`` p < 0.01, ``*`` p < 0.05, ``n.s.``, or ``n/c`` when not computable.

    Parameters
    ----------
    result
        The test.
    adjusted
        Use ``p_holm`` (when given) instead of the raw p-value.
    p_holm
        The Holm-adjusted p-value of this result.
    """
    if result is None or not result.computable:
        return "n/c"
    p = p_holm if (adjusted and p_holm is not None) else result.p_value
    if not math.isfinite(p):
        return "n/c"
    return "***" if p < 0.001 else "**" if p < 0.01 else "*" if p < 0.05 else "n.s."


def _style(ax) -> None:  # type: ignore[no-untyped-def]  # matplotlib Axes left untyped in the figure helpers
    ax.spines["top"].set_visible(False)
    ax.spines["right"].set_visible(False)
    ax.grid(axis="y", color="#dddddd", linewidth=0.6)
    ax.set_axisbelow(True)


def wrap_note(text: str, width_in: float) -> str:
    """A caveat wrapped to the figure's width (6.5 pt text: about 19 characters an inch)."""
    import textwrap

    return "\n".join(textwrap.wrap(text, max(20, int(width_in * 19)))) if text else ""


def add_note(fig: Figure, note: str) -> None:
    """Print a wrapped caveat along the bottom of the figure (its margin leaves :func:`note_lines` lines free)."""
    if note:
        fig.text(0.01, 0.01, wrap_note(note, fig.get_size_inches()[0]), fontsize=6.5, color="#444444",
                 ha="left", va="bottom", linespacing=1.2)


def note_lines(note: str, width_in: float) -> int:
    """How many lines :func:`add_note` takes for ``note`` on a figure ``width_in`` wide."""
    return wrap_note(note, width_in).count("\n") + 1 if note else 0


def margins(fig: Figure, left: float, right: float, bottom: float, top: float, **space: float) -> None:
    """Fixed margins in inches (constrained layout costs more than drawing the figure twice over)."""
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=left / w, right=1 - right / w, bottom=bottom / h, top=1 - top / h, **space)


def _bars_panel(ax, groups: Sequence[tuple[str, pd.DataFrame, str]], metric: str, rng: np.random.Generator) -> None:  # type: ignore[no-untyped-def]  # as above
    width = 0.36
    top = 0.0
    for gi, (_label, frame, mark) in enumerate(groups):
        heights = {}
        for k, mode in enumerate(("off", "on")):
            vals = frame.loc[frame["haptic_mode"] == mode, metric].to_numpy(dtype=float)
            vals = vals[np.isfinite(vals)]
            x = gi + (k - 0.5) * width
            q1, med, q3 = np.percentile(vals, (25, 50, 75)) if len(vals) else (math.nan,) * 3
            ax.bar(x, med if math.isfinite(med) else 0.0, width * 0.92, color=MODE_COLORS[mode], alpha=0.85,
                   label=_MODE_NAMES[mode] if gi == 0 else None, zorder=2)
            ax.annotate(str(len(vals)), (x, 0.0), xytext=(0, -1), textcoords="offset points", ha="center",
                        va="top", fontsize=5.5, color="#333333", annotation_clip=False)
            if len(vals):
                if len(vals) > 1:  # one participant has no spread: no whisker (not one of length 0)
                    ax.errorbar(x, med, yerr=[[med - q1], [q3 - med]], color="#333333", capsize=3, linewidth=0.9,
                                zorder=3)
                ax.scatter(x + rng.uniform(-0.08, 0.08, len(vals)), vals, s=6, color="#222222", alpha=0.55,
                           zorder=4, linewidths=0)
                heights[mode] = max(q3, float(vals.max()))
            else:
                ax.text(x, 0, "no data", ha="center", va="bottom", fontsize=6, rotation=90)
        if heights:
            h = max(heights.values())
            y = h * 1.06 if h > 0 else 0.05
            ax.plot([gi - width / 2, gi - width / 2, gi + width / 2, gi + width / 2],
                    [y * 0.98, y, y, y * 0.98], color="#333333", linewidth=0.8)
            ax.text(gi, y, mark, ha="center", va="bottom")
            top = max(top, y * 1.15)
    ax.set_xticks(range(len(groups)), [g[0] for g in groups])
    ax.tick_params(axis="x", pad=8)  # room for the n under the bars
    ax.set_ylabel(METRIC_LABELS.get(metric, metric))
    if (known := by_participant_name(metric)) is not None and known.boolean:
        top = 1.15  # a rate: room for the marks above 1, nothing more
    if top > 0:
        ax.set_ylim(0, top)
    _style(ax)


@styled
def mode_bars(
    metrics: Sequence[str],
    overall: pd.DataFrame,
    by_target: pd.DataFrame,
    marks: Mapping[tuple[str, str], str],
    *,
    target_order: Sequence[str] | None = None,
    title: str = "",
    note: str = "",
) -> Figure:
    """Bar panels, one per metric: each target and overall, OFF vs ON.

    Parameters
    ----------
    metrics
        Columns of the per-participant tables to draw, one panel each (one panel: a column wide; more: the page).
    overall, by_target
        :func:`analysis.stats.aggregate.per_participant` without and with the target split.
    marks
        Significance mark per ``(metric, group)`` where group is a target
        label or ``"overall"`` (see :func:`significance_mark`).
    target_order
        Target labels left to right (default: by increasing target force when
        ``target_force_n`` is known, else alphabetical).
    title
        Figure title.
    note
        A caveat printed under the panels (e.g. the error window, or who has no value).
    """
    targets = list(target_order) if target_order else sorted(by_target["target_label"].unique())
    width = COLUMN_IN if len(metrics) == 1 else PAGE_IN
    extra = 0.12 * note_lines(note, width)
    fig = Figure(figsize=(width, 2.7 + extra), dpi=_DPI)
    margins(fig, 0.5, 0.08, 0.3 + extra, 0.62 + 0.2 * bool(title), wspace=0.3)
    axes = fig.subplots(1, len(metrics), squeeze=False)[0]
    rng = np.random.default_rng(0)  # jitter of the dots, fixed so figures are reproducible
    for ax, metric in zip(axes, metrics, strict=True):
        groups = [(t, by_target[by_target["target_label"] == t], marks.get((metric, t), "")) for t in targets]
        groups.append(("overall", overall, marks.get((metric, "overall"), "")))
        _bars_panel(ax, groups, metric, rng)
    # the legend says what the bars are: a figure is also read apart from the report
    axes[0].legend(frameon=False, ncols=2, loc="lower left", bbox_to_anchor=(0.0, 1.01),
                   title="median [IQR]; dots: participants; n below", alignment="left")
    add_note(fig, note)
    if title:
        fig.suptitle(title)
    return fig


@styled
def paired_lines(per_part: pd.DataFrame, metrics: Sequence[str], marks: Mapping[str, str]) -> Figure:
    """Each participant's value with haptics OFF and ON, joined, per metric; the median in black.

    Participants are spread a little sideways (in participant order), so equal values -- several at a success
    rate of 0 or 1 -- stay visible as separate lines rather than one.
    """
    fig = Figure(figsize=(PAGE_IN, 2.5), dpi=_DPI)
    margins(fig, 0.45, 0.08, 0.25, 0.5, wspace=0.55)
    axes = fig.subplots(1, len(metrics), squeeze=False)[0]
    for ax, metric in zip(axes, metrics, strict=True):
        wide = by_mode(per_part, metric)
        k = len(wide)
        for i, (_, row) in enumerate(wide.iterrows()):
            dx = 0.12 * (i / (k - 1) - 0.5) if k > 1 else 0.0
            ax.plot([dx, 1 + dx], [row["off"], row["on"]], color="#7f7f7f", alpha=0.6, linewidth=0.7, marker="o",
                    markersize=2.5, label="participant" if i == 0 else None)
        med = [float(np.nanmedian(wide[m])) if wide[m].notna().any() else math.nan for m in ("off", "on")]
        ax.plot([0, 1], med, color="black", linewidth=1.8, marker="s", markersize=4, label="median", zorder=5)
        ax.set_xticks([0, 1], ["OFF", "ON"])
        ax.set_xlim(-0.35, 1.35)
        ax.set_title(f"{METRIC_LABELS.get(metric, metric)}  {marks.get(metric, '')}")
        _style(ax)
    fig.legend(*axes[0].get_legend_handles_labels(), frameon=False, ncols=2, loc="upper left",
               bbox_to_anchor=(0.0, 1.0))
    return fig


@styled
def pipeline_trace(samples: pd.DataFrame, *, target_force_n: float | None = None, band: TrialScreen | None = None,
                   title: str = "", error_window: str | None = None, abort: tuple[float, str] | None = None) -> Figure:
    """One trial's force through the pipeline (the paper's Fig. 6), drawn for judging the task.

    Top panel: the task force (magnitude of the compensated, filtered contact
    force -- the value the trial was judged on, blue), the force rendered on
    the haptic device (green) and the target band; its axis is set by the
    target (:func:`protocol.study.display.task_axis_top_n`).  Bottom panel, on its own axis: the raw
    sensor force (red), dominated by the tool's weight.  Intervals in contact
    (task force above :data:`protocol.tasks.window.CONTACT_THRESHOLD_N`) are shaded
    in both.  Legends sit above the data.

    Parameters
    ----------
    samples
        :func:`analysis.reading.recorded.read_trial_samples` output (its ``faults`` column, where recorded, marks when a
        watchdog fault latched).
    target_force_n
        The trial's target force (it scales the axis).
    band
        What the trial's task shows of it (:meth:`protocol.tasks.base.Task.screen`): its band, drawn with its legend.
    title
        Figure title.
    error_window
        ``"cue"`` or ``"first_contact"``: the window RMSE and Max AE are taken over, marked under the force.
    abort
        (time since the cue, cause in words) of an aborted trial: a red line and its label at that time.
    """
    t = samples["t_s"].to_numpy(dtype=float)

    def mag(prefix: str) -> np.ndarray:
        c: list[npt.NDArray[np.float64]] = [samples[f"{prefix}_f{a}"].to_numpy(dtype=float) for a in "xyz"]
        return np.sqrt(c[0] ** 2 + c[1] ** 2 + c[2] ** 2)

    task = samples["force_n"].to_numpy(dtype=float)
    fig = Figure(figsize=(PAGE_IN, 4.0), dpi=_DPI)
    margins(fig, 0.55, 0.1, 0.4, 0.75 if title else 0.55, hspace=0.42)
    ax, ax_raw = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    contact = task > CONTACT_THRESHOLD_N
    if contact.any():
        edges = np.flatnonzero(np.diff(np.concatenate(([0], contact.astype(np.int8), [0]))))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            for axis in (ax, ax_raw):
                axis.axvspan(t[a], t[b - 1], color="#bbbbbb", alpha=0.22, linewidth=0,
                             label="in contact" if (a == edges[0] and axis is ax) else None)
    drawn = None if band is None else band.band_over(t[::10])  # the band where it was (a tracked target's moves)
    if band is not None and drawn is not None:
        ax.fill_between(t[::10], drawn[0], drawn[1], color="#0072B2", alpha=0.18, linewidth=0,
                        label=band.band_legend)
        for edge in drawn:
            ax.plot(t[::10], edge, color="#0072B2", linewidth=0.6, linestyle="--")
    ax.plot(*peak_downsample(t, task), color="#1f4e9c", linewidth=0.9, label="task force |F| (compensated, filtered)")
    ax.plot(*peak_downsample(t, mag("render")), color="#2ca02c", linewidth=0.8, linestyle=(0, (4, 1.5)),
            label="rendered on the haptic device")
    finite = task[np.isfinite(task)]
    peak = float(finite.max()) if len(finite) else math.nan
    top = task_axis_top_n(target_force_n, peak)
    ax.set_ylim(0.0, top)
    if math.isfinite(peak) and peak > top:
        ax.text(0.99, 0.97, f"peak {peak:.2f} N: above the axis", transform=ax.transAxes, ha="right", va="top",
                fontsize=6.5, color="#b00020")
    ax.set_ylabel("force (N)")
    ax_raw.plot(*peak_downsample(t, mag("raw")), color="#d62728", linewidth=0.8)
    ax_raw.set_ylabel("raw |F| (N)")
    ax_raw.set_title("raw sensor force, tool weight included (own axis)", fontsize=6.5, loc="left", pad=2)
    ax_raw.set_xlabel("time since cue (s)")
    _mark_window(ax, t, contact, error_window)
    _mark_abort(ax, ax_raw, t, samples, abort)
    if title:
        fig.suptitle(title, x=0.55 / PAGE_IN, ha="left")
    ax.legend(frameon=False, ncols=3, loc="lower left", bbox_to_anchor=(0.0, 1.0))
    _style(ax)
    _style(ax_raw)
    return fig


def _mark_window(ax, t: np.ndarray, contact: np.ndarray, window: str | None) -> None:  # type: ignore[no-untyped-def]  # as above
    """A bracket along the bottom of the force axis: the samples RMSE and Max AE are taken over."""
    if window is None or not len(t):
        return
    start = t[0] if window == "cue" else (t[int(np.argmax(contact))] if contact.any() else math.nan)
    what = "from the cue" if window == "cue" else "from first contact"
    if not math.isfinite(start):
        ax.text(0.01, 0.03, "error window (from first contact): no contact, no RMSE or Max AE",
                transform=ax.transAxes, fontsize=6.5, color="#444444")
        return
    y = ax.get_ylim()[1] * 0.02
    ax.annotate("", xy=(t[-1], y), xytext=(start, y), arrowprops={"arrowstyle": "|-|", "color": "#444444",
                                                                    "lw": 0.8, "shrinkA": 0, "shrinkB": 0})
    # at the window's end, where the force has settled (at the target, or wherever the trial ended) rather than
    # rising through the label; a light box keeps it legible over a trace that does pass
    ax.text(t[-1], y * 2.2, f"error window ({what}): RMSE, Max AE", ha="right", va="bottom", fontsize=6.5,
            color="#444444",
            bbox={"boxstyle": "square,pad=0.1", "facecolor": "white", "edgecolor": "none", "alpha": 0.8},
            zorder=5)


def _mark_abort(ax, ax_raw, t: np.ndarray, samples: pd.DataFrame, abort: tuple[float, str] | None) -> None:  # type: ignore[no-untyped-def]  # as above
    """An aborted trial: where a watchdog fault latched (from the recorded flags) and where the trial ended, each
    a red line with its time and cause in a boxed label (on the left of a line in the right half of the axis)."""
    labels: list[tuple[float, str, str]] = []  # (time, text, line style)
    if "faults" in samples.columns and len(t):
        faults = samples["faults"].to_numpy()
        latched = np.flatnonzero(faults != 0)
        if len(latched):
            i = int(latched[0])
            labels.append((float(t[i]), f"{fault_names(int(faults[i]))} latched at {t[i]:.3f} s", ":"))
    if abort is not None:
        at, cause = abort
        if labels and abs(labels[0][0] - at) < 0.05:  # the fault that aborted it: one label, not two on one line
            labels[0] = (at, f"{labels[0][1]}; aborted at {at:.3f} s\n{cause}", "-")
        else:
            labels.append((at, f"aborted at {at:.3f} s\n{cause}", "-"))
    lo, hi = (float(t[0]), float(t[-1])) if len(t) else (0.0, 1.0)
    top = ax.get_ylim()[1]
    for k, (at, text, style) in enumerate(labels):
        for axis in (ax, ax_raw):
            axis.axvline(at, color="#b00020", linewidth=1.2 if style == "-" else 0.9, linestyle=style, zorder=6)
        right = at > (lo + hi) / 2
        ax.text(at, top * (0.97 - 0.2 * k), text, color="#b00020", fontsize=6.5, va="top",
                ha="right" if right else "left", zorder=7, linespacing=1.3,
                bbox={"facecolor": "white", "edgecolor": "#b00020", "linewidth": 0.6, "pad": 2.0, "alpha": 0.92})


def peak_downsample(t: np.ndarray, y: np.ndarray, buckets: int = 1200) -> tuple[np.ndarray, np.ndarray]:
    """Keep each bucket's minimum and maximum, in time order, so no peak is lost on screen.

    A 12 s trial has 12 001 samples for a plot about 1000 pixels wide; drawing
    every one costs time and file size (SVG) and shows nothing more.  Each of
    ``buckets`` equal runs of samples keeps its lowest and highest sample (NaN
    samples are skipped within a bucket).

    Parameters
    ----------
    t, y
        Samples; returned unchanged when there are at most ``2·buckets``.
    buckets
        Number of buckets.

    Returns
    -------
    t, y
        The kept samples.
    """
    n = len(y)
    if n <= 2 * buckets:
        return t, y
    edges = np.linspace(0, n, buckets + 1).astype(np.int64)
    keep = []
    for a, b in itertools.pairwise(edges):
        seg = y[a:b]
        if not np.isfinite(seg).any():
            keep.append(a)
            continue
        i, j = a + int(np.nanargmin(seg)), a + int(np.nanargmax(seg))
        keep.extend((i, j) if i <= j else (j, i))
    idx = np.asarray(keep, dtype=np.int64)
    return t[idx], y[idx]


def render(builder: str, args: tuple[Any, ...], kwargs: dict[str, Any], folder: str | Path, name: str) -> bytes:
    """Build a figure with this module's function ``builder`` and :func:`save` it (a picklable task for a worker)."""
    if builder not in _BUILDERS:
        raise ValueError(f"builder = {builder!r}: allowed values are {', '.join(sorted(_BUILDERS))}")
    return save(_BUILDERS[builder](*args, **kwargs), folder, name)


def trial_trace(database: str, session_id: int, trial_index: int, **kwargs: Any) -> Figure:
    """:func:`pipeline_trace` of a stored trial, read from its database."""
    return pipeline_trace(read_trial_samples(database, session_id, trial_index), **kwargs)


def stored_trial_figure(database: str, trial: Mapping[str, Any], samples: pd.DataFrame, task: Task,
                        error_window: str = "cue") -> Figure:
    """``plot-trial``'s figure of one stored trial (a row of :attr:`analysis.reading.load.StudyData.trials`).

    The title names the participant, session, trial, target, mode and outcome; an aborted trial is marked at
    the moment it ended with its cause (``abort_reason``, e.g. ``fault: SENSOR_STALE: newest F/T sample 6.0 ms
    old (limit 5 ms)``), and where a watchdog fault latched, from the recorded flags.
    """
    number = int(trial["trial_index"]) + 1
    outcome = str(trial["outcome"])
    cause = trial.get("abort_cause")
    what = f"aborted ({cause})" if outcome == "aborted" and isinstance(cause, str) and cause else outcome
    title = (f"{trial['participant_code']}, session {int(trial['session_id'])}, trial {number}: "
             f"{trial['target_label']} {float(trial['target_force_n']):g} N, haptics "
             f"{str(trial['haptic_mode']).upper()}, {what}")
    abort = None
    if outcome == "aborted":
        reason = trial.get("abort_reason")
        at = float(trial["ended_at_s"]) - float(trial["started_at_s"])
        abort = (at, str(reason) if isinstance(reason, str) and reason else "cause not recorded")
    return pipeline_trace(samples, target_force_n=float(trial["target_force_n"]),
                          band=task.screen(TrialTarget.of(trial)), title=title,
                          error_window=error_window if outcome != "aborted" else None, abort=abort)


def save(fig: Figure, folder: str | Path, name: str) -> bytes:
    """Write ``folder/name.png`` (300 dpi), ``.pdf`` and ``.svg``; return the PNG bytes (for embedding)."""
    import matplotlib

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    with matplotlib.rc_context(cast(Any, _VECTOR_RC)):
        fig.savefig(buf, format="png", dpi=_DPI)
        for suffix in ("svg", "pdf"):
            fig.savefig(folder / f"{name}.{suffix}", format=suffix, metadata=_NO_DATE[suffix])
    png = buf.getvalue()
    (folder / f"{name}.png").write_bytes(png)
    return png


def save_one(fig: Figure, path: str | Path) -> None:
    """Write one figure file; its format from the suffix (.png at 300 dpi, .pdf, .svg with real text)."""
    import matplotlib

    with matplotlib.rc_context(cast(Any, _VECTOR_RC)):
        fig.savefig(path, dpi=_DPI, metadata=_NO_DATE.get(Path(path).suffix.lower().lstrip(".")))


_BUILDERS: dict[str, Callable[..., Figure]] = {
    "mode_bars": mode_bars,
    "paired_lines": paired_lines,
    "pipeline_trace": pipeline_trace,
    "trial_trace": trial_trace,
}
