"""Figures of a whole recorded session: the paper's Fig. 6 over minutes, and a replay against the recording.

Drawn from arrays (the recording's columns and what replay recomputed), so
this module reads no database and runs no pipeline.  Long sessions are
decimated for drawing only (:func:`analysis.plots.figures.peak_downsample` keeps
every peak); nothing computed from them is.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from matplotlib.figure import Figure

from analysis.plots.figures import peak_downsample, styled
from protocol.tasks.window import CONTACT_THRESHOLD_N

__all__ = ["SessionMarks", "contact_mask", "replay_figure", "session_trace"]

_RAW, _COMP, _RENDER, _REPLAY = "#d62728", "#1f77b4", "#2ca02c", "#E69F00"


def _spans(ax, t: npt.NDArray[np.float64], mask: npt.NDArray[np.bool_], **kw) -> None:  # type: ignore[no-untyped-def]  # matplotlib Axes left untyped in the figure helpers
    m = np.concatenate(([False], mask, [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    for k, (lo, hi) in enumerate(zip(edges[0::2], edges[1::2], strict=True)):
        ax.axvspan(t[lo], t[hi - 1], label=kw.pop("label", None) if k == 0 else None, **kw)


def contact_mask(force_n: npt.NDArray[np.float64], min_ms: int = 50) -> npt.NDArray[np.bool_]:
    """Records in contact: the task force above the contact threshold, runs and gaps shorter than ``min_ms`` ignored."""
    above = np.asarray(force_n, dtype=np.float64) > CONTACT_THRESHOLD_N
    m = np.concatenate(([False], above, [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    runs = [(lo, hi) for lo, hi in zip(edges[0::2], edges[1::2], strict=True) if hi - lo >= min_ms]
    out = np.zeros(len(above), dtype=bool)
    for k, (lo, hi) in enumerate(runs):
        if k and lo - runs[k - 1][1] < min_ms:  # bridge a short gap between two contacts
            lo = runs[k - 1][1]
        out[lo:hi] = True
    return out


@dataclass(frozen=True)
class SessionMarks:
    """What happened in a session besides the force, for :func:`session_trace` to mark.

    Attributes
    ----------
    bands
        (session times from the cue to the trial end, band low, band high at them) of every trial, s and N: its
        target band where it was over the trial (a tracked target's moves), shaded.
    aborted
        (cue time, end time, "trial 4: fault: SENSOR_STALE ...") of every aborted trial.
    pauses
        (start, end) of every experimenter pause (the end is the session's last record if never resumed).
    resumes
        Session times at which a resumed run of the session began.
    """

    bands: Sequence[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]] = ()
    aborted: Sequence[tuple[float, float, str]] = ()
    pauses: Sequence[tuple[float, float]] = ()
    resumes: Sequence[float] = ()


@styled
def session_trace(
    t_s: npt.NDArray[np.float64], raw_n: npt.NDArray[np.float64], compensated_n: npt.NDArray[np.float64],
    rendered_n: npt.NDArray[np.float64], in_trial: npt.NDArray[np.bool_], title: str,
    trial_starts: Sequence[tuple[float, str]] = (), marks: SessionMarks | None = None,
    faults: npt.NDArray[np.int64] | None = None,
) -> Figure:
    """The force through the pipeline over a whole session (the paper's Fig. 6), with what happened marked.

    Top: the compensated force magnitude (blue: the filtered, compensated
    force, as the trials were judged on) and the rendered force (green) on one
    axis, a zero baseline, trials shaded grey with each trial's target band over it, contact shaded blue
    (:func:`contact_mask`), aborted trials hatched red with their cause, experimenter pauses hatched grey,
    latched faults as red bars along the top and resumes as vertical lines; bottom, on an axis of its own: the
    raw sensor force, the tool's weight included (red).

    Parameters
    ----------
    t_s
        Session time of each record, s.
    raw_n, compensated_n, rendered_n
        Force magnitudes, N.
    in_trial
        Records inside a trial window.
    title
        Figure title.
    trial_starts
        (cue time, label) of each trial, written over the shading.
    marks
        Target bands, aborted trials, pauses and resumes (:class:`SessionMarks`).
    faults
        Each record's latched-fault bitmask (0: none), drawn where non-zero.
    """
    marks = marks or SessionMarks()
    width = float(np.clip((t_s[-1] - t_s[0]) / 15.0, 10.0, 28.0)) if len(t_s) else 10.0
    listing = _listing(t_s, marks, faults)
    rows = (len(listing) + 1) // 2  # two columns of "what happened"
    fig = Figure(figsize=(width, 5.6 + 0.16 * rows), layout="constrained")
    axes = fig.subplots(3 if listing else 2, 1, height_ratios=(3, 1.2, 0.1 + 0.16 * rows)[: 3 if listing else 2])
    top, bottom = axes[0], axes[1]
    bottom.sharex(top)
    top.tick_params(labelbottom=False)
    _spans(top, t_s, np.asarray(in_trial, bool), color="#eeeeee", zorder=0, label="trial")
    _spans(top, t_s, contact_mask(compensated_n), color="#cfe2f3", alpha=0.6, zorder=0,
           label=f"contact (> {CONTACT_THRESHOLD_N:g} N)")
    for k, (times, lo, hi) in enumerate(marks.bands):
        top.fill_between(times, lo, hi, color="#0072B2", alpha=0.25, linewidth=0, zorder=1,
                         label="target band" if k == 0 else None)
    top.axhline(0.0, color="#555555", linewidth=0.6, zorder=1)
    top.plot(*peak_downsample(t_s, np.asarray(compensated_n), 4000), color=_COMP, linewidth=0.7,
             label="compensated |F| (filtered: the task force)", zorder=2)
    top.plot(*peak_downsample(t_s, np.asarray(rendered_n), 4000), color=_RENDER, linewidth=0.7,
             label="rendered on the haptic device", zorder=3)
    ymax = max(1.0, float(np.nanmax(compensated_n)) * 1.08 if len(t_s) else 1.0)
    top.set_ylim(-0.05 * ymax, ymax)
    for t0, label in trial_starts:
        # boxed, above the aborted-trial hatching, so an aborted trial's own label stays legible
        top.text(t0, ymax * 0.99, label, fontsize=6, va="top", ha="left", color="#444444", rotation=90, zorder=6,
                 bbox={"boxstyle": "square,pad=0.1", "facecolor": "white", "edgecolor": "none", "alpha": 0.85})
    _mark_events(top, bottom, t_s, marks, faults, ymax)
    top.set_ylabel("force (N)")
    top.set_title(title, loc="left")
    top.legend(loc="lower left", bbox_to_anchor=(0.0, 1.06), ncol=5, frameon=False)
    bottom.plot(*peak_downsample(t_s, np.asarray(raw_n), 4000), color=_RAW, linewidth=0.7)
    bottom.set_ylabel("raw |F| (N)")
    bottom.set_title("raw sensor force, tool weight included (own axis)", fontsize=7, loc="left", pad=2)
    bottom.set_xlabel("session time (s)")
    for ax in (top, bottom):
        ax.spines["top"].set_visible(False)
        ax.spines["right"].set_visible(False)
    if listing:
        axes[2].axis("off")
        half = (len(listing) + 1) // 2
        for col, part in enumerate((listing[:half], listing[half:])):
            axes[2].text(0.5 * col, 1.0, "\n".join(part), transform=axes[2].transAxes, va="top", ha="left",
                         fontsize=7, color="#333333", linespacing=1.35)
    return fig


def _fault_onsets(faults: npt.NDArray[np.int64] | None) -> list[int]:
    """Record indices where a latched fault begins (the bitmask turns non-zero)."""
    if faults is None or not len(faults):
        return []
    latched = np.asarray(faults) != 0
    m = np.concatenate(([False], latched))
    return [int(i) for i in np.flatnonzero(m[1:] & ~m[:-1])]


def _listing(t_s: npt.NDArray[np.float64], marks: SessionMarks, faults: npt.NDArray[np.int64] | None) -> list[str]:
    """What happened, in time order, each line tagged as on the figure (A1 an aborted trial, F1 a fault)."""
    from protocol.study.labels import fault_names

    items = [(a, f"A{k + 1}  {why}, {a:.3f}–{b:.3f} s") for k, (a, b, why) in enumerate(marks.aborted)]
    items += [(float(t_s[i]), f"F{k + 1}  {fault_names(int(faults[i]))} latched at {t_s[i]:.3f} s")  # type: ignore[index]  # no onsets when faults is None
              for k, i in enumerate(_fault_onsets(faults))]
    items += [(a, f"experimenter pause {a:.3f}–{b:.3f} s") for a, b in marks.pauses]
    items += [(t, f"resumed at {t:.3f} s (a new run of the session)") for t in marks.resumes]
    return [text for _, text in sorted(items, key=lambda x: x[0])]


def _mark_events(top, bottom, t_s: npt.NDArray[np.float64], marks: SessionMarks,  # type: ignore[no-untyped-def]  # matplotlib Axes left untyped in the figure helpers
                 faults: npt.NDArray[np.int64] | None, ymax: float) -> None:
    """Aborted trials (hatched, tagged A1 …), pauses (hatched grey), faults (a red bar along the bottom, tagged
    F1 …) and resumes (a dashed line); the tags are listed in words under the figure (:func:`_listing`)."""
    tag = {"fontsize": 6.5, "fontweight": "bold", "ha": "center", "va": "bottom",
           "bbox": {"facecolor": "white", "edgecolor": "none", "pad": 0.5}}
    for k, (a, b, _) in enumerate(marks.aborted):
        for ax in (top, bottom):
            ax.axvspan(a, b, facecolor="none", edgecolor="#b00020", hatch="////", linewidth=0, zorder=1,
                       label="aborted trial (not counted)" if k == 0 and ax is top else None)
        top.text((a + b) / 2, ymax * 0.74, f"A{k + 1}", color="#b00020", zorder=6, **tag)
    for k, (a, b) in enumerate(marks.pauses):
        for ax in (top, bottom):
            ax.axvspan(a, b, facecolor="none", edgecolor="#777777", hatch="\\\\", linewidth=0, zorder=1,
                       label="experimenter pause" if k == 0 and ax is top else None)
    onsets = _fault_onsets(faults)
    if onsets:
        latched = np.asarray(faults) != 0
        low = -0.05 * ymax
        m = np.concatenate(([False], latched, [False]))
        edges = np.flatnonzero(m[1:] != m[:-1])
        for j, (lo, hi) in enumerate(zip(edges[0::2], edges[1::2], strict=True)):
            top.fill_between([t_s[lo], t_s[hi - 1] + 0.05], low, low * 0.2, color="#b00020", linewidth=0, zorder=5,
                             label="fault latched" if j == 0 else None)
        for k, i in enumerate(onsets):
            top.text(t_s[i], low * 0.2, f"F{k + 1}", color="#b00020", zorder=6, **tag)
    for k, t in enumerate(marks.resumes):
        for ax in (top, bottom):
            ax.axvline(t, color="#6a3d9a", linewidth=1.2, linestyle="--", zorder=4,
                       label="resumed (a new run)" if k == 0 and ax is top else None)


@styled
def replay_figure(
    t_s: npt.NDArray[np.float64], recorded_n: npt.NDArray[np.float64], replayed_n: npt.NDArray[np.float64],
    what: str, worst: tuple[float, float, str] | None = None,
) -> Figure:
    """The rendered force the participant felt against what other settings would have rendered.

    Top: the whole session; bottom: the trial where they differ most (``worst`` = its window and label).
    """
    fig = Figure(figsize=(12, 5.4), layout="constrained")
    top, bottom = fig.subplots(2, 1, height_ratios=(1, 1))
    for ax, lo, hi in ((top, None, None), (bottom, *(worst[:2] if worst else (None, None)))):
        sel = np.ones(len(t_s), bool) if lo is None else (t_s >= lo) & (t_s <= hi)
        ax.plot(*peak_downsample(t_s[sel], np.asarray(recorded_n)[sel], 3000), color=_RENDER, linewidth=0.8,
                label="rendered (recorded)")
        ax.plot(*peak_downsample(t_s[sel], np.asarray(replayed_n)[sel], 3000), color=_REPLAY, linewidth=0.8,
                label=f"replayed: {what}")
        ax.set_ylabel("rendered |F| (N)")
        ax.spines["top"].set_visible(False)
        ax.spines["right"].set_visible(False)
    top.set_title("the whole session", loc="left")
    top.legend(loc="lower left", bbox_to_anchor=(0.0, 1.08), ncol=2, frameon=False, fontsize=8)
    bottom.set_title(worst[2] if worst else "", loc="left")
    bottom.set_xlabel("session time (s)")
    return fig
