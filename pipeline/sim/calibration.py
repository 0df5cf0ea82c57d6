"""Automatic gravity/bias calibration on the simulated rig.

On hardware the experimenter moves the robot through the pose set; here the
simulated robot is re-oriented pose by pose, with the tool hanging clear of the
tissue, and the same averaging and least squares as on hardware
(:func:`pipeline.commissioning.payload_identification.identify_payload`) produce the calibration.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from pipeline.commissioning.payload_identification import CalibrationPose, identify_payload, recommended_pose_set
from pipeline.core.clock import Clock
from pipeline.force.frames import Mat3, mat_mul, transpose
from pipeline.force.payload_compensator import PayloadCalibration
from pipeline.sim.block import hold_still
from pipeline.sim.hand import HoldStill
from pipeline.sim.rig import SimRig
from pipeline.sim.robot import TOOL_DOWN

__all__ = ["auto_calibrate", "calibration_duration_ns", "collect_pose", "measure_poses"]


def _settle_ticks(settle_s: float) -> int:
    return max(1, int(settle_s * 1000))


def calibration_duration_ns(n_poses: int, *, samples_per_pose: int = 200, settle_s: float = 0.3) -> int:
    """Rig time :func:`auto_calibrate` takes for ``n_poses`` poses: settle, then average, at 1 kHz, ns."""
    return n_poses * (_settle_ticks(settle_s) + samples_per_pose) * 1_000_000


def collect_pose(rig: SimRig, clock: Clock, samples: int, label: str = "",
                 period_ns: int = 1_000_000) -> CalibrationPose:
    """Average ``samples`` ticks of wrench at the current pose into a :class:`CalibrationPose`.

    The orientation is the one the robot *reports*, combined with the
    nominal sensor mounting -- exactly what the application knows on hardware.
    """
    acc = [0.0] * 6
    hold_still(rig, clock, samples, acc, period_ns)  # each tick's newest wrench added in, tick by tick
    pose = rig.robot.read_pose()
    rot_base_sensor = mat_mul(pose.rot_base_tip, rig.config.rot_tip_sensor)
    return CalibrationPose(rot_base_sensor, tuple(a / samples for a in acc), label)  # type: ignore[arg-type]  # six items: mypy cannot count a generator


def measure_poses(
    rig: SimRig,
    clock: Clock,
    orientations: Sequence[Mat3],
    *,
    samples_per_pose: int = 200,
    settle_s: float = 0.3,
    progress: Callable[[int, int], None] | None = None,
) -> list[CalibrationPose]:
    """Turn the simulated robot through ``orientations`` (sensor orientations ``rot_base_sensor``) and average the
    wrench at each, the tool hanging clear of the tissue: the poses an experimenter would record.

    ``progress`` is called with (poses done, total); see :func:`auto_calibrate` for the other parameters.
    """
    rots = list(orientations)
    rts_t = transpose(rig.config.rot_tip_sensor)
    old_driver = rig.driver
    # The hand returns the stylus to its start pose: the tip hangs at the
    # start gap above the tissue, out of contact, while the tool re-orients.
    rig.set_driver(HoldStill(0.0))
    settle_ticks = _settle_ticks(settle_s)
    poses: list[CalibrationPose] = []
    try:
        for k, rot_base_sensor in enumerate(rots):
            rig.robot.set_orientation(mat_mul(rot_base_sensor, rts_t))
            hold_still(rig, clock, settle_ticks)
            poses.append(collect_pose(rig, clock, samples_per_pose, label=f"P{k + 1:02d}"))
            if progress is not None:
                progress(k + 1, len(rots))
    finally:
        rig.robot.set_orientation(TOOL_DOWN)
        rig.set_driver(old_driver)
    return poses


def auto_calibrate(
    rig: SimRig,
    clock: Clock,
    orientations: Sequence[Mat3] | None = None,
    *,
    samples_per_pose: int = 200,
    settle_s: float = 0.3,
    model: str = "auto",
    progress: Callable[[int, int], None] | None = None,
) -> tuple[PayloadCalibration, list[CalibrationPose]]:
    """Run the pose set on the simulated rig and identify the payload.

    Parameters
    ----------
    rig, clock
        The rig and the clock that paces it (a virtual clock makes this instant).
    orientations
        Sensor orientations ``rot_base_sensor``; default
        :func:`pipeline.commissioning.payload_identification.recommended_pose_set` (24 poses).
    samples_per_pose, settle_s
        Averaging and settling per pose (science.md §1.2: settle, then average 100–500).
    progress
        Called with (poses done, total).

    Returns
    -------
    (calibration, poses)
    """
    rots = list(orientations) if orientations is not None else recommended_pose_set(24)
    poses = measure_poses(rig, clock, rots, samples_per_pose=samples_per_pose, settle_s=settle_s, progress=progress)
    return identify_payload(poses, model=model), poses
