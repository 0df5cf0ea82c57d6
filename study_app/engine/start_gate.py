"""The real rig's gate before a session starts or resumes: the calibration chain on record, the force at rest low.

The chain (TCP, payload, frames) must be on record for the mounted tool -- or the experimenter gives a reason to
start without it, stored with the session -- and then, in every case, the compensated force at rest over
``REST_CHECK_S`` must be below ``REST_MAX_FORCE_N``: without a payload that fits the mounted tool, the tool's own
weight would be rendered as feedback.  What the gate decides is :mod:`pipeline.commissioning.steps`'.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline.commissioning.rig_calibration import CalibrationFileError, RigCalibrationFile, ToolCalibration
from pipeline.commissioning.steps import REST_CHECK_S, rest_check_note, rest_force_n, rest_verdict
from study_app.engine import messages as m
from study_app.engine.core import EngineCore
from study_app.engine.ring_windows import RingWindows
from study_app.engine.tool_records import ToolRecords

if TYPE_CHECKING:
    from pipeline.settings.hardware import HardwareConfig

__all__ = ["StartGate", "other_arms_missing"]

_COMP = ("comp_fx", "comp_fy", "comp_fz")


class StartGate:
    """The real rig's start gate of one study engine (driver thread only).

    Parameters
    ----------
    engine
        The engine whose start or resume waits: it applies the command again once the rest check passes.
    records
        What is on record for each arm's tool.
    windows
        Where the force at rest is measured.
    """

    def __init__(self, engine: EngineCore, records: ToolRecords, windows: RingWindows) -> None:
        self.engine = engine
        self.records = records
        self.windows = windows
        self._passed: object | None = None  # a start whose rest check passed: let it through once
        self._starting: object | None = None  # a start waiting for its rest check
        self._override: tuple[str, str, float] | None = None  # (what was missing, the reason, force at rest N)

    def take_override(self) -> tuple[str, str, float] | None:
        """The override the session that just started was let through with (once), or None."""
        override, self._override = self._override, None
        return override

    def provenance(self) -> dict[str, Any]:
        """What a session stores about a start without the chain on record (``config_json``), if it was one."""
        if self._override is None:
            return {}
        return {"calibration_override": {"missing": self._override[0], "reason": self._override[1],
                                         "rest_force_n": self._override[2]}}

    def check(self, cmd: m.StartSession | m.ResumeSession) -> bool:
        """The real rig's calibration gate; True when the start waits for its rest check (it comes back later).

        Raises :class:`RuntimeError` (one line, naming the missing step) when the start is refused.
        """
        if not self.engine.real:
            return False
        if cmd is self._passed:
            self._passed = None
            return False
        self._override = None  # a start that failed after its check must not lend its override to this one
        missing = self.records.tool_cal.missing(*self.records.frames_in_use())
        hardware = self.engine.hardware
        if hardware is not None and len(hardware.arms) > 1:
            # a rig of several arms: every arm's chain, each named (the first's is the wizard's)
            first = hardware.arms[0].name
            missing = (f"arm {first}: {missing}" if missing else
                       other_arms_missing(hardware, self.engine.eng.frameworks))
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
            tool_cal = self.records.tool_cal
            refusal = rest_verdict(f, tool_cal.tool, overridden=bool(reason),
                                   payload_on_record=tool_cal.payload is not None)
            if refusal:
                self.engine.publish(m.CommandRefused(type(cmd).__name__, f"real rig: {refusal}"))
                return
            if reason:
                self._override = (missing, reason, f)
            self._passed = cmd
            self.engine.handle(cmd)

        def abandoned() -> None:
            self._starting = None  # the measurement was abandoned: Start may be pressed again

        try:
            self.windows.open(type(cmd).__name__, REST_CHECK_S, _COMP, done, abandoned)
        except RuntimeError:
            self._starting = None
            raise
        self.engine.publish(m.StartChecking(REST_CHECK_S, rest_check_note(self.records.tool_cal.tool,
                                                                          overridden=bool(missing and reason))))
        return True


def other_arms_missing(hardware: HardwareConfig, frameworks: Mapping[str, Any]) -> str:
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
