"""The calibration wizard's state: pose set, progress, and the verdict with its reason."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

from study_app.engine import messages as m
from study_app.models import Emitter

__all__ = ["CalibrationModel", "pose_name"]

_DESCRIPTIONS = {
    "recommended": "24 poses tilted up to 60° in every direction, so gravity turns in the sensor frame and the "
                   "tool's weight, centre of mass and the sensor bias are all determined — use this one.",
    "quick": "6 well-spread poses: a quick check, less averaging of noise.",
    "tool-down only": "6 poses that only turn the tool about the vertical: gravity never changes in the sensor "
                      "frame, so the payload cannot be identified. The wizard refuses it and says why.",
}


@dataclass
class CalibrationModel:
    """``state`` ∈ {idle, running, accepted, refused}; the active calibration comes from the engine."""

    pose_set: str = "recommended"
    state: str = "idle"
    done: int = 0
    total: int = 0
    result: m.CalibrationDone | None = None
    active: dict[str, object] | None = None
    #: "sim" or "real" (from EngineReady; "" before): what the step's text speaks of.
    rig: str = ""
    changed: Emitter = field(default_factory=Emitter)

    @staticmethod
    def describe(pose_set: str) -> str:
        """What a pose set is for."""
        return _DESCRIPTIONS[pose_set]

    def set_pose_set(self, name: str) -> None:
        """Choose one of :data:`study_app.engine.messages.POSE_SETS`."""
        if name not in m.POSE_SETS:
            raise ValueError(f"pose set = {name!r}: allowed values are {', '.join(m.POSE_SETS)}")
        self.pose_set = name
        self.changed.emit()

    def command(self) -> m.Calibrate:
        """Start a run (the engine answers with progress and a result)."""
        self.state, self.done, self.total, self.result = "running", 0, 0, None
        self.changed.emit()
        return m.Calibrate(self.pose_set)

    def apply(self, ev: object) -> None:
        """Update from engine events."""
        if isinstance(ev, m.EngineReady):
            self.active, self.rig = ev.calibration, ev.rig
        elif isinstance(ev, m.CalibrationProgress):
            self.state, self.done, self.total = "running", ev.done, ev.total
        elif isinstance(ev, m.CalibrationDone):
            self.result = ev
            self.state = "accepted" if ev.accepted else "refused"
            if ev.accepted:
                self.active = ev.calibration
        elif isinstance(ev, m.CommandRefused) and ev.command == "Calibrate":
            self.state = "refused"
            self.result = m.CalibrationDone(False, ev.message, self.pose_set, 0, math.nan, math.nan, math.nan, [], None)
        else:
            return
        self.changed.emit()

    def intro(self) -> str:
        """What the payload step does, on the rig there is (the simulated one has no hardware to speak of)."""
        if self.rig == "real":
            return ("The wrist sensor reads the instrument's weight and its own offsets as well as the contact force. "
                    "Move the robot to each pose shown (teach pendant or its teleoperation), with the tool hanging "
                    "free, and press Record pose: the engine averages the wrench and reads the TCP orientation. "
                    "Identify fits the payload and bias and refuses a badly spread or noisy set.")
        if not self.rig:
            return "Waiting for the study engine …"
        return ("Simulated rig — no hardware is attached. The simulated wrist sensor reports the simulated "
                "instrument's weight and a sensor bias on top of the contact force, as a real one does. Run "
                "calibration: the simulated robot holds the tool clear of the tissue in each pose of the set by itself "
                "(nothing to move or hold), and the same least-squares fit as on the real rig identifies the payload "
                "and the bias, accepted or refused by the same rules.")

    def verdict(self) -> str:
        """One line: accepted (stored with the next session) or refused with the reason."""
        r = self.result
        if self.state == "running":
            if self.rig == "sim":
                return f"measuring pose {self.done} of {self.total or '…'} — the simulated robot moves by itself"
            return f"measuring pose {self.done} of {self.total or '…'} — keep the tool clear of the tissue"
        if r is None:
            return "Run the pose set to identify the tool's weight, centre of mass and the sensor bias."
        if r.accepted:
            if self.rig == "real":  # the real rig saves it for the mounted tool too (the chain's record)
                return "Accepted: installed in the force path, saved for the tool and stored with every session."
            return "Accepted: installed in the force path and stored with the next session."
        return f"Refused — the previous calibration stays in use. Reason: {r.reason}"

    def summary(self) -> list[tuple[str, str]]:
        """Figures of the last result (label, value)."""
        r = self.result
        if r is None:
            return []
        out = [("Poses", str(r.n_poses)), ("Condition number", _fmt(r.condition_number, "{:.3g}"))]
        out.append(("RMS force residual", _fmt(r.rms_force_residual_n, "{:.4f} N")))
        out.append(("RMS torque residual", _fmt(r.rms_torque_residual_nm, "{:.5f} N·m")))
        cal = r.calibration
        if cal is not None:
            out.append(("Payload mass", f"{float(cal['mass_kg']):.4f} kg"))
            out.append(("Model", str(cal["model"])))
        return out


def pose_name(label: str) -> str:
    """A calibration pose as people call it: ``pose 7`` (a pose set's ``P07`` reads like a participant's code)."""
    hit = re.fullmatch(r"P(\d+)", label)
    return f"pose {int(hit.group(1))}" if hit else label


def _fmt(v: float, f: str) -> str:
    return "–" if not math.isfinite(v) else f.format(v)
