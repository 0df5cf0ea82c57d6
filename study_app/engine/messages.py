"""Commands to and events from the study engine process (small typed records, no strings as topics).

The GUI sends a command over the engine's pipe; the engine publishes events
on its queue.  Both sides import this module, so every message is a frozen
dataclass that pickles across the process boundary.  Times called ``t_s``
are sample times of the loop records (the ``t_s`` column of the ring), so a
display can relate an event to the plotted samples whatever the clock speed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pipeline.commissioning.steps import PAYLOAD_POSE_SETS
from pipeline.commissioning.tcp import PIVOT_POSE_SETS
from pipeline.force.frames import Mat3, Vec3
from pipeline.force.payload_compensator import Wrench
from protocol.study.records import TrialRecord

__all__ = [
    "DRIVER_MODES",
    "JAW_ACTIONS",
    "PIVOT_SETS",
    "POSE_SETS",
    "AbortSession",
    "AbortTrial",
    "Calibrate",
    "CalibrateTcp",
    "CalibrationDone",
    "CalibrationProgress",
    "CalibrationStatus",
    "CheckFrames",
    "CommandRefused",
    "EngineFault",
    "EngineOpening",
    "EngineReady",
    "EngineStopped",
    "FaultInjected",
    "FrameAxisChecked",
    "FrameCheckDone",
    "Health",
    "IdentifyPoses",
    "IdentifyTcp",
    "InjectFault",
    "JawCommand",
    "JawState",
    "ListSessions",
    "ManualTarget",
    "OperatorStop",
    "Pause",
    "PhaseEntered",
    "PivotRecorded",
    "PoseRecorded",
    "RecordFrameAxis",
    "RecordPivot",
    "RecordPose",
    "ResetFaults",
    "ResetStats",
    "Resume",
    "ResumeSession",
    "SessionEnded",
    "SessionStarted",
    "SessionsListed",
    "SetDriver",
    "Shutdown",
    "StartChecking",
    "StartSession",
    "TcpCalibrationDone",
    "TrialEnded",
    "TrialStarted",
]

#: Who holds the simulated stylus.
DRIVER_MODES = ("autopilot", "manual")
#: The driver reported by the real rig: a person holds the Touch; nothing can be switched.
REAL_DRIVER = "participant"
#: Calibration pose sets offered by the wizard (named once, by :func:`pipeline.commissioning.steps.pose_set`).
POSE_SETS = PAYLOAD_POSE_SETS
#: TCP pivot orientation sets the wizard offers on the simulated rig
#: (:func:`pipeline.commissioning.tcp.pivot_orientations`).
PIVOT_SETS = PIVOT_POSE_SETS
#: What the jaw controls ask for: fully open, fully closed, one step toward open / toward closed.
JAW_ACTIONS = ("open", "close", "step_open", "step_close")


# -- commands (GUI → engine) --------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class StartSession:
    """Create a session in the database (schedule and calibration stored first) and run it.

    On the real rig a session starts only with the calibration chain on record for the mounted tool and
    the compensated force at rest below 0.1 N; ``override_reason`` (non-empty) starts it anyway, and the
    reason is stored with the session.  The study's rules (:mod:`protocol.runner.study_rules`: one seed per
    study, training before the experiment) are the engine's to enforce; ``training_override`` (non-empty)
    starts an experiment without the completed training the protocol requires, and is stored as a
    ``deviation`` event.
    """

    db_path: str
    code: str
    kind: str  # "training" | "experiment"
    protocol_path: str | None
    seed: int
    participant_number: int
    override_reason: str = ""
    training_override: str = ""


@dataclass(frozen=True, slots=True)
class ResumeSession:
    """Continue an interrupted session at its first unfinished trial (real rig: the calibration gate, as
    StartSession)."""

    db_path: str
    session_id: int
    override_reason: str = ""


@dataclass(frozen=True, slots=True)
class ListSessions:
    """List the interrupted (resumable) sessions of a database."""

    db_path: str


@dataclass(frozen=True, slots=True)
class Pause:
    """Hold before the next trial."""


@dataclass(frozen=True, slots=True)
class Resume:
    """Continue after a pause."""


@dataclass(frozen=True, slots=True)
class AbortTrial:
    """Abort the running trial (stored as aborted, re-queued).

    ``trial_index`` binds the command to the trial the experimenter confirmed: the engine refuses it
    when that trial is no longer running (a late "Yes" never aborts the next trial).
    """

    reason: str = "aborted by the experimenter"
    trial_index: int | None = None


@dataclass(frozen=True, slots=True)
class AbortSession:
    """Abort the running trial and end the session (refused if ``session_id`` is given and is not the running one)."""

    reason: str = "aborted by the experimenter"
    session_id: int | None = None


@dataclass(frozen=True, slots=True)
class ResetFaults:
    """Clear latched faults whose condition has gone away."""


@dataclass(frozen=True, slots=True)
class OperatorStop:
    """Latch an operator stop (force ramps to zero until reset)."""


@dataclass(frozen=True, slots=True)
class InjectFault:
    """Simulated rig only: rehearse a fault (:mod:`pipeline.sim.faults`, :mod:`protocol.runner.rehearsal`).

    ``trial`` None: now; else ``seconds`` after the cue of the running
    session's ``trial``-th trial (1-based, the order the participant meets them).
    ``kill`` ends the engine process itself, as a crash would.
    """

    kind: str
    trial: int | None = None
    seconds: float = 0.0


@dataclass(frozen=True, slots=True)
class Calibrate:
    """Run the gravity/bias identification with one of :data:`POSE_SETS`."""

    pose_set: str = "recommended"
    arm: str = ""  # the arm to commission ("": the first, a one-arm rig's only one)


@dataclass(frozen=True, slots=True)
class RecordPose:
    """Real rig: average ``seconds`` of raw wrench at the robot's current pose and read its TCP orientation.

    The engine answers with :class:`PoseRecorded` (or :class:`CommandRefused` naming why,
    e.g. the robot moved while recording).  ``target_rot_base_sensor`` is the pose the wizard
    asked for; the recorded orientation is the one the robot reports.
    """

    label: str
    seconds: float = 1.0
    target_rot_base_sensor: Mat3 | None = None  # row-major
    arm: str = ""  # the arm to commission ("": the first, a one-arm rig's only one)


@dataclass(frozen=True, slots=True)
class IdentifyPoses:
    """Real rig: identify payload and bias from recorded poses (label, rot_base_sensor as 9 numbers, wrench); install if
    accepted."""

    poses: tuple[tuple[str, Mat3, Wrench], ...]
    pose_set: str = "recommended"
    arm: str = ""  # the arm to commission ("": the first, a one-arm rig's only one)


@dataclass(frozen=True, slots=True)
class CalibrateTcp:
    """Simulated rig: run the TCP pivot calibration with one of :data:`PIVOT_SETS` (the simulated robot turns)."""

    pose_set: str = "recommended"
    arm: str = ""  # the arm to commission ("": the first, a one-arm rig's only one)


@dataclass(frozen=True, slots=True)
class RecordPivot:
    """Real rig: the tip rests in the divot; average the TCP pose for ``seconds`` (answered by
    :class:`PivotRecorded`)."""

    label: str
    seconds: float = 0.5
    arm: str = ""  # the arm to commission ("": the first, a one-arm rig's only one)


@dataclass(frozen=True, slots=True)
class IdentifyTcp:
    """Real rig: pivot calibration from recorded flange poses (label, rot_base_flange as 9 numbers, position m)."""

    poses: tuple[tuple[str, Mat3, Vec3], ...]
    arm: str = ""  # the arm to commission ("": the first, a one-arm rig's only one)


@dataclass(frozen=True, slots=True)
class CheckFrames:
    """Simulated rig: the frame and sign check (the simulated experimenter pushes the free tip along each axis)."""

    arm: str = ""  # the arm to commission ("": the first, a one-arm rig's only one)


@dataclass(frozen=True, slots=True)
class RecordFrameAxis:
    """Real rig: record ``seconds`` while the experimenter pushes the free tip along base ``axis`` (+x, +y, +z)."""

    axis: str
    seconds: float = 3.0
    arm: str = ""  # the arm to commission ("": the first, a one-arm rig's only one)


@dataclass(frozen=True, slots=True)
class JawCommand:
    """Move the instrument's jaw: one of :data:`JAW_ACTIONS` (stored as an event of the running session)."""

    action: str


@dataclass(frozen=True, slots=True)
class SetDriver:
    """Hand the simulated stylus to the simulated participant or to a person."""

    mode: str


@dataclass(frozen=True, slots=True)
class ManualTarget:
    """Where a person wants the stylus: the arm's equilibrium, m along the Touch's +y (pressing < 0)."""

    y_m: float


@dataclass(frozen=True, slots=True)
class ResetStats:
    """Restart the loop-timing statistics (benchmarks)."""


@dataclass(frozen=True, slots=True)
class Shutdown:
    """Finish the current trial's records, ramp the force to zero and exit."""


# -- events (engine → GUI) ----------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class EngineReady:
    """The rig is connected, the loop runs; ``ring_name`` is the shared sample ring."""

    ring_name: str
    rig: str
    clock: str
    calibration: dict[str, Any]
    surface_z_m: float
    tip_home_m: tuple[float, float, float]
    driver: str
    rot_tip_sensor: Mat3 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)  # the sensor mount, row-major
    devices: list[str] = field(default_factory=list)
    #: The rig's arms (the task arm first) with their shared rings' names (the first's is ``ring_name``); one arm: ().
    arm_rings: tuple[tuple[str, str], ...] = ()
    #: Each arm's sensor mount (``rot_tip_sensor``, row-major), by name, on a rig of several arms.
    arm_mounts: tuple[tuple[str, Mat3], ...] = ()


@dataclass(frozen=True, slots=True)
class CommandRefused:
    """A command could not be carried out; ``message`` names what and why."""

    command: str
    message: str


@dataclass(frozen=True, slots=True)
class SessionsListed:
    """Resumable sessions of a database: dicts with session_id, code, kind, started_at, trials_planned (the
    designed trials), trials_done (designed trials done), trials_aborted (aborted attempts) and trials_total
    (the schedule with its re-runs).

    ``known``: every session of the database (:func:`study_app.engine.session_list.list_sessions`), for the setup
    form's checks (a code or participant number already used); ``withdrawn``: who withdrew (``code``,
    ``withdrawn_at``; :func:`study_app.engine.session_list.list_withdrawn`), whose codes are not used again.
    """

    db_path: str
    sessions: list[dict[str, Any]]
    known: list[dict[str, Any]] = field(default_factory=list)
    withdrawn: list[dict[str, str]] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class SessionStarted:
    """A session is stored and running."""

    session_id: int
    code: str
    kind: str
    trials_total: int
    start_position: int
    tolerance_fraction: float
    max_trial_s: float
    pause_s: float
    cue_s: float
    live_force_aid: bool
    schedule: list[dict[str, Any]] = field(default_factory=list)
    participant_number: int = 0
    #: A resumed session's trials stored before, in index order.
    stored_trials: list[TrialRecord] = field(default_factory=list)
    #: The session's (so the study's) seed.
    seed: int = 0


@dataclass(frozen=True, slots=True)
class TrialStarted:
    """The cue of a trial (the participant screen shows its word)."""

    t_s: float
    trial_index: int
    position: int  # 1-based position in the schedule
    trials_total: int
    target_label: str
    target_force_n: float
    haptic_mode: str
    #: The trial this one re-runs (an aborted one), or None for a trial of the design.
    repeat_of: int | None = None


@dataclass(frozen=True, slots=True)
class PhaseEntered:
    """The trial machine entered ``phase`` (idle, cued, active, pause) at sample time ``t_s``."""

    t_s: float
    trial_index: int
    phase: str


@dataclass(frozen=True, slots=True)
class TrialEnded:
    """A trial ended and its record was stored; ``trials_total`` is the schedule's length now (re-runs included)."""

    t_s: float
    record: TrialRecord
    trials_total: int


@dataclass(frozen=True, slots=True)
class SessionEnded:
    """The session ended (``status``: completed or aborted; or ``interrupted`` when left resumable)."""

    session_id: int
    status: str
    reason: str
    completed: int
    aborted: int
    successes: int


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
    """Result of a TCP pivot calibration: saved and in use if ``accepted``, else ``reason`` says which orientations to
    add.

    ``result`` is :meth:`pipeline.commissioning.tcp.TipCalibration.to_dict`; ``error_mm`` the distance from the
    simulated
    rig's true tip (NaN on the real rig).
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


@dataclass(frozen=True, slots=True)
class StartChecking:
    """Real rig: Start was accepted by the calibration gate; the force at rest is measured for ``seconds`` first."""

    seconds: float
    message: str


@dataclass(frozen=True, slots=True)
class JawState:
    """The jaw: position (fraction open, pulse width), whether at a limit, its fault ("" when healthy), the last
    command."""

    fraction_open: float
    pulse_us: int
    at_limit: bool
    fault: str
    last: str


@dataclass(frozen=True, slots=True)
class EngineFault:
    """The loop latched (``kind='fault'``), saw a latched fault's condition go (``'fault_cleared'``) or reset
    (``'faults_reset'``)."""

    t_s: float
    kind: str
    faults: int
    detail: str
    #: The same moment on the running session's clock (as the database stores it), NaN when no session runs.
    session_t_s: float = float("nan")


@dataclass(frozen=True, slots=True)
class FaultInjected:
    """A rehearsed fault was planned (``when`` says for when) or fired (``when`` = "now" or the trial it hit)."""

    kind: str
    when: str


@dataclass(frozen=True, slots=True)
class Health:
    """Loop timing since the last stats reset (µs) and the engine's state, published about twice a second."""

    loop_rate_hz: float
    period_p50_us: float
    period_p99_us: float
    abs_dev_p99_us: float
    periods_over_2ms: int
    missed_slots: int
    ticks: int
    faults: int
    haptic_on: bool
    driver: str
    session_running: bool
    paused: bool
    abs_dev_p50_us: float = float("nan")
    period_max_us: float = float("nan")
    #: Late periods explained by cause (:meth:`pipeline.runtime.jitter_trace.LateTickTracer.summary`), when tracing.
    late_periods: dict[str, Any] | None = None
    #: Why the session's next cue is held back ("" = it is not): a latched fault waiting for a reset, the pause after
    #: it.
    waiting: str = ""
    #: The haptic device's motor heat as a fraction of its thermal budget, and the force it may render now (derated), N.
    haptic_heat_fraction: float = 0.0
    haptic_force_limit_n: float = float("nan")
    #: The haptic device's peak and continuous ratings, N (derating lowers the limit from the first toward the second).
    haptic_peak_force_n: float = float("nan")
    haptic_continuous_force_n: float = float("nan")
    #: Why the haptic loop is dead ("" while it runs).
    loop_dead: str = ""
    #: How the loop thread is scheduled (:func:`pipeline.core.clock.prepare_realtime_thread`; "virtual clock" when
    #: virtual).
    scheduling: str = ""
    #: A rig of several arms: per arm, the task arm first, (name, largest task force of its newest records in N,
    #: latched faults); empty on a rig of one arm.
    arms: tuple[tuple[str, float, int], ...] = ()


@dataclass(frozen=True, slots=True)
class EngineOpening:
    """Real rig: the engine is opening this device now (a device that hangs is named by the last of these)."""

    device: str


@dataclass(frozen=True, slots=True)
class EngineStopped:
    """The engine has ramped the force to zero and is exiting."""

    reason: str
    stats: dict[str, float]
