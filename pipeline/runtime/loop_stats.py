"""Tick-period statistics of the haptic loop (:attr:`pipeline.runtime.loop.HapticLoop.stats`)."""

from __future__ import annotations

import math

__all__ = ["LoopStats"]


class LoopStats:
    """Tick-period statistics over arbitrarily long runs (1 µs histogram up to 50 ms)."""

    _BINS = 50_000

    def __init__(self, period_ns: int) -> None:
        self.period_ns = period_ns
        self.reset()

    def reset(self) -> None:
        """Forget all periods."""
        self._hist = [0] * (self._BINS + 1)
        self._nominal = 0  # periods exactly the nominal one: in no field below (see add)
        self._count = 0
        self._max_ns = 0
        self._over_2ms = 0
        self.missed_slots = 0

    def add(self, period_ns: int) -> None:
        """Record one tick period."""
        if period_ns == self.period_ns:
            # The nominal period -- every tick on a virtual clock -- is only counted; the figures add the count in
            # when they are read (readers only read: no other thread writes a field the loop writes).  One compare
            # and one increment instead of the bin, the count, the maximum and the 2 ms test.
            self._nominal += 1
            return
        us = period_ns // 1000
        self._hist[us if 0 <= us < self._BINS else self._BINS] += 1
        self._count += 1
        if period_ns > self._max_ns:
            self._max_ns = period_ns
        if period_ns > 2_000_000:
            self._over_2ms += 1

    def add_nominal(self, n: int) -> None:
        """Record ``n`` tick periods of exactly the nominal length (ticks run in a block on a virtual clock)."""
        self._nominal += n

    @property
    def count(self) -> int:
        """Periods recorded."""
        return self._count + self._nominal

    @property
    def max_ns(self) -> int:
        """The longest period, ns (0: none yet)."""
        return max(self._max_ns, self.period_ns) if self._nominal else self._max_ns

    @property
    def over_2ms(self) -> int:
        """Periods over 2 ms."""
        return self._over_2ms + (self._nominal if self.period_ns > 2_000_000 else 0)

    def _histogram(self) -> list[int]:
        """The periods' 1 µs histogram, the nominal ones in their bin."""
        hist = list(self._hist)
        us = self.period_ns // 1000
        hist[us if 0 <= us < self._BINS else self._BINS] += self._nominal
        return hist

    def _quantile_us(self, q: float, hist: list[int]) -> float:
        n = sum(hist)
        if n == 0:
            return math.nan
        target = q * n
        acc = 0
        for i, c in enumerate(hist):
            acc += c
            if acc >= target:
                return float(i)
        return float(len(hist) - 1)

    def summary(self) -> dict[str, float]:
        """p50/p99/max of the period and p99 of |period − nominal|, µs; counts."""
        hist = self._histogram()
        nominal_us = self.period_ns // 1000
        dev = [0] * (self._BINS + 1)
        for i, c in enumerate(hist):
            if c:
                dev[abs(i - nominal_us)] += c
        return {
            "ticks": float(self.count),
            "period_p50_us": self._quantile_us(0.5, hist),
            "period_p99_us": self._quantile_us(0.99, hist),
            "period_max_us": self.max_ns / 1000.0,
            "abs_dev_p99_us": self._quantile_us(0.99, dev),
            "periods_over_2ms": float(self.over_2ms),
            "missed_slots": float(self.missed_slots),
        }
