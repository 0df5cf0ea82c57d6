"""A dependency-free text progress bar for long command-line work."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO

#: A time left is said once the work has run this long and this share is done: earlier, the rate is the start-up's.
_ETA_AFTER_S = 2.0
_ETA_AFTER_FRACTION = 0.01


class ProgressBar:
    """Redraws ``label [#####     ] 42% 3.1/7.3 s  (4.2 s, about 6 s left)`` in place on a terminal, sparsely
    elsewhere; the time left is the mean rate so far extrapolated, said once it means something.

    Parameters
    ----------
    total
        Value at completion.
    label
        Text before the bar.
    unit
        Unit shown after the counts.
    stream
        Where to draw (stderr, so stdout stays clean for ``--json``).
    decimals
        Decimals of the counts (0 for things counted, like trials or samples).
    clock
        The clock of the elapsed time (seconds; tests give their own).
    """

    def __init__(self, total: float, label: str = "", unit: str = "", stream: TextIO | None = None,
                 decimals: int = 1, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self.decimals = decimals
        self.total = float(total) if total > 0 else 1.0
        self.label = label
        self.unit = unit
        self.stream = stream or sys.stderr
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._last_draw = 0.0
        self._last_pct = -1
        self._start = clock()

    def update(self, done: float) -> None:
        """Show progress ``done`` of ``total`` (throttled to 10 redraws per second)."""
        now = self._clock()
        frac = min(1.0, max(0.0, done / self.total))
        pct = int(frac * 100)
        if self._tty:
            if now - self._last_draw < 0.1 and frac < 1.0:
                return
        elif pct // 10 == self._last_pct // 10 and frac < 1.0:
            return  # not a terminal (CI log): a line every 10 %
        self._last_draw = now
        self._last_pct = pct
        width = 30
        fill = int(frac * width)
        bar = "#" * fill + " " * (width - fill)
        unit = f" {self.unit}" if self.unit else ""
        elapsed = now - self._start
        text = (f"{self.label} [{bar}] {pct:3d}% {done:,.{self.decimals}f}/{self.total:,.{self.decimals}f}{unit}  "
                f"({elapsed:.1f} s{_time_left(elapsed, frac)})")
        if self._tty:
            self.stream.write("\r" + text)
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def close(self) -> None:
        """Finish the line."""
        if self._tty:
            self.stream.write("\n")
            self.stream.flush()


def _time_left(elapsed_s: float, frac: float) -> str:
    """``", about 3 min left"`` from the mean rate so far, or "" while it says nothing yet (or at the end)."""
    if elapsed_s < _ETA_AFTER_S or not _ETA_AFTER_FRACTION <= frac < 1.0:
        return ""
    left_s = elapsed_s * (1.0 - frac) / frac
    if left_s < 60:
        return f", about {max(1, round(left_s))} s left"
    if left_s < 3600:
        return f", about {round(left_s / 60)} min left"
    return f", about {left_s / 3600:.1f} h left"
