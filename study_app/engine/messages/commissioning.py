"""The messages of the commissioning chain: the calibration steps (GUI → engine) and their results (engine → GUI).

Applied by :class:`study_app.engine.commissioning.Commissioning`; shown by the calibration wizard's models
(:mod:`study_app.models.calibration`, :mod:`study_app.models.real_calibration`,
:mod:`study_app.models.commissioning`).  Every step's command names the arm it commissions (:class:`ArmStep`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pipeline.commissioning.steps import PAYLOAD_POSE_SETS
from pipeline.commissioning.tcp import PIVOT_POSE_SETS
from pipeline.force.frames import Mat3, Vec3
from pipeline.force.payload_compensator import Wrench

__all__ = [
    "PIVOT_SETS",
    "POSE_SETS",
    "ArmStep",
    "Calibrate",
    "CalibrateTcp",
    "CalibrationDone",
    "CalibrationProgress",
    "CalibrationStatus",
    "CheckFrames",
    "FrameAxisChecked",
    "FrameCheckDone",
    "IdentifyPoses",
    "IdentifyTcp",
    "PivotRecorded",
    "PoseRecorded",
    "RecordFrameAxis",
    "RecordPivot",
    "RecordPose",
    "TcpCalibrationDone",
]

#: Calibration pose sets offered by the wizard (named once, by :func:`pipeline.commissioning.steps.pose_set`).
POSE_SETS = PAYLOAD_POSE_SETS
#: TCP pivot orientation sets the wizard offers on the simulated rig
#: (:func:`pipeline.commissioning.tcp.pivot_orientations`).
PIVOT_SETS = PIVOT_POSE_SETS


# -- commands (GUI → engine) --------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class ArmStep:
    """A calibration step's command: ``arm`` names the arm it commissions ("": the first, a one-arm rig's only one).

    Given by keyword (``Calibrate("quick", arm="right")``); the calibration window sets it for the arm it shows.
    """

    arm: str = field(default="", kw_only=True)


@dataclass(frozen=True, slots=True)
class Calibrate(ArmStep):
    """Run the gravity/bias identification with one of :data:`POSE_SETS`."""

    pose_set: str = "recommended"


@dataclass(frozen=True, slots=True)
class RecordPose(ArmStep):
    """Real rig: average ``seconds`` of raw wrench at the robot's current pose and read its TCP orientation.

    The engine answers with :class:`PoseRecorded` (or :class:`CommandRefused` naming why,
    e.g. the robot moved while recording).  ``target_rot_base_sensor`` is the pose the wizard
    asked for; the recorded orientation is the one the robot reports.
    """

    label: str
    seconds: float = 1.0
    target_rot_base_sensor: Mat3 | None = None  # row-major


@dataclass(frozen=True, slots=True)
class IdentifyPoses(ArmStep):
    """Real rig: identify payload and bias from recorded poses (label, rot_base_sensor as 9 numbers, wrench); install if
    accepted."""

    poses: tuple[tuple[str, Mat3, Wrench], ...]
    pose_set: str = "recommended"


@dataclass(frozen=True, slots=True)
class CalibrateTcp(ArmStep):
    """Simulated rig: run the TCP pivot calibration with one of :data:`PIVOT_SETS` (the simulated robot turns)."""

    pose_set: str = "recommended"


@dataclass(frozen=True, slots=True)
class RecordPivot(ArmStep):
    """Real rig: the tip rests in the divot; average the TCP pose for ``seconds`` (answered by
    :class:`PivotRecorded`)."""

    label: str
    seconds: float = 0.5


@dataclass(frozen=True, slots=True)
class IdentifyTcp(ArmStep):
    """Real rig: pivot calibration from recorded flange poses (label, rot_base_flange as 9 numbers, position m)."""

    poses: tuple[tuple[str, Mat3, Vec3], ...]


@dataclass(frozen=True, slots=True)
class CheckFrames(ArmStep):
    """Simulated rig: the frame and sign check (the simulated experimenter pushes the free tip along each axis)."""


@dataclass(frozen=True, slots=True)
class RecordFrameAxis(ArmStep):
    """Real rig: record ``seconds`` while the experimenter pushes the free tip along base ``axis`` (+x, +y, +z)."""

    axis: str
    seconds: float = 3.0


# -- events (engine → GUI) ----------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class CalibrationProgress:
    """Pose ``done`` of ``total`` measured."""

    done: int
    total: int
    label: str


@dataclass(frozen=True, slots=True)
class CalibrationDone:
    """Result of a calibration run: installed if ``accepted``, else ``reason`` says why not."""

    accepted: bool
    reason: str
    pose_set: str
    n_poses: int
    condition_number: float
    rms_force_residual_n: float
    rms_torque_residual_nm: float
    residuals: list[tuple[str, float, float]]
    calibration: dict[str, Any] | None


@dataclass(frozen=True, slots=True)
class PoseRecorded:
    """One calibration pose measured on the real rig.

    ``rot_base_sensor`` is the reported TCP orientation times the configured sensor mount;
    ``off_target_deg`` the angle between it and the requested pose (NaN if none was given);
    ``force_std_n`` the standard deviation of the force magnitude while averaging.
    """

    label: str
    samples: int
    wrench: tuple[float, float, float, float, float, float]
    rot_base_sensor: Mat3  # row-major
    tcp_position_m: tuple[float, float, float]
    off_target_deg: float
    force_std_n: float


@dataclass(frozen=True, slots=True)
class PivotRecorded:
    """Real rig: one orientation of the TCP pivot calibration, as the flange pose (base frame)."""

    label: str
    rot_base_flange: Mat3  # row-major
    flange_position_m: tuple[float, float, float]
    moved_mm: float


@dataclass(frozen=True, slots=True)
class TcpCalibrationDone:
    """Result of a TCP pivot calibration: saved and in use if ``accepted``, else ``reason`` says which orientations
    to add.

    ``result`` is :meth:`pipeline.commissioning.tcp.TipCalibration.to_dict`; ``error_mm`` the distance from the
    simulated rig's true tip (NaN on the real rig).
    """

    accepted: bool
    reason: str
    pose_set: str
    n_poses: int
    result: dict[str, Any] | None
    error_mm: float = float("nan")


@dataclass(frozen=True, slots=True)
class FrameAxisChecked:
    """One axis of the frame and sign check (:meth:`pipeline.commissioning.frame_check.AxisCheck.to_dict`, and its line
    of text)."""

    axis: str
    passed: bool
    line: str
    result: dict[str, Any]


@dataclass(frozen=True, slots=True)
class FrameCheckDone:
    """Every axis checked: the verdict (one line), each axis' line; on record for the tool either way."""

    passed: bool
    summary: str
    lines: list[str]


@dataclass(frozen=True, slots=True)
class CalibrationStatus:
    """What is on record for the mounted tool: per step (name, done, one line), and what the session gate would say.

    ``missing`` is "" when a session may start (real rig), else the one line of the first step to do;
    ``file`` the calibration file ("" on the simulated rig, where nothing is saved).
    """

    rig: str
    tool: str
    file: str
    steps: list[tuple[str, bool, str]]
    missing: str
    arm: str = ""  # the arm it is about ("": a one-arm rig's)
