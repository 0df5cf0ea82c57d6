"""A dependency-free text progress bar for long command-line work."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class ProgressBar:
    """Redraws ``label [#####     ] 42% 3.1/7.3 s`` in place on a terminal, sparsely elsewhere.

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
    """

    def __init__(self, total: float, label: str = "", unit: str = "", stream: TextIO | None = None,
                 decimals: int = 1) -> None:
        self.decimals = decimals
        self.total = float(total) if total > 0 else 1.0
        self.label = label
        self.unit = unit
        self.stream = stream or sys.stderr
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._last_draw = 0.0
        self._last_pct = -1
        self._start = time.monotonic()

    def update(self, done: float) -> None:
        """Show progress ``done`` of ``total`` (throttled to 10 redraws per second)."""
        now = time.monotonic()
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
                f"({elapsed:.1f} s)")
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
