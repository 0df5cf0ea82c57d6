"""Live plot data pulled from the sample ring: a 10 s window, peak-downsampled for drawing.

The GUI pulls at ~30 Hz (pyqtgraph's idiom: producers never push); each pull
copies only the records written since the last one.  The experimenter's
panel shows the task force (the magnitude of the compensated, filtered force
the trial is judged on) and the rendered force against the target band, on an
axis set by the target; a second panel, on its own axis, the raw sensor force
(tool weight included) or the compensated components.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from protocol.study.display import task_axis_top_n

__all__ = ["TASK_SERIES", "PlotModel", "nice_range", "peak_downsample"]

#: Curves of the task-force panel: the task force the trial is judged on, and the force rendered on the Touch.
TASK_SERIES = ("force_n", "render_n")

_F = npt.NDArray[np.float64]


def peak_downsample(t: _F, y: _F, bins: int) -> tuple[_F, _F]:
    """Keep each bin's minimum and maximum (in time order), so spikes survive downsampling.

    Returns at most ``2 * bins`` points; input shorter than that is returned as is.
    """
    n = len(y)
    if n <= 2 * bins or bins < 1:
        return t, y
    per = n // bins
    m = per * bins
    ys = y[n - m:].reshape(bins, per)
    ts = t[n - m:].reshape(bins, per)
    i_min = np.argmin(ys, axis=1)
    i_max = np.argmax(ys, axis=1)
    first = np.minimum(i_min, i_max)
    second = np.maximum(i_min, i_max)
    rows = np.arange(bins)
    t_out = np.empty(2 * bins)
    y_out = np.empty(2 * bins)
    t_out[0::2], t_out[1::2] = ts[rows, first], ts[rows, second]
    y_out[0::2], y_out[1::2] = ys[rows, first], ys[rows, second]
    return t_out, y_out


def nice_range(lo: float, hi: float, step: float = 0.5, min_span: float = 1.0,
               floor_zero: bool = False) -> tuple[float, float]:
    """An axis range covering ``[lo, hi]`` with 5 % headroom, snapped outwards to multiples of ``step``.

    Snapping is what keeps the axes still: the range changes only when the data
    crosses a step, so pyqtgraph re-renders its axis ticks (the costliest part
    of a frame) a few times per trial instead of 30 times a second.
    """
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return (0.0, min_span) if floor_zero else (-min_span / 2, min_span / 2)
    pad = 0.05 * max(hi - lo, 0.0)
    a = 0.0 if floor_zero and lo >= 0 else math.floor((lo - pad) / step) * step
    b = math.ceil((hi + pad) / step) * step
    if b - a < min_span:
        b = a + min_span if floor_zero else b
        if b - a < min_span:
            a = b - min_span
    return (float(a), float(b))


class PlotModel:
    """Rolling window of the ring's newest records.

    Parameters
    ----------
    window_s
        Seconds of sample time shown.
    rate_hz
        Nominal record rate (sizes the buffer).
    bins
        Peak-downsampling bins per curve (~ the plot's width in pixels).
    """

    SERIES = ("raw_n", "comp_n", "render_n", "comp_fx", "comp_fy", "comp_fz", "force_n")

    def __init__(self, window_s: float = 10.0, rate_hz: float = 1000.0, bins: int = 600) -> None:
        self.window_s = window_s
        self.bins = bins
        self.capacity = int(window_s * rate_hz)
        self.t = np.empty(0)
        self.data: dict[str, _F] = {k: np.empty(0) for k in self.SERIES}
        self.ring: object | None = None
        self.cursor = 0
        self.last_row: np.void | None = None
        self.new_rows: np.ndarray = np.empty(0)
        self.lost = 0
        #: Records passed over unread because the GUI was more than a window behind.
        self.skipped = 0
        #: A rig of several arms: the task arm's name ("" for one arm), and each other arm's live force, pulled
        #: from that arm's own ring as this model pulls the task arm's (name → model).
        self.task_arm = ""
        self.arms: dict[str, PlotModel] = {}

    def attach_arms(self, task_arm: str, rings: dict[str, object]) -> None:
        """Pull the other arms' records too, each from its own ring (a rig of several arms)."""
        self.task_arm = task_arm
        self.arms = {}
        for name, ring in rings.items():
            p = PlotModel(self.window_s, bins=self.bins)
            p.attach(ring)
            self.arms[name] = p

    def attach(self, ring: object) -> None:
        """Read from this ring (anything with ``read_since`` / ``write_count``), starting with its last window."""
        self.ring = ring
        self.cursor = max(0, ring.write_count - self.capacity)  # type: ignore[attr-defined]  # the ring is typed object here

    def detach(self) -> None:
        """Stop reading (the engine is going away)."""
        self.ring = None
        for p in self.arms.values():
            p.detach()

    def reset(self) -> None:
        """Forget every sample (a new engine: its clock starts again at zero)."""
        self.detach()
        self.task_arm, self.arms = "", {}
        self.t = np.empty(0)
        self.data = {k: np.empty(0) for k in self.SERIES}
        self.cursor = 0
        self.last_row = None
        self.new_rows = np.empty(0)

    def pull(self) -> int:
        """Copy what is new (the other arms' too); returns the number of the task arm's new records."""
        for p in self.arms.values():
            p.pull()
        ring = self.ring
        if ring is None:
            self.new_rows = np.empty(0)
            return 0
        # Far behind (a stall, a suspended laptop)?  Only the last window can be shown: skip the rest
        # unread, so one pull never copies or converts more than `capacity` records.
        oldest_needed = ring.write_count - self.capacity  # type: ignore[attr-defined]  # as above
        if self.cursor < oldest_needed:
            self.skipped += oldest_needed - self.cursor
            self.cursor = oldest_needed
        res = ring.read_since(self.cursor)  # type: ignore[attr-defined]  # as above
        self.cursor = res.cursor
        self.lost += res.lost
        rows = res.rows
        self.new_rows = rows
        n_new = len(rows)
        if n_new == 0:
            return 0
        rows = rows[-self.capacity:]
        self.last_row = rows[-1]
        new = {
            "raw_n": np.hypot(np.hypot(rows["raw_fx"], rows["raw_fy"]), rows["raw_fz"]),
            "comp_n": np.hypot(np.hypot(rows["filt_fx"], rows["filt_fy"]), rows["filt_fz"]),
            "render_n": np.hypot(np.hypot(rows["render_fx"], rows["render_fy"]), rows["render_fz"]),
            "comp_fx": rows["filt_fx"], "comp_fy": rows["filt_fy"], "comp_fz": rows["filt_fz"],
            "force_n": rows["force_n"],
        }
        t_new = np.asarray(rows["t_s"], dtype=np.float64)
        t = np.concatenate((self.t, t_new))
        keep = t >= t[-1] - self.window_s
        keep[: max(0, len(t) - self.capacity)] = False
        self.t = t[keep]
        for k, v in new.items():
            self.data[k] = np.concatenate((self.data[k], np.asarray(v, dtype=np.float64)))[keep]
        return n_new

    @property
    def latest_t_s(self) -> float:
        """Sample time of the newest record (0 before any)."""
        return float(self.t[-1]) if len(self.t) else 0.0

    def y_range(self, names: tuple[str, ...], floor_zero: bool = False,
                include: tuple[float, ...] = ()) -> tuple[float, float]:
        """Axis range for these series over the window and the values ``include`` (see :func:`nice_range`)."""
        lo, hi = min(include, default=math.inf), max(include, default=-math.inf)
        for k in names:
            v = self.data[k]
            v = v[np.isfinite(v)]
            if len(v):
                lo, hi = min(lo, float(v.min())), max(hi, float(v.max()))
        if lo > hi:
            return nice_range(math.nan, math.nan, floor_zero=floor_zero)
        return nice_range(lo, hi, floor_zero=floor_zero)

    def peak(self, names: tuple[str, ...], since_t_s: float | None = None) -> float:
        """Largest finite value of these series over the window (NaN when there is none).

        With ``since_t_s`` (a trial's cue, sample time) only the samples from then on count: the window still
        holds the previous trial's force for seconds after a cue, and its peak is not the current trial's.
        """
        keep = slice(None) if since_t_s is None else self.t >= since_t_s
        peaks = [float(np.max(v[np.isfinite(v)])) for v in (self.data[k][keep] for k in names)
                 if np.isfinite(v).any()]
        return max(peaks, default=math.nan)

    def task_axis(self, target_force_n: float | None, since_t_s: float | None = None) -> tuple[float, float]:
        """The task-force axis (0, top): set by the target (:func:`protocol.study.display.task_axis_top_n`), in steps,
        stretched for the peak since ``since_t_s`` (the current trial's cue; the whole window when None)."""
        return (0.0, task_axis_top_n(target_force_n, self.peak(TASK_SERIES, since_t_s), snap_fraction=0.5))

    def x_of(self, t_s: float | None) -> float | None:
        """Where sample time ``t_s`` falls on the plots' time axis (seconds relative to the newest sample, at
        most 0), or None: no time given, no data yet, or older than the window (it has scrolled out)."""
        if t_s is None or len(self.t) == 0:
            return None
        x = min(0.0, t_s - float(self.t[-1]))  # an event can arrive before the ring's records of its moment
        return x if x >= -self.window_s else None

    def curve(self, name: str) -> tuple[_F, _F]:
        """(time relative to the newest sample, values), peak-downsampled."""
        if len(self.t) == 0:
            return np.empty(0), np.empty(0)
        return peak_downsample(self.t - self.t[-1], self.data[name], self.bins)
