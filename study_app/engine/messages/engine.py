"""The engine's own messages: its lifetime, its health and the loop's faults, the stylus's driver, the jaw, the
rehearsed faults (GUI → engine and engine → GUI).

Applied by :class:`study_app.engine.host.StudyEngine` (and its rooms); shown by :mod:`study_app.models.health`,
the rig view and the window's engine line.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pipeline.force.frames import Mat3

__all__ = [
    "DRIVER_MODES",
    "JAW_ACTIONS",
    "REAL_DRIVER",
    "CommandRefused",
    "EngineFault",
    "EngineOpening",
    "EngineReady",
    "EngineStopped",
    "FaultInjected",
    "Health",
    "InjectFault",
    "JawCommand",
    "JawState",
    "ManualTarget",
    "OperatorStop",
    "ResetFaults",
    "ResetStats",
    "SetDriver",
    "Shutdown",
]

#: Who holds the simulated stylus.
DRIVER_MODES = ("autopilot", "manual")
#: The driver reported by the real rig: a person holds the Touch; nothing can be switched.
REAL_DRIVER = "participant"
#: What the jaw controls ask for: fully open, fully closed, one step toward open / toward closed.
JAW_ACTIONS = ("open", "close", "step_open", "step_close")


# -- commands (GUI → engine) --------------------------------------------------------------------
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
class EngineOpening:
    """Real rig: the engine is opening this device now (a device that hangs is named by the last of these)."""

    device: str


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
    #: The process id of the loop's own process (real clock, :mod:`study_app.engine.loop_process`); 0 when the loop
    #: is a thread of the engine's process.
    loop_pid: int = 0
    #: The end-to-end latency, stage by stage (:meth:`pipeline.assembly.latency.Latency.to_dict`); real clock only.
    latency: dict[str, Any] | None = None


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
class JawState:
    """The jaw: position (fraction open, pulse width), whether at a limit, its fault ("" when healthy), the last
    command."""

    fraction_open: float
    pulse_us: int
    at_limit: bool
    fault: str
    last: str


@dataclass(frozen=True, slots=True)
class EngineStopped:
    """The engine has ramped the force to zero and is exiting."""

    reason: str
    stats: dict[str, float]
