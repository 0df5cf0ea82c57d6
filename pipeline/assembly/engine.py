"""Assembling an engine: the rig (simulated or real), Algorithm 1 and the 1 kHz loop, in this process.

:func:`build_sim_engine` builds the simulated rig (and calibrates its payload);
:func:`build_hardware_engine` opens the real rig a hardware file describes and
puts the calibration on record for its tool to use.  Both return one
:class:`Engine`.  Running an engine in a process of its own, talking to it and
supervising it is the top floor's job (``study_app.engine.host``, the GUI's
study engine; ``study_app.headless``, the headless study runner).

The simulators are imported only when a simulated rig is built: a real rig's
process never loads them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from pipeline.core.clock import Clock, MonotonicClock, VirtualClock
from pipeline.core.tick_record import TICK_DTYPE
from pipeline.devices.rig import SINGLE_ARM_NAME
from pipeline.force.bias_refinement import RlsBias
from pipeline.force.framework import FrameworkConfig, HapticFramework
from pipeline.force.payload_compensator import NO_PAYLOAD, PayloadCalibration
from pipeline.runtime.loop import FAULT_POLICIES, HapticLoop
from pipeline.runtime.loop_messages import AllowBiasRefinement, SetHaptics
from pipeline.runtime.ring import RingBuffer
from pipeline.runtime.watchdog import WatchdogConfig

if TYPE_CHECKING:
    from pipeline.sim.rig import SimRigConfig

__all__ = ["Engine", "EngineConfig", "arm_devices", "build_hardware_engine", "build_sim_engine"]


@dataclass(frozen=True, slots=True)
class EngineConfig:
    """What the engine builds.

    Attributes
    ----------
    sim
        Simulated-rig parameters (:class:`pipeline.sim.rig.SimRigConfig`; None: its defaults).
    framework
        Algorithm 1 parameters.
    watchdog
        Fault limits.
    clock
        ``"real"`` (paced at 1 kHz) or ``"virtual"`` (as fast as the CPU allows).
    calibrate
        Run the automatic gravity/bias calibration before the loop starts.
    driver
        Who holds the stylus: ``"scripted"`` (repeated presses) or ``"hold"``.
    haptics_on
        Feedback state at start.
    refine_bias
        Online bias refinement (RLS, science.md §1.4) allowed from the start.
        The study runner allows it only between trials; the estimator's own
        contact gate refuses samples with more than 0.15 N of innovation.
    ring_seconds
        Ring buffer length in seconds of records.
    arms
        The simulated rig's arms by name, the first first (``("right",)``: the one-arm rig; two names: two
        :class:`pipeline.sim.rig.SimRig` on one clock, :class:`pipeline.sim.arms.SimArms`).
    fault_policy
        What a fault on one arm does to the others: ``"both"`` (all ramp to zero) or ``"independent"``.
    """

    sim: SimRigConfig | None = None
    framework: FrameworkConfig = field(default_factory=FrameworkConfig)
    watchdog: WatchdogConfig = field(default_factory=WatchdogConfig)
    clock: str = "real"
    calibrate: bool = True
    driver: str = "scripted"
    haptics_on: bool = True
    refine_bias: bool = True
    ring_seconds: float = 30.0
    arms: tuple[str, ...] = (SINGLE_ARM_NAME,)
    fault_policy: str = "both"

    def __post_init__(self) -> None:
        if not 1 <= len(self.arms) <= 4 or len(set(self.arms)) != len(self.arms) or not all(
                isinstance(a, str) and a for a in self.arms):
            raise ValueError(f"arms = {self.arms!r}: one to four distinct, non-empty arm names")
        if self.fault_policy not in FAULT_POLICIES:
            raise ValueError(f"fault_policy = {self.fault_policy!r}: allowed values are 'both' and 'independent'")
        if self.clock not in ("real", "virtual"):
            raise ValueError(f"clock = {self.clock!r}: allowed values are 'real' and 'virtual'")
        if self.driver not in ("scripted", "hold"):
            raise ValueError(f"driver = {self.driver!r}: allowed values are 'scripted' and 'hold'")
        if not 1.0 <= self.ring_seconds <= 3600.0:
            raise ValueError(f"ring_seconds = {self.ring_seconds!r}: must be between 1 and 3600")


@dataclass
class Engine:
    """An assembled rig, force path and loop (in-process), simulated or real.

    Attributes
    ----------
    rig
        :class:`pipeline.sim.rig.SimRig` or :class:`pipeline.assembly.real_rig.RealRig`.
    simulated
        True for the simulated rig (its configuration is ``rig.config``).
    calibration_file
        Real rig: its calibration file (:mod:`pipeline.commissioning.rig_calibration`), if the hardware file names one.
    tool
        Real rig: the mounted instrument whose record in the calibration file is in use.
    frameworks, rings, calibrations
        Per arm by name, the first arm first (its are ``framework``, ``ring`` and ``calibration``).
    """

    rig: Any
    framework: HapticFramework
    loop: HapticLoop
    clock: Clock
    calibration: PayloadCalibration
    ring: RingBuffer | None
    simulated: bool
    calibration_file: Any = None
    tool: str = "instrument"
    frameworks: dict[str, HapticFramework] = field(default_factory=dict)
    rings: dict[str, RingBuffer | None] = field(default_factory=dict)
    calibrations: dict[str, PayloadCalibration] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.frameworks:  # one arm: the loop's own
            name = self.loop.arms[0].name
            self.frameworks = {name: self.framework}
            self.rings = {name: self.ring}
            self.calibrations = {name: self.calibration}


def arm_devices(eng: Any, arm: str) -> Any:
    """An arm's devices by name ("": the first) of an assembled engine (this process's :class:`Engine`, or the
    stand-in for one in the loop's own process, :class:`pipeline.assembly.remote_engine.RemoteEngine`): the rig itself
    for the first arm (it forwards to it), else the simulated rig's own rig of that arm or the real rig's arm."""
    if not arm or arm == next(iter(eng.frameworks)):
        return eng.rig
    return eng.rig.rig(arm) if eng.simulated else eng.rig.arm(arm)


def build_sim_engine(
    config: EngineConfig,
    *,
    shared_ring: bool = False,
    clock: Clock | None = None,
    progress: Any = None,
) -> Engine:
    """Assemble rig → calibration → framework → loop for the simulated rig.

    Parameters
    ----------
    config
        What to build.
    shared_ring
        Put the ring buffer in shared memory (another process will read it).
    clock
        Override the clock (default from ``config.clock``).
    progress
        Optional ``progress(done, total)`` for the calibration.
    """
    from pipeline.commissioning.payload_identification import recommended_pose_set
    from pipeline.sim import participant_tick
    from pipeline.sim.arms import SimArms
    from pipeline.sim.calibration import auto_calibrate, calibration_duration_ns
    from pipeline.sim.hand import ScriptedPresses
    from pipeline.sim.rig import SimRig, SimRigConfig

    participant_tick.warm_kernels()  # a simulated participant may be handed the stylus while the loop runs

    clk: Clock = clock or (VirtualClock() if config.clock == "virtual" else MonotonicClock())
    base = config.sim if config.sim is not None else SimRigConfig()
    arms = SimArms.build(config.arms, base) if len(config.arms) > 1 else None
    sims: list[SimRig] = list(arms.rigs) if arms is not None else [SimRig(base)]
    calibrations: list[PayloadCalibration] = []
    for sim in sims:
        calibration = NO_PAYLOAD
        if config.calibrate:
            poses = recommended_pose_set(24)
            cal_clock = clk
            if not isinstance(clk, VirtualClock):
                # Instant even when the loop is paced in real time: on a virtual clock placed so that it
                # ends now.  The rig's clocked state (the robot's next controller cycle, sample times) then
                # carries on with the real clock; a clock starting now would leave the rig 12 s in the
                # future, and the robot would hold the last calibration pose until real time caught up.
                cal_clock = VirtualClock(clk.now_ns() - calibration_duration_ns(len(poses)))
            calibration, _ = auto_calibrate(sim, cal_clock, poses, progress=progress)
        if config.driver == "scripted":
            sim.set_driver(ScriptedPresses())
        calibrations.append(calibration)
    pipelines = [_pipeline(config.framework, cal, sim.haptic.peak_force_n, config, shared_ring)
                 for sim, cal in zip(sims, calibrations, strict=True)]
    rig: Any = arms if arms is not None else sims[0]
    (framework, ring), others = pipelines[0], pipelines[1:]
    loop = HapticLoop(rig, framework, clk, ring, watchdog=config.watchdog, arm_pipelines=others,
                      fault_policy=config.fault_policy)
    if arms is None and isinstance(clk, VirtualClock) and not shared_ring:
        # on a virtual clock a one-arm loop's ticks run in compiled blocks (pipeline.sim.block: the same ticks)
        from pipeline.sim.block import SimBlocks

        loop.block_runner = SimBlocks(loop, sims[0]).run_ticks
    loop.submit(SetHaptics(config.haptics_on))
    loop.submit(AllowBiasRefinement(config.refine_bias))
    names = config.arms
    return Engine(rig, framework, loop, clk, calibrations[0], ring, simulated=True,
                  frameworks={n: fw for n, (fw, _) in zip(names, pipelines, strict=True)},
                  rings={n: rg for n, (_, rg) in zip(names, pipelines, strict=True)},
                  calibrations=dict(zip(names, calibrations, strict=True)))


def _pipeline(
    fw_config: FrameworkConfig, calibration: PayloadCalibration, peak_n: float, config: EngineConfig, shared: bool,
) -> tuple[HapticFramework, RingBuffer]:
    """One arm's framework (online bias refinement on top of its calibration) and ring."""
    rls = RlsBias(calibration.force_bias_n, calibration.torque_bias_nm)
    framework = HapticFramework(fw_config, calibration, device_peak_n=peak_n, rls=rls)
    return framework, RingBuffer.create(TICK_DTYPE, int(config.ring_seconds * 1000), shared=shared)


def build_hardware_engine(
    hardware: Any,
    *,
    watchdog: WatchdogConfig | None = None,
    clock: Clock | None = None,
    shared_ring: bool = False,
    ring_seconds: float = 30.0,
    on_open: Any = None,
    open_haptic: Any = None,
    jaws: bool = True,
) -> Engine:
    """Open the real rig of a :class:`pipeline.settings.hardware.HardwareConfig` and assemble framework and loop.

    What is on record for the mounted tool (``[calibration] tool``) in the calibration file
    (:class:`pipeline.commissioning.rig_calibration.RigCalibrationFile`) is put to use: its payload calibration
    compensates, and online bias refinement runs on top of it; its TCP calibration moves the robot's
    poses to the calibrated tip.  Without a payload on record there is no compensation and no bias
    refinement -- an "online bias only" start cannot work (its contact gate sees the tool's weight as
    contact), and a session on the real rig is refused until the payload step is done.  Each arm uses its own
    calibration file and tool, and has its own framework and ring; the loop follows the file's ``fault_policy``.
    Feedback starts off: the experimenter turns it on.  ``on_open(name)`` is
    called before each device is opened, and ``open_haptic(settings, clock)``, if given, opens every arm's haptic
    device in place of its model's backend (see :func:`pipeline.assembly.real_rig.build_real_rig`).  ``jaws=False``
    leaves the jaw actuators to whoever drives the loop (the study engine's process opens them when the loop runs
    in a process of its own: the loop needs only the stylus buttons).

    Raises
    ------
    pipeline.commissioning.rig_calibration.CalibrationFileError
        The calibration file cannot be read (before any device is opened).
    """
    from pipeline.assembly.real_rig import build_real_rig
    from pipeline.commissioning.rig_calibration import RigCalibrationFile

    clk: Clock = clock or MonotonicClock()
    arms = hardware.arms
    files = [RigCalibrationFile.load(a.calibration_file) if a.calibration_file else None for a in arms]
    records = [f.tool(a.calibration_tool) if f is not None else None for a, f in zip(arms, files, strict=True)]
    tips = {a.name: r.tcp.tip_in_flange_m if r is not None and r.tcp is not None else None
            for a, r in zip(arms, records, strict=True)}
    rig = build_real_rig(hardware, clk, on_open=on_open, arm_tips_m=tips, open_haptic=open_haptic, with_jaw=jaws)
    pipelines: list[tuple[HapticFramework, RingBuffer]] = []
    calibrations: list[PayloadCalibration] = []
    for a, r, dev in zip(arms, records, rig.real_arms, strict=True):
        payload = r.payload if r is not None else None
        calibration = payload if payload is not None else NO_PAYLOAD
        rls = RlsBias(calibration.force_bias_n, calibration.torque_bias_nm) if payload is not None else None
        framework = HapticFramework(a.framework, calibration, device_peak_n=dev.haptic.peak_force_n, rls=rls)
        pipelines.append((framework, RingBuffer.create(TICK_DTYPE, int(ring_seconds * 1000), shared=shared_ring)))
        calibrations.append(calibration)
    (framework, ring), others = pipelines[0], pipelines[1:]
    loop = HapticLoop(rig, framework, clk, ring, watchdog=watchdog or WatchdogConfig(), arm_pipelines=others,
                      fault_policy=hardware.fault_policy)
    names = [a.name for a in arms]
    return Engine(rig, framework, loop, clk, calibrations[0], ring, simulated=False, calibration_file=files[0],
                  tool=hardware.calibration_tool,
                  frameworks={n: fw for n, (fw, _) in zip(names, pipelines, strict=True)},
                  rings={n: rg for n, (_, rg) in zip(names, pipelines, strict=True)},
                  calibrations=dict(zip(names, calibrations, strict=True)))
