"""How a task-force axis is scaled for people: by the target, so the target band is always readable.

The live plot of the experimenter's window and the trial figures of the
report (``plot-trial``) share this rule.  An axis fitted to the data lets one
large force -- the raw sensor's 7.6 N of tool weight, a hard press into the
tissue -- squeeze a ±10 % band around 0.6 N into a strip a few pixels high.
"""

from __future__ import annotations

import math

__all__ = ["TASK_AXIS_STRETCH_MAX", "TASK_AXIS_TARGETS", "task_axis_top_n"]

#: The axis shows 0 to this many times the target force (a ±10 % band is then 8 % of its height) ...
TASK_AXIS_TARGETS = 2.5
#: ... stretched for a larger peak up to this many times the target; a larger force is drawn clipped.
TASK_AXIS_STRETCH_MAX = 4.0


def task_axis_top_n(target_force_n: float | None, peak_n: float, *, snap_fraction: float = 0.0) -> float:
    """Upper end of a task-force axis that starts at 0 N.

    Parameters
    ----------
    target_force_n
        The target F* (N); None or not positive: the axis follows the data (``peak_n`` + 10 %, at least 1 N).
    peak_n
        Largest force to show (N); NaN when there is none.
    snap_fraction
        Round a stretched top up to a multiple of this fraction of F* (0: no rounding), so a live axis
        moves only when the data cross a step.

    Returns
    -------
    float
        ``2.5·F*``, or up to ``4·F*`` to show a larger peak with 5 % headroom.
    """
    if target_force_n is None or not (target_force_n > 0 and math.isfinite(target_force_n)):
        return max(1.0, peak_n * 1.1) if math.isfinite(peak_n) else 1.0
    top = TASK_AXIS_TARGETS * target_force_n
    if math.isfinite(peak_n) and peak_n * 1.05 > top:
        top = peak_n * 1.05
        if snap_fraction > 0:
            step = snap_fraction * target_force_n
            top = math.ceil(top / step - 1e-9) * step
        top = min(top, TASK_AXIS_STRETCH_MAX * target_force_n)
    return top
