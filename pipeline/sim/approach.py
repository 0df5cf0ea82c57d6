"""The simulated participant's approach to the tissue: where it aims, and when a watched one is stopped.

Two pure functions of what the participant sees and believes (:mod:`pipeline.sim.participant` keeps the state):

* :func:`approach_end_y` -- the feed-forward approach's end: the believed surface (the visible gap plus the trial's
  surface-depth error) plus the believed target indentation, and with feedback ON the expected push-back the
  participant pre-compensates;
* :func:`seen_over_aim` -- the check of a *watched* approach (feedback OFF, model version 3): the approach that
  cannot feel contact is watched on the camera image, delayed by the visual channel's latency, and stopped when the
  force the participant reads into the seen indentation passes ``(1 + excess)`` × the force aimed at.

Why the watch (docs/participant-calibration.md has the fit and its validation).  Without force feedback the approach is
slower (v2's fitted factor 1.75: contact can only be seen) because it is guided by the image: aiming movements are
corrected online from vision with a delay of a visual reaction (Elliott, Helsen & Chua 2001, *Psychol. Bull.*
127:342-357; Saunders & Knill 2003, *Exp. Brain Res.* 152:341-352), and a move that meets something sooner than
expected is stopped and re-planned (a guarded move).  Model v2 had none of it: an approach whose surface-depth error
sat 2-3σ deep ended 9-13 mm past where it was meant to (10 % of OFF trials had a Max AE above 7.9 N at targets of
0.6 and 1.2 N), which made OFF's Max AE 40 % above the paper's on the participants ``run`` meets.  With feedback
the approach is not watched this way: it is fast and feed-forward, planned *through* the expected push-back (which
physically limits how deep it goes, :mod:`pipeline.sim.hand`), and corrected by feel after it.
"""

from __future__ import annotations

__all__ = ["approach_end_y", "seen_over_aim"]


def approach_end_y(y_stylus_m: float, gap_m: float, indentation_m: float, surface_err_m: float,
                   target_depth_m: float, motion_scale: float, pushback_m: float) -> float:
    """Where the feed-forward approach ends (m along the Touch's +y from the start pose; pressing is negative).

    ``gap_m`` and ``indentation_m`` are what the image showed (clipped to the rig's range: a NaN gap is taken as the
    rig's 15 mm start gap, a NaN indentation as none); ``surface_err_m`` > 0 believes the surface deeper than it is;
    ``pushback_m`` is the expected push-back the participant pre-compensates (0 without feedback).
    """
    if not (0.0 <= gap_m <= 0.1):
        gap_m = 0.015 if gap_m != gap_m else (0.0 if gap_m < 0.0 else 0.1)
    if not (0.0 <= indentation_m <= 0.05):
        indentation_m = 0.0 if (indentation_m != indentation_m or indentation_m < 0.0) else 0.05
    surface = y_stylus_m - (gap_m + surface_err_m) / motion_scale + indentation_m / motion_scale
    return surface - target_depth_m / motion_scale - pushback_m


def seen_over_aim(indentation_m: float, stiffness_belief: float, exponent: float, aim_n: float,
                  excess: float) -> bool:
    """True when the force read into the seen indentation (``k̂·δⁿ``) exceeds ``(1 + excess) · aim_n``.

    No usable image (NaN, negative or beyond 50 mm) is no reason to stop.
    """
    if not (0.0 <= indentation_m <= 0.05):
        return False
    return stiffness_belief * float(indentation_m**exponent) > (1.0 + excess) * aim_n
