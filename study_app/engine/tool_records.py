"""What is on record for each arm's mounted tool (TCP, payload, frame check), as the study engine keeps it.

On the real rig each arm's record lives in its calibration file (loaded when the engine was built, saved as each
accepted step comes); on the simulated rig it is this run's and never saved.  What a session stores of it is
:meth:`ToolRecords.provenance`; what the window shows of it, :class:`study_app.engine.messages.CalibrationStatus`.
"""

from __future__ import annotations

from typing import Any

from pipeline.commissioning.rig_calibration import CalibrationFileError, RigCalibrationFile, ToolCalibration, now_iso
from pipeline.force.frames import Mat3
from study_app.engine import messages as m
from study_app.engine.core import EngineCore
from study_app.engine.rig_arms import RigArms

__all__ = ["ToolRecords"]


class ToolRecords:
    """Per arm, what is on record for its mounted tool (driver thread only).

    Parameters
    ----------
    engine
        The engine whose rig the tools are mounted on (its calibration files, its frames); it publishes the status.
    arms
        The rig's arms.
    """

    def __init__(self, engine: EngineCore, arms: RigArms) -> None:
        self.engine = engine
        self.arms = arms
        self._files = {a: self._calibration_file(a) for a in arms.names}
        #: Per arm, what is on record for its mounted tool (real rig: from its calibration file; simulated: this run's).
        self.tool_cals: dict[str, ToolCalibration] = {a: self._tool_record(a) for a in arms.names}

    @property
    def tool_cal(self) -> ToolCalibration:
        """What is on record for the first arm's tool (a one-arm rig's)."""
        return self.tool_cals[self.arms.first]

    def _calibration_file(self, arm: str) -> RigCalibrationFile | None:
        """The real rig's calibration file of an arm (loaded when the engine was built, so it reads), else None."""
        eng = self.engine.eng
        if eng.simulated:
            return None
        if arm == self.arms.first:
            return eng.calibration_file
        hw = self.arms.hardware_arm(arm)
        return RigCalibrationFile.load(hw.calibration_file) if hw is not None and hw.calibration_file else None

    def _tool(self, arm: str) -> str:
        """The tool mounted on an arm (real rig: the hardware file's, its record's name in the calibration file)."""
        hw = self.arms.hardware_arm(arm)
        return str(hw.calibration_tool) if hw is not None and arm != self.arms.first else self.engine.eng.tool

    def _tool_record(self, arm: str) -> ToolCalibration:
        eng = self.engine.eng
        if not eng.simulated:
            f = self._files[arm]
            return ToolCalibration(self._tool(arm)) if f is None else f.tool(self._tool(arm))
        # the simulated rig calibrated its payload as it was built; TCP and frames are this run's, never saved
        return ToolCalibration("simulated instrument", payload=eng.calibrations[arm], payload_date=now_iso())

    def frames_in_use(self, arm: str = "") -> tuple[Mat3, Mat3]:
        """The frame rotations an arm's force path uses (the first arm's by default)."""
        fw = self.engine.eng.frameworks[arm or self.arms.first].config
        return fw.rot_tip_sensor, fw.rot_haptic_base

    def publish_status(self) -> None:
        """What is on record, per arm (a one-arm rig's status names no arm)."""
        several = len(self.arms.names) > 1
        for arm in self.arms.names:
            f, rec = self._files[arm], self.tool_cals[arm]
            self.engine.publish(m.CalibrationStatus(self.engine.config.rig, rec.tool, f.path if f is not None else "",
                                                    rec.status(), rec.missing(*self.frames_in_use(arm)),
                                                    arm if several else ""))

    def record(self, arm: str, step: str, result: Any) -> None:
        """Put an accepted result on record for an arm (real rig: saved in its calibration file); publish the status."""
        f = self._files[arm]
        if f is not None:
            try:
                self.tool_cals[arm] = f.record(self._tool(arm), step, result)
            except CalibrationFileError as exc:
                self.tool_cals[arm] = self.tool_cals[arm].with_step(step, result)
                self.engine.publish(m.CommandRefused("calibration file", f"{exc}: the result is in use but not saved"))
            hw = self.arms.hardware_arm(arm)
            if step == "tcp" and hw is not None:
                # the robot's poses move to the new tip at once (the pendant's TCP stays what the file says)
                off = hw.robot.tcp_offset_m
                self.arms.devices(arm).robot.tcp_correction_m = tuple(
                    t - o for t, o in zip(result.tip_in_flange_m, off, strict=True))
        else:
            self.tool_cals[arm] = self.tool_cals[arm].with_step(step, result)
        self.publish_status()

    def provenance(self) -> dict[str, Any]:
        """What a session stores about the calibration chain (``config_json``): tool, file, every step on record."""
        def chain(arm: str) -> dict[str, Any]:
            f, rec = self._files[arm], self.tool_cals[arm]
            return {"tool": rec.tool, "file": f.path if f is not None else None, **rec.to_dict()}

        out: dict[str, Any] = {"rig_calibration": chain(self.arms.first)}
        if len(self.arms.names) > 1:  # every arm's chain (the first's is rig_calibration)
            out["arms_rig_calibration"] = {a: chain(a) for a in self.arms.names}
        return out
