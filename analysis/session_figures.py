"""Figures of a whole recorded session: the paper's Fig. 6 over minutes, and a replay against the recording.

Drawn from arrays (the recording's columns and what replay recomputed), so
this module reads no database and runs no pipeline.  Long sessions are
decimated for drawing only (:func:`analysis.figures.peak_downsample` keeps
every peak); nothing computed from them is.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
from matplotlib.figure import Figure

from analysis.figures import peak_downsample
from protocol.metrics import CONTACT_THRESHOLD_N

__all__ = ["contact_mask", "replay_figure", "session_trace"]

_RAW, _COMP, _RENDER, _REPLAY = "#d62728", "#1f77b4", "#2ca02c", "#E69F00"


def _spans(ax, t: npt.NDArray[np.float64], mask: npt.NDArray[np.bool_], **kw) -> None:  # type: ignore[no-untyped-def]
    m = np.concatenate(([False], mask, [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    for k, (lo, hi) in enumerate(zip(edges[0::2], edges[1::2])):
        ax.axvspan(t[lo], t[hi - 1], label=kw.pop("label", None) if k == 0 else None, **kw)


def contact_mask(force_n: npt.NDArray[np.float64], min_ms: int = 50) -> npt.NDArray[np.bool_]:
    """Records in contact: the task force above the contact threshold, runs and gaps shorter than ``min_ms`` ignored."""
    above = np.asarray(force_n, dtype=np.float64) > CONTACT_THRESHOLD_N
    m = np.concatenate(([False], above, [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    runs = [(lo, hi) for lo, hi in zip(edges[0::2], edges[1::2]) if hi - lo >= min_ms]
    out = np.zeros(len(above), dtype=bool)
    for k, (lo, hi) in enumerate(runs):
        if k and lo - runs[k - 1][1] < min_ms:  # bridge a short gap between two contacts
            lo = runs[k - 1][1]
        out[lo:hi] = True
    return out


def session_trace(
    t_s: npt.NDArray[np.float64], raw_n: npt.NDArray[np.float64], compensated_n: npt.NDArray[np.float64],
    rendered_n: npt.NDArray[np.float64], in_trial: npt.NDArray[np.bool_], title: str,
    trial_starts: Sequence[tuple[float, str]] = (),
) -> Figure:
    """The force through the pipeline over a whole session (the paper's Fig. 6).

    Top: the compensated force magnitude (blue: the filtered, compensated
    force, as the trials were judged on) and the rendered force (green) on one
    axis, a zero baseline, trials shaded grey, contact shaded blue
    (:func:`contact_mask`); bottom, on an axis of its own: the raw sensor force,
    the tool's weight included (red).

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
    """
    width = float(np.clip((t_s[-1] - t_s[0]) / 15.0, 10.0, 28.0)) if len(t_s) else 10.0
    fig = Figure(figsize=(width, 5.2), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1.2))
    _spans(top, t_s, np.asarray(in_trial, bool), color="#eeeeee", zorder=0, label="trial")
    _spans(top, t_s, contact_mask(compensated_n), color="#cfe2f3", alpha=0.6, zorder=0,
           label=f"contact (> {CONTACT_THRESHOLD_N:g} N)")
    top.axhline(0.0, color="#555555", linewidth=0.6, zorder=1)
    top.plot(*peak_downsample(t_s, np.asarray(compensated_n), 4000), color=_COMP, linewidth=0.7,
             label="compensated |F| (filtered: the task force)", zorder=2)
    top.plot(*peak_downsample(t_s, np.asarray(rendered_n), 4000), color=_RENDER, linewidth=0.7,
             label="rendered on the haptic device", zorder=3)
    ymax = max(1.0, float(np.nanmax(compensated_n)) * 1.08 if len(t_s) else 1.0)
    top.set_ylim(-0.05 * ymax, ymax)
    for t0, label in trial_starts:
        top.text(t0, ymax * 0.99, label, fontsize=6, va="top", ha="left", color="#444444", rotation=90)
    top.set_ylabel("force (N)")
    top.set_title(title, fontsize=9, loc="left")
    top.legend(loc="lower left", bbox_to_anchor=(0.0, 1.06), ncol=4, frameon=False, fontsize=7)
    bottom.plot(*peak_downsample(t_s, np.asarray(raw_n), 4000), color=_RAW, linewidth=0.7)
    bottom.set_ylabel("raw |F| (N)")
    bottom.set_title("raw sensor force, tool weight included (own axis)", fontsize=7, loc="left", pad=2)
    bottom.set_xlabel("session time (s)")
    for ax in (top, bottom):
        ax.spines["top"].set_visible(False)
        ax.spines["right"].set_visible(False)
    return fig


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
    top.set_title("the whole session", fontsize=9, loc="left")
    top.legend(loc="lower left", bbox_to_anchor=(0.0, 1.08), ncol=2, frameon=False, fontsize=8)
    bottom.set_title(worst[2] if worst else "", fontsize=9, loc="left")
    bottom.set_xlabel("session time (s)")
    return fig
