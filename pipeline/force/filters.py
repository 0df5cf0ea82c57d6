"""Moving-average filter of the compensated force (paper, Sec. IV).

The filter runs *after* compensation: filtering raw readings would smear the
gravity term that the compensation removes pose by pose (paper §IV).

A plain running sum is cheap but not safe over a session: it drifts like √n,
and one inf/NaN sample poisons it forever while one 1e17 spike leaves a
permanent offset (docs/science.md §7).  Here non-finite samples are rejected
before they enter the window, and the running sum is replaced by an exactly
rounded ``math.fsum`` of the window every ``window`` samples, so the error
never accumulates beyond one window's worth of roundings and any residue of a
spike is flushed within ``2·window`` samples of its arrival.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from pipeline.force.frames import Vec3

__all__ = ["MovingAverage", "MovingAverage3", "exact_sum", "group_delay_s"]

_FSUM = math.fsum


def exact_sum(values: list[float]) -> float:
    """Correctly rounded sum (``math.fsum``); ±inf when the true sum overflows.

    ``fsum`` raises on intermediate overflow; a window of finite samples near
    DBL_MAX may legitimately sum beyond it, and the filter must not raise at
    1 kHz.  The plain sum then gives the overflowed ±inf (or NaN for mixed
    signs); the next re-sum repairs the running sum once the window is finite
    again.
    """
    try:
        return _FSUM(values)
    except OverflowError:
        return sum(values)


def _check_window(window: object) -> int:
    if isinstance(window, bool) or not isinstance(window, int) or not 1 <= window <= 1_000_000:
        raise ValueError(f"window = {window!r}: must be a whole number of samples from 1 to 1000000")
    return window


def group_delay_s(window: int, rate_hz: float = 1000.0) -> float:
    """Group delay of a ``window``-sample moving average, ``(N - 1) / 2`` samples, in s."""
    return (_check_window(window) - 1) / 2.0 / rate_hz


class MovingAverage3:
    """Moving average of 3-vectors (a force), exact over arbitrarily long runs.

    Parameters
    ----------
    window
        Number of samples averaged (1 = pass-through).  At 1 kHz the group
        delay is ``(window - 1) / 2`` ms.

    Notes
    -----
    Until ``window`` samples have arrived the output is the mean of those seen.
    A sample with any non-finite component is rejected (counted in
    :attr:`rejected`) and the previous mean is returned unchanged.
    """

    # State: the three sample rings in ``_buf`` and the running sums, the
    # ring index and the sample count in one tuple ``_st`` -- one attribute
    # read and one write per sample, which is what makes it cheap at 1 kHz.
    # The rings are cleared in place and never replaced: HapticFramework's
    # fused per-tick path holds them instead of loading them every tick.
    __slots__ = ("_buf", "_st", "rejected", "window")

    def __init__(self, window: int) -> None:
        self.window = _check_window(window)
        self.rejected = 0
        self._buf = ([0.0] * window, [0.0] * window, [0.0] * window)
        self.reset()

    def reset(self) -> None:
        """Empty the window (the next output is the next sample)."""
        for b in self._buf:  # in place: see the note on the state above
            b[:] = (0.0,) * self.window
        self._st = (0.0, 0.0, 0.0, 0, 0)

    @property
    def count(self) -> int:
        """Samples currently in the window (≤ ``window``)."""
        return self._st[4]

    def state(self) -> dict[str, Any]:
        """The window's contents and running sums, JSON-safe and exact (see :meth:`load_state`)."""
        return {"window": self.window, "buf": [list(b) for b in self._buf], "st": list(self._st),
                "rejected": self.rejected}

    def load_state(self, d: Mapping[str, Any]) -> None:
        """Continue exactly from a :meth:`state` of a filter of the same window (rings refilled in place)."""
        if int(d["window"]) != self.window:
            raise ValueError(f"filter state of window {d['window']!r}: this filter's window is {self.window}")
        for ring, values in zip(self._buf, d["buf"], strict=True):
            ring[:] = [float(v) for v in values]
        sx, sy, sz, i, n = d["st"]
        self._st = (float(sx), float(sy), float(sz), int(i), int(n))
        self.rejected = int(d["rejected"])

    def update(self, x: float, y: float, z: float) -> Vec3:
        """Add one sample and return the mean of the last ``window`` accepted samples."""
        if (x - x) + (y - y) + (z - z) != 0.0:  # NaN or ±inf in any component
            self.rejected += 1
            return self.mean
        sx, sy, sz, i, n = self._st
        bx, by, bz = self._buf
        sx += x - bx[i]
        sy += y - by[i]
        sz += z - bz[i]
        bx[i] = x
        by[i] = y
        bz[i] = z
        i += 1
        w = self.window
        if n < w:
            n += 1
        if i == w:
            i = 0
            # Re-sum exactly once per window: bounds rounding drift and flushes
            # the residue a huge spike leaves behind when it is evicted.
            sx = exact_sum(bx)
            sy = exact_sum(by)
            sz = exact_sum(bz)
        self._st = (sx, sy, sz, i, n)
        if (sx - sx) + (sy - sy) + (sz - sz) != 0.0:
            return self._mean_without_overflow()
        return (sx / n, sy / n, sz / n)

    @property
    def mean(self) -> Vec3:
        """Current output (zeros before the first accepted sample)."""
        sx, sy, sz, _, n = self._st
        if n == 0:
            return (0.0, 0.0, 0.0)
        if (sx - sx) + (sy - sy) + (sz - sz) != 0.0:
            return self._mean_without_overflow()
        return (sx / n, sy / n, sz / n)

    def _mean_without_overflow(self) -> Vec3:
        """Mean of a window of finite samples whose sum exceeds DBL_MAX: sum the samples divided by n."""
        n = self._st[4]
        bx, by, bz = self._buf
        return (
            _FSUM([v / n for v in bx]),
            _FSUM([v / n for v in by]),
            _FSUM([v / n for v in bz]),
        )


class MovingAverage:
    """Moving average of a scalar signal; same guarantees as :class:`MovingAverage3`.

    >>> ma = MovingAverage(2)
    >>> ma.update(1.0), ma.update(3.0), ma.update(5.0)
    (1.0, 2.0, 4.0)
    """

    __slots__ = ("_core",)

    def __init__(self, window: int) -> None:
        self._core = MovingAverage3(window)

    @property
    def window(self) -> int:
        """Number of samples averaged."""
        return self._core.window

    @property
    def rejected(self) -> int:
        """Non-finite samples refused so far."""
        return self._core.rejected

    def reset(self) -> None:
        """Empty the window."""
        self._core.reset()

    def update(self, sample: float) -> float:
        """Add one sample and return the current mean."""
        return self._core.update(float(sample), 0.0, 0.0)[0]
