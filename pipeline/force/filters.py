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

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from pipeline.core import exact
from pipeline.core.compiled import KernelState, State, fingerprint, kernel, warm_once
from pipeline.force.frames import Vec3

__all__ = ["MovingAverage", "MovingAverage3", "group_delay_s", "ma3_mean", "ma3_update", "state_size"]

# The state of a 3-vector moving average (:class:`MovingAverage3`), one float64 array: the running sums, the ring
# index, the count, the samples rejected, the window, then the three rings (x, y, z) of ``window`` samples each.
_SX, _SY, _SZ, _I, _N, _REJECTED, _W, _BUF = range(8)


def state_size(window: int) -> int:
    """The length of the state array of a ``window``-sample :class:`MovingAverage3`."""
    return _BUF + 3 * window


def _check_window(window: object) -> int:
    if isinstance(window, bool) or not isinstance(window, int) or not 1 <= window <= 1_000_000:
        raise ValueError(f"window = {window!r}: must be a whole number of samples from 1 to 1000000")
    return window


def group_delay_s(window: int, rate_hz: float = 1000.0) -> float:
    """Group delay of a ``window``-sample moving average, ``(N - 1) / 2`` samples, in s."""
    return (_check_window(window) - 1) / 2.0 / rate_hz


def _compile_mean(callees: int) -> Callable[..., tuple[float, float, float]]:
    """:func:`ma3_mean` closed over the :func:`pipeline.core.compiled.fingerprint` of :mod:`pipeline.core.exact`
    (numba keys its cache on a kernel's own file and closure: a closure must hold plain values only, never another
    kernel, whose pickled form differs from process to process)."""

    @kernel
    def ma3_mean(st: State) -> tuple[float, float, float]:
        """The current output (zeros before the first accepted sample)."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        n = st[_N]
        if n == 0.0:
            return (0.0, 0.0, 0.0)
        sx, sy, sz = st[_SX], st[_SY], st[_SZ]
        if (sx - sx) + (sy - sy) + (sz - sz) != 0.0:
            # a window of finite samples whose sum exceeds DBL_MAX: sum the samples divided by n
            w = int(st[_W])
            b = st[_BUF:]
            return (exact.fsum(b[:w] / n), exact.fsum(b[w:2 * w] / n), exact.fsum(b[2 * w:3 * w] / n))
        return (sx / n, sy / n, sz / n)

    return ma3_mean


def _compile_update(callees: int) -> Callable[..., tuple[float, float, float]]:
    """:func:`ma3_update` closed over the same fingerprint (it calls :func:`ma3_mean`, a global of this module)."""

    @kernel
    def ma3_update(st: State, x: float, y: float, z: float) -> tuple[float, float, float]:
        """Add one sample; the mean of the last ``window`` accepted samples (:meth:`MovingAverage3.update`)."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        if (x - x) + (y - y) + (z - z) != 0.0:  # NaN or ±inf in any component
            st[_REJECTED] += 1.0
            return ma3_mean(st)
        w = int(st[_W])
        i = int(st[_I])
        n = st[_N]
        b = st[_BUF:]
        sx = st[_SX] + (x - b[i])
        sy = st[_SY] + (y - b[w + i])
        sz = st[_SZ] + (z - b[2 * w + i])
        b[i] = x
        b[w + i] = y
        b[2 * w + i] = z
        i += 1
        if n < w:
            n += 1.0
        if i == w:
            i = 0
            # Re-sum exactly once per window: bounds rounding drift and flushes
            # the residue a huge spike leaves behind when it is evicted.
            sx = exact.fsum(b[:w])
            sy = exact.fsum(b[w:2 * w])
            sz = exact.fsum(b[2 * w:3 * w])
        st[_SX] = sx
        st[_SY] = sy
        st[_SZ] = sz
        st[_I] = i
        st[_N] = n
        if (sx - sx) + (sy - sy) + (sz - sz) != 0.0:
            return ma3_mean(st)
        return (sx / n, sy / n, sz / n)

    return ma3_update


ma3_mean = _compile_mean(fingerprint(exact))
ma3_update = _compile_update(fingerprint(exact))


class MovingAverage3(KernelState):
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
    :attr:`rejected`) and the previous mean is returned unchanged.  The arithmetic is :func:`ma3_update`'s, compiled,
    over the array :attr:`array` (Algorithm 1's compiled tick runs the same kernel on the framework's slice of it).
    """

    __slots__ = ("window",)

    def __init__(self, window: int) -> None:
        self.window = _check_window(window)
        #: The state (running sums, index, count, rejected, window, rings) as :func:`ma3_update` reads it.
        self.array: State = np.zeros(state_size(window))
        self.reset()
        _warm(self.array)

    def reset(self) -> None:
        """Empty the window (the next output is the next sample); the count of rejected samples stays."""
        st = self.array
        rejected = st[_REJECTED]
        st[:] = 0.0
        st[_REJECTED], st[_W] = rejected, float(self.window)

    @property
    def rejected(self) -> int:
        """Non-finite samples refused so far."""
        return int(self.array[_REJECTED])

    @property
    def count(self) -> int:
        """Samples currently in the window (≤ ``window``)."""
        return int(self.array[_N])

    def _rings(self) -> tuple[State, State, State]:
        b, w = self.array[_BUF:], self.window
        return b[:w], b[w:2 * w], b[2 * w:]

    def state(self) -> dict[str, Any]:
        """The window's contents and running sums, JSON-safe and exact (see :meth:`load_state`)."""
        st = self.array
        return {"window": self.window, "buf": [r.tolist() for r in self._rings()],
                "st": [float(st[_SX]), float(st[_SY]), float(st[_SZ]), int(st[_I]), int(st[_N])],
                "rejected": self.rejected}

    def load_state(self, d: Mapping[str, Any]) -> None:
        """Continue exactly from a :meth:`state` of a filter of the same window (rings refilled in place)."""
        if int(d["window"]) != self.window:
            raise ValueError(f"filter state of window {d['window']!r}: this filter's window is {self.window}")
        for ring, values in zip(self._rings(), d["buf"], strict=True):
            ring[:] = [float(v) for v in values]
        sx, sy, sz, i, n = d["st"]
        st = self.array
        st[_SX], st[_SY], st[_SZ], st[_I], st[_N] = float(sx), float(sy), float(sz), int(i), int(n)
        st[_REJECTED] = int(d["rejected"])

    def update(self, x: float, y: float, z: float) -> Vec3:
        """Add one sample and return the mean of the last ``window`` accepted samples."""
        return ma3_update(self.array, float(x), float(y), float(z))

    @property
    def mean(self) -> Vec3:
        """Current output (zeros before the first accepted sample)."""
        return ma3_mean(self.array)


def _warm(array: State) -> None:
    """Compile the filter's kernels (or load them from numba's cache) once a process, on a copy of a filter's state:
    a filter's first sample waits for no compiler."""
    def compile_them() -> None:
        st = array.copy()
        ma3_update(st, 0.0, 0.0, 0.0)
        ma3_mean(st)

    warm_once(__name__, compile_them)


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
