"""What goes into the haptic loop and what comes out of it: commands, events and the record's columns.

Commands (:data:`Command`) are queued with :meth:`pipeline.runtime.loop.HapticLoop.submit`
from any thread and applied at the start of the next tick; a
:class:`LoopEvent` is something the experimenter must see and the study record
must keep; :data:`RECORD_FIELDS` names the columns of the record the loop
writes at every tick.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

from pipeline.core import tick_record

if TYPE_CHECKING:
    from pipeline.core.force_program import ForceProgram
    from pipeline.force.payload_compensator import PayloadCalibration

__all__ = [
    "RECORD_FIELDS",
    "AllowBiasRefinement",
    "Command",
    "CommandForce",
    "ControllerDetached",
    "LatchFault",
    "LoopEvent",
    "Mark",
    "OperatorStop",
    "ResetFaults",
    "SetCalibration",
    "SetHaptics",
    "StartRecording",
    "StopRecording",
]

#: Fields of one loop record, in order (defined with their types in :mod:`pipeline.core.tick_record`).
RECORD_FIELDS = tick_record.RECORD_FIELDS


@dataclass(frozen=True, slots=True)
class SetHaptics:
    """Turn haptic feedback on or off (off ramps the rendered force to zero)."""

    on: bool


@dataclass(frozen=True, slots=True)
class Mark:
    """Stamp ``trial_index`` and ``phase`` (an int code owned by the protocol) into the records."""

    trial_index: int
    phase: int


@dataclass(frozen=True, slots=True)
class ResetFaults:
    """Clear latched faults whose condition has gone away, and re-arm the haptic device."""


@dataclass(frozen=True, slots=True)
class OperatorStop:
    """Latch an operator stop: the force ramps to zero until reset."""


@dataclass(frozen=True, slots=True)
class ControllerDetached:
    """The controlling process went away: latch ``ENGINE_DETACHED`` (the engine then stops)."""


@dataclass(frozen=True, slots=True)
class LatchFault:
    """Latch ``fault`` from outside the loop (its supervisor saw it stall); the event was already reported.

    The output restarts from zero: the device's command watchdog has dropped it.
    """

    fault: int


@dataclass(frozen=True, slots=True)
class AllowBiasRefinement:
    """Allow (between trials, tool in free space) or forbid online bias refinement."""

    allowed: bool


@dataclass(frozen=True, slots=True)
class SetCalibration:
    """Install a new payload calibration (a :class:`pipeline.force.payload_compensator.PayloadCalibration`).

    ``arm``: on the arm of that name ("": the first arm, the only one of a one-arm rig).
    """

    calibration: PayloadCalibration
    arm: str = ""


@dataclass(frozen=True, slots=True)
class StartRecording:
    """Begin a replayable record: snapshot the framework, then log what replay needs (:attr:`HapticLoop.replay_log`).

    The snapshot is taken once every command of the tick has been applied, and
    logged as ``(tick, "snapshot", {"token": token, "framework": ..., "refine_bias": ...})``;
    from then on every pose the framework takes (``"pose"``: rotation, position,
    pose time), every change of the bias-refinement permission (``"refine"``), every
    framework reset (``"reset"``) and calibration (``"calibration"``), every change
    of the haptic device's force limit passed on to the safety stage
    (``"device_limit"``: the device's limit, N; thermal derating) and every time
    the output is dropped to zero outside the framework's step (``"zero"``: why --
    ``"late_tick"``, ``"latch_fault"`` or ``"fail_safe"``) is logged with its
    tick, in the order the loop applied them (:mod:`pipeline.force.replay`).
    """

    token: int


@dataclass(frozen=True, slots=True)
class CommandForce:
    """Render ``program`` from this tick on instead of the sensor's force (None: the sensor's again, Algorithm 1).

    The program's time starts at the tick that applies the command; its force passes the safety stage as every
    rendered force does (:meth:`pipeline.force.framework.HapticFramework.step_commanded`).  Logged for replay as
    ``(tick, "program", knots or None)``.
    """

    program: ForceProgram | None


@dataclass(frozen=True, slots=True)
class StopRecording:
    """Stop logging for replay (the log is left for its reader to drain)."""


Command = (SetHaptics | Mark | ResetFaults | OperatorStop | ControllerDetached | AllowBiasRefinement | SetCalibration
           | LatchFault | StartRecording | StopRecording | CommandForce)


class LoopEvent(NamedTuple):
    """Something the experimenter must see, and the study record must keep.

    ``kind`` is ``"fault"`` (a fault latched; ``detail`` names it and the value
    that tripped it), ``"fault_cleared"`` (a latched fault's condition went
    away; it stays latched until a reset), ``"faults_reset"`` (a reset:
    ``faults`` is what is still latched after it, ``detail`` what was latched
    before), ``"derating"`` / ``"derating_ended"`` (the haptic device's motors
    got warm and it lowered its force limit / it cooled and renders its full
    peak again) or ``"output_restarted"`` (a tick came later than the
    device's command watchdog: the device had dropped the force, and the
    output ramps in again from zero).  ``t_ns`` is on the records' time axis (``t_ns`` of the tick's
    record: ns since the loop's first tick).  ``arm`` names the rig's arm the event is about (its
    ``faults`` are that arm's latched set); "" for one made outside a loop.
    """

    t_ns: int
    kind: str
    faults: int
    detail: str
    arm: str = ""
