"""What the study engine is built from: its configuration, the rig (simulated or real), the simulated stylus's driver.

:func:`build_engine` assembles the :class:`pipeline.assembly.engine.Engine` a
:class:`HostConfig` asks for -- the simulated rig with its driver, or the real
rig of a hardware file (devices opened one by one, each announced first).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

from pipeline.assembly.engine import Engine, EngineConfig, build_hardware_engine, build_sim_engine
from pipeline.commissioning.rig_calibration import CalibrationFileError
from pipeline.core.aim import TrialAim
from pipeline.devices.interfaces import DeviceError
from pipeline.devices.rig import SINGLE_ARM_NAME
from pipeline.settings.hardware import HardwareConfig, HardwareError, load_hardware
from study_app.engine import messages as m
from study_app.guide_paths import hardware_template

if TYPE_CHECKING:  # the simulated rig's types: a real rig's engine process never loads the simulators
    from pipeline.sim.hand import HandObservation
    from pipeline.sim.participant import SimulatedParticipant

__all__ = ["MANUAL_Y_RANGE_M", "HostConfig", "StylusControl", "SwitchableDriver", "build_engine", "build_real_engine",
           "hardware_of"]

#: Lowest / highest equilibrium a person may command with the mouse, m along the Touch's +y.
MANUAL_Y_RANGE_M = (-0.030, 0.005)


@dataclass(frozen=True, slots=True)
class HostConfig:
    """What the study engine builds.

    Attributes
    ----------
    rig
        ``"sim"`` or ``"real"``.
    hardware_path
        hardware.toml for the real rig.
    haptic_factory
        Real rig, tests only: ``"module:function"`` opening the haptic device instead of the Touch
        (called as ``open_haptic(HapticSettings, clock)``; no Touch on CI machines).
    clock
        ``"real"`` (1 kHz on the monotonic clock) or ``"virtual"`` (rehearsals, screenshots, tests).
    speed
        Virtual clock only: simulated seconds per wall second (0 = as fast as the CPU allows).
    rig_seed
        Seed of the simulated rig.
    block_ticks
        Virtual clock: ticks per driver step.
    health_period_s
        Wall time between :class:`study_app.engine.messages.Health` events.
    trace_jitter
        Real clock only: explain every loop period over 1.5 ms (:mod:`pipeline.runtime.jitter_trace`),
        reported in :attr:`study_app.engine.messages.Health.late_periods` (diagnosis and benchmarks).
    sim_mount_error_deg
        Simulated rig: the sensor is mounted turned about its z axis by this much, unknown to the pipeline
        (``SimRigConfig.sensor_z_mount_deg``): rehearse the frame check failing.
    sim_settings
        Simulated rig: the pipeline settings (``gui --set``, :mod:`pipeline.force.pipeline_settings`) that are not
        the paper's, as (name, value) pairs; stored with each session like ``run --set``'s.
    sim_arms
        Simulated rig: its arms by name, the one the participant holds first; a session's protocol must name that
        one its task arm (``design.task_arm``; the window restarts the engine with the task arm first when it is not,
        :mod:`study_app.models.arms`), and records every arm (docs/architecture.md, "Every arm recorded").
    loop_process
        Real clock: the loop runs alone in a process of its own (:mod:`study_app.engine.loop_process`); False: in
        a thread of the engine's process (so it does anyway where the OS cannot start that process: Windows).
    lsl
        Every session publishes its force streams and trial markers on the Lab Streaming Layer (``gui --lsl``, as a
        protocol's ``[lsl] outlets = true``: docs/lsl.md).
    """

    rig: str = "sim"
    hardware_path: str | None = None
    clock: str = "real"
    haptic_factory: str | None = None
    speed: float = 1.0
    rig_seed: int = 0
    block_ticks: int = 50
    health_period_s: float = 0.5
    trace_jitter: bool = False
    sim_mount_error_deg: float = 0.0
    sim_settings: tuple[tuple[str, float], ...] = ()
    sim_arms: tuple[str, ...] = (SINGLE_ARM_NAME,)
    loop_process: bool = True
    lsl: bool = False

    def __post_init__(self) -> None:
        if self.rig not in ("sim", "real"):
            raise ValueError(f"rig = {self.rig!r}: allowed values are 'sim' and 'real'")
        if self.clock not in ("real", "virtual"):
            raise ValueError(f"clock = {self.clock!r}: allowed values are 'real' and 'virtual'")
        if self.rig == "real" and self.clock != "real":
            raise ValueError(f"clock = {self.clock!r}: the real rig runs on the real clock only")
        if self.haptic_factory is not None and ":" not in self.haptic_factory:
            raise ValueError(f"haptic_factory = {self.haptic_factory!r}: must be 'module:function'")
        if not (math.isfinite(self.speed) and self.speed >= 0):
            raise ValueError(f"speed = {self.speed!r}: must be a finite number ≥ 0")
        if self.block_ticks < 1:
            raise ValueError(f"block_ticks = {self.block_ticks!r}: must be ≥ 1")
        if not self.sim_arms or len(set(self.sim_arms)) != len(self.sim_arms):
            raise ValueError(f"sim_arms = {self.sim_arms!r}: must be distinct arm names")
        if self.rig == "real" and self.sim_arms != (SINGLE_ARM_NAME,):
            raise ValueError("sim_arms: the real rig's arms are its hardware file's")


class StylusControl(Protocol):
    """The simulated stylus's driver as the engine drives it: who drives, the mouse's target, the simulated
    participant and its cues (:class:`SwitchableDriver` here, or its stand-in for the loop's own process,
    :class:`study_app.engine.loop_process.RemoteDriver`)."""

    mode: str

    def set_mode(self, mode: str) -> None: ...

    def set_manual_y(self, y_m: float) -> None: ...

    def install(self, participant: SimulatedParticipant | None) -> None: ...

    def begin_trial(self, aim: TrialAim, t_s: float) -> None: ...

    def end_trial(self, t_s: float) -> None: ...


class SwitchableDriver:
    """The simulated stylus's driver: the simulated participant (autopilot) or a person (manual).

    It is also the session runner's participant: trial notifications always
    reach the simulated participant, and the participant always sees the
    observations, so switching back to autopilot mid-session is seamless.
    """

    def __init__(self) -> None:
        self.mode = "autopilot"
        self.participant: SimulatedParticipant | None = None
        self.manual_y_m = 0.0

    def install(self, participant: SimulatedParticipant | None) -> None:
        """Hand the autopilot to a new simulated participant (None: none, the session ended)."""
        self.participant = participant

    def set_mode(self, mode: str) -> None:
        """Switch who drives (one of :data:`study_app.engine.messages.DRIVER_MODES`)."""
        if mode not in m.DRIVER_MODES:
            raise ValueError(f"driver = {mode!r}: allowed values are {', '.join(m.DRIVER_MODES)}")
        self.mode = mode

    def set_manual_y(self, y_m: float) -> None:
        """The person's equilibrium point, clamped to the safe stylus range."""
        if not math.isfinite(y_m):
            raise ValueError(f"manual target = {y_m!r}: must be a finite number of metres")
        lo, hi = MANUAL_Y_RANGE_M
        self.manual_y_m = min(hi, max(lo, float(y_m)))

    def equilibrium_y(self, obs: HandObservation) -> float:
        """Equilibrium of the arm this tick."""
        p = self.participant
        y = p.equilibrium_y(obs) if p is not None else 0.0
        return self.manual_y_m if self.mode == "manual" else y

    def begin_trial(self, aim: TrialAim, t_s: float) -> None:
        """Forward the cue (what the trial's task asks) to the simulated participant."""
        if self.participant is not None:
            self.participant.begin_trial(aim, t_s)

    def end_trial(self, t_s: float) -> None:
        """Forward the end of a trial."""
        if self.participant is not None:
            self.participant.end_trial(t_s)


def _import_factory(spec: str) -> Callable[..., Any]:
    import importlib

    module, _, attr = spec.partition(":")
    try:
        return getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise RuntimeError(f"haptic_factory = {spec!r}: cannot be imported ({exc})") from None


def build_real_engine(
    config: HostConfig, *, shared_ring: bool, on_open: Callable[[str], None] | None = None, jaws: bool = True,
) -> tuple[Engine, HardwareConfig, str]:
    """Load the hardware file, open the devices and assemble the loop
    (:func:`pipeline.assembly.engine.build_hardware_engine`).

    Returns the engine, the validated hardware config and the file's text (stored with each session).
    ``on_open(device)`` is called before each device is opened; ``jaws=False`` leaves the jaw actuators closed (the
    study engine opens them itself when the loop runs in a process of its own).

    Raises
    ------
    RuntimeError
        One line: the file is missing or invalid (naming the field), or a device cannot be opened (naming it).
    """
    hw, text = hardware_of(config)
    # The rig-construction seam: haptic_factory opens every arm's haptic device in place of its model's backend
    # (tests, with no Touch on CI, open one that speaks the HDAPI through the real Touch backend).
    open_haptic = None if config.haptic_factory is None else _import_factory(config.haptic_factory)
    try:
        eng = build_hardware_engine(hw, shared_ring=shared_ring, ring_seconds=30.0, on_open=on_open,
                                    open_haptic=open_haptic, jaws=jaws)
    except (DeviceError, CalibrationFileError) as exc:
        raise RuntimeError(f"real rig: {exc}") from None
    return eng, hw, text


def hardware_of(config: HostConfig) -> tuple[HardwareConfig, str]:
    """The real rig's hardware file: validated, and as written (stored with each session).

    Raises
    ------
    RuntimeError
        One line: no file given, or the file is missing or invalid (naming the field).
    """
    if not config.hardware_path:
        raise RuntimeError(f"real rig: no hardware file given; pass --hardware FILE (see {hardware_template()})")
    try:
        hw = load_hardware(config.hardware_path)
        with open(config.hardware_path, encoding="utf-8") as fh:
            return hw, fh.read()
    except HardwareError as exc:
        raise RuntimeError(f"real rig: {exc}") from None


def build_engine(
    config: HostConfig, driver: SwitchableDriver, *, shared_ring: bool, on_open: Callable[[str], None] | None = None,
    jaws: bool = True,
) -> tuple[Engine, HardwareConfig | None, str]:
    """The engine ``config`` asks for: the simulated rig driven by ``driver``, or the real rig of its hardware file
    (``jaws=False``: its jaw actuators left closed).

    Returns the engine, the validated hardware config and the file's text (None and "" for the simulated rig).
    """
    if config.rig == "real":
        return build_real_engine(config, shared_ring=shared_ring, on_open=on_open, jaws=jaws)
    from pipeline.assembly.sim_config import sim_rig_config
    from pipeline.force.pipeline_settings import framework_with

    eng = build_sim_engine(
        EngineConfig(sim=sim_rig_config(config.rig_seed, sensor_z_mount_deg=config.sim_mount_error_deg),
                     clock=config.clock, calibrate=True, driver="hold", haptics_on=False, refine_bias=True,
                     ring_seconds=30.0, framework=framework_with(dict(config.sim_settings)), arms=config.sim_arms),
        shared_ring=shared_ring,
    )
    eng.rig.set_driver(driver)
    return eng, None, ""

