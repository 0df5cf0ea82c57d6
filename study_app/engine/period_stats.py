"""Loop timing of the study engine, from the ring's ``period_ns`` column (numpy only, cheap)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["PeriodStats"]


class PeriodStats:
    """Histogram of tick periods (1 µs bins), in seconds, from the ring's ``period_ns`` column -- cheap, numpy only.

    The loop's own :class:`pipeline.runtime.loop.LoopStats` summary walks 50 000 bins in
    Python; doing that twice a second in the loop's process would steal the
    GIL from the loop thread for milliseconds.
    """

    BINS = 50_001

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.hist = np.zeros(self.BINS, dtype=np.int64)
        self._pending: list[np.ndarray] = []
        self.count = 0
        self.span_s = 0.0  # on the loop's own clock (virtual or real)

    def add(self, period_s: np.ndarray) -> None:
        # binned lazily (at summary time): one 50 000-bin pass per summary, not per block
        if len(period_s):
            self._pending.append(np.asarray(period_s, dtype=np.float64).copy())
            self.count += len(period_s)
            self.span_s += float(np.sum(period_s))

    def _fold(self) -> None:
        if self._pending:
            us = np.clip(np.round(np.concatenate(self._pending) * 1e6), 0, self.BINS - 1).astype(np.int64)
            self._pending = []
            self.hist += np.bincount(us, minlength=self.BINS)

    def _quantile(self, hist: np.ndarray, q: float) -> float:
        n = int(hist.sum())
        if n == 0:
            return math.nan
        return float(np.searchsorted(np.cumsum(hist), q * n))

    def summary(self, nominal_us: int = 1000) -> dict[str, float]:
        self._fold()
        h = self.hist
        idx = np.arange(self.BINS)
        dev = np.bincount(np.abs(idx - nominal_us), weights=h, minlength=self.BINS)
        return {
            "ticks": float(self.count),
            "period_p50_us": self._quantile(h, 0.5),
            "period_p99_us": self._quantile(h, 0.99),
            "abs_dev_p50_us": self._quantile(dev, 0.5),
            "abs_dev_p99_us": self._quantile(dev, 0.99),
            "periods_over_2ms": float(h[2001:].sum()),
            "period_max_us": float(np.flatnonzero(h)[-1]) if self.count else math.nan,
            "fraction_over_2ms": float(h[2001:].sum()) / self.count if self.count else math.nan,
            "rate_hz": self.count / self.span_s if self.span_s > 0 else math.nan,
        }
