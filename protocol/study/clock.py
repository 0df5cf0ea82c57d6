"""The session clock: where loop time (integer ns) becomes session time (seconds), in one place.

Inside the program every time is an integer count of nanoseconds on the haptic
loop's clock (``t_ns`` of its records).  Session time -- the seconds in the
``events``, ``trials`` and ``session_blocks`` columns -- runs across a
session's runs: a resumed run continues from the last stored moment.  A run's
records are one segment of the recording, and the segment's ``recordings`` row
pins its loop clock to the session clock: at loop time ``t0_ns`` the session
clock read ``started_at_s``.  :meth:`SessionClock.seconds` is the one formula
that turns loop ns into session seconds; it is used at the edges only (the
database columns, CSVs, plots, displays).

Why not session-clock nanoseconds: the anchor ``started_at_s`` of a resumed
run is a stored double (the last stored session time plus a step), and a
double made from it and back would move the stored values by the last bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["SessionClock"]


@dataclass(frozen=True, slots=True)
class SessionClock:
    """Session time of loop timestamps: at loop time ``t0_ns`` the session clock read ``started_at_s``.

    Attributes
    ----------
    started_at_s
        Session time at the anchor, s (a segment's ``recordings.started_at_s``).
    t0_ns
        Loop time at the anchor, ns (a segment's ``recordings.t0_ns``: its first record).
    """

    started_at_s: float
    t0_ns: int

    def seconds(self, t_ns: int) -> float:
        """Session time of one loop timestamp, s."""
        return self.started_at_s + (t_ns - self.t0_ns) / 1e9

    def seconds_of(self, t_ns: npt.NDArray[np.int64]) -> npt.NDArray[np.float64]:
        """Session time of an array of loop timestamps, s (element for element equal to :meth:`seconds`)."""
        return self.started_at_s + (t_ns - self.t0_ns) / 1e9
