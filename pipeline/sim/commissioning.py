"""The commissioning steps a lab runs on the real rig, carried out on the simulated one.

* :func:`pivot_poses` -- the TCP pivot calibration: the tip rests in the
  divot (``SimRigConfig.pivot_m``) while the instrument is turned through the
  orientations; the robot reports its flange pose, which with the tip at
  ``SimRigConfig.tip_in_flange_m`` is ``pivot − R·t`` -- plus the robot's
  repeatability and the tip's seat in the divot (``pivot_noise_m``).  Nothing
  of the true offset reaches the caller but through these poses.
* :func:`push_axes` -- the frame and sign check: with the tip free, the
  simulated experimenter pushes it along each base axis (a 1 N push, ramped
  in and out) while the loop runs with feedback off; the loop's records give
  the compensated base-frame force and the force it would render.

The payload/bias step is :func:`pipeline.sim.calibration.auto_calibrate`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from pipeline.commissioning.frame_check import AXES, FrameCheck, axis_vector, check_axis
from pipeline.commissioning.tcp import PivotPose
from pipeline.force.frames import Mat3, mat_vec
from pipeline.runtime.loop import HapticLoop
from pipeline.runtime.loop_messages import AllowBiasRefinement, SetHaptics
from pipeline.sim.hand import HoldStill
from pipeline.sim.rig import SimRig

if TYPE_CHECKING:
    from pipeline.force.framework import HapticFramework
    from pipeline.runtime.ring import RingBuffer

__all__ = ["PUSH_N", "pivot_poses", "push_axes"]

#: How hard the simulated experimenter pushes the tip, N (gently: well below the tissue's, above the check's 0.3 N).
PUSH_N = 1.0
_RAMP_S, _HOLD_S, _REST_S = 0.3, 0.8, 0.4


def pivot_poses(rig: SimRig, orientations: Sequence[Mat3], seed: int = 0) -> list[PivotPose]:
    """The flange poses the robot reports with the tip in the divot at each orientation (``rot_base_flange``)."""
    cfg = rig.config
    rng = np.random.default_rng([cfg.seed, seed, 11])
    t = cfg.tip_in_flange_m
    out = []
    for k, rot in enumerate(orientations):
        seat = cfg.pivot_m + rng.normal(0.0, cfg.pivot_noise_m, 3)
        tip_base = mat_vec(rot, t)
        flange = seat - np.asarray(tip_base) + rng.normal(0.0, cfg.pivot_noise_m, 3)
        out.append(PivotPose(rot, tuple(float(v) for v in flange), f"O{k + 1}"))  # type: ignore[arg-type]  # three items: mypy cannot count a generator
    return out


def push_axes(
    rig: SimRig, loop: HapticLoop, ring: RingBuffer, axes: Sequence[str] = AXES, *, push_n: float = PUSH_N,
    progress: Callable[[str], None] | None = None, framework: HapticFramework | None = None,
) -> FrameCheck:
    """Push the free tip along each axis with the loop running (feedback off) and check the directions.

    ``ring`` is the loop's ring buffer (the records are read back from it).  The rig's stylus is held
    still (the tip hangs clear of the tissue) and restored afterwards.  On a loop of several arms ``rig``,
    ``ring`` and ``framework`` are the checked arm's (``framework`` None: the loop's first arm's).
    """
    old = rig.driver
    rig.set_driver(HoldStill(0.0))
    loop.submit(SetHaptics(False))
    loop.submit(AllowBiasRefinement(False))
    fw = framework if framework is not None else loop.framework
    results = []
    try:
        loop.run_ticks(int(_REST_S * 1000))
        for axis in axes:
            if progress is not None:
                progress(axis)
            e = np.asarray(axis_vector(axis), dtype=float)
            cursor = ring.write_count
            n_ramp, n_hold = int(_RAMP_S * 1000), int(_HOLD_S * 1000)
            profile = np.concatenate([np.linspace(0.0, 1.0, n_ramp), np.ones(n_hold), np.linspace(1.0, 0.0, n_ramp)])
            for k in profile:
                rig.push_base_n = tuple(float(v) for v in push_n * k * e)  # type: ignore[assignment]  # three items: mypy cannot count a generator
                loop.run_ticks(1)
            rig.push_base_n = (0.0, 0.0, 0.0)
            loop.run_ticks(int(_REST_S * 1000))
            rows = ring.read_since(cursor).rows
            base = np.stack([rows["base_fx"], rows["base_fy"], rows["base_fz"]], axis=1)
            scaled = np.stack([rows["scaled_fx"], rows["scaled_fy"], rows["scaled_fz"]], axis=1)
            results.append(check_axis(axis, base, scaled, fw.config.rot_haptic_base))
    finally:
        rig.push_base_n = (0.0, 0.0, 0.0)
        rig.set_driver(old)
    return FrameCheck(tuple(results), fw.config.rot_tip_sensor, fw.config.rot_haptic_base)
