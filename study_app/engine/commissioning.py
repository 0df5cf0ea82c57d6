"""Commissioning the rig from the study engine: payload, TCP and frame steps, what is on record, and the session gate.

:class:`Commissioning` belongs to a :class:`study_app.engine.host.StudyEngine`
(it sees it as an :class:`study_app.engine.core.EngineCore`) and runs on its driver thread.  On the simulated rig each
step runs
automatically; on the real rig the experimenter records poses, pivot
orientations and axis pushes one at a time, each averaged over a window of
the ring's records (:class:`_Window`).  Accepted results are put on record for
the mounted tool (real rig: saved in the rig's calibration file).  Before a
session starts on the real rig, :meth:`Commissioning.gate` requires the chain
on record (or the experimenter's reason to start without it) and then, in
every case, a compensated force at rest below ``REST_MAX_FORCE_N``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.commissioning.frame_check import AXES, AxisCheck, FrameCheck, check_axis
from pipeline.commissioning.payload_identification import (
    CalibrationPose,
    DegeneratePoseSetError,
    identify_payload,
    recommended_pose_set,
)
from pipeline.commissioning.rig_calibration import CalibrationFileError, ToolCalibration, now_iso
from pipeline.commissioning.tcp import PivotPose, identify_tip, pivot_orientations
from pipeline.force.frames import Mat3, as_mat3, axis_angle, mat_mul
from pipeline.force.payload_compensator import PayloadCalibration
from pipeline.runtime.clock import MonotonicClock
from pipeline.runtime.loop_messages import SetCalibration
from study_app.engine import messages as m
from study_app.engine.core import EngineCore

__all__ = [
    "CALIBRATION_MAX_CONDITION", "CALIBRATION_MAX_RMS_FORCE_N", "REST_CHECK_S", "REST_MAX_FORCE_N", "Commissioning",
    "calibration_verdict", "check_target", "pose_set", "rotation_angle_deg",
]

#: The wizard refuses a pose set whose (column-scaled) regressor is worse conditioned than this.
CALIBRATION_MAX_CONDITION = 1000.0
#: ... or whose fit leaves more than this RMS force residual (a pose in contact, a loose tool).
CALIBRATION_MAX_RMS_FORCE_N = 0.05
#: A calibration pose is refused if the TCP turned more than this, or moved more than the next, while averaging.
POSE_STILL_DEG = 0.5
POSE_STILL_M = 0.002
#: ... or if a force sample older than this was averaged (the sensor stalled).
POSE_MAX_SENSOR_AGE_S = 0.05
#: Real rig: a session starts only if the compensated force at rest, averaged over this long, is below the next.
REST_CHECK_S = 2.0
REST_MAX_FORCE_N = 0.1
#: Real rig, TCP pivot step: a recorded orientation is refused if the TCP moved more than this while averaging.
PIVOT_STILL_M = 0.0002
PIVOT_STILL_DEG = 0.2
_RAW_WRENCH = ("raw_fx", "raw_fy", "raw_fz", "raw_tx", "raw_ty", "raw_tz")


def rotation_angle_deg(a: Mat3, b: Mat3) -> float:
    """The angle of the rotation taking orientation ``a`` to ``b``, degrees (0–180)."""
    ra, rb = np.asarray(a, dtype=float).reshape(3, 3), np.asarray(b, dtype=float).reshape(3, 3)
    c = (float(np.trace(ra.T @ rb)) - 1.0) / 2.0
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def pose_set(name: str) -> list[Mat3]:
    """Sensor orientations ``rot_base_sensor`` of a named calibration pose set.

    ``recommended``: 24 well-spread tilts (science.md §1.2); ``quick``: 6;
    ``tool-down only``: 6 yaws about the vertical with the tool pointing down,
    which leave gravity fixed in the sensor frame -- a degenerate set the
    wizard must refuse (kept so an experimenter can see what a refusal says).
    """
    if name == "recommended":
        return recommended_pose_set(24)
    if name == "quick":
        return recommended_pose_set(6)
    if name == "tool-down only":
        down = recommended_pose_set(24)[0]
        return [mat_mul(axis_angle((0.0, 0.0, 1.0), k * 0.5), down) for k in range(6)]
    raise ValueError(f"pose set = {name!r}: allowed values are {', '.join(m.POSE_SETS)}")


def check_target(rows: Any) -> Mat3:
    """A requested pose's ``rot_base_sensor`` (validated)."""
    from pipeline.force.frames import check_rotation

    return check_rotation(rows, "target_rot_base_sensor")


def calibration_verdict(cal: PayloadCalibration) -> str:
    """Empty if the calibration is acceptable, else the reason it is refused."""
    if cal.condition_number > CALIBRATION_MAX_CONDITION:
        return (f"condition number {cal.condition_number:.3g} is above {CALIBRATION_MAX_CONDITION:g}: the poses do not "
                "vary the tool's orientation enough; use the recommended set")
    if cal.rms_force_residual_n > CALIBRATION_MAX_RMS_FORCE_N:
        return (f"RMS force residual {cal.rms_force_residual_n:.3g} N is above {CALIBRATION_MAX_RMS_FORCE_N:g} N: "
                "a pose was in contact or the tool moved; check the tool hangs free and repeat")
    return ""


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


class Commissioning:
    """The commissioning chain of one study engine (driver thread only).

    Parameters
    ----------
    engine
        The engine whose rig, loop and ring the steps use.
    """

    def __init__(self, engine: EngineCore) -> None:
        self.engine = engine
        #: What is on record for the mounted tool (real rig: from the calibration file; simulated: this run's).
        self.tool_cal = self._tool_record()
        self._windows: list[_Window] = []
        self._frame_axes: dict[str, AxisCheck] = {}
        self._gate_passed: object | None = None  # a start whose rest check passed: let it through once
        self._starting: object | None = None  # a start waiting for its rest check
        self._override: tuple[str, str, float] | None = None  # (what was missing, the reason, force at rest N)

    def take_override(self) -> tuple[str, str, float] | None:
        """The override the session that just started was let through with (once), or None."""
        override, self._override = self._override, None
        return override

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
        if not (math.isfinite(cmd.seconds) and 0.1 <= cmd.seconds <= 10.0):
            raise ValueError(f"record seconds = {cmd.seconds!r}: allowed 0.1 to 10 s")
        target = None
        if cmd.target_rot_base_sensor is not None:
            target = check_target(cmd.target_rot_base_sensor)
        now = e.eng.clock.now_ns()
        pose0 = e.eng.rig.robot.read_pose()
        if not all(math.isfinite(x) for x in pose0.position_m):
            raise RuntimeError("robot: no TCP pose received yet; check the RTDE connection (Devices tab)")
        age_s = (now - pose0.t_ns) * 1e-9
        if age_s > 0.5:
            raise RuntimeError(f"robot: the newest TCP pose is {age_s:.1f} s old; check the RTDE connection")
        label = cmd.label

        def done(cols: dict[str, np.ndarray]) -> None:
            self._pose_recorded(label, pose0, target, np.stack([cols[c] for c in _RAW_WRENCH], axis=1))

        # average only records written after this command (the window drains everything up to now first)
        self._open_window("RecordPose", cmd.seconds, _RAW_WRENCH, done, label=label,
                          stalled=f"pose {label}: the force sensor stalled while recording (check the Devices tab) "
                                  "— record it again")

    def _pose_recorded(self, label: str, pose0: Any, target: Mat3 | None, w: np.ndarray) -> None:
        e = self.engine
        pose1 = e.eng.rig.robot.read_pose()
        turned = rotation_angle_deg(pose0.rot_base_tip, pose1.rot_base_tip)
        moved = math.dist(pose0.position_m, pose1.position_m)
        if not np.isfinite(w).all():
            reason = "the force sensor gave non-finite readings"
        elif not (turned <= POSE_STILL_DEG and moved <= POSE_STILL_M):
            reason = (f"the robot moved while recording ({turned:.2f}°, {moved * 1e3:.1f} mm; allowed "
                      f"{POSE_STILL_DEG:g}° and {POSE_STILL_M * 1e3:g} mm) — let it stand still and record again")
        else:
            reason = ""
        if reason:
            e.publish(m.CommandRefused("RecordPose", f"pose {label}: {reason}"))
            return
        rot_base_sensor = mat_mul(pose1.rot_base_tip, e.eng.framework.config.rot_tip_sensor)
        mean = w.mean(axis=0)
        e.publish(m.PoseRecorded(
            label=label, samples=len(w), wrench=tuple(float(x) for x in mean),  # type: ignore[arg-type]  # six items: mypy cannot count a generator
            rot_base_sensor=as_mat3(rot_base_sensor),
            tcp_position_m=tuple(float(x) for x in pose1.position_m),  # type: ignore[arg-type]  # three items, likewise
            off_target_deg=rotation_angle_deg(target, rot_base_sensor) if target is not None else math.nan,
            force_std_n=float(np.std(np.linalg.norm(w[:, :3], axis=1))),
        ))

    def identify(self, cmd: m.IdentifyPoses) -> None:
        if not self.engine.real:
            raise RuntimeError("simulated rig: the poses run automatically (Run calibration)")
        self.engine.require_idle("calibrate")
        poses = [CalibrationPose(rot, wrench, label) for label, rot, wrench in cmd.poses]
        self.engine.publish(self._judged(cmd.pose_set, len(poses), lambda: (identify_payload(poses), len(poses))))

    def _judged(self, name: str, n_poses: int,
                identify: Callable[[], tuple[PayloadCalibration, int]]) -> m.CalibrationDone:
        """Identify (``identify`` gives the calibration and how many poses it used), judge, install an accepted one."""
        try:
            cal, n_used = identify()
        except DegeneratePoseSetError as exc:
            return m.CalibrationDone(False, str(exc), name, n_poses, float(exc.condition_number or math.inf),
                                     math.nan, math.nan, [], None)
        reason = calibration_verdict(cal)
        if reason == "":
            self.engine.calibration = cal
            self.engine.loop.submit(SetCalibration(cal))
            self._record_step("payload", cal)
        return m.CalibrationDone(
            reason == "", reason, name, n_used, cal.condition_number, cal.rms_force_residual_n,
            cal.rms_torque_residual_nm, [(r.label, r.force_residual_n, r.torque_residual_nm) for r in cal.residuals],
            cal.to_dict(),
        )

    def calibrate(self, name: str) -> None:
        """Simulated rig: run the pose set automatically (the loop paused), identify, judge, install."""
        from pipeline.sim.calibration import auto_calibrate

        self.engine.require_idle("calibrate")
        rots = pose_set(name)
        real = self.engine.config.clock == "real"
        if real:
            self.engine.loop.stop(timeout_s=5.0)  # ramps the force to zero first
            clock: Any = MonotonicClock()
        else:
            self.engine.loop.ramp_down()
            clock = self.engine.loop.clock
        self.engine.drain_ring()

        def run_poses() -> tuple[PayloadCalibration, int]:
            assert self.engine.eng.simulated
            cal, used = auto_calibrate(
                self.engine.eng.rig, clock, rots,
                progress=lambda done, n: self.engine.publish(m.CalibrationProgress(done, n, f"P{done:02d}")),
            )
            return cal, len(used)

        try:
            result = self._judged(name, len(rots), run_poses)
        finally:
            self.engine.after_loop_pause(real)
        self.engine.publish(result)

    def _tool_record(self) -> ToolCalibration:
        eng = self.engine.eng
        if not eng.simulated:
            if eng.calibration_file is None:
                return ToolCalibration(eng.tool)
            return eng.calibration_file.tool(eng.tool)
        # the simulated rig calibrated its payload as it was built; TCP and frames are this run's, never saved
        return ToolCalibration("simulated instrument", payload=eng.calibration, payload_date=now_iso())

    def frames_in_use(self) -> tuple[Mat3, Mat3]:
        fw = self.engine.eng.framework.config
        return fw.rot_tip_sensor, fw.rot_haptic_base

    def publish_status(self) -> None:
        eng = self.engine.eng
        path = eng.calibration_file.path if not eng.simulated and eng.calibration_file is not None else ""
        self.engine.publish(m.CalibrationStatus(self.engine.config.rig, self.tool_cal.tool, path,
                                                self.tool_cal.status(), self.tool_cal.missing(*self.frames_in_use())))

    def _record_step(self, step: str, result: Any) -> None:
        """Put an accepted result on record (real rig: saved in the calibration file) and publish the status."""
        eng = self.engine.eng
        if not eng.simulated and eng.calibration_file is not None:
            try:
                self.tool_cal = eng.calibration_file.record(eng.tool, step, result)
            except CalibrationFileError as exc:
                self.tool_cal = self.tool_cal.with_step(step, result)
                self.engine.publish(m.CommandRefused("calibration file", f"{exc}: the result is in use but not saved"))
            if step == "tcp" and self.engine.hardware is not None:
                # the robot's poses move to the new tip at once (the pendant's TCP stays what the file says)
                off = self.engine.hardware.robot.tcp_offset_m
                eng.rig.robot.tcp_correction_m = tuple(t - o for t, o in zip(result.tip_in_flange_m, off, strict=True))
        else:
            self.tool_cal = self.tool_cal.with_step(step, result)
        self.publish_status()

    def provenance(self) -> dict[str, Any]:
        """What a session stores about the calibration chain (``config_json``): tool, file, every step on record."""
        eng = self.engine.eng
        path = eng.calibration_file.path if not eng.simulated and eng.calibration_file is not None else None
        out: dict[str, Any] = {"rig_calibration": {"tool": self.tool_cal.tool, "file": path, **self.tool_cal.to_dict()}}
        if self._override is not None:
            out["calibration_override"] = {"missing": self._override[0], "reason": self._override[1],
                                           "rest_force_n": self._override[2]}
        return out

    def calibrate_tcp(self, name: str) -> None:
        from pipeline.sim.commissioning import pivot_poses
        from pipeline.sim.robot import TOOL_DOWN

        if not self.engine.eng.simulated:
            raise RuntimeError("real rig: rest the tip in the divot, turn the instrument and record each orientation "
                               "(Record orientation), then Compute")
        self.engine.require_idle("TCP calibration")
        if name not in m.PIVOT_SETS:
            raise ValueError(f"pose set = {name!r}: allowed values are {', '.join(m.PIVOT_SETS)}")
        rig = self.engine.eng.rig
        self._tcp_identified(pivot_poses(rig, pivot_orientations(name, TOOL_DOWN)), name, rig.config.tip_in_flange_m)

    def _tcp_identified(self, poses: list[PivotPose], name: str, truth: Any = None) -> None:
        try:
            tc = identify_tip(poses)
        except ValueError as exc:
            self.engine.publish(m.TcpCalibrationDone(False, str(exc), name, len(poses), None))
            return
        err = math.dist(tc.tip_in_flange_m, truth) * 1e3 if truth is not None else math.nan
        self._record_step("tcp", tc)
        self.engine.publish(m.TcpCalibrationDone(True, "", name, tc.n_poses, tc.to_dict(), err))

    def record_pivot(self, cmd: m.RecordPivot) -> None:
        if self.engine.eng.simulated:
            raise RuntimeError("simulated rig: the orientations run automatically (Run TCP calibration)")
        self.engine.require_idle("record orientation")
        if not (math.isfinite(cmd.seconds) and 0.1 <= cmd.seconds <= 5.0):
            raise ValueError(f"record seconds = {cmd.seconds!r}: allowed 0.1 to 5 s")
        robot = self.engine.eng.rig.robot
        pose0 = robot.read_pose()
        if not all(math.isfinite(x) for x in pose0.position_m):
            raise RuntimeError("robot: no TCP pose received yet; check the RTDE connection (Devices tab)")
        label = cmd.label

        def done(cols: dict[str, np.ndarray]) -> None:
            p = np.stack([cols["tip_x_m"], cols["tip_y_m"], cols["tip_z_m"]], axis=1)
            pose1 = robot.read_pose()
            moved = float(np.max(np.linalg.norm(p - p.mean(axis=0), axis=1)))
            turned = rotation_angle_deg(pose0.rot_base_tip, pose1.rot_base_tip)
            if not (moved <= PIVOT_STILL_M and turned <= PIVOT_STILL_DEG):
                self.engine.publish(m.CommandRefused("RecordPivot", (
                    f"orientation {label}: the robot moved while recording ({moved * 1e3:.2f} mm, {turned:.2f}°; "
                    f"allowed {PIVOT_STILL_M * 1e3:g} mm and {PIVOT_STILL_DEG:g}°) — hold it still and record again")))
                return
            rot = pose1.rot_base_tip
            tip = self.tool_cal.tcp.tip_in_flange_m if self.tool_cal.tcp is not None else (
                self.engine.hardware.robot.tcp_offset_m if self.engine.hardware is not None else (0.0, 0.0, 0.0))
            off = np.asarray(rot).reshape(3, 3) @ np.asarray(tip)
            flange = tuple(float(v) for v in p.mean(axis=0) - off)
            self.engine.publish(m.PivotRecorded(label, as_mat3(rot), flange, moved * 1e3))  # type: ignore[arg-type]  # flange: three items, likewise

        self._open_window("RecordPivot", cmd.seconds, ("tip_x_m", "tip_y_m", "tip_z_m"), done)

    def identify_tcp(self, cmd: m.IdentifyTcp) -> None:
        if self.engine.eng.simulated:
            raise RuntimeError("simulated rig: the orientations run automatically (Run TCP calibration)")
        self.engine.require_idle("TCP calibration")
        self._tcp_identified([PivotPose(rot, pos, label) for label, rot, pos in cmd.poses], "recorded")

    def check_frames(self) -> None:
        from pipeline.sim.commissioning import push_axes

        if not self.engine.eng.simulated:
            raise RuntimeError("real rig: push the free tip along each axis in turn (Record +x, +y, +z)")
        self.engine.require_idle("frame check")
        real = self.engine.config.clock == "real"
        if real:
            self.engine.loop.stop(timeout_s=5.0)  # the check runs the loop itself, paced on the same clock
        self.engine.drain_ring()
        try:
            assert self.engine.ring is not None
            check = push_axes(self.engine.eng.rig, self.engine.loop, self.engine.ring)
        finally:
            self.engine.cursor = self.engine.ring.write_count  # the check's own records are not the loop's timing
            self.engine.after_loop_pause(real)
        for a in check.axes:
            self.engine.publish(m.FrameAxisChecked(a.axis, a.passed, a.describe(), a.to_dict()))
        self._frames_done(check)

    def _frames_done(self, check: FrameCheck) -> None:
        self._record_step("frames", check)
        summary = check.summary()
        mount = self.engine.calibration.mount_angle_deg
        if not check.passed and mount > 5.0:
            summary += f" (the payload calibration finds the sensor {mount:.1f}° from its configured mount)"
        self.engine.publish(m.FrameCheckDone(check.passed, summary, [a.describe() for a in check.axes]))

    def record_frame_axis(self, cmd: m.RecordFrameAxis) -> None:
        if self.engine.eng.simulated:
            raise RuntimeError("simulated rig: the pushes run automatically (Run frame check)")
        self.engine.require_idle("frame check")
        if cmd.axis not in AXES:
            raise ValueError(f"axis = {cmd.axis!r}: allowed values are {', '.join(AXES)}")
        if not (math.isfinite(cmd.seconds) and 0.5 <= cmd.seconds <= 10.0):
            raise ValueError(f"record seconds = {cmd.seconds!r}: allowed 0.5 to 10 s")
        if self.tool_cal.payload is None:
            raise RuntimeError("frame check: no payload calibration on record for tool "
                               f"{self.tool_cal.tool!r}; the chain runs in order: calibrate the payload first")
        axis = cmd.axis
        rhb = self.frames_in_use()[1]

        def done(cols: dict[str, np.ndarray]) -> None:
            base = np.stack([cols["base_fx"], cols["base_fy"], cols["base_fz"]], axis=1)
            scaled = np.stack([cols["scaled_fx"], cols["scaled_fy"], cols["scaled_fz"]], axis=1)
            res = check_axis(axis, base, scaled, rhb)
            self._frame_axes[axis] = res
            self.engine.publish(m.FrameAxisChecked(axis, res.passed, res.describe(), res.to_dict()))
            if all(a in self._frame_axes for a in AXES):
                check = FrameCheck(tuple(self._frame_axes[a] for a in AXES), *self.frames_in_use())
                self._frame_axes = {}
                self._frames_done(check)

        self._open_window("RecordFrameAxis", cmd.seconds,
                          ("base_fx", "base_fy", "base_fz", "scaled_fx", "scaled_fy", "scaled_fz"), done)

    def _open_window(self, command: str, seconds: float, cols: tuple[str, ...],
                     done: Callable[[dict[str, np.ndarray]], None], abandoned: Callable[[], None] | None = None,
                     *, label: str = "", stalled: str = "") -> None:
        """Collect ``seconds`` of records written after now, then call ``done`` (see :class:`_Window`)."""
        if any(w.command == command for w in self._windows):
            raise RuntimeError(f"{command}: a recording is already running")
        self.engine.drain_ring()
        start = self.engine.last_t_ns + 1 if self.engine.loop.tick_count else 0
        self._windows.append(_Window(command, int(round(seconds * 1000)), start, cols, done, [], abandoned=abandoned,
                                     label=label, stalled=stalled))

    def feed(self, rows: np.ndarray) -> None:
        """The newest records of the ring: fill the open windows, finish those that are full."""
        for w in list(self._windows):
            sel = rows[rows["t_ns"] >= w.start_ns]
            if len(sel):
                if float(np.max(sel["sensor_age_ns"])) * 1e-9 > POSE_MAX_SENSOR_AGE_S:
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
            f = float(math.hypot(*(float(np.mean(cols[c])) for c in ("comp_fx", "comp_fy", "comp_fz"))))
            if not f < REST_MAX_FORCE_N:
                self.engine.publish(m.CommandRefused(type(cmd).__name__, (
                    f"real rig: the compensated force at rest is {f:.3f} N over {REST_CHECK_S:g} s (limit "
                    f"{REST_MAX_FORCE_N:g} N): the tool touches something, or its payload calibration does not match "
                    f"the mounted tool {self.tool_cal.tool!r}; keep it clear and still, or calibrate the payload again"
                    + ("; an override does not waive this check" if reason else ""))))
                return
            if reason:
                self._override = (missing, reason, f)
            self._gate_passed = cmd
            self.engine.handle(cmd)

        def abandoned() -> None:
            self._starting = None  # the measurement was abandoned: Start may be pressed again

        try:
            self._open_window(type(cmd).__name__, REST_CHECK_S, ("comp_fx", "comp_fy", "comp_fz"), done, abandoned)
        except RuntimeError:
            self._starting = None
            raise
        self.engine.publish(m.StartChecking(REST_CHECK_S,
                                            f"calibration on record for tool {self.tool_cal.tool!r}; measuring "
                                            f"the compensated force at rest for {REST_CHECK_S:g} s — keep the "
                                            "instrument still and clear of everything"))
        return True
