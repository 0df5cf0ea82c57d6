"""The real rig's calibration wizard, step by step (Qt-free).

On hardware nobody can re-orient the tool for us: the wizard shows one target
pose of :func:`pipeline.commissioning.payload_identification.recommended_pose_set` at a time, the
experimenter moves the robot there with its own teach pendant or teleoperation,
and presses *Record pose*; the engine averages the raw wrench for
``seconds`` and reads the TCP orientation the robot reports (off the GUI
thread).  When enough poses are in, *Identify* sends them back to the engine,
which fits, judges (condition number, residuals) and installs an accepted
calibration; the next session stores it.

``state`` ∈ {idle, at_pose, recording, identifying, accepted, refused}.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from pipeline.commissioning.payload_identification import recommended_pose_set
from pipeline.force.frames import IDENTITY, Mat3, as_mat3, mat_mul, matrix_to_rotvec, transpose
from study_app.engine import messages as m
from study_app.models import Emitter

__all__ = ["MIN_POSES", "OFF_TARGET_WARN_DEG", "REAL_POSE_SETS", "PoseStep", "RealCalibrationModel"]

#: Pose sets offered on the real rig (number of poses).
REAL_POSE_SETS = {"recommended": 24, "quick": 6}
#: Identification needs at least this many recorded poses (the affine model's minimum).
MIN_POSES = 6
#: A recorded pose further than this from its target is kept but flagged (the fit uses the measured orientation).
OFF_TARGET_WARN_DEG = 15.0


@dataclass
class PoseStep:
    """One pose of the set: where the sensor should point, and what was measured there."""

    label: str
    target_rot_base_sensor: Mat3
    recorded: m.PoseRecorded | None = None


@dataclass
class RealCalibrationModel:
    """Walks the experimenter through the pose set; turns presses into engine commands.

    Parameters
    ----------
    rot_tip_sensor
        The sensor mount of the hardware file (from :class:`study_app.engine.messages.EngineReady`):
        converts a target sensor orientation into the TCP orientation the pendant shows.
    seconds
        Averaging time per pose.
    """

    rot_tip_sensor: Mat3 = IDENTITY
    seconds: float = 1.0
    pose_set: str = "recommended"
    state: str = "idle"
    steps: list[PoseStep] = field(default_factory=list)
    index: int = 0
    message: str = ""
    #: A rig of several arms: each arm's sensor mount by name (from EngineReady).
    mounts: dict[str, Mat3] = field(default_factory=dict)
    changed: Emitter = field(default_factory=Emitter)

    # -- the walk ----------------------------------------------------------------------------------
    def for_arm(self, name: str) -> None:
        """Walk the poses of the arm called ``name`` (a rig of several arms): its targets as its pendant shows them
        (its own sensor mount); a walk under way starts again from its first pose (its poses were the other arm's)."""
        if name in self.mounts:
            self.rot_tip_sensor = self.mounts[name]
        if self.steps:
            self.begin(self.pose_set)

    def begin(self, pose_set: str = "recommended") -> None:
        """Start (or restart) a pose set: every pose unrecorded, the first one shown."""
        if pose_set not in REAL_POSE_SETS:
            raise ValueError(f"pose set = {pose_set!r}: allowed values are {', '.join(REAL_POSE_SETS)}")
        self.pose_set = pose_set
        rots = recommended_pose_set(REAL_POSE_SETS[pose_set])
        self.steps = [PoseStep(f"pose {k + 1}", r) for k, r in enumerate(rots)]  # never "P01": a participant's code
        self.index, self.state, self.message = 0, "at_pose", ""
        self.changed.emit()

    @property
    def current(self) -> PoseStep | None:
        """The pose to move to now (None before :meth:`begin`)."""
        return self.steps[self.index] if self.steps and self.state in ("at_pose", "recording") else None

    @property
    def recorded(self) -> list[PoseStep]:
        """Poses measured so far, in set order."""
        return [s for s in self.steps if s.recorded is not None]

    def go_to(self, index: int) -> None:
        """Show pose ``index`` (to record it, or record it again)."""
        if self.state == "recording":
            raise RuntimeError("a pose is being recorded")
        if not 0 <= index < len(self.steps):
            raise ValueError(f"pose index = {index}: allowed 0 to {len(self.steps) - 1}")
        self.index, self.state, self.message = index, "at_pose", ""
        self.changed.emit()

    def skip(self) -> None:
        """Leave the current pose unrecorded and show the next unrecorded one (e.g. out of the robot's reach)."""
        if self.state != "at_pose":
            return
        nxt = self._next_unrecorded(self.index + 1)
        self.index = nxt if nxt is not None else self.index
        self.message = "" if nxt is not None else "no unrecorded pose left after this one"
        self.changed.emit()

    def _next_unrecorded(self, start: int) -> int | None:
        n = len(self.steps)
        for k in range(n):
            i = (start + k) % n
            if self.steps[i].recorded is None:
                return i
        return None

    # -- commands ----------------------------------------------------------------------------------
    def can_record(self) -> bool:
        """A pose is shown and nothing is being recorded."""
        return self.state == "at_pose" and self.current is not None

    def record_command(self) -> m.RecordPose:
        """Record the shown pose (the engine averages the wrench and reads the TCP pose)."""
        step = self.current
        if step is None or self.state != "at_pose":
            raise RuntimeError("no pose to record: start the pose set first")
        self.state, self.message = "recording", ""
        self.changed.emit()
        return m.RecordPose(step.label, self.seconds, as_mat3(step.target_rot_base_sensor))

    def identify_refusal(self) -> str:
        """Why identification is not possible now ("" if it is)."""
        if self.state == "recording":
            return "a pose is being recorded"
        if self.state == "identifying":
            return "identification is running"
        n = len(self.recorded)
        if n < MIN_POSES:
            return f"record at least {MIN_POSES} poses first ({n} so far)"
        return ""

    def identify_command(self) -> m.IdentifyPoses:
        """Identify from the recorded poses."""
        why = self.identify_refusal()
        if why:
            raise RuntimeError(f"cannot identify: {why}")
        poses = tuple((s.label, s.recorded.rot_base_sensor, s.recorded.wrench) for s in self.recorded)  # type: ignore[union-attr]  # every step is recorded (identify_refusal)
        self.state, self.message = "identifying", ""
        self.changed.emit()
        return m.IdentifyPoses(poses, self.pose_set)

    # -- engine events -----------------------------------------------------------------------------
    def apply(self, ev: object) -> None:
        """Update from engine events."""
        if isinstance(ev, m.EngineReady):
            self.rot_tip_sensor = tuple(ev.rot_tip_sensor)  # type: ignore[assignment]  # nine items: mypy cannot count tuple()
            self.mounts = dict(ev.arm_mounts)
        elif isinstance(ev, m.PoseRecorded):
            step = next((s for s in self.steps if s.label == ev.label), None)
            if step is None:
                return
            step.recorded = ev
            far = ev.off_target_deg > OFF_TARGET_WARN_DEG
            self.message = (f"{ev.label.capitalize()} is {ev.off_target_deg:.0f}° from its target — kept (the fit uses "
                            "the measured orientation), but the set may be less well spread" if far else "")
            nxt = self._next_unrecorded(self.steps.index(step) + 1)
            self.state = "at_pose"
            if nxt is not None:
                self.index = nxt  # (when every pose is recorded the instruction says so: press Identify)
        elif isinstance(ev, m.CommandRefused) and ev.command == "RecordPose":
            self.state, self.message = "at_pose", ev.message
        elif isinstance(ev, m.CommandRefused) and ev.command == "IdentifyPoses":
            self.state, self.message = "refused", ev.message
        elif isinstance(ev, m.CalibrationDone) and self.state == "identifying":
            self.state = "accepted" if ev.accepted else "refused"
            self.message = "" if ev.accepted else ev.reason
        else:
            return
        self.changed.emit()

    # -- what the view shows -------------------------------------------------------------------------
    def target_tcp(self, step: PoseStep) -> tuple[tuple[float, float, float], float]:
        """The target as the UR pendant shows it: TCP rotation vector (rad), and the sensor axis' tilt from vertical
        (°)."""
        rot_base_tip = mat_mul(step.target_rot_base_sensor, transpose(self.rot_tip_sensor))
        rotvec = matrix_to_rotvec(rot_base_tip)
        z = step.target_rot_base_sensor[8]  # base-z component of the sensor's z axis (Mat3 is row-major, flat)
        tilt = math.degrees(math.acos(min(1.0, max(-1.0, abs(z)))))
        return (float(rotvec[0]), float(rotvec[1]), float(rotvec[2])), tilt

    def instruction(self) -> str:
        """What the experimenter should do now."""
        step = self.current
        if self.state == "idle":
            return "Choose a pose set and press Start pose set: the wizard shows one pose at a time."
        if self.state in ("accepted", "refused", "identifying"):
            return {"identifying": "identifying …",
                    "accepted": "Accepted: installed in the force path and saved for the tool (on record above).",
                    "refused": f"Refused — the previous calibration stays in use. Reason: {self.message}"}[self.state]
        if step is None:
            return ""
        done, total = self.progress()
        if self.state == "at_pose" and done == total:
            # the last pose is recorded: no target is left to move to
            return (f"All {total} poses are recorded: press Identify (Previous pose goes back to record one "
                    "again).")
        (rx, ry, rz), tilt = self.target_tcp(step)
        k = self.steps.index(step) + 1
        head = f"{step.label.capitalize()} ({k} of {len(self.steps)}): "
        if self.state == "recording":
            return head + f"recording {self.seconds:g} s — keep the robot still and the tool clear of everything"
        return (head + f"move the TCP to rotation vector ({rx:+.3f}, {ry:+.3f}, {rz:+.3f}) rad — sensor tilted "
                f"{tilt:.0f}° from vertical — with the tool hanging free, then press Record pose.")

    def progress(self) -> tuple[int, int]:
        """(recorded, total)."""
        return len(self.recorded), len(self.steps)
