"""Commissioning the rig from the study engine: the steps' data gathered from the ring, their results as messages.

:class:`Commissioning` belongs to a :class:`study_app.engine.host.StudyEngine`
(it sees it as an :class:`study_app.engine.core.EngineCore`) and runs on its driver thread.  What each step
decides -- its limits, its verdicts, its refusals, what it puts on record -- is the commissioning service
:mod:`pipeline.commissioning.steps`, which ``haptic-study calibrate`` presents too; this module only gathers
the service's inputs and publishes its results.  On the simulated rig each step runs automatically; on the
real rig the experimenter records poses, pivot orientations and axis pushes one at a time, each averaged over a
window of the ring's records (:class:`_Window`).  Accepted results are put on record for the mounted tool (real
rig: saved in the rig's calibration file).  Before a session starts on the real rig, :meth:`Commissioning.gate`
requires the chain on record (or the experimenter's reason to start without it) and then, in every case, a
compensated force at rest below ``REST_MAX_FORCE_N``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline.commissioning.frame_check import AXES, AxisCheck, FrameCheck, check_axis
from pipeline.commissioning.payload_identification import CalibrationPose
from pipeline.commissioning.rig_calibration import CalibrationFileError, RigCalibrationFile, ToolCalibration, now_iso
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
    rest_check_note,
    rest_force_n,
    rest_verdict,
    robot_pose_refusal,
    rotation_angle_deg,
    sensor_stalled,
    tcp_step,
)
from pipeline.commissioning.tcp import PivotPose, pivot_orientations
from pipeline.core.clock import MonotonicClock
from pipeline.force.frames import Mat3, check_rotation
from pipeline.runtime.loop_messages import SetCalibration
from study_app.engine import messages as m
from study_app.engine.core import EngineCore

if TYPE_CHECKING:
    from pipeline.settings.hardware import HardwareConfig

__all__ = [
    "CALIBRATION_MAX_CONDITION", "CALIBRATION_MAX_RMS_FORCE_N", "REST_CHECK_S", "REST_MAX_FORCE_N", "Commissioning",
    "calibration_verdict", "check_target", "other_arms_missing", "pose_set", "rotation_angle_deg",
]

_RAW_WRENCH = ("raw_fx", "raw_fy", "raw_fz", "raw_tx", "raw_ty", "raw_tz")
_TIP = ("tip_x_m", "tip_y_m", "tip_z_m")
_COMP = ("comp_fx", "comp_fy", "comp_fz")
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


@dataclass
class _Window:
    """Records of the ring collected for a calibration step or the session gate (driver thread).

    ``done(columns)`` gets each column in ``cols`` over exactly ``need`` records; if the recording is
    abandoned instead (the sensor stalled: published as a refusal of ``command``), ``abandoned()`` is called.
    """

    command: str
    need: int
    start_ns: int
    cols: tuple[str, ...]
    done: Callable[[dict[str, np.ndarray]], None]
    chunks: list[np.ndarray]
    got: int = 0
    abandoned: Callable[[], None] | None = None
    label: str = ""  # what is being recorded (a pose's label), for messages
    stalled: str = ""  # the refusal if the sensor stalls ("" for the generic one)
    #: The arm whose ring is read ("": the first's, fed by the engine's drain); another arm's from ``cursor`` on.
    arm: str = ""
    cursor: int = 0


class Commissioning:
    """The commissioning chain of one study engine (driver thread only).

    Parameters
    ----------
    engine
        The engine whose rig, loop and ring the steps use.
    """

    def __init__(self, engine: EngineCore) -> None:
        self.engine = engine
        #: The rig's arms by name, the first (the task arm) first; each is commissioned on its own.
        self.arms: tuple[str, ...] = tuple(engine.eng.frameworks)
        self._files = {a: self._calibration_file(a) for a in self.arms}
        #: Per arm, what is on record for its mounted tool (real rig: from its calibration file; simulated: this run's).
        self.tool_cals: dict[str, ToolCalibration] = {a: self._tool_record(a) for a in self.arms}
        self._windows: list[_Window] = []
        self._frame_axes: dict[str, AxisCheck] = {}
        self._frame_arm = ""  # the arm whose axes ``_frame_axes`` holds
        self._gate_passed: object | None = None  # a start whose rest check passed: let it through once
        self._starting: object | None = None  # a start waiting for its rest check
        self._override: tuple[str, str, float] | None = None  # (what was missing, the reason, force at rest N)

    @property
    def tool_cal(self) -> ToolCalibration:
        """What is on record for the first arm's tool (a one-arm rig's)."""
        return self.tool_cals[self.arms[0]]

    def arm_of(self, name: str) -> str:
        """The arm a command names ("": the first), checked: a name the rig lacks is a ValueError naming its arms."""
        if not name:
            return self.arms[0]
        if name not in self.arms:
            raise ValueError(f"arm = {name!r}: this rig has no such arm; its arms: {', '.join(self.arms)}")
        return name

    def devices(self, arm: str) -> Any:
        """An arm's devices (``sensor``, ``robot``; simulated: its whole rig): the rig itself for the first arm,
        whose calls it forwards, else the arm's own."""
        rig = self.engine.eng.rig
        if arm == self.arms[0]:
            return rig
        return rig.rig(arm) if self.engine.eng.simulated else rig.arm(arm)

    def _hardware_arm(self, arm: str) -> Any:
        """The hardware file's table of an arm (real rig), None on the simulated rig."""
        hw = self.engine.hardware
        return hw.arm(arm) if hw is not None else None

    def _calibration_file(self, arm: str) -> RigCalibrationFile | None:
        """The real rig's calibration file of an arm (loaded when the engine was built, so it reads), else None."""
        eng = self.engine.eng
        if eng.simulated:
            return None
        if arm == self.arms[0]:
            return eng.calibration_file
        hw = self._hardware_arm(arm)
        return RigCalibrationFile.load(hw.calibration_file) if hw is not None and hw.calibration_file else None

    def take_override(self) -> tuple[str, str, float] | None:
        """The override the session that just started was let through with (once), or None."""
        override, self._override = self._override, None
        return override

    # -- payload ------------------------------------------------------------------------------------------------
    def record_pose(self, cmd: m.RecordPose) -> None:
        """Real rig: average the raw wrench over ``cmd.seconds`` at the robot's pose (it must stand still)."""
        e = self.engine
        if e.eng.simulated:
            raise RuntimeError("simulated rig: the poses run automatically (Run calibration)")
        e.require_idle("record pose")
        busy = next((w for w in self._windows if w.command == "RecordPose"), None)
        if busy is not None:
            raise RuntimeError(f"record pose: pose {busy.label} is still being recorded")
        if not cmd.label.strip():
            raise ValueError("pose label = '': must name the pose")
        _check_seconds("RecordPose", cmd.seconds)
        target = check_target(cmd.target_rot_base_sensor) if cmd.target_rot_base_sensor is not None else None
        arm = self.arm_of(cmd.arm)
        self._payload_chain(arm)  # at the first pose, not after the experimenter has jogged the robot through all
        robot = self.devices(arm).robot
        pose0 = robot.read_pose()
        refusal = robot_pose_refusal(pose0, e.eng.clock.now_ns())
        if refusal:
            raise RuntimeError(f"{refusal} (Devices tab)")
        label, rot_tip_sensor = cmd.label, e.eng.frameworks[arm].config.rot_tip_sensor

        def done(cols: dict[str, np.ndarray]) -> None:
            w = np.stack([cols[c] for c in _RAW_WRENCH], axis=1)
            rp = record_pose(label, w, pose0, robot.read_pose(), rot_tip_sensor, target)
            if not rp.accepted:
                e.publish(m.CommandRefused("RecordPose", f"pose {label}: {rp.reason}"))
                return
            e.publish(m.PoseRecorded(label, rp.samples, rp.wrench, rp.rot_base_sensor, rp.tcp_position_m,
                                     rp.off_target_deg, rp.force_std_n))

        # average only records written after this command (the window drains everything up to now first)
        self._open_window("RecordPose", cmd.seconds, _RAW_WRENCH, done, label=label, arm=arm,
                          stalled=f"pose {label}: the force sensor stalled while recording (check the Devices tab) "
                                  "— record it again")

    def identify(self, cmd: m.IdentifyPoses) -> None:
        """Real rig: identify the payload from the recorded poses; install and record an accepted one."""
        if not self.engine.real:
            raise RuntimeError("simulated rig: the poses run automatically (Run calibration)")
        self.engine.require_idle("calibrate")
        arm = self.arm_of(cmd.arm)
        self._payload_chain(arm)
        poses = [CalibrationPose(rot, wrench, label) for label, rot, wrench in cmd.poses]
        self.engine.publish(self._installed(arm, payload_step(poses, cmd.pose_set)))

    def _payload_chain(self, arm: str) -> None:
        """The chain's order, as ``calibrate payload`` keeps it: the payload step needs the tool's TCP on record."""
        refusal = chain_refusal(self.tool_cals[arm], "payload")
        if refusal:
            raise RuntimeError(f"payload: {refusal}")

    def _installed(self, arm: str, result: PayloadResult) -> m.CalibrationDone:
        """Install an accepted payload calibration in the arm's force path and record it; the wizard's message."""
        if result.record is not None:
            if arm == self.arms[0]:
                self.engine.calibration = result.record  # the task arm's: the session's calibration_json
            self.engine.eng.calibrations[arm] = result.record  # every arm's: the session's config_json
            self.engine.loop.submit(SetCalibration(result.record, arm=arm))
            self._record_step(arm, result.step, result.record)
        return _calibration_done(result)

    def calibrate(self, name: str, arm_name: str = "") -> None:
        """Simulated rig: run the pose set automatically on an arm (the loop paused), identify, judge, install."""
        from pipeline.sim.calibration import measure_poses

        self.engine.require_idle("calibrate")
        arm = self.arm_of(arm_name)
        rots = pose_set(name)
        real = self.engine.config.clock == "real"
        if real:
            self.engine.loop.stop(timeout_s=5.0)  # ramps the force to zero first
            clock: Any = MonotonicClock()
        else:
            self.engine.loop.ramp_down()
            clock = self.engine.loop.clock
        self.engine.drain_ring()
        try:
            assert self.engine.eng.simulated
            poses = measure_poses(
                self.devices(arm), clock, rots,
                progress=lambda done, n: self.engine.publish(m.CalibrationProgress(done, n, f"P{done:02d}")),
            )
            result = self._installed(arm, payload_step(poses, name))
        finally:
            self.engine.after_loop_pause(real)
        self.engine.publish(result)

    # -- what is on record --------------------------------------------------------------------------------------
    def _tool(self, arm: str) -> str:
        """The tool mounted on an arm (real rig: the hardware file's, its record's name in the calibration file)."""
        hw = self._hardware_arm(arm)
        return str(hw.calibration_tool) if hw is not None and arm != self.arms[0] else self.engine.eng.tool

    def _tool_record(self, arm: str) -> ToolCalibration:
        eng = self.engine.eng
        if not eng.simulated:
            f = self._files[arm]
            return ToolCalibration(self._tool(arm)) if f is None else f.tool(self._tool(arm))
        # the simulated rig calibrated its payload as it was built; TCP and frames are this run's, never saved
        return ToolCalibration("simulated instrument", payload=eng.calibrations[arm], payload_date=now_iso())

    def frames_in_use(self, arm: str = "") -> tuple[Mat3, Mat3]:
        """The frame rotations an arm's force path uses (the first arm's by default)."""
        fw = self.engine.eng.frameworks[arm or self.arms[0]].config
        return fw.rot_tip_sensor, fw.rot_haptic_base

    def publish_status(self) -> None:
        """What is on record, per arm (a one-arm rig's status names no arm)."""
        several = len(self.arms) > 1
        for arm in self.arms:
            f, rec = self._files[arm], self.tool_cals[arm]
            self.engine.publish(m.CalibrationStatus(self.engine.config.rig, rec.tool, f.path if f is not None else "",
                                                    rec.status(), rec.missing(*self.frames_in_use(arm)),
                                                    arm if several else ""))

    def _record_step(self, arm: str, step: str, result: Any) -> None:
        """Put an accepted result on record for an arm (real rig: saved in its calibration file); publish the status."""
        f = self._files[arm]
        if f is not None:
            try:
                self.tool_cals[arm] = f.record(self._tool(arm), step, result)
            except CalibrationFileError as exc:
                self.tool_cals[arm] = self.tool_cals[arm].with_step(step, result)
                self.engine.publish(m.CommandRefused("calibration file", f"{exc}: the result is in use but not saved"))
            hw = self._hardware_arm(arm)
            if step == "tcp" and hw is not None:
                # the robot's poses move to the new tip at once (the pendant's TCP stays what the file says)
                off = hw.robot.tcp_offset_m
                self.devices(arm).robot.tcp_correction_m = tuple(
                    t - o for t, o in zip(result.tip_in_flange_m, off, strict=True))
        else:
            self.tool_cals[arm] = self.tool_cals[arm].with_step(step, result)
        self.publish_status()

    def provenance(self) -> dict[str, Any]:
        """What a session stores about the calibration chain (``config_json``): tool, file, every step on record."""
        def chain(arm: str) -> dict[str, Any]:
            f, rec = self._files[arm], self.tool_cals[arm]
            return {"tool": rec.tool, "file": f.path if f is not None else None, **rec.to_dict()}

        out: dict[str, Any] = {"rig_calibration": chain(self.arms[0])}
        if len(self.arms) > 1:  # every arm's chain (the first's is rig_calibration)
            out["arms_rig_calibration"] = {a: chain(a) for a in self.arms}
        if self._override is not None:
            out["calibration_override"] = {"missing": self._override[0], "reason": self._override[1],
                                           "rest_force_n": self._override[2]}
        return out

    # -- TCP ----------------------------------------------------------------------------------------------------
    def calibrate_tcp(self, name: str, arm_name: str = "") -> None:
        """Simulated rig: the simulated robot turns the instrument about the divot; fit, judge, record."""
        from pipeline.sim.commissioning import pivot_poses
        from pipeline.sim.robot import TOOL_DOWN

        if not self.engine.eng.simulated:
            raise RuntimeError("real rig: rest the tip in the divot, turn the instrument and record each orientation "
                               "(Record orientation), then Compute")
        self.engine.require_idle("TCP calibration")
        if name not in m.PIVOT_SETS:
            raise ValueError(f"pose set = {name!r}: allowed values are {', '.join(m.PIVOT_SETS)}")
        arm = self.arm_of(arm_name)
        rig = self.devices(arm)
        poses = pivot_poses(rig, pivot_orientations(name, TOOL_DOWN))
        self._tcp_done(arm, tcp_step(poses, name, rig.config.tip_in_flange_m))

    def _tcp_done(self, arm: str, r: TcpResult) -> None:
        if r.record is not None:
            self._record_step(arm, r.step, r.record)
        self.engine.publish(m.TcpCalibrationDone(r.accepted, r.reason, r.pose_set, r.n_poses,
                                                 r.record.to_dict() if r.record is not None else None, r.error_mm))

    def record_pivot(self, cmd: m.RecordPivot) -> None:
        """Real rig: average the TCP position over ``cmd.seconds`` with the tip in the divot (it must stand still)."""
        if self.engine.eng.simulated:
            raise RuntimeError("simulated rig: the orientations run automatically (Run TCP calibration)")
        self.engine.require_idle("record orientation")
        _check_seconds("RecordPivot", cmd.seconds)
        arm = self.arm_of(cmd.arm)
        robot = self.devices(arm).robot
        pose0 = robot.read_pose()
        refusal = robot_pose_refusal(pose0)
        if refusal:
            raise RuntimeError(f"{refusal} (Devices tab)")
        label = cmd.label
        # the TCP the ring's positions are at: the one on record (the robot's poses were moved to it), else the
        # pendant's
        hw, rec = self._hardware_arm(arm), self.tool_cals[arm]
        tip = rec.tcp.tip_in_flange_m if rec.tcp is not None else (
            hw.robot.tcp_offset_m if hw is not None else (0.0, 0.0, 0.0))

        def done(cols: dict[str, np.ndarray]) -> None:
            p = np.stack([cols[c] for c in _TIP], axis=1)
            rp = record_pivot(label, p, pose0.rot_base_tip, robot.read_pose().rot_base_tip, tip)
            if not rp.accepted:
                self.engine.publish(m.CommandRefused("RecordPivot", f"orientation {label}: {rp.reason}"))
                return
            self.engine.publish(m.PivotRecorded(label, rp.rot_base_flange, rp.flange_position_m, rp.moved_mm))

        self._open_window("RecordPivot", cmd.seconds, _TIP, done, arm=arm)

    def identify_tcp(self, cmd: m.IdentifyTcp) -> None:
        """Real rig: fit the tip from the recorded orientations; record an accepted one."""
        if self.engine.eng.simulated:
            raise RuntimeError("simulated rig: the orientations run automatically (Run TCP calibration)")
        self.engine.require_idle("TCP calibration")
        arm = self.arm_of(cmd.arm)
        self._tcp_done(arm, tcp_step([PivotPose(rot, pos, label) for label, rot, pos in cmd.poses], "recorded"))

    # -- frames -------------------------------------------------------------------------------------------------
    def check_frames(self, arm_name: str = "") -> None:
        """Simulated rig: the simulated experimenter pushes the free tip along each axis (the loop runs)."""
        from pipeline.sim.commissioning import push_axes

        if not self.engine.eng.simulated:
            raise RuntimeError("real rig: push the free tip along each axis in turn (Record +x, +y, +z)")
        self.engine.require_idle("frame check")
        arm = self.arm_of(arm_name)
        ring = self.engine.eng.rings[arm]
        real = self.engine.config.clock == "real"
        if real:
            self.engine.loop.stop(timeout_s=5.0)  # the check runs the loop itself, paced on the same clock
        self.engine.drain_ring()
        try:
            assert ring is not None
            check = push_axes(self.devices(arm), self.engine.loop, ring, framework=self.engine.eng.frameworks[arm])
        finally:
            self.engine.cursor = self.engine.ring.write_count  # the check's own records are not the loop's timing
            self.engine.after_loop_pause(real)
        for a in check.axes:
            self.engine.publish(m.FrameAxisChecked(a.axis, a.passed, a.describe(), a.to_dict()))
        self._frames_done(arm, check)

    def _frames_done(self, arm: str, check: FrameCheck) -> None:
        r = frames_step(check, self.engine.eng.calibrations[arm].mount_angle_deg)
        self._record_step(arm, r.step, r.record)
        self.engine.publish(m.FrameCheckDone(r.passed, r.summary, [a.describe() for a in check.axes]))

    def record_frame_axis(self, cmd: m.RecordFrameAxis) -> None:
        """Real rig: record ``cmd.seconds`` while the experimenter pushes the free tip along ``cmd.axis``."""
        if self.engine.eng.simulated:
            raise RuntimeError("simulated rig: the pushes run automatically (Run frame check)")
        self.engine.require_idle("frame check")
        if cmd.axis not in AXES:
            raise ValueError(f"axis = {cmd.axis!r}: allowed values are {', '.join(AXES)}")
        _check_seconds("RecordFrameAxis", cmd.seconds)
        arm = self.arm_of(cmd.arm)
        refusal = chain_refusal(self.tool_cals[arm], "frames")
        if refusal:
            raise RuntimeError(f"frame check: {refusal}")
        if arm != self._frame_arm:  # another arm's pushes are not this arm's
            self._frame_axes, self._frame_arm = {}, arm
        axis = cmd.axis
        rts, rhb = self.frames_in_use(arm)

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

        self._open_window("RecordFrameAxis", cmd.seconds, _BASE_SCALED, done, arm=arm)

    # -- the windows of the ring's records ----------------------------------------------------------------------
    def _open_window(self, command: str, seconds: float, cols: tuple[str, ...],
                     done: Callable[[dict[str, np.ndarray]], None], abandoned: Callable[[], None] | None = None,
                     *, label: str = "", stalled: str = "", arm: str = "") -> None:
        """Collect ``seconds`` of an arm's records written after now (the first arm's by default), then call ``done``
        (see :class:`_Window`)."""
        if any(w.command == command for w in self._windows):
            raise RuntimeError(f"{command}: a recording is already running")
        self.engine.drain_ring()
        start = self.engine.last_t_ns + 1 if self.engine.loop.tick_count else 0
        other = arm if arm and arm != self.arms[0] else ""
        ring = self.engine.eng.rings[other] if other else None
        self._windows.append(_Window(command, int(round(seconds * 1000)), start, cols, done, [], abandoned=abandoned,
                                     label=label, stalled=stalled, arm=other,
                                     cursor=ring.write_count if ring is not None else 0))

    def feed(self, rows: np.ndarray) -> None:
        """The newest records of the ring: fill the open windows, finish those that are full."""
        for w in list(self._windows):
            sel = rows[rows["t_ns"] >= w.start_ns] if not w.arm else self._arm_rows(w)
            if len(sel):
                if sensor_stalled(sel["sensor_age_ns"]):
                    self._windows.remove(w)
                    again = ("measuring the force at rest (check the Devices tab) — press Start again"
                             if w.command in ("StartSession", "ResumeSession")
                             else "recording (check the Devices tab) — record again")
                    self.engine.publish(m.CommandRefused(w.command,
                                                         w.stalled or f"the force sensor stalled while {again}"))
                    if w.abandoned is not None:
                        w.abandoned()
                    continue
                w.chunks.append(np.stack([sel[c] for c in w.cols], axis=1))
                w.got += len(sel)
            if w.got >= w.need:
                self._windows.remove(w)
                data = np.concatenate(w.chunks)[: w.need]
                try:
                    w.done({c: data[:, i] for i, c in enumerate(w.cols)})
                except (ValueError, RuntimeError) as exc:
                    self.engine.publish(m.CommandRefused(w.command, str(exc)))

    def _arm_rows(self, w: _Window) -> np.ndarray:
        """The records another arm's ring got since the window last read it (each arm's loop writes its own)."""
        ring = self.engine.eng.rings[w.arm]
        assert ring is not None
        got = ring.read_since(w.cursor)
        w.cursor = got.cursor
        return got.rows[got.rows["t_ns"] >= w.start_ns]

    # -- the real rig's session gate ------------------------------------------------------------------------------
    def gate(self, cmd: m.StartSession | m.ResumeSession) -> bool:
        """The real rig's calibration gate; True when the start waits for its rest check (it comes back later).

        The chain (TCP, payload, frames) must be on record for the mounted tool -- or the experimenter gives a
        reason to start without it -- and then, in every case, the compensated force at rest over
        ``REST_CHECK_S`` must be below ``REST_MAX_FORCE_N``.

        Raises :class:`RuntimeError` (one line, naming the missing step) when the start is refused.
        """
        if not self.engine.real:
            return False
        if cmd is self._gate_passed:
            self._gate_passed = None
            return False
        self._override = None  # a start that failed after its check must not lend its override to this one
        missing = self.tool_cal.missing(*self.frames_in_use())
        if self.engine.hardware is not None and len(self.engine.hardware.arms) > 1:
            # a rig of several arms: every arm's chain, each named (the first's is the wizard's)
            first = self.engine.hardware.arms[0].name
            missing = (f"arm {first}: {missing}" if missing else
                       other_arms_missing(self.engine.hardware, self.engine.eng.frameworks))
        # the override waives the steps on record, never the force at rest: without a payload that fits the
        # mounted tool the tool's own weight would be rendered as feedback
        reason = cmd.override_reason.strip()
        if missing and not reason:
            raise RuntimeError(f"real rig: {missing}")
        if self._starting is not None:
            raise RuntimeError("start: the force at rest is being measured; wait for it")
        self._starting = cmd

        def done(cols: dict[str, np.ndarray]) -> None:
            self._starting = None
            f = rest_force_n(np.stack([cols[c] for c in _COMP], axis=1))
            refusal = rest_verdict(f, self.tool_cal.tool, overridden=bool(reason),
                                   payload_on_record=self.tool_cal.payload is not None)
            if refusal:
                self.engine.publish(m.CommandRefused(type(cmd).__name__, f"real rig: {refusal}"))
                return
            if reason:
                self._override = (missing, reason, f)
            self._gate_passed = cmd
            self.engine.handle(cmd)

        def abandoned() -> None:
            self._starting = None  # the measurement was abandoned: Start may be pressed again

        try:
            self._open_window(type(cmd).__name__, REST_CHECK_S, _COMP, done, abandoned)
        except RuntimeError:
            self._starting = None
            raise
        self.engine.publish(m.StartChecking(REST_CHECK_S, rest_check_note(self.tool_cal.tool,
                                                                          overridden=bool(missing and reason))))
        return True


def other_arms_missing(hardware: HardwareConfig, frameworks: dict[str, Any]) -> str:
    """The real rig's arms after the first: "" when each has its calibration chain (TCP, payload, frame check) on
    record in its own calibration file for its tool, else one line naming the arm and its first missing step.

    ``frameworks``: each arm's pipeline by name (its ``config`` holds the frame rotations in use).
    """
    for arm in hardware.arms[1:]:
        try:
            rec = (RigCalibrationFile.load(arm.calibration_file).tool(arm.calibration_tool) if arm.calibration_file
                   else ToolCalibration(arm.calibration_tool))
        except CalibrationFileError as exc:
            return f"arm {arm.name}: {exc}"
        fw = frameworks[arm.name].config
        missing = rec.missing(fw.rot_tip_sensor, fw.rot_haptic_base)
        if missing:
            return f"arm {arm.name}: {missing}"
    return ""
