"""The commissioning steps as one service: their limits, their judgements and what each puts on record.

Two front ends run the commissioning chain -- the study engine for the GUI's calibration wizard
(:mod:`study_app.engine.commissioning`, which averages windows of the ring's records) and
``haptic-study calibrate`` (:mod:`study_app.cli.calibrate_cmds`, which reads the devices itself).  Each
gathers its data its own way and hands it here; everything that decides -- is a recording still enough, is a
payload fit good enough, did the frames pass, is the force at rest low enough, which step must come first --
lives in this module, with every limit and every refusal's words defined once.  Each front end then presents
the same frozen result: the engine as messages, the command line as text or JSON.

The functions are pure (no device, no clock, no printing): the inputs are averaged sensor windows and robot
poses, the outputs frozen records.  ``reason`` is ``""`` when a step or a recording is accepted, else the
one-line refusal (without the front end's prefix: which pose, which command).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import ClassVar, TypeAlias

import numpy as np
import numpy.typing as npt

from pipeline.commissioning.frame_check import AXES, AxisCheck, FrameCheck
from pipeline.commissioning.payload_identification import (
    CalibrationPose,
    DegeneratePoseSetError,
    identify_payload,
    recommended_pose_set,
)
from pipeline.commissioning.rig_calibration import ToolCalibration
from pipeline.commissioning.tcp import PivotPose, TipCalibration, identify_tip
from pipeline.devices.interfaces import PoseSample
from pipeline.force.frames import Mat3, Vec3, as_mat3, axis_angle, mat_mul, transpose
from pipeline.force.payload_compensator import PayloadCalibration, Wrench

__all__ = [
    "CALIBRATION_MAX_CONDITION",
    "CALIBRATION_MAX_RMS_FORCE_N",
    "PAYLOAD_POSE_SETS",
    "PIVOT_STILL_DEG",
    "PIVOT_STILL_M",
    "POSE_MAX_AGE_S",
    "POSE_MAX_SENSOR_AGE_S",
    "POSE_STILL_DEG",
    "POSE_STILL_M",
    "REST_CHECK_S",
    "REST_MAX_FORCE_N",
    "FramesResult",
    "PayloadResult",
    "RecordedPivot",
    "RecordedPose",
    "TcpResult",
    "calibration_verdict",
    "chain_refusal",
    "frame_check_of",
    "frames_step",
    "payload_step",
    "pose_set",
    "record_pivot",
    "record_pose",
    "rest_check_note",
    "rest_force_n",
    "rest_verdict",
    "robot_pose_refusal",
    "rotation_angle_deg",
    "sensor_stalled",
    "tcp_step",
    "tcp_target",
]

_FloatArray: TypeAlias = npt.NDArray[np.float64]

#: Named payload pose sets (see :func:`pose_set`).
PAYLOAD_POSE_SETS = ("recommended", "quick", "tool-down only")
#: A payload fit whose (column-scaled) regressor is worse conditioned than this is refused ...
CALIBRATION_MAX_CONDITION = 1000.0
#: ... as is one that leaves more than this RMS force residual (a pose in contact, a loose tool), N.
CALIBRATION_MAX_RMS_FORCE_N = 0.05
#: A payload pose is refused if the TCP turned more than this (degrees), or moved more than the next (m), while
#: its wrench was averaged.
POSE_STILL_DEG = 0.5
POSE_STILL_M = 0.002
#: ... or if a force sample older than this was averaged (the sensor stalled), s.
POSE_MAX_SENSOR_AGE_S = 0.05
#: A recording does not start from a robot pose older than this, s (the RTDE stream stopped).
POSE_MAX_AGE_S = 0.5
#: A TCP pivot orientation is refused if the TCP moved more than this (m) or turned more than the next (degrees)
#: while it was averaged: the tip must stay seated in the divot.
PIVOT_STILL_M = 0.0002
PIVOT_STILL_DEG = 0.2
#: Real rig: a session starts only if the compensated force at rest, averaged over this long (s), is below the
#: next (N).
REST_CHECK_S = 2.0
REST_MAX_FORCE_N = 0.1
#: Which step's result each step needs on record first (the chain runs tcp → payload → frames).
_NEEDS = {"payload": ("tcp", "TCP calibration"), "frames": ("payload", "payload calibration")}


# -- shared pieces --------------------------------------------------------------------------------------------
def rotation_angle_deg(a: Mat3, b: Mat3) -> float:
    """The angle of the rotation taking orientation ``a`` to ``b``, degrees (0–180)."""
    ra, rb = np.asarray(a, dtype=float).reshape(3, 3), np.asarray(b, dtype=float).reshape(3, 3)
    c = (float(np.trace(ra.T @ rb)) - 1.0) / 2.0
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def pose_set(name: str) -> list[Mat3]:
    """Sensor orientations ``rot_base_sensor`` of a named payload pose set (:data:`PAYLOAD_POSE_SETS`).

    ``recommended``: 24 well-spread tilts (science.md §1.2); ``quick``: 6; ``tool-down only``: 6 yaws about the
    vertical with the tool pointing down, which leave gravity fixed in the sensor frame -- a degenerate set the
    identification refuses (kept so an experimenter can see what a refusal says).
    """
    if name == "recommended":
        return recommended_pose_set(24)
    if name == "quick":
        return recommended_pose_set(6)
    if name == "tool-down only":
        down = recommended_pose_set(24)[0]
        return [mat_mul(axis_angle((0.0, 0.0, 1.0), k * 0.5), down) for k in range(6)]
    raise ValueError(f"pose set = {name!r}: allowed values are {', '.join(PAYLOAD_POSE_SETS)}")


def tcp_target(rot_base_sensor: Mat3, rot_tip_sensor: Mat3) -> Mat3:
    """The TCP orientation ``rot_base_tip`` that puts the sensor at ``rot_base_sensor`` (what the pendant shows)."""
    return mat_mul(rot_base_sensor, transpose(rot_tip_sensor))


def _moved_refusal(moved_m: float, turned_deg: float, max_m: float, max_deg: float) -> str:
    """"" if the robot stood still enough, else the refusal (one text for every recording)."""
    if moved_m <= max_m and turned_deg <= max_deg:
        return ""
    return (f"the robot moved while recording ({moved_m * 1e3:.2f} mm, {turned_deg:.2f}°; allowed {max_m * 1e3:g} mm "
            f"and {max_deg:g}°) — hold it still and record again")


def robot_pose_refusal(pose: PoseSample, now_ns: int | None = None) -> str:
    """"" if ``pose`` can start a recording; else why not (no pose yet, or older than :data:`POSE_MAX_AGE_S`)."""
    if not all(math.isfinite(x) for x in pose.position_m):
        return "no TCP pose received from the robot yet; check the RTDE connection"
    if now_ns is not None and (now_ns - pose.t_ns) * 1e-9 > POSE_MAX_AGE_S:
        return f"the robot's newest TCP pose is {(now_ns - pose.t_ns) * 1e-9:.1f} s old; check the RTDE connection"
    return ""


def sensor_stalled(sensor_age_ns: npt.ArrayLike) -> bool:
    """A window averaged a force sample older than :data:`POSE_MAX_SENSOR_AGE_S` (the sensor stalled)."""
    ages = np.asarray(sensor_age_ns, dtype=float)
    return bool(ages.size) and float(np.max(ages)) * 1e-9 > POSE_MAX_SENSOR_AGE_S


def chain_refusal(record: ToolCalibration, step: str) -> str:
    """"" if ``step`` may run for the tool on ``record``; else which step must come first (the chain's order)."""
    if step not in _NEEDS:
        return ""
    needed, what = _NEEDS[step]
    if getattr(record, needed) is not None:
        return ""
    return f"no {what} on record for tool {record.tool!r}; the chain runs in order: calibrate {needed} first"


# -- payload ----------------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class RecordedPose:
    """One payload pose measured with the tool hanging free: the averaged wrench at the robot's orientation.

    ``reason`` is "" when the pose is usable, else why it is refused; ``rot_base_sensor`` is the reported TCP
    orientation times the configured sensor mount; ``off_target_deg`` the angle from the requested orientation
    (NaN if none was given); ``force_std_n`` the standard deviation of the force magnitude over the window.
    """

    label: str
    reason: str
    samples: int
    wrench: Wrench
    rot_base_sensor: Mat3
    tcp_position_m: Vec3
    off_target_deg: float
    force_std_n: float

    @property
    def accepted(self) -> bool:
        """The pose may go into the identification."""
        return self.reason == ""

    def pose(self) -> CalibrationPose:
        """The pose for :func:`payload_step`."""
        return CalibrationPose(self.rot_base_sensor, self.wrench, self.label)


def record_pose(label: str, wrench: npt.ArrayLike, before: PoseSample, after: PoseSample, rot_tip_sensor: Mat3,
                target_rot_base_sensor: Mat3 | None = None) -> RecordedPose:
    """Judge and average one payload pose.

    Parameters
    ----------
    label
        The pose's name (``"P01"``).
    wrench
        The raw wrench over the window, shape (n, 6), N and N·m (sensor frame).
    before, after
        The robot's TCP pose when the window opened and when it closed (the robot must stand still).
    rot_tip_sensor
        The configured sensor mount (``[frames]``).
    target_rot_base_sensor
        The orientation the experimenter was asked for, if any.
    """
    w = np.asarray(wrench, dtype=float).reshape(-1, 6)
    rot = mat_mul(after.rot_base_tip, rot_tip_sensor)
    position = (float(after.position_m[0]), float(after.position_m[1]), float(after.position_m[2]))
    reason = robot_pose_refusal(before) or robot_pose_refusal(after)
    if not reason and not (len(w) and np.isfinite(w).all()):
        reason = "the force sensor gave non-finite readings" if len(w) else "the force sensor gave no readings"
    if not reason:
        reason = _moved_refusal(math.dist(before.position_m, after.position_m),
                                rotation_angle_deg(before.rot_base_tip, after.rot_base_tip), POSE_STILL_M,
                                POSE_STILL_DEG)
    if reason:
        nan6 = (math.nan,) * 6
        return RecordedPose(label, reason, len(w), nan6, rot, position, math.nan, math.nan)
    m = w.mean(axis=0)
    mean: Wrench = (float(m[0]), float(m[1]), float(m[2]), float(m[3]), float(m[4]), float(m[5]))
    off = rotation_angle_deg(target_rot_base_sensor, rot) if target_rot_base_sensor is not None else math.nan
    return RecordedPose(label, "", len(w), mean, rot, position, off,
                        float(np.std(np.linalg.norm(w[:, :3], axis=1))))


def calibration_verdict(cal: PayloadCalibration) -> str:
    """"" if the payload calibration is acceptable, else the reason it is refused."""
    if cal.condition_number > CALIBRATION_MAX_CONDITION:
        return (f"condition number {cal.condition_number:.3g} is above {CALIBRATION_MAX_CONDITION:g}: the poses do not "
                "vary the tool's orientation enough; use the recommended set")
    if cal.rms_force_residual_n > CALIBRATION_MAX_RMS_FORCE_N:
        return (f"RMS force residual {cal.rms_force_residual_n:.3g} N is above {CALIBRATION_MAX_RMS_FORCE_N:g} N: "
                "a pose was in contact or the tool moved; check the tool hangs free and repeat")
    return ""


@dataclass(frozen=True, slots=True)
class PayloadResult:
    """The payload/bias step: the identification judged.

    ``calibration`` is None when the poses could not determine the payload (``reason`` says which to add);
    ``condition_number`` is the fit's, or the degenerate set's when there is no fit.
    """

    accepted: bool
    reason: str
    pose_set: str
    n_poses: int
    condition_number: float
    calibration: PayloadCalibration | None

    #: The step this result belongs to (its key in the calibration file).
    step: ClassVar[str] = "payload"

    @property
    def record(self) -> PayloadCalibration | None:
        """What goes on record for the tool: an accepted calibration, else nothing."""
        return self.calibration if self.accepted else None


def payload_step(poses: Sequence[CalibrationPose], pose_set_name: str) -> PayloadResult:
    """Identify the payload from ``poses`` and judge it (:func:`calibration_verdict`)."""
    try:
        cal = identify_payload(poses)
    except DegeneratePoseSetError as exc:
        return PayloadResult(False, str(exc), pose_set_name, len(poses), float(exc.condition_number or math.inf), None)
    reason = calibration_verdict(cal)
    return PayloadResult(reason == "", reason, pose_set_name, len(cal.residuals), cal.condition_number, cal)


# -- TCP ----------------------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class RecordedPivot:
    """One orientation of the pivot calibration: the flange pose with the tip in the divot (base frame).

    ``reason`` is "" when usable, else why it is refused; ``moved_mm`` the largest distance of the TCP from its
    mean over the window, ``turned_deg`` the turn between the window's first and last orientation.
    """

    label: str
    reason: str
    rot_base_flange: Mat3
    flange_position_m: Vec3
    moved_mm: float
    turned_deg: float

    @property
    def accepted(self) -> bool:
        """The orientation may go into the fit."""
        return self.reason == ""

    def pose(self) -> PivotPose:
        """The pose for :func:`tcp_step`."""
        return PivotPose(self.rot_base_flange, self.flange_position_m, self.label)


def record_pivot(label: str, tcp_positions_m: npt.ArrayLike, rot_first: Mat3, rot_last: Mat3,
                 tip_in_flange_m: Sequence[float]) -> RecordedPivot:
    """Judge and average one pivot orientation.

    Parameters
    ----------
    tcp_positions_m
        The TCP positions the robot reported over the window, shape (n, 3), m (base frame).
    rot_first, rot_last
        The TCP orientation ``rot_base_tip`` when the window opened and when it closed.
    tip_in_flange_m
        Where the reported TCP lies in the flange frame (the TCP the robot reports poses at): the flange pose
        is the TCP pose moved back by it.
    """
    p = np.asarray(tcp_positions_m, dtype=float).reshape(-1, 3)
    rot = as_mat3(rot_last)
    if not (len(p) and np.isfinite(p).all()):
        nan3 = (math.nan, math.nan, math.nan)
        return RecordedPivot(label, "no TCP pose received from the robot yet; check the RTDE connection", rot, nan3,
                             math.nan, math.nan)
    mean = p.mean(axis=0)
    moved = float(np.max(np.linalg.norm(p - mean, axis=1)))
    turned = rotation_angle_deg(rot_first, rot_last)
    flange = mean - np.asarray(rot, dtype=float).reshape(3, 3) @ np.asarray(tip_in_flange_m, dtype=float)
    return RecordedPivot(label, _moved_refusal(moved, turned, PIVOT_STILL_M, PIVOT_STILL_DEG), rot,
                         (float(flange[0]), float(flange[1]), float(flange[2])), moved * 1e3, turned)


@dataclass(frozen=True, slots=True)
class TcpResult:
    """The TCP pivot calibration: accepted with its ``calibration``, or refused (``reason``: which orientations to add).

    ``error_mm`` is the distance from a known true tip (the simulated rig's), NaN when there is none.
    """

    accepted: bool
    reason: str
    pose_set: str
    n_poses: int
    calibration: TipCalibration | None
    error_mm: float = math.nan

    #: The step this result belongs to (its key in the calibration file).
    step: ClassVar[str] = "tcp"

    @property
    def record(self) -> TipCalibration | None:
        """What goes on record for the tool: an accepted calibration, else nothing."""
        return self.calibration if self.accepted else None


def tcp_step(poses: Sequence[PivotPose], pose_set_name: str,
             true_tip_in_flange_m: Sequence[float] | None = None) -> TcpResult:
    """Fit the tip from the pivot ``poses`` (:func:`pipeline.commissioning.tcp.identify_tip`) and judge it."""
    try:
        tc = identify_tip(poses)
    except ValueError as exc:
        return TcpResult(False, str(exc), pose_set_name, len(poses), None)
    err = (math.dist(tc.tip_in_flange_m, [float(v) for v in true_tip_in_flange_m]) * 1e3
           if true_tip_in_flange_m is not None else math.nan)
    return TcpResult(True, "", pose_set_name, tc.n_poses, tc, err)


# -- frames ------------------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class FramesResult:
    """The frame and sign check over every axis, and its one-line verdict (with the payload's hint on a failure)."""

    check: FrameCheck
    summary: str

    #: The step this result belongs to (its key in the calibration file).
    step: ClassVar[str] = "frames"

    @property
    def passed(self) -> bool:
        """Every axis passed."""
        return self.check.passed

    @property
    def record(self) -> FrameCheck:
        """What goes on record: the check, passed or not (the session gate refuses a failed one, and says why)."""
        return self.check


def frame_check_of(axes: Mapping[str, AxisCheck], rot_tip_sensor: Mat3, rot_haptic_base: Mat3) -> FrameCheck | None:
    """The whole check once every axis of :data:`AXES` is in ``axes`` (checked one at a time), else None."""
    if not all(a in axes for a in AXES):
        return None
    return FrameCheck(tuple(axes[a] for a in AXES), rot_tip_sensor, rot_haptic_base)


def frames_step(check: FrameCheck, mount_angle_deg: float | None = None) -> FramesResult:
    """The verdict of a frame check; ``mount_angle_deg`` (the payload calibration's) explains a large mount error."""
    summary = check.summary()
    if not check.passed and mount_angle_deg is not None and mount_angle_deg > 5.0:
        summary += f" (the payload calibration finds the sensor {mount_angle_deg:.1f}° from its configured mount)"
    return FramesResult(check, summary)


# -- the session gate's rest check -------------------------------------------------------------------------------
def rest_force_n(comp_f: npt.ArrayLike) -> float:
    """The compensated force at rest: the magnitude of the mean over the window, N (``comp_f`` shape (n, 3))."""
    f = np.asarray(comp_f, dtype=float).reshape(-1, 3)
    return float(math.hypot(*(float(np.mean(f[:, i])) for i in range(3))))


def rest_verdict(force_n: float, tool: str, overridden: bool = False, payload_on_record: bool = True) -> str:
    """"" if a session may start with this force at rest, else why not (an override never waives it).

    ``payload_on_record``: False when the tool has no payload calibration, so its own weight is what was measured
    (a refusal must not send the experimenter looking for a contact or a payload "again").
    """
    if force_n < REST_MAX_FORCE_N:
        return ""
    head = f"the compensated force at rest is {force_n:.3f} N over {REST_CHECK_S:g} s (limit {REST_MAX_FORCE_N:g} N)"
    if payload_on_record:
        why = (f"the tool touches something, or its payload calibration does not match the mounted tool {tool!r}; "
               "keep it clear and still, or calibrate the payload again")
    else:
        why = (f"no payload calibration is on record for tool {tool!r}, so the tool's own weight counts as force; "
               "calibrate the payload first (the calibration wizard's step 2, or haptic-study calibrate payload)")
    return f"{head}: {why}" + ("; an override does not waive this check" if overridden else "")


def rest_check_note(tool: str, overridden: bool = False) -> str:
    """What the experimenter is told while the force at rest is measured (``overridden``: started without the
    calibration chain on record, with a reason)."""
    head = (f"starting without the calibration chain of tool {tool!r} (your reason is stored)" if overridden
            else f"calibration on record for tool {tool!r}")
    return (f"{head}; measuring the compensated force at rest for {REST_CHECK_S:g} s — keep the instrument still and "
            "clear of everything")
