"""How a simulated person perceives (the regulation participant's and the tracking hand's one definition).

* :func:`newest_at` -- the observation a delayed percept sees: the newest of the last :data:`HISTORY_TICKS` ticks'
  observations at or before the time looked at, never one from before the trial's cue;
* :func:`weber_sigma` -- the per-look log noise of the felt force at its displayed level: the participant's Weber
  fraction σ_h at the GENTLE display (0.257 N), falling as ``(0.257/f)^0.325`` to a floor of 0.8 σ_h at FIRM's
  0.509 N (docs/science.md §4.1: JNDs of 10–15 % at the GENTLE display, 8–12 % at FIRM's);
* :func:`inverse_scale` -- the tissue force whose rendered magnitude is the felt one: the inverse of the pipeline's
  tanh law (:func:`pipeline.force.scaling.scale_magnitude`), clipped short of its asymptote.
"""

from __future__ import annotations

import math

from pipeline.core.compiled import State, kernel

__all__ = ["HISTORY_TICKS", "inverse_scale", "newest_at", "weber_sigma"]

#: Ticks of observation history a simulated person keeps: ≥ the longest percept delay (0.36 s) at 1 kHz, a power of
#: two (the ring's index wraps by a mask).
HISTORY_TICKS = 1024
_MASK = HISTORY_TICKS - 1

#: The felt force at the GENTLE target through the paper's law (3 N · tanh(0.6 N / 7 N)), N.
DISPLAY_GENTLE_N = 0.257
_WEBER_EXP = 0.325
_WEBER_FLOOR = 0.8
#: The felt force is read back no closer than this to f_max: the tanh law's inverse is infinite there.
_X_MAX = 0.999


@kernel
def newest_at(times_s: State, newest: int, t_s: float, not_before_s: float) -> int:
    """Index, in a ring of :data:`HISTORY_TICKS` observation times whose newest is at ``newest`` (unfilled slots -inf),
    of the newest observation at or before ``t_s`` -- or before ``not_before_s`` if ``t_s`` is earlier; the oldest
    kept if none is that old (compiled: a look back of 0.36 s is 360 steps)."""
    if t_s < not_before_s:
        t_s = not_before_s
    j = newest
    for _ in range(HISTORY_TICKS - 1):
        if times_s[j] <= t_s:
            return j
        jn = (j - 1) & _MASK
        if times_s[jn] == -math.inf:
            return j
        j = jn
    return j


def weber_sigma(sigma_haptic: float, felt_n: float) -> float:
    """Log noise of one look at a felt force of ``felt_n`` N, for a participant whose σ_h at GENTLE is
    ``sigma_haptic``."""
    if felt_n > DISPLAY_GENTLE_N:
        return sigma_haptic * max(_WEBER_FLOOR, float((DISPLAY_GENTLE_N / felt_n) ** _WEBER_EXP))
    return sigma_haptic


def inverse_scale(felt_n: float, f_max_n: float, f_scale_n: float) -> float:
    """Tissue force (N) whose rendered magnitude is ``felt_n``: ``f_scale·atanh(felt/f_max)``, 0 for none or less,
    the argument clipped at 0.999 (a felt force at or past f_max reads as ≈ 3.8 f_scale, not infinity)."""
    x = felt_n / f_max_n
    if x <= 0.0:
        return 0.0
    if x >= _X_MAX:
        x = _X_MAX
    return f_scale_n * math.atanh(x)
