"""Building the rig + loop, and running them in an engine process of their own.

Why a process: on a 2-core machine a Qt window painting pyqtgraph curves in
the same process as the 1 kHz loop holds the GIL for milliseconds per curve
and drops the loop to ~640 Hz; with the GUI in another process the loop keeps
p99 ≈ 1.04 ms (science.md §7).  So the app starts an :class:`EngineProcess`
that owns the devices and the loop; other processes talk to it through a
command pipe, an event queue and the shared-memory :class:`pipeline.ring.RingBuffer`.

If the controlling process goes away (closed or crashed GUI), the engine
notices the broken pipe, latches ``ENGINE_DETACHED``, ramps the force to zero
and exits cleanly.
"""

from __future__ import annotations

import multiprocessing as mp
import queue
import threading
import time
from dataclasses import dataclass, field
from typing import Any

from pipeline.clock import (
    Clock, MonotonicClock, VirtualClock, collect_garbage, manual_garbage_collection, prepare_realtime_thread,
)
from pipeline.compensation import NO_PAYLOAD, PayloadCalibration, RlsBias
from pipeline.framework import FrameworkConfig, HapticFramework
from pipeline.jitter_trace import LateTickTracer
from pipeline.loop import RECORD_FIELDS, AllowBiasRefinement, Command, ControllerDetached, HapticLoop, LoopEvent, SetHaptics, WatchdogConfig
from pipeline.ring import RingBuffer
from pipeline.sim.hand import ScriptedPresses
from pipeline.sim.rig import SimRig, SimRigConfig

__all__ = [
    "EngineConfig",
    "EngineProcess",
    "EngineStartError",
    "HardwareEngine",
    "SimEngine",
    "build_hardware_engine",
    "build_sim_engine",
]


class EngineStartError(RuntimeError):
    """The engine process could not start (a device failed to open, or it did not become ready in time)."""


@dataclass(frozen=True, slots=True)
class EngineConfig:
    """What the engine builds.

    Attributes
    ----------
    sim
        Simulated-rig parameters (the only rig until real backends are configured).
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
    hardware_file
        A ``hardware.toml``: the engine opens the real rig it describes
        (:func:`build_hardware_engine`) instead of the simulated one; ``sim``,
        ``framework``, ``calibrate`` and ``driver`` are then unused (the file
        holds the framework parameters and the calibration), and feedback
        starts off whatever ``haptics_on`` says -- the experimenter turns it on.
    trace_jitter
        Real clock only: explain every late loop period
        (:class:`pipeline.jitter_trace.LateTickTracer`, ~30 µs per tick);
        the explanation comes with the final statistics
        (:attr:`EngineProcess.late_periods`).
    """

    sim: SimRigConfig = field(default_factory=SimRigConfig)
    framework: FrameworkConfig = field(default_factory=FrameworkConfig)
    watchdog: WatchdogConfig = field(default_factory=WatchdogConfig)
    clock: str = "real"
    calibrate: bool = True
    driver: str = "scripted"
    haptics_on: bool = True
    refine_bias: bool = True
    ring_seconds: float = 30.0
    hardware_file: str | None = None
    trace_jitter: bool = False

    def __post_init__(self) -> None:
        if self.clock not in ("real", "virtual"):
            raise ValueError(f"clock = {self.clock!r}: allowed values are 'real' and 'virtual'")
        if self.driver not in ("scripted", "hold"):
            raise ValueError(f"driver = {self.driver!r}: allowed values are 'scripted' and 'hold'")
        if not 1.0 <= self.ring_seconds <= 3600.0:
            raise ValueError(f"ring_seconds = {self.ring_seconds!r}: must be between 1 and 3600")


@dataclass
class SimEngine:
    """The assembled simulated rig, force path and loop (in-process)."""

    rig: SimRig
    framework: HapticFramework
    loop: HapticLoop
    clock: Clock
    calibration: PayloadCalibration
    ring: RingBuffer | None


def build_sim_engine(
    config: EngineConfig,
    *,
    shared_ring: bool = False,
    clock: Clock | None = None,
    progress: Any = None,
) -> SimEngine:
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
    from pipeline.compensation import recommended_pose_set
    from pipeline.sim.calibration import auto_calibrate, calibration_duration_ns

    clk: Clock = clock or (VirtualClock() if config.clock == "virtual" else MonotonicClock())
    rig = SimRig(config.sim)
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
        calibration, _ = auto_calibrate(rig, cal_clock, poses, progress=progress)
    if config.driver == "scripted":
        rig.set_driver(ScriptedPresses())
    rls = RlsBias(calibration.force_bias_n, calibration.torque_bias_nm)
    framework = HapticFramework(config.framework, calibration, device_peak_n=rig.haptic.peak_force_n, rls=rls)
    ring = RingBuffer.create(RECORD_FIELDS, int(config.ring_seconds * 1000), shared=shared_ring)
    loop = HapticLoop(rig, framework, clk, ring, watchdog=config.watchdog)
    loop.submit(SetHaptics(config.haptics_on))
    loop.submit(AllowBiasRefinement(config.refine_bias))
    return SimEngine(rig, framework, loop, clk, calibration, ring)


@dataclass
class HardwareEngine:
    """The real rig, force path and loop (in-process); ``rig`` is a :class:`pipeline.hardware.RealRig`.

    ``calibration_file`` is the rig's calibration file (:mod:`pipeline.rig_calibration`) and
    ``tool`` the mounted instrument whose record is in use.
    """

    rig: Any
    framework: HapticFramework
    loop: HapticLoop
    clock: Clock
    calibration: PayloadCalibration
    ring: RingBuffer | None
    calibration_file: Any = None
    tool: str = "instrument"


def build_hardware_engine(
    hardware: Any,
    *,
    watchdog: WatchdogConfig | None = None,
    clock: Clock | None = None,
    shared_ring: bool = False,
    ring_seconds: float = 30.0,
    on_open: Any = None,
) -> HardwareEngine:
    """Open the real rig of a :class:`pipeline.hardware.HardwareConfig` and assemble framework and loop.

    What is on record for the mounted tool (``[calibration] tool``) in the calibration file
    (:class:`pipeline.rig_calibration.RigCalibrationFile`) is put to use: its payload calibration
    compensates, and online bias refinement runs on top of it; its TCP calibration moves the robot's
    poses to the calibrated tip.  Without a payload on record there is no compensation and no bias
    refinement -- an "online bias only" start cannot work (its contact gate sees the tool's weight as
    contact), and a session on the real rig is refused until the payload step is done.
    Feedback starts off: the experimenter turns it on.  ``on_open(name)`` is
    called before each device is opened (see :func:`pipeline.hardware.build_real_rig`).

    Raises
    ------
    pipeline.rig_calibration.CalibrationFileError
        The calibration file cannot be read (before any device is opened).
    """
    from pipeline.hardware import build_real_rig
    from pipeline.rig_calibration import RigCalibrationFile

    clk: Clock = clock or MonotonicClock()
    cal_file = RigCalibrationFile.load(hardware.calibration_file) if hardware.calibration_file else None
    record = cal_file.tool(hardware.calibration_tool) if cal_file is not None else None
    payload = record.payload if record is not None else None
    tip = record.tcp.tip_in_flange_m if record is not None and record.tcp is not None else None
    rig = build_real_rig(hardware, clk, on_open=on_open, tip_in_flange_m=tip)
    calibration = payload if payload is not None else NO_PAYLOAD
    rls = RlsBias(calibration.force_bias_n, calibration.torque_bias_nm) if payload is not None else None
    framework = HapticFramework(hardware.framework, calibration, device_peak_n=rig.haptic.peak_force_n, rls=rls)
    ring = RingBuffer.create(RECORD_FIELDS, int(ring_seconds * 1000), shared=shared_ring)
    loop = HapticLoop(rig, framework, clk, ring, watchdog=watchdog or WatchdogConfig())
    return HardwareEngine(rig, framework, loop, clk, calibration, ring, cal_file, hardware.calibration_tool)


# -- the engine process -----------------------------------------------------------------------
def _build_for_process(config: EngineConfig, events: Any) -> SimEngine | HardwareEngine | None:
    """Build the engine the config asks for; on failure report one ``("error", message)`` and return None."""
    if config.hardware_file is None:
        return build_sim_engine(config, shared_ring=True)
    from pipeline.devices import DeviceError
    from pipeline.hardware import HardwareError, load_hardware

    try:
        hw = load_hardware(config.hardware_file)
        return build_hardware_engine(
            hw, watchdog=config.watchdog, shared_ring=True, ring_seconds=config.ring_seconds,
            on_open=lambda what: events.put(("opening", what)),
        )
    except (HardwareError, DeviceError) as exc:
        events.put(("error", str(exc)))
    except ValueError as exc:  # the calibration file (CalibrationFileError names it)
        events.put(("error", str(exc)))
    return None


def _engine_main(config: EngineConfig, conn: Any, events: Any, max_ticks: int | None) -> None:
    """Entry point of the engine process."""
    eng = _build_for_process(config, events)
    if eng is None:
        return
    loop = eng.loop
    loop.on_event = lambda ev: events.put(("loop_event", tuple(ev)))
    stop = threading.Event()

    def _receive() -> None:
        # Blocking receive in its own thread: the loop only drains a deque.
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):
                # controller gone: make the device safe and exit
                loop.submit(ControllerDetached())
                stop.set()
                return
            if msg == "stop":
                stop.set()
                return
            loop.submit(msg)

    threading.Thread(target=_receive, name="engine-commands", daemon=True).start()
    assert eng.ring is not None
    real = config.clock == "real"
    scheduling = prepare_realtime_thread() if real else "virtual clock"
    tracer = None
    if real and config.trace_jitter:
        tracer = LateTickTracer(MonotonicClock())
        loop.clock = tracer
    events.put(("ready", eng.ring.name, eng.calibration.to_dict(), scheduling))
    if tracer is not None:
        tracer.refresh()  # the threads: this one (the loop), the command receiver, the event queue's feeder
    if real:
        # a full collector pass over this process holds the GIL for 6–10 ms: freeze what exists, and let
        # the collector run only right after a tick, never started mid-tick by an allocation
        manual_garbage_collection()
    try:
        loop.run(stop, max_ticks=max_ticks, between_ticks=collect_garbage if real else None)
    finally:
        late = None
        if tracer is not None:
            late = tracer.summary()
            tracer.close()
        events.put(("stopped", loop.stats.summary(), loop.tick_count, int(loop.faults), late))
        try:
            eng.rig.close()
        except Exception as exc:  # noqa: BLE001 - a device failing to close must not keep the ring alive
            events.put(("close_error", str(exc)))
        time.sleep(0.2)  # let the reader copy the last records before the segment goes
        eng.ring.close()


class EngineProcess:
    """Start and talk to the engine process.

    Parameters
    ----------
    config
        What the engine builds.
    max_ticks
        Stop by itself after this many ticks (benchmarks and tests).
    """

    def __init__(self, config: EngineConfig, max_ticks: int | None = None) -> None:
        self.config = config
        self._ctx = mp.get_context("spawn")  # no fork of a process that may hold Qt or threads
        self._conn, child_conn = self._ctx.Pipe()
        self._events = self._ctx.Queue()
        self._proc = self._ctx.Process(
            target=_engine_main, args=(config, child_conn, self._events, max_ticks), name="haptic-engine", daemon=True
        )
        self._child_conn = child_conn
        self.ring: RingBuffer | None = None
        self.calibration: dict[str, Any] | None = None
        self.final_stats: dict[str, float] | None = None
        #: How the loop thread is scheduled, e.g. ``"SCHED_FIFO/20"`` (known once started).
        self.scheduling = ""
        self.final_ticks: int | None = None
        self.final_faults: int | None = None
        #: Late periods explained by cause (:meth:`pipeline.jitter_trace.LateTickTracer.summary`), with ``trace_jitter``.
        self.late_periods: dict[str, Any] | None = None
        self.loop_events: list[LoopEvent] = []
        #: The device the engine was opening last (hardware engines), for the start-up error.
        self.opening: str | None = None

    def start(self, timeout_s: float = 30.0) -> None:
        """Spawn the engine and wait until its ring buffer is ready.

        Raises
        ------
        EngineStartError
            A device failed to open (the message is the device's error, naming
            it), or the engine was not ready within ``timeout_s`` (the message
            names the device it was still opening); the process is ended.
        """
        self._proc.start()
        self._child_conn.close()
        deadline = time.monotonic() + timeout_s
        while True:
            remaining = deadline - time.monotonic()
            try:
                msg = self._events.get(timeout=max(0.01, min(0.25, remaining)))
            except queue.Empty:
                if remaining > 0.25 and self._proc.is_alive():
                    continue
                if remaining > 0.25:  # died: take its last word if it is still in flight, else say so now
                    try:
                        msg = self._events.get(timeout=0.5)
                    except queue.Empty:
                        code = self._proc.exitcode
                        self.kill()
                        raise EngineStartError(f"engine process exited during start-up (exit code {code})") from None
                else:
                    self.kill()
                    where = f" (still opening the {self.opening})" if self.opening else ""
                    raise EngineStartError(f"engine did not become ready within {timeout_s:g} s{where}") from None
            if msg[0] == "opening":
                self.opening = msg[1]
                continue
            if msg[0] == "error":
                self.kill()
                raise EngineStartError(f"engine could not start: {msg[1]}")
            if msg[0] == "ready":
                self.ring = RingBuffer.attach(msg[1])
                self.calibration = msg[2]
                self.scheduling = msg[3]
                return
            self._handle(msg)

    def send(self, command: Command) -> None:
        """Send a loop command."""
        self._conn.send(command)

    def poll_events(self) -> list[tuple[Any, ...]]:
        """Drain pending engine messages (loop events are also kept in :attr:`loop_events`)."""
        out = []
        while True:
            try:
                msg = self._events.get_nowait()
            except queue.Empty:
                return out
            self._handle(msg)
            out.append(msg)

    def _handle(self, msg: tuple[Any, ...]) -> None:
        if msg[0] == "loop_event":
            self.loop_events.append(LoopEvent(*msg[1]))
        elif msg[0] == "stopped":
            self.final_stats, self.final_ticks, self.final_faults, self.late_periods = msg[1], msg[2], msg[3], msg[4]

    def wait(self, timeout_s: float | None = None) -> None:
        """Wait for the engine to exit by itself (after ``max_ticks``)."""
        end = None if timeout_s is None else time.monotonic() + timeout_s
        while self.final_stats is None:
            remaining = None if end is None else max(0.0, end - time.monotonic())
            try:
                self._handle(self._events.get(timeout=remaining))
            except queue.Empty:
                break
        self._proc.join(timeout_s)

    def stop(self, timeout_s: float = 5.0) -> None:
        """Ask the engine to ramp down and exit; wait for it."""
        if self._proc.is_alive():
            try:
                self._conn.send("stop")
            except (OSError, BrokenPipeError):
                pass
            self.wait(timeout_s)
        self.close()

    def kill(self) -> None:
        """Terminate without ceremony (tests of the detach path use closing the pipe instead)."""
        if self._proc.is_alive():
            self._proc.kill()
        self._proc.join(2.0)
        self.close()

    def detach(self) -> None:
        """Close our end of the command pipe, as a crashed GUI would."""
        self._conn.close()

    @property
    def alive(self) -> bool:
        """True while the engine process runs."""
        return self._proc.is_alive()

    def close(self) -> None:
        """Release the ring and queues."""
        if self.ring is not None:
            self.ring.close()
            self.ring = None
