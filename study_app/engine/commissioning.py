"""Commissioning the rig from the study engine: the steps' data gathered from the ring, their results as messages.

:class:`Commissioning` belongs to a :class:`study_app.engine.host.StudyEngine`
(it sees it as an :class:`study_app.engine.core.EngineCore`) and runs on its driver thread.  What each step
decides -- its limits, its verdicts, its refusals, what it puts on record -- is the commissioning service
:mod:`pipeline.commissioning.steps`, which ``haptic-study calibrate`` presents too; this module only gathers
the service's inputs and publishes its results.  On the simulated rig each step runs automatically; on the
real rig the experimenter records poses, pivot orientations and axis pushes one at a time, each averaged over a
window of the ring's records (:mod:`study_app.engine.ring_windows`).  Accepted results are put on record for the
mounted tool (:mod:`study_app.engine.tool_records`; real rig: saved in the rig's calibration file).  Before a
session starts on the real rig, :class:`study_app.engine.start_gate.StartGate` requires the chain on record (or
the experimenter's reason to start without it) and then, in every case, a compensated force at rest below
``REST_MAX_FORCE_N``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pipeline.commissioning.frame_check import AXES, AxisCheck, FrameCheck, check_axis
from pipeline.commissioning.payload_identification import CalibrationPose
from pipeline.commissioning.steps import (
    CALIBRATION_MAX_CONDITION,
    CALIBRATION_MAX_RMS_FORCE_N,
    REST_CHECK_S,
    REST_MAX_FORCE_N,
    PayloadResult,
    TcpResult,
    calibration_verdict,
    chain_refusal,
    frame_check_of,
    frames_step,
    payload_step,
    pose_set,
    record_pivot,
    record_pose,
    robot_pose_refusal,
    rotation_angle_deg,
    tcp_step,
)
from pipeline.commissioning.tcp import PivotPose, pivot_orientations
from pipeline.force.frames import Mat3, check_rotation
from pipeline.runtime.loop_messages import SetCalibration
from study_app.engine import messages as m
from study_app.engine.core import EngineCore
from study_app.engine.rig_arms import RigArms
from study_app.engine.ring_windows import RingWindows
from study_app.engine.start_gate import StartGate
from study_app.engine.tool_records import ToolRecords

__all__ = [
    "CALIBRATION_MAX_CONDITION", "CALIBRATION_MAX_RMS_FORCE_N", "REST_CHECK_S", "REST_MAX_FORCE_N", "Commissioning",
    "calibration_verdict", "check_target", "pose_set", "rotation_angle_deg",
]

_RAW_WRENCH = ("raw_fx", "raw_fy", "raw_fz", "raw_tx", "raw_ty", "raw_tz")
_TIP = ("tip_x_m", "tip_y_m", "tip_z_m")
_BASE_SCALED = ("base_fx", "base_fy", "base_fz", "scaled_fx", "scaled_fy", "scaled_fz")
#: How long the experimenter may ask each real-rig recording to average (the command's ``seconds``), s.
_SECONDS = {"RecordPose": (0.1, 10.0), "RecordPivot": (0.1, 5.0), "RecordFrameAxis": (0.5, 10.0)}


def check_target(rows: Any) -> Mat3:
    """A requested pose's ``rot_base_sensor`` (validated)."""
    return check_rotation(rows, "target_rot_base_sensor")


def _check_seconds(command: str, seconds: float) -> None:
    lo, hi = _SECONDS[command]
    if not (math.isfinite(seconds) and lo <= seconds <= hi):
        raise ValueError(f"record seconds = {seconds!r}: allowed {lo:g} to {hi:g} s")


def _calibration_done(r: PayloadResult) -> m.CalibrationDone:
    """The payload step's result as the wizard's message."""
    cal = r.calibration
    if cal is None:
        return m.CalibrationDone(False, r.reason, r.pose_set, r.n_poses, r.condition_number, math.nan, math.nan, [],
                                 None)
    return m.CalibrationDone(
        r.accepted, r.reason, r.pose_set, r.n_poses, cal.condition_number, cal.rms_force_residual_n,
        cal.rms_torque_residual_nm, [(x.label, x.force_residual_n, x.torque_residual_nm) for x in cal.residuals],
        cal.to_dict(),
    )


class Commissioning:
    """The commissioning chain of one study engine (driver thread only).

    Parameters
    ----------
    engine
        The engine whose rig, loop and ring the steps use.
    arms
        The rig's arms: each is commissioned on its own.
    """

    def __init__(self, engine: EngineCore, arms: RigArms) -> None:
        self.engine = engine
        self.arms = arms
        #: Per arm, what is on record for its mounted tool.
        self.records = ToolRecords(engine, arms)
        #: The real-rig recordings under way.
        self.windows = RingWindows(engine, arms.first)
        #: The real rig's gate before a session starts or resumes.
        self.gate = StartGate(engine, self.records, self.windows)
        self._frame_axes: dict[str, AxisCheck] = {}
        self._frame_arm = ""  # the arm whose axes ``_frame_axes`` holds

    def feed(self, rows: np.ndarray) -> None:
        """The newest records of the task arm's ring: fill the recordings under way."""
        self.windows.feed(rows)

    def publish_status(self) -> None:
        """What is on record, per arm."""
        self.records.publish_status()

    def provenance(self) -> dict[str, Any]:
        """What a session stores about the calibration chain (``config_json``): tool, file, every step on record,
        and a start without it."""
        return {**self.records.provenance(), **self.gate.provenance()}

    # -- payload ------------------------------------------------------------------------------------------------
    def record_pose(self, cmd: m.RecordPose) -> None:
        """Real rig: average the raw wrench over ``cmd.seconds`` at the robot's pose (it must stand still)."""
        e = self.engine
        if e.eng.simulated:
            raise RuntimeError("simulated rig: the poses run automatically (Run calibration)")
        e.require_idle("record pose")
        busy = self.windows.busy("RecordPose")
        if busy is not None:
            raise RuntimeError(f"record pose: {_pose(busy.label)} is still being recorded")
        if not cmd.label.strip():
            raise ValueError("pose label = '': must name the pose")
        _check_seconds("RecordPose", cmd.seconds)
        target = check_target(cmd.target_rot_base_sensor) if cmd.target_rot_base_sensor is not None else None
        arm = self.arms.of(cmd.arm)
        self._payload_chain(arm)  # at the first pose, not after the experimenter has jogged the robot through all
        robot = self.arms.devices(arm).robot
        pose0 = robot.read_pose()
        refusal = robot_pose_refusal(pose0, e.eng.clock.now_ns())
        if refusal:
            raise RuntimeError(f"{refusal} (Devices tab)")
        label, rot_tip_sensor = cmd.label, e.eng.frameworks[arm].config.rot_tip_sensor

        def done(cols: dict[str, np.ndarray]) -> None:
            w = np.stack([cols[c] for c in _RAW_WRENCH], axis=1)
            rp = record_pose(label, w, pose0, robot.read_pose(), rot_tip_sensor, target)
            if not rp.accepted:
                e.publish(m.CommandRefused("RecordPose", f"{_pose(label)}: {rp.reason}"))
                return
            e.publish(m.PoseRecorded(label, rp.samples, rp.wrench, rp.rot_base_sensor, rp.tcp_position_m,
                                     rp.off_target_deg, rp.force_std_n))

        # average only records written after this command (the window drains everything up to now first)
        self.windows.open("RecordPose", cmd.seconds, _RAW_WRENCH, done, label=label, arm=arm,
                          stalled=f"{_pose(label)}: the force sensor stalled while recording (check the Devices tab) "
                                  "— record it again")

    def identify(self, cmd: m.IdentifyPoses) -> None:
        """Real rig: identify the payload from the recorded poses; install and record an accepted one."""
        if not self.engine.real:
            raise RuntimeError("simulated rig: the poses run automatically (Run calibration)")
        self.engine.require_idle("calibrate")
        arm = self.arms.of(cmd.arm)
        self._payload_chain(arm)
        poses = [CalibrationPose(rot, wrench, label) for label, rot, wrench in cmd.poses]
        self.engine.publish(self._installed(arm, payload_step(poses, cmd.pose_set)))

    def _payload_chain(self, arm: str) -> None:
        """The chain's order, as ``calibrate payload`` keeps it: the payload step needs the tool's TCP on record."""
        refusal = chain_refusal(self.records.tool_cals[arm], "payload")
        if refusal:
            raise RuntimeError(f"payload: {refusal}")

    def _installed(self, arm: str, result: PayloadResult) -> m.CalibrationDone:
        """Install an accepted payload calibration in the arm's force path and record it; the wizard's message."""
        if result.record is not None:
            if arm == self.arms.first:
                self.engine.calibration = result.record  # the task arm's: the session's calibration_json
            self.engine.eng.calibrations[arm] = result.record  # every arm's: the session's config_json
            self.engine.loop.submit(SetCalibration(result.record, arm=arm))
            self.records.record(arm, result.step, result.record)
        return _calibration_done(result)

    def calibrate(self, cmd: m.Calibrate) -> None:
        """Simulated rig: run the pose set automatically on an arm (the loop paused), identify, judge, install."""
        if self.engine.real:
            raise RuntimeError("real rig: the poses are recorded one at a time in the calibration wizard "
                               "(move the robot, then Record pose)")
        self.engine.require_idle("calibrate")
        name, arm = cmd.pose_set, self.arms.of(cmd.arm)
        poses = self.engine.run_paused(
            "measure_poses", lambda done, n: self.engine.publish(m.CalibrationProgress(done, n, f"pose {done}")),
            arm=arm, rotations=pose_set(name))
        self.engine.publish(self._installed(arm, payload_step(poses, name)))

    # -- TCP ----------------------------------------------------------------------------------------------------
    def calibrate_tcp(self, cmd: m.CalibrateTcp) -> None:
        """Simulated rig: the simulated robot turns the instrument about the divot; fit, judge, record."""
        from pipeline.sim.commissioning import pivot_poses
        from pipeline.sim.robot import TOOL_DOWN

        if not self.engine.eng.simulated:
            raise RuntimeError("real rig: rest the tip in the divot, turn the instrument and record each orientation "
                               "(Record orientation), then Compute")
        self.engine.require_idle("TCP calibration")
        name = cmd.pose_set
        if name not in m.PIVOT_SETS:
            raise ValueError(f"pose set = {name!r}: allowed values are {', '.join(m.PIVOT_SETS)}")
        arm = self.arms.of(cmd.arm)
        rig = self.arms.devices(arm)
        poses = pivot_poses(rig, pivot_orientations(name, TOOL_DOWN))
        self._tcp_done(arm, tcp_step(poses, name, rig.config.tip_in_flange_m))

    def _tcp_done(self, arm: str, r: TcpResult) -> None:
        if r.record is not None:
            self.records.record(arm, r.step, r.record)
        self.engine.publish(m.TcpCalibrationDone(r.accepted, r.reason, r.pose_set, r.n_poses,
                                                 r.record.to_dict() if r.record is not None else None, r.error_mm))

    def record_pivot(self, cmd: m.RecordPivot) -> None:
        """Real rig: average the TCP position over ``cmd.seconds`` with the tip in the divot (it must stand still)."""
        if self.engine.eng.simulated:
            raise RuntimeError("simulated rig: the orientations run automatically (Run TCP calibration)")
        self.engine.require_idle("record orientation")
        _check_seconds("RecordPivot", cmd.seconds)
        arm = self.arms.of(cmd.arm)
        robot = self.arms.devices(arm).robot
        pose0 = robot.read_pose()
        refusal = robot_pose_refusal(pose0)
        if refusal:
            raise RuntimeError(f"{refusal} (Devices tab)")
        label = cmd.label
        # the TCP the ring's positions are at: the one on record (the robot's poses were moved to it), else the
        # pendant's
        hw, rec = self.arms.hardware_arm(arm), self.records.tool_cals[arm]
        tip = rec.tcp.tip_in_flange_m if rec.tcp is not None else (
            hw.robot.tcp_offset_m if hw is not None else (0.0, 0.0, 0.0))

        def done(cols: dict[str, np.ndarray]) -> None:
            p = np.stack([cols[c] for c in _TIP], axis=1)
            rp = record_pivot(label, p, pose0.rot_base_tip, robot.read_pose().rot_base_tip, tip)
            if not rp.accepted:
                self.engine.publish(m.CommandRefused("RecordPivot", f"orientation {label}: {rp.reason}"))
                return
            self.engine.publish(m.PivotRecorded(label, rp.rot_base_flange, rp.flange_position_m, rp.moved_mm))

        self.windows.open("RecordPivot", cmd.seconds, _TIP, done, arm=arm)

    def identify_tcp(self, cmd: m.IdentifyTcp) -> None:
        """Real rig: fit the tip from the recorded orientations; record an accepted one."""
        if self.engine.eng.simulated:
            raise RuntimeError("simulated rig: the orientations run automatically (Run TCP calibration)")
        self.engine.require_idle("TCP calibration")
        arm = self.arms.of(cmd.arm)
        self._tcp_done(arm, tcp_step([PivotPose(rot, pos, label) for label, rot, pos in cmd.poses], "recorded"))

    # -- frames -------------------------------------------------------------------------------------------------
    def check_frames(self, cmd: m.CheckFrames) -> None:
        """Simulated rig: the simulated experimenter pushes the free tip along each axis (the loop runs ticks
        itself, paced on its clock, between its own runs)."""
        if not self.engine.eng.simulated:
            raise RuntimeError("real rig: push the free tip along each axis in turn (Record +x, +y, +z)")
        self.engine.require_idle("frame check")
        arm = self.arms.of(cmd.arm)
        check: FrameCheck = self.engine.run_paused("push_axes", arm=arm)
        for a in check.axes:
            self.engine.publish(m.FrameAxisChecked(a.axis, a.passed, a.describe(), a.to_dict()))
        self._frames_done(arm, check)

    def _frames_done(self, arm: str, check: FrameCheck) -> None:
        r = frames_step(check, self.engine.eng.calibrations[arm].mount_angle_deg)
        self.records.record(arm, r.step, r.record)
        self.engine.publish(m.FrameCheckDone(r.passed, r.summary, [a.describe() for a in check.axes]))

    def record_frame_axis(self, cmd: m.RecordFrameAxis) -> None:
        """Real rig: record ``cmd.seconds`` while the experimenter pushes the free tip along ``cmd.axis``."""
        if self.engine.eng.simulated:
            raise RuntimeError("simulated rig: the pushes run automatically (Run frame check)")
        self.engine.require_idle("frame check")
        if cmd.axis not in AXES:
            raise ValueError(f"axis = {cmd.axis!r}: allowed values are {', '.join(AXES)}")
        _check_seconds("RecordFrameAxis", cmd.seconds)
        arm = self.arms.of(cmd.arm)
        refusal = chain_refusal(self.records.tool_cals[arm], "frames")
        if refusal:
            raise RuntimeError(f"frame check: {refusal}")
        if arm != self._frame_arm:  # another arm's pushes are not this arm's
            self._frame_axes, self._frame_arm = {}, arm
        axis = cmd.axis
        rts, rhb = self.records.frames_in_use(arm)

        def done(cols: dict[str, np.ndarray]) -> None:
            base = np.stack([cols[c] for c in _BASE_SCALED[:3]], axis=1)
            scaled = np.stack([cols[c] for c in _BASE_SCALED[3:]], axis=1)
            res = check_axis(axis, base, scaled, rhb)
            self._frame_axes[axis] = res
            self.engine.publish(m.FrameAxisChecked(axis, res.passed, res.describe(), res.to_dict()))
            # the newest push of each axis is kept after a check, as the window shows them: pushing one axis again
            # (the one that failed) judges the three newest pushes and puts that verdict on record
            check = frame_check_of(self._frame_axes, rts, rhb)
            if check is not None:
                self._frames_done(arm, check)

        self.windows.open("RecordFrameAxis", cmd.seconds, _BASE_SCALED, done, arm=arm)


def _pose(label: str) -> str:
    """A recorded pose named in a refusal: ``pose 3`` (a label that is not one already: ``pose P03``)."""
    return label if label.startswith("pose") else f"pose {label}"
