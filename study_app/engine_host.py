"""The study engine: rig + 1 kHz loop + session runner + recorder, in a process of its own (no Qt).

Why a separate process: a Qt window painting curves in the loop's process
holds the GIL for milliseconds per curve and breaks the 1 kHz loop
(science.md §7).  The GUI therefore only talks to this process:

* commands (:mod:`study_app.messages`) arrive over a pipe and are applied by
  one driver thread, so session state has a single owner;
* events are published on a queue (trial started/ended with metrics, phases,
  faults, health, calibration results);
* samples go through the shared-memory :class:`pipeline.ring.RingBuffer` the
  loop writes and the GUI pulls from at ~30 Hz.

If the pipe breaks (the GUI closed or crashed) the engine latches
``ENGINE_DETACHED`` (the force ramps to zero), aborts the running trial so its
row is stored with the reason (the session stays resumable), commits, and exits.

:class:`StudyEngine` is usable in-process on a virtual clock (tests);
:func:`host_main` is the process entry point, started by
:class:`study_app.engine_client.EngineClient`.
"""

from __future__ import annotations

import collections
import dataclasses
import gc
import json
import math
import os
import queue
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.clock import MonotonicClock, VirtualClock, collect_garbage, manual_garbage_collection, prepare_helper_thread
from pipeline.compensation import (
    CalibrationPose, DegeneratePoseSetError, PayloadCalibration, identify_payload, recommended_pose_set,
)
from pipeline.devices import DeviceError
from pipeline.engine import EngineConfig, HardwareEngine, SimEngine, build_hardware_engine, build_sim_engine
from pipeline.frames import Mat3, axis_angle, mat_mul
from pipeline.hardware import HardwareConfig, HardwareError, load_hardware
from pipeline.jitter_trace import LateTickTracer
from pipeline.loop import ControllerDetached, LoopEvent, SetCalibration
from pipeline.loop import OperatorStop as LoopOperatorStop
from pipeline.loop import ResetFaults as LoopResetFaults
from pipeline.sim.hand import HandObservation
from pipeline.frame_check import AXES, AxisCheck, FrameCheck, check_axis
from pipeline.jaw_control import JawController
from pipeline.rig_calibration import CalibrationFileError, ToolCalibration, now_iso
from pipeline.supervisor import LoopSupervisor
from pipeline.tcp import PivotPose, identify_tip, pivot_orientations
from pipeline.sim.rig import SimRigConfig
from protocol.config import ProtocolError, load_protocol
from pipeline.sim.participant import SimulatedParticipant
from protocol.rehearsal import FAULT_KINDS, FaultPlan, RehearsalTrigger
from protocol.session import SessionRunner
from protocol.session_setup import (
    OpenedSession, delivery_limits, finish_session, open_new_session, open_resumed_session, participant_seeds,
    raw_wrench_scales, start_runner,
)
from protocol.storage import Recorder, StorageError, StudyDatabase, new_owner_token, validate_code
from study_app.session_config import config_record, real_config_record
from protocol.records import AbortCause, TrialRecord
from protocol.trial import PhaseChanged, TrialPhase
from study_app import messages as m
from study_app.session_list import list_sessions

__all__ = [
    "CALIBRATION_MAX_CONDITION", "CALIBRATION_MAX_RMS_FORCE_N", "HostConfig", "StudyEngine", "SwitchableDriver",
    "build_real_engine", "host_main", "pose_set", "rotation_angle_deg",
]

#: The wizard refuses a pose set whose (column-scaled) regressor is worse conditioned than this.
CALIBRATION_MAX_CONDITION = 1000.0
#: ... or whose fit leaves more than this RMS force residual (a pose in contact, a loose tool).
CALIBRATION_MAX_RMS_FORCE_N = 0.05
#: Lowest / highest equilibrium a person may command with the mouse, m along the Touch's +y.
MANUAL_Y_RANGE_M = (-0.030, 0.005)
#: A calibration pose is refused if the TCP turned more than this, or moved more than the next, while averaging.
POSE_STILL_DEG = 0.5
POSE_STILL_M = 0.002
#: ... or if a force sample older than this was averaged (the sensor stalled).
POSE_MAX_SENSOR_AGE_S = 0.05
#: Real rig: a session starts only if the compensated force at rest, averaged over this long, is below the next.
REST_CHECK_S = 2.0
REST_MAX_FORCE_N = 0.1
#: Real rig, TCP pivot step: a recorded orientation is refused if the TCP moved more than this while averaging.
PIVOT_STILL_M = 0.0002
PIVOT_STILL_DEG = 0.2
#: The driver thread wakes this long after a loop tick starts (a tick takes ~50 µs): see StudyEngine.quiet_wait_s.
QUIET_OFFSET_NS = 150_000
_RAW_WRENCH = ("raw_fx", "raw_fy", "raw_fz", "raw_tx", "raw_ty", "raw_tz")


def rotation_angle_deg(a: Mat3, b: Mat3) -> float:
    """The angle of the rotation taking orientation ``a`` to ``b``, degrees (0–180)."""
    ra, rb = np.asarray(a, dtype=float).reshape(3, 3), np.asarray(b, dtype=float).reshape(3, 3)
    c = (float(np.trace(ra.T @ rb)) - 1.0) / 2.0
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def _import_factory(spec: str) -> Callable[..., Any]:
    import importlib

    module, _, attr = spec.partition(":")
    try:
        return getattr(importlib.import_module(module), attr)  # type: ignore[no-any-return]
    except (ImportError, AttributeError) as exc:
        raise RuntimeError(f"haptic_factory = {spec!r}: cannot be imported ({exc})") from None


def build_real_engine(config: HostConfig, *, shared_ring: bool) -> tuple[HardwareEngine, HardwareConfig, str]:
    """Load the hardware file, open the devices and assemble the loop (:func:`pipeline.engine.build_hardware_engine`).

    Returns the engine, the validated hardware config and the file's text (stored with each session).

    Raises
    ------
    RuntimeError
        One line: the file is missing or invalid (naming the field), or a device cannot be opened (naming it).
    """
    if not config.hardware_path:
        raise RuntimeError("real rig: no hardware file given; pass --hardware FILE (see hardware.example.toml)")
    try:
        hw = load_hardware(config.hardware_path)
        with open(config.hardware_path, encoding="utf-8") as fh:
            text = fh.read()
    except HardwareError as exc:
        raise RuntimeError(f"real rig: {exc}") from None
    import pipeline.hardware as hardware_module

    # The rig-construction seam: build_real_rig opens the Touch through pipeline.hardware.open_haptic.
    # Tests (no Touch on CI) swap in a device that speaks the HDAPI through the real Touch backend.
    original = hardware_module.open_haptic
    if config.haptic_factory is not None:
        hardware_module.open_haptic = _import_factory(config.haptic_factory)  # type: ignore[assignment]
    try:
        eng = build_hardware_engine(hw, shared_ring=shared_ring, ring_seconds=30.0)
    except (DeviceError, CalibrationFileError) as exc:
        raise RuntimeError(f"real rig: {exc}") from None
    finally:
        hardware_module.open_haptic = original
    return eng, hw, text


@dataclass
class _Recording:
    """A calibration pose being averaged from the ring (driver thread)."""

    label: str
    need: int
    start_ns: int  # loop time (the ring's t_ns)
    pose0: Any
    target: Mat3 | None
    chunks: list[np.ndarray]
    got: int = 0


@dataclass
class _Window:
    """Records of the ring collected for a calibration step or the session gate (driver thread).

    ``done(columns)`` gets each column in ``cols`` over exactly ``need`` records; if the recording is
    abandoned instead (the sensor stalled: published as a refusal of ``command``), ``abandoned()`` is called.
    """

    command: str
    need: int
    start_ns: int
    cols: tuple[str, ...]
    done: Callable[[dict[str, np.ndarray]], None]
    chunks: list[np.ndarray]
    got: int = 0
    abandoned: Callable[[], None] | None = None


def pose_set(name: str) -> list[Mat3]:
    """Sensor orientations ``rot_base_sensor`` of a named calibration pose set.

    ``recommended``: 24 well-spread tilts (science.md §1.2); ``quick``: 6;
    ``tool-down only``: 6 yaws about the vertical with the tool pointing down,
    which leave gravity fixed in the sensor frame -- a degenerate set the
    wizard must refuse (kept so an experimenter can see what a refusal says).
    """
    if name == "recommended":
        return recommended_pose_set(24)
    if name == "quick":
        return recommended_pose_set(6)
    if name == "tool-down only":
        down = recommended_pose_set(24)[0]
        return [mat_mul(axis_angle((0.0, 0.0, 1.0), k * 0.5), down) for k in range(6)]
    raise ValueError(f"pose set = {name!r}: allowed values are {', '.join(m.POSE_SETS)}")


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
        ``"real"`` (1 kHz on the monotonic clock, loop in its own thread) or
        ``"virtual"`` (rehearsals, screenshots, tests).
    speed
        Virtual clock only: simulated seconds per wall second (0 = as fast as the CPU allows).
    rig_seed
        Seed of the simulated rig.
    block_ticks
        Virtual clock: ticks per driver step.
    health_period_s
        Wall time between :class:`study_app.messages.Health` events.
    trace_jitter
        Real clock only: explain every loop period over 1.5 ms (:mod:`pipeline.jitter_trace`),
        reported in :attr:`study_app.messages.Health.late_periods` (diagnosis and benchmarks).
    sim_mount_error_deg
        Simulated rig: the sensor is mounted turned about its z axis by this much, unknown to the pipeline
        (``SimRigConfig.sensor_z_mount_deg``): rehearse the frame check failing.
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

    def set_mode(self, mode: str) -> None:
        """Switch who drives (one of :data:`study_app.messages.DRIVER_MODES`)."""
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

    def begin_trial(self, target_force_n: float, haptic_on: bool, t_s: float) -> None:
        """Forward the cue to the simulated participant."""
        if self.participant is not None:
            self.participant.begin_trial(target_force_n, haptic_on, t_s)

    def practice(self, target_force_n: float, haptic_on: bool, t_s: float, live_force_n_visible: bool) -> None:
        """Forward a training trial to the simulated participant."""
        if self.participant is not None:
            self.participant.practice(target_force_n, haptic_on, t_s, live_force_n_visible)

    def end_trial(self, t_s: float) -> None:
        """Forward the end of a trial."""
        if self.participant is not None:
            self.participant.end_trial(t_s)


class _PeriodStats:
    """Histogram of tick periods (1 µs bins) read from the ring's ``period_s`` column -- cheap, numpy only.

    The loop's own :class:`pipeline.loop.LoopStats` summary walks 50 000 bins in
    Python; doing that twice a second in the loop's process would steal the
    GIL from the loop thread for milliseconds.
    """

    BINS = 50_001

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.hist = np.zeros(self.BINS, dtype=np.int64)
        self._pending: list[np.ndarray] = []
        self.count = 0
        self.span_s = 0.0  # on the loop's own clock (virtual or real)

    def add(self, period_s: np.ndarray) -> None:
        # binned lazily (at summary time): one 50 000-bin pass per summary, not per block
        if len(period_s):
            self._pending.append(np.asarray(period_s, dtype=np.float64).copy())
            self.count += len(period_s)
            self.span_s += float(np.sum(period_s))

    def _fold(self) -> None:
        if self._pending:
            us = np.clip(np.round(np.concatenate(self._pending) * 1e6), 0, self.BINS - 1).astype(np.int64)
            self._pending = []
            self.hist += np.bincount(us, minlength=self.BINS)

    def _quantile(self, hist: np.ndarray, q: float) -> float:
        n = int(hist.sum())
        if n == 0:
            return math.nan
        return float(np.searchsorted(np.cumsum(hist), q * n))

    def summary(self, nominal_us: int = 1000) -> dict[str, float]:
        self._fold()
        h = self.hist
        idx = np.arange(self.BINS)
        dev = np.bincount(np.abs(idx - nominal_us), weights=h, minlength=self.BINS)
        return {
            "ticks": float(self.count),
            "period_p50_us": self._quantile(h, 0.5),
            "period_p99_us": self._quantile(h, 0.99),
            "abs_dev_p50_us": self._quantile(dev, 0.5),
            "abs_dev_p99_us": self._quantile(dev, 0.99),
            "periods_over_2ms": float(h[2001:].sum()),
            "period_max_us": float(np.flatnonzero(h)[-1]) if self.count else math.nan,
            "fraction_over_2ms": float(h[2001:].sum()) / self.count if self.count else math.nan,
            "rate_hz": self.count / self.span_s if self.span_s > 0 else math.nan,
        }


class StudyEngine:
    """Owns the rig, the loop, the session runner and the recorder; applies commands; publishes events.

    Parameters
    ----------
    config
        What to build.
    publish
        Called with each event (thread-safe: the loop thread reports faults through it).
    shared_ring
        Put the sample ring in shared memory (the engine process) or private memory (in-process tests).
    """

    def __init__(self, config: HostConfig, publish: Callable[[object], None], *, shared_ring: bool = True) -> None:
        self.config = config
        self.publish = publish
        self.real = config.rig == "real"
        self.driver = SwitchableDriver()
        self.hardware: HardwareConfig | None = None
        self.hardware_text = ""
        self.eng: SimEngine | HardwareEngine
        if self.real:
            self.eng, self.hardware, self.hardware_text = build_real_engine(config, shared_ring=shared_ring)
        else:
            self.eng = build_sim_engine(
                EngineConfig(sim=SimRigConfig(seed=config.rig_seed, sensor_z_mount_deg=config.sim_mount_error_deg),
                             clock=config.clock, calibrate=True, driver="hold",
                             haptics_on=False, refine_bias=True, ring_seconds=30.0),
                shared_ring=shared_ring,
            )
            self.eng.rig.set_driver(self.driver)
        self.calibration: PayloadCalibration = self.eng.calibration
        self._recording: _Recording | None = None
        assert self.eng.ring is not None
        self.ring = self.eng.ring
        self.cursor = self.ring.write_count
        self.loop = self.eng.loop
        self.loop.on_event = self._on_loop_event
        self.tracer: LateTickTracer | None = None
        if config.trace_jitter and config.clock == "real":
            self.tracer = LateTickTracer(MonotonicClock())
            self.loop.clock = self.tracer
        self.stats = _PeriodStats()
        self.runner: SessionRunner | None = None
        self.recorder: Recorder | None = None
        self.db: StudyDatabase | None = None
        self.opened: OpenedSession | None = None
        self.trigger: RehearsalTrigger | None = None
        # loop events for the runner: appended on the loop thread, taken by the driver thread (deque ops are atomic)
        self._loop_events: collections.deque[LoopEvent] = collections.deque()
        #: This engine's lease token (one per engine process).
        self.lease_owner = new_owner_token()
        self.session_code = ""
        self._last_health = 0.0
        self._anchor_wall = time.monotonic()
        self._anchor_ticks = 0
        self._ticks_run = 0
        self._running = False
        self._last_t_ns = 0
        self._stats_from_tick = 0
        self.closed = False
        #: Watches the loop thread and its tick counter (real clock; the virtual clock runs the loop in step()).
        self.supervisor = LoopSupervisor(self.loop)
        #: Why the haptic loop died ("" while it runs): nothing that needs the loop can be done any more.
        self.loop_dead = ""
        #: What is on record for the mounted tool (real rig: from the calibration file; simulated: this run's).
        self.tool_cal = self._tool_record()
        self._windows: list[_Window] = []
        self._frame_axes: dict[str, AxisCheck] = {}
        self._gate_passed: object | None = None  # a start whose rest check passed: let it through once
        self._starting: object | None = None  # a start waiting for its rest check
        self._override: tuple[str, str, float] | None = None  # (what was missing, the reason, force at rest N)
        #: The instrument's jaw (the simulated one, or the Arduino of the hardware file); None: there is none.
        self.jaw = self._make_jaw()

    # -- lifetime -------------------------------------------------------------------------------
    def start(self) -> None:
        """Start the loop (its own thread on the real clock) and announce the engine."""
        if self.config.clock == "real":
            self.loop.start()
        self._running = True
        if isinstance(self.eng, SimEngine):
            rc = self.eng.rig.config
            surface_z_m, tip_home_m, rot_tip_sensor = rc.surface_z_m, tuple(rc.tip_home_m), rc.rot_tip_sensor
        else:
            surface_z_m, tip_home_m = math.nan, (math.nan, math.nan, math.nan)
            rot_tip_sensor = self.eng.framework.config.rot_tip_sensor
        self.publish(m.EngineReady(
            ring_name=self.ring.name or "", rig=self.config.rig, clock=self.config.clock,
            calibration=self.calibration.to_dict(), surface_z_m=surface_z_m,
            tip_home_m=tip_home_m, driver=self.driver_name,  # type: ignore[arg-type]
            rot_tip_sensor=tuple(float(x) for x in rot_tip_sensor),
            devices=self._device_summary(),
        ))
        self._publish_calibration_status()
        if self.jaw is not None:
            self.jaw.start()
            self._publish_jaw("")

    @property
    def driver_name(self) -> str:
        """Who drives the stylus: the simulated-rig driver mode, or a person on the real rig."""
        return m.REAL_DRIVER if self.real else self.driver.mode

    def _device_summary(self) -> list[str]:
        hw = self.hardware
        if hw is None:
            return ["simulated rig (F/T sensor, UR3, Touch twins)"]
        out = [f"F/T sensor: Net F/T at {hw.sensor.host}:{hw.sensor.port}",
               f"robot: UR over RTDE at {hw.robot.host} ({hw.robot.mode})",
               f"haptic device: {hw.haptic.device_name}"]
        if hw.jaw is not None:
            out.append(f"jaw actuator: {hw.jaw.port}")
        return out

    def close(self, reason: str, *, detached: bool = False) -> None:
        """Leave the current session resumable with complete records, ramp the force to zero, stop."""
        if self.closed:
            return
        if detached:
            self.loop.submit(ControllerDetached())  # latches: the force ramps to zero at once
        runner = self.runner
        if runner is not None and not runner.done:
            if runner.machine.phase in (TrialPhase.CUED, TrialPhase.ACTIVE):
                runner.abort_trial(reason, cause="interrupted")
                self._step_until(lambda: runner.machine.phase not in (TrialPhase.CUED, TrialPhase.ACTIVE))
            t_s = runner.session_time_s(self._last_t_ns)
            assert self.recorder is not None
            self.recorder.event(runner.session_id, t_s, "detached" if detached else "closed", reason)
            self._end_session("interrupted", reason)
        if self.config.clock == "real":
            self.loop.stop(timeout_s=5.0)
        elif not self.loop_dead:
            self.loop.ramp_down()
        if self.tracer is not None:
            self.tracer.close()
        if self.jaw is not None:
            self.jaw.close()
        self._drain_ring()
        try:
            self.eng.rig.close()
        except DeviceError as exc:  # the force is already zero; say what did not close cleanly
            reason = f"{reason}; {exc}"
        self.closed = True
        self.publish(m.EngineStopped(reason, self.stats.summary()))

    def release_ring(self) -> None:
        """Free the shared ring (after the GUI had a chance to copy the last records)."""
        self.ring.close()

    def _step_until(self, done: Callable[[], bool], timeout_s: float = 2.0) -> None:
        end = time.monotonic() + timeout_s
        while not done() and time.monotonic() < end:
            self.step(throttle=False)
            if self.config.clock == "real":
                time.sleep(0.002)

    # -- the driver thread's work ---------------------------------------------------------------------
    def step(self, *, throttle: bool = True) -> None:
        """Advance: run a block of ticks (virtual clock), feed new records to the runner, publish health."""
        if self.loop_dead:
            return
        if self.config.clock == "virtual":
            n = self.config.block_ticks
            try:
                self.loop.run_ticks(n)
            except Exception as exc:  # noqa: BLE001 - the loop died in this thread: make safe, report, store
                self.loop.fail_safe(f"the haptic loop died ({exc!r}); the haptic device's command watchdog dropped "
                                    "the force to zero", thread_dead=True)
                self._loop_died(repr(exc))
                return
            self._ticks_run += n
            if throttle and self.config.speed > 0:
                self._throttle()
        elif self.supervisor.check() is not None:
            if self.supervisor.dead:
                self._loop_died(self.supervisor.dead)
                return
            self._store_loop_events()  # frozen: no records come, but its event must reach the record now
        self._drain_ring()
        if self.jaw is not None and self.jaw.events:
            self._drain_jaw()
        now = time.monotonic()
        if now - self._last_health >= self.config.health_period_s:
            self._last_health = now
            if self.tracer is not None:
                self.tracer.refresh()
            self.publish(self.health())

    def _store_loop_events(self) -> None:
        """Hand the pending loop events to the session runner without records (the loop writes none)."""
        runner = self.runner
        if runner is not None and self._loop_events:
            runner.process(np.empty(0), [self._loop_events.popleft() for _ in range(len(self._loop_events))])

    def _loop_died(self, why: str) -> None:
        """The haptic loop is dead (its fault is latched and reported): store it, leave the session resumable."""
        self.loop_dead = why
        self._drain_ring()  # the records it wrote before it died
        self._store_loop_events()
        runner = self.runner
        if runner is not None and not runner.done:
            reason = (f"the haptic loop died ({why}); the session is interrupted: restart the engine (Restart engine "
                      "in the window) and resume it")
            assert self.recorder is not None
            self.recorder.event(runner.session_id, runner.session_time_s(self._last_t_ns), "session_interrupted",
                                reason)
            self._end_session("interrupted", reason)
        self.publish(self.health())

    def _require_loop(self, what: str) -> None:
        if self.loop_dead:
            raise RuntimeError(f"{what}: the haptic loop died ({self.loop_dead}); restart the engine (Restart engine "
                               "in the window; an interrupted session can be resumed)")

    def quiet_wait_s(self, interval_s: float) -> float:
        """Seconds to wait to wake ``QUIET_OFFSET_NS`` after a loop tick, about ``interval_s`` from now.

        Real clock only.  The driver's work (runner, recorder hand-off, events)
        takes the GIL; if it asks for it while the loop thread spins to its
        deadline or runs a tick, the interpreter forces the loop out after a
        switch interval and the tick starts late.  Waking just after a tick
        leaves the driver (and the recorder it feeds) most of the loop's
        ~0.8 ms sleep to finish in.  The tick grid is read from the newest
        record the driver has seen (its start on the loop's clock).
        """
        if not self.loop.tick_count:
            return interval_s
        now = time.perf_counter_ns()
        period = self.loop.period_ns
        last_tick = self.loop.t0_ns + self._last_t_ns
        target = now + int(interval_s * 1e9)
        target -= (target - last_tick - QUIET_OFFSET_NS) % period
        return max(0.0, (target - now) * 1e-9)

    def _throttle(self) -> None:
        # keep simulated time at `speed` × wall time; after a stall, re-anchor instead of bursting
        ahead = self._anchor_wall + (self._ticks_run - self._anchor_ticks) * 1e-3 / self.config.speed - time.monotonic()
        if ahead > 0:
            time.sleep(ahead)
        elif ahead < -0.2:
            self._reanchor()

    def _reanchor(self) -> None:
        self._anchor_wall = time.monotonic()
        self._anchor_ticks = self._ticks_run

    def _drain_ring(self) -> None:
        res = self.ring.read_since(self.cursor)
        self.cursor = res.cursor
        rows = res.rows
        if len(rows) == 0:
            return
        if self._stats_from_tick:
            # the first tick after a calibration carries the calibration's gap: not a loop overrun
            keep = rows["tick"] >= self._stats_from_tick
            self.stats.add(rows["period_s"][keep])
        else:
            self.stats.add(rows["period_s"])
        self._last_t_ns = int(rows["t_ns"][-1])
        if self._recording is not None:
            self._feed_recording(rows)
        if self._windows:
            self._feed_windows(rows)
        runner = self.runner
        # the loop's events and replay log after its records: every entry of a tick whose record was read is in
        events = [self._loop_events.popleft() for _ in range(len(self._loop_events))]
        log = self.loop.replay_log
        replay_log = [log.popleft() for _ in range(len(log))]
        if runner is None:
            return
        if res.lost:
            runner.records_lost(res.lost)
        runner.process(rows, events, replay_log)
        if self.trigger is not None:
            self.trigger.poll(self._last_t_ns)
        if runner.done:
            self._end_session(runner.status, runner.stop_reason)

    def health(self) -> m.Health:
        """The engine's state and loop timing since the last stats reset."""
        s = self.stats.summary()
        runner = self.runner
        return m.Health(
            loop_rate_hz=s["rate_hz"], period_p50_us=s["period_p50_us"], period_p99_us=s["period_p99_us"],
            abs_dev_p99_us=s["abs_dev_p99_us"], periods_over_2ms=int(s["periods_over_2ms"]),
            missed_slots=int(self.loop.stats.missed_slots), ticks=int(s["ticks"]), faults=int(self.loop.faults),
            haptic_on=bool(self.loop.haptic_on), driver=self.driver_name,
            session_running=runner is not None and not runner.done, paused=bool(runner is not None and runner.paused),
            abs_dev_p50_us=s["abs_dev_p50_us"], period_max_us=s["period_max_us"],
            late_periods=None if self.tracer is None else self.tracer.summary(),
            waiting=runner.state.waiting if runner is not None and not runner.done else "",
            **self._health_extra(),
        )

    def _on_loop_event(self, ev: LoopEvent) -> None:
        # called from the loop thread: only hand the event on (to the GUI, and to the runner for the record)
        self._loop_events.append(ev)
        runner = self.runner
        session_t = math.nan
        if runner is not None and not runner.done and runner.clock is not None:
            session_t = runner.session_time_s(ev.t_ns)  # what the events table will say
        self.publish(m.EngineFault(ev.t_ns * 1e-9, ev.kind, int(ev.faults), ev.detail, session_t))

    # -- commands -------------------------------------------------------------------------------------
    def handle(self, cmd: object) -> None:
        """Apply one command; anything that cannot be done is answered with :class:`CommandRefused`."""
        name = type(cmd).__name__
        try:
            self._handle(cmd)
        except (StorageError, ProtocolError, ValueError, RuntimeError) as exc:
            self.publish(m.CommandRefused(name, str(exc)))

    def _handle(self, cmd: object) -> None:
        runner = self.runner
        if isinstance(cmd, m.StartSession):
            self._start_session(cmd)
        elif isinstance(cmd, m.ResumeSession):
            self._resume_session(cmd)
        elif isinstance(cmd, m.ListSessions):
            self.publish(m.SessionsListed(cmd.db_path, list_resumable(cmd.db_path),
                                          list_sessions(cmd.db_path, check=False)))
        elif isinstance(cmd, (m.Pause, m.Resume, m.AbortTrial, m.AbortSession)):
            if runner is None or runner.done:
                raise RuntimeError("no session is running")
            if isinstance(cmd, m.Pause):
                runner.pause()
            elif isinstance(cmd, m.Resume):
                runner.resume()
            elif isinstance(cmd, m.AbortTrial):
                running = runner.machine.phase in (TrialPhase.CUED, TrialPhase.ACTIVE)
                spec = runner.machine.spec
                if cmd.trial_index is not None and not (running and spec is not None and spec.index == cmd.trial_index):
                    # confirmed for a trial that has ended since: never abort the next one instead
                    raise RuntimeError(f"trial {cmd.trial_index + 1} had already ended: nothing was aborted")
                if not running:
                    raise RuntimeError("no trial is running (between trials or paused)")
                runner.abort_trial(cmd.reason, trial_index=cmd.trial_index)
            else:
                if cmd.session_id is not None and cmd.session_id != runner.session_id:
                    raise RuntimeError(f"session {cmd.session_id} had already ended: nothing was aborted")
                runner.abort_session(cmd.reason)
        elif isinstance(cmd, m.ResetFaults):
            self._require_loop("reset faults")
            self.loop.submit(LoopResetFaults())
        elif isinstance(cmd, m.InjectFault):
            self._inject_fault(cmd)
        elif isinstance(cmd, m.OperatorStop):
            self.loop.submit(LoopOperatorStop())
        elif isinstance(cmd, m.Calibrate):
            if self.real:
                raise RuntimeError("real rig: the poses are recorded one at a time in the calibration wizard "
                                   "(move the robot, then Record pose)")
            self._calibrate(cmd.pose_set)
        elif isinstance(cmd, m.RecordPose):
            self._record_pose(cmd)
        elif isinstance(cmd, m.IdentifyPoses):
            self._identify(cmd)
        elif isinstance(cmd, m.CalibrateTcp):
            self._calibrate_tcp(cmd.pose_set)
        elif isinstance(cmd, m.RecordPivot):
            self._record_pivot(cmd)
        elif isinstance(cmd, m.IdentifyTcp):
            self._identify_tcp(cmd)
        elif isinstance(cmd, m.CheckFrames):
            self._check_frames()
        elif isinstance(cmd, m.RecordFrameAxis):
            self._record_frame_axis(cmd)
        elif isinstance(cmd, m.JawCommand):
            if self.jaw is None:
                raise RuntimeError("jaw: no jaw actuator on this rig (add a [jaw] table to the hardware file)")
            self.jaw.submit(cmd.action)
        elif isinstance(cmd, (m.SetDriver, m.ManualTarget)):
            if self.real:
                raise RuntimeError("real rig: a person holds the stylus; the simulated participant and manual "
                                   "driving exist on the simulated rig only")
            if isinstance(cmd, m.SetDriver):
                self.driver.set_mode(cmd.mode)
                self.publish(self.health())
            else:
                self.driver.set_manual_y(cmd.y_m)
        elif isinstance(cmd, m.ResetStats):
            self.stats.reset()
            if self.tracer is not None:
                self.tracer.reset()
        else:
            raise ValueError(f"unknown command {cmd!r}")

    def _require_idle(self, what: str) -> None:
        self._require_loop(what)
        if self.runner is not None and not self.runner.done:
            raise RuntimeError(f"{what}: a session is running (end or abort it first)")

    def _open_db(self, path: str) -> StudyDatabase:
        if not path:
            raise StorageError("study database: no file given")
        return StudyDatabase(path)

    def _start_session(self, cmd: m.StartSession) -> None:
        self._require_idle("start")
        validate_code(cmd.code)
        if cmd.kind not in ("training", "experiment"):
            raise ValueError(f"session kind = {cmd.kind!r}: allowed values are 'training' and 'experiment'")
        if cmd.seed < 0 or cmd.participant_number < 1:
            raise ValueError(f"seed = {cmd.seed}, participant number = {cmd.participant_number}: need seed ≥ 0 and number ≥ 1")
        protocol = load_protocol(cmd.protocol_path or None)
        if self._gate(cmd):
            return
        db = self._open_db(cmd.db_path)
        try:
            opened = open_new_session(
                db, code=cmd.code, number=cmd.participant_number, kind=cmd.kind, protocol=protocol, seed=cmd.seed,
                rig=self.config.rig,
                config={**self._config_record(participant_seeds(cmd.seed, cmd.participant_number)[1]), "app": "gui",
                        **self._calibration_provenance()},
                calibration=self.calibration.to_dict(), lease_owner=self.lease_owner,
                note=f"{cmd.kind} session for {cmd.code}, seed {cmd.seed} (GUI)",
            )
        except BaseException:
            db.close()
            raise
        self._run(db, opened)

    def _config_record(self, participant_seed: int) -> dict[str, Any]:
        if isinstance(self.eng, SimEngine):
            return config_record(self.eng, self.config.clock, self.config.rig_seed, participant_seed)
        assert self.hardware is not None
        return real_config_record(self.hardware, self.hardware_text, self.eng)

    def _resume_session(self, cmd: m.ResumeSession) -> None:
        self._require_idle("resume")
        if self._gate(cmd):
            return
        db = self._open_db(cmd.db_path)
        try:
            opened = open_resumed_session(db, cmd.session_id, lease_owner=self.lease_owner,
                                          calibration=self.calibration.to_dict())
        except BaseException:
            db.close()
            raise
        self._run(db, opened)

    def _run(self, db: StudyDatabase, opened: OpenedSession) -> None:
        if isinstance(self.eng, SimEngine):
            self.driver.participant = SimulatedParticipant(seed=opened.participant_seed)
            sim_rig = self.eng.rig
            participant: SwitchableDriver | None = self.driver
            participant_time: Callable[[], float] | None = lambda: sim_rig.sim_time_s
        else:  # a person holds the Touch: nothing to notify, nothing simulated
            participant, participant_time = None, None
        # a resumed session's table and progress start from what is stored (read before the recorder writes)
        stored = [TrialRecord.from_row(r) for r in db.trial_rows(opened.session_id)] if opened.resumed else []
        recorder, runner = start_runner(
            db, opened, submit=self.loop.submit, participant=participant, participant_time=participant_time,
            limits=delivery_limits(self.loop), auto_reset_faults=False, threaded=True,
            scales=raw_wrench_scales(self.eng.rig.sensor),
        )
        runner.listeners.append(self._on_runner_event)
        self.trigger = None
        self.db, self.recorder, self.runner, self.opened, self.session_code = db, recorder, runner, opened, opened.code
        if self._override is not None:
            missing, why, rest_n = self._override
            self._override = None
            recorder.event(opened.session_id, opened.clock_offset_s, "calibration_override",
                           f"started by the experimenter's override: {missing or 'the calibration chain was on record'}; "
                           f"the compensated force at rest was {rest_n:.3f} N (limit {REST_MAX_FORCE_N:g} N). "
                           f"Reason: {why}")
        if self.config.clock == "real":
            gc.freeze()  # the session's long-lived objects: out of the collector's full passes (see host_main)
        tr = opened.protocol.trial
        self.publish(m.SessionStarted(
            session_id=opened.session_id, code=opened.code, kind=opened.kind, trials_total=len(opened.schedule),
            start_position=opened.start_position, tolerance_fraction=tr.tolerance_fraction,
            max_trial_s=tr.max_trial_s, pause_s=tr.pause_s, cue_s=tr.cue_s, live_force_aid=opened.live_force_aid,
            schedule=[dataclasses.asdict(sp) for sp in opened.schedule],
            participant_number=opened.participant_number, stored_trials=stored,
        ))

    # -- fault rehearsal (simulated rig) -------------------------------------------------------------
    def _inject_fault(self, cmd: m.InjectFault) -> None:
        if not isinstance(self.eng, SimEngine):
            raise RuntimeError("fault rehearsal: refused on the real rig (a person's hand is on it); "
                               "rehearse on the simulated rig")
        if cmd.kind not in FAULT_KINDS:
            raise ValueError(f"fault kind = {cmd.kind!r}: allowed values are {', '.join(FAULT_KINDS)}")
        if not (math.isfinite(cmd.seconds) and 0 <= cmd.seconds <= 600):
            raise ValueError(f"fault seconds = {cmd.seconds!r}: must be a number from 0 to 600")
        if cmd.trial is None:
            if cmd.kind == "kill":
                os.kill(os.getpid(), signal.SIGKILL)  # as a crash would: the GUI sees the engine die
            rig, loop = self.eng.rig, self.loop
            rig.inject_fault(cmd.kind, loop.clock.now_ns())
            self.publish(m.FaultInjected(cmd.kind, "now"))
            return
        runner, opened = self.runner, self.opened
        if runner is None or runner.done or opened is None:
            raise RuntimeError("fault rehearsal at a trial: start or resume a session first (or inject it now)")
        n, begun = len(runner.schedule), runner.state.trial_position
        later = (f"the trials still to come are {begun + 1} to {n}" if begun + 1 < n
                 else f"the one still to come is trial {n}" if begun + 1 == n
                 else f"every trial of this session has begun (all {n}); inject it now instead")
        if cmd.trial < 1 or cmd.trial > n:
            raise ValueError(f"fault trial = {cmd.trial}: the session has trials 1 to {n}; {later}")
        if cmd.trial <= begun:
            raise ValueError(f"fault trial = {cmd.trial}: trial {cmd.trial} has already begun; {later}")
        plan = FaultPlan(cmd.kind, opened.code, cmd.trial, cmd.seconds, opened.kind)
        eng = self.eng

        def inject(kind: str, at_ns: int) -> None:
            eng.rig.inject_fault(kind, eng.loop.t0_ns + at_ns)

        def kill() -> None:
            os.kill(os.getpid(), signal.SIGKILL)

        def cancel(kind: str, at_ns: int) -> None:
            eng.rig.cancel_fault(kind, eng.loop.t0_ns + at_ns)

        trig = RehearsalTrigger.for_session([plan], opened.code, opened.kind, runner.state.trial_position,
                                            inject, kill, cancel)
        if self.trigger is not None:  # keep what was planned before
            trig._pending.extend(self.trigger._pending)
        else:
            runner.listeners.append(lambda ev: self.trigger.on_runner_event(ev) if self.trigger else None)
        self.trigger = trig
        self.publish(m.FaultInjected(cmd.kind, f"trial {cmd.trial} + {cmd.seconds:g} s"))

    def _on_runner_event(self, ev: object) -> None:
        runner = self.runner
        if runner is None:
            return
        if isinstance(ev, PhaseChanged):
            t_s = ev.t_ns * 1e-9
            if ev.new is TrialPhase.ACTIVE and runner.machine.spec is not None:
                spec = runner.machine.spec
                self.publish(m.TrialStarted(
                    t_s, spec.index, runner.state.trial_position, runner.state.trials_total, spec.target_label,
                    spec.target_force_n, spec.haptic_mode,
                ))
            self.publish(m.PhaseEntered(t_s, ev.trial_index, str(ev.new)))
        elif isinstance(ev, TrialRecord):
            cause = ev.abort_cause
            if cause in (AbortCause.GAP, AbortCause.FEEDBACK):  # not a watchdog fault, so the loop said nothing
                self.publish(m.EngineFault(ev.end_ns * 1e-9, cause.value, int(self.loop.faults), ev.abort_reason or "",
                                           ev.ended_at_s))
            self.publish(m.TrialEnded(ev.end_ns * 1e-9, ev, runner.state.trials_total))

    def _end_session(self, status: str, reason: str) -> None:
        runner, recorder, db, opened = self.runner, self.recorder, self.db, self.opened
        assert runner is not None and recorder is not None and db is not None and opened is not None
        self.runner = self.recorder = self.db = self.opened = None
        self.trigger = None
        self.driver.participant = None
        error = ""
        try:
            finish_session(db, recorder, opened)
        except StorageError as exc:
            error = str(exc)
        finally:
            db.close()
        st = runner.state
        self.publish(m.SessionEnded(runner.session_id, status, reason or error, st.completed, st.aborted, st.successes))

    # -- calibration on the real rig: pose by pose -----------------------------------------------------
    def _record_pose(self, cmd: m.RecordPose) -> None:
        if not isinstance(self.eng, HardwareEngine):
            raise RuntimeError("simulated rig: the poses run automatically (Run calibration)")
        self._require_idle("record pose")
        if self._recording is not None:
            raise RuntimeError(f"record pose: pose {self._recording.label} is still being recorded")
        if not cmd.label.strip():
            raise ValueError("pose label = '': must name the pose")
        if not (math.isfinite(cmd.seconds) and 0.1 <= cmd.seconds <= 10.0):
            raise ValueError(f"record seconds = {cmd.seconds!r}: allowed 0.1 to 10 s")
        target = None
        if cmd.target_rot_base_sensor is not None:
            target = check_target(cmd.target_rot_base_sensor)
        now = self.eng.clock.now_ns()
        pose0 = self.eng.rig.robot.read_pose()
        if not all(math.isfinite(x) for x in pose0.position_m):
            raise RuntimeError("robot: no TCP pose received yet; check the RTDE connection (Devices tab)")
        age_s = (now - pose0.t_ns) * 1e-9
        if age_s > 0.5:
            raise RuntimeError(f"robot: the newest TCP pose is {age_s:.1f} s old; check the RTDE connection")
        # average only records written after this command: everything up to now is drained first
        self._drain_ring()
        start = self._last_t_ns + 1 if self.loop.tick_count else 0
        self._recording = _Recording(cmd.label, int(round(cmd.seconds * 1000)), start, pose0, target, [])

    def _feed_recording(self, rows: np.ndarray) -> None:
        rec = self._recording
        assert rec is not None
        sel = rows[rows["t_ns"] >= rec.start_ns]
        if len(sel):
            if float(np.max(sel["sensor_age_s"])) > POSE_MAX_SENSOR_AGE_S:
                self._recording = None
                self.publish(m.CommandRefused("RecordPose", f"pose {rec.label}: the force sensor stalled while "
                                              "recording (check the Devices tab) — record it again"))
                return
            rec.chunks.append(np.stack([sel[c] for c in _RAW_WRENCH], axis=1))
            rec.got += len(sel)
        if rec.got < rec.need:
            return
        self._recording = None
        assert isinstance(self.eng, HardwareEngine)
        w = np.concatenate(rec.chunks)[: rec.need]
        pose1 = self.eng.rig.robot.read_pose()
        turned = rotation_angle_deg(rec.pose0.rot_base_tip, pose1.rot_base_tip)
        moved = math.dist(rec.pose0.position_m, pose1.position_m)
        if not np.isfinite(w).all():
            reason = "the force sensor gave non-finite readings"
        elif not (turned <= POSE_STILL_DEG and moved <= POSE_STILL_M):
            reason = (f"the robot moved while recording ({turned:.2f}°, {moved * 1e3:.1f} mm; allowed "
                      f"{POSE_STILL_DEG:g}° and {POSE_STILL_M * 1e3:g} mm) — let it stand still and record again")
        else:
            reason = ""
        if reason:
            self.publish(m.CommandRefused("RecordPose", f"pose {rec.label}: {reason}"))
            return
        rot_base_sensor = mat_mul(pose1.rot_base_tip, self.eng.framework.config.rot_tip_sensor)
        mean = w.mean(axis=0)
        self.publish(m.PoseRecorded(
            label=rec.label, samples=len(w), wrench=tuple(float(x) for x in mean),  # type: ignore[arg-type]
            rot_base_sensor=tuple(float(x) for x in rot_base_sensor),
            tcp_position_m=tuple(float(x) for x in pose1.position_m),  # type: ignore[arg-type]
            off_target_deg=rotation_angle_deg(rec.target, rot_base_sensor) if rec.target is not None else math.nan,
            force_std_n=float(np.std(np.linalg.norm(w[:, :3], axis=1))),
        ))

    def _identify(self, cmd: m.IdentifyPoses) -> None:
        if not self.real:
            raise RuntimeError("simulated rig: the poses run automatically (Run calibration)")
        self._require_idle("calibrate")
        poses = [CalibrationPose(rot, wrench, label) for label, rot, wrench in cmd.poses]
        self.publish(self._identified(poses, cmd.pose_set))

    def _identified(self, poses: list[CalibrationPose], name: str) -> m.CalibrationDone:
        """Identify, judge, and install an accepted calibration in the running loop."""
        try:
            cal = identify_payload(poses)
        except DegeneratePoseSetError as exc:
            return m.CalibrationDone(False, str(exc), name, len(poses), float(exc.condition_number or math.inf),
                                     math.nan, math.nan, [], None)
        reason = calibration_verdict(cal)
        if reason == "":
            self.calibration = cal
            self.loop.submit(SetCalibration(cal))
            self._record_step("payload", cal)
        return m.CalibrationDone(
            reason == "", reason, name, len(poses), cal.condition_number, cal.rms_force_residual_n,
            cal.rms_torque_residual_nm, [(r.label, r.force_residual_n, r.torque_residual_nm) for r in cal.residuals],
            cal.to_dict(),
        )

    # -- calibration on the simulated rig: automatic ----------------------------------------------------
    def _calibrate(self, name: str) -> None:
        from pipeline.sim.calibration import auto_calibrate

        self._require_idle("calibrate")
        rots = pose_set(name)
        real = self.config.clock == "real"
        if real:
            self.loop.stop(timeout_s=5.0)  # ramps the force to zero first
            clock: Any = MonotonicClock()
        else:
            self.loop.ramp_down()
            clock = self.loop.clock
        self._drain_ring()
        total = len(rots)
        result: m.CalibrationDone
        try:
            assert isinstance(self.eng, SimEngine)
            cal, poses = auto_calibrate(
                self.eng.rig, clock, rots,
                progress=lambda done, n: self.publish(m.CalibrationProgress(done, n, f"P{done:02d}")),
            )
        except DegeneratePoseSetError as exc:
            result = m.CalibrationDone(False, str(exc), name, total, float(exc.condition_number or math.inf),
                                       math.nan, math.nan, [], None)
        else:
            reason = calibration_verdict(cal)
            result = m.CalibrationDone(
                reason == "", reason, name, len(poses), cal.condition_number, cal.rms_force_residual_n,
                cal.rms_torque_residual_nm, [(r.label, r.force_residual_n, r.torque_residual_nm) for r in cal.residuals],
                cal.to_dict(),
            )
            if reason == "":
                self.calibration = cal
                self.loop.submit(SetCalibration(cal))
                self._record_step("payload", cal)
        finally:
            self._after_loop_pause(real)
        self.publish(result)

    def _after_loop_pause(self, restart: bool) -> None:
        """The loop ran the rig for a calibration step: restart its timing statistics (and its thread)."""
        self.stats.reset()
        self._stats_from_tick = self.loop.tick_count + 1
        self._reanchor()
        if restart:
            if self.tracer is not None:
                self.tracer.restart()
            self.loop.start()

    # -- the commissioning chain: what is on record, and the steps (TCP, payload above, frames) ------------------
    def _tool_record(self) -> ToolCalibration:
        eng = self.eng
        if isinstance(eng, HardwareEngine):
            return eng.calibration_file.tool(eng.tool) if eng.calibration_file is not None else ToolCalibration(eng.tool)
        # the simulated rig calibrated its payload as it was built; TCP and frames are this run's, never saved
        return ToolCalibration("simulated instrument", payload=eng.calibration, payload_date=now_iso())

    def _frames_in_use(self) -> tuple[Mat3, Mat3]:
        fw = self.eng.framework.config
        return fw.rot_tip_sensor, fw.rot_haptic_base

    def _publish_calibration_status(self) -> None:
        eng = self.eng
        path = eng.calibration_file.path if isinstance(eng, HardwareEngine) and eng.calibration_file is not None else ""
        self.publish(m.CalibrationStatus(self.config.rig, self.tool_cal.tool, path, self.tool_cal.status(),
                                         self.tool_cal.missing(*self._frames_in_use())))

    def _record_step(self, step: str, result: Any) -> None:
        """Put an accepted result on record (real rig: saved in the calibration file) and publish the status."""
        eng = self.eng
        if isinstance(eng, HardwareEngine) and eng.calibration_file is not None:
            try:
                self.tool_cal = eng.calibration_file.record(eng.tool, step, result)
            except CalibrationFileError as exc:
                self.tool_cal = self.tool_cal.with_step(step, result)
                self.publish(m.CommandRefused("calibration file", f"{exc}: the result is in use but not saved"))
            if step == "tcp" and self.hardware is not None:
                # the robot's poses move to the new tip at once (the pendant's TCP stays what the file says)
                off = self.hardware.robot.tcp_offset_m
                eng.rig.robot.tcp_correction_m = tuple(t - o for t, o in zip(result.tip_in_flange_m, off))
        else:
            self.tool_cal = self.tool_cal.with_step(step, result)
        self._publish_calibration_status()

    def _calibration_provenance(self) -> dict[str, Any]:
        """What a session stores about the calibration chain (``config_json``): tool, file, every step on record."""
        eng = self.eng
        path = eng.calibration_file.path if isinstance(eng, HardwareEngine) and eng.calibration_file is not None else None
        out: dict[str, Any] = {"rig_calibration": {"tool": self.tool_cal.tool, "file": path, **self.tool_cal.to_dict()}}
        if self._override is not None:
            out["calibration_override"] = {"missing": self._override[0], "reason": self._override[1],
                                           "rest_force_n": self._override[2]}
        return out

    def _calibrate_tcp(self, name: str) -> None:
        from pipeline.sim.commissioning import pivot_poses
        from pipeline.sim.robot import TOOL_DOWN

        if not isinstance(self.eng, SimEngine):
            raise RuntimeError("real rig: rest the tip in the divot, turn the instrument and record each orientation "
                               "(Record orientation), then Compute")
        self._require_idle("TCP calibration")
        if name not in m.PIVOT_SETS:
            raise ValueError(f"pose set = {name!r}: allowed values are {', '.join(m.PIVOT_SETS)}")
        rig = self.eng.rig
        self._tcp_identified(pivot_poses(rig, pivot_orientations(name, TOOL_DOWN)), name, rig.config.tip_in_flange_m)

    def _tcp_identified(self, poses: list[PivotPose], name: str, truth: Any = None) -> None:
        try:
            tc = identify_tip(poses)
        except ValueError as exc:
            self.publish(m.TcpCalibrationDone(False, str(exc), name, len(poses), None))
            return
        err = math.dist(tc.tip_in_flange_m, truth) * 1e3 if truth is not None else math.nan
        self._record_step("tcp", tc)
        self.publish(m.TcpCalibrationDone(True, "", name, tc.n_poses, tc.to_dict(), err))

    def _record_pivot(self, cmd: m.RecordPivot) -> None:
        if not isinstance(self.eng, HardwareEngine):
            raise RuntimeError("simulated rig: the orientations run automatically (Run TCP calibration)")
        self._require_idle("record orientation")
        if not (math.isfinite(cmd.seconds) and 0.1 <= cmd.seconds <= 5.0):
            raise ValueError(f"record seconds = {cmd.seconds!r}: allowed 0.1 to 5 s")
        robot = self.eng.rig.robot
        pose0 = robot.read_pose()
        if not all(math.isfinite(x) for x in pose0.position_m):
            raise RuntimeError("robot: no TCP pose received yet; check the RTDE connection (Devices tab)")
        label = cmd.label

        def done(cols: dict[str, np.ndarray]) -> None:
            p = np.stack([cols["tip_x_m"], cols["tip_y_m"], cols["tip_z_m"]], axis=1)
            pose1 = robot.read_pose()
            moved = float(np.max(np.linalg.norm(p - p.mean(axis=0), axis=1)))
            turned = rotation_angle_deg(pose0.rot_base_tip, pose1.rot_base_tip)
            if not (moved <= PIVOT_STILL_M and turned <= PIVOT_STILL_DEG):
                self.publish(m.CommandRefused("RecordPivot", (
                    f"orientation {label}: the robot moved while recording ({moved * 1e3:.2f} mm, {turned:.2f}°; allowed "
                    f"{PIVOT_STILL_M * 1e3:g} mm and {PIVOT_STILL_DEG:g}°) — hold it still and record again")))
                return
            rot = pose1.rot_base_tip
            tip = self.tool_cal.tcp.tip_in_flange_m if self.tool_cal.tcp is not None else (
                self.hardware.robot.tcp_offset_m if self.hardware is not None else (0.0, 0.0, 0.0))
            off = np.asarray(rot).reshape(3, 3) @ np.asarray(tip)
            flange = tuple(float(v) for v in p.mean(axis=0) - off)
            self.publish(m.PivotRecorded(label, tuple(float(x) for x in rot), flange, moved * 1e3))  # type: ignore[arg-type]

        self._open_window("RecordPivot", cmd.seconds, ("tip_x_m", "tip_y_m", "tip_z_m"), done)

    def _identify_tcp(self, cmd: m.IdentifyTcp) -> None:
        if not isinstance(self.eng, HardwareEngine):
            raise RuntimeError("simulated rig: the orientations run automatically (Run TCP calibration)")
        self._require_idle("TCP calibration")
        self._tcp_identified([PivotPose(rot, pos, label) for label, rot, pos in cmd.poses], "recorded")

    def _check_frames(self) -> None:
        from pipeline.sim.commissioning import push_axes

        if not isinstance(self.eng, SimEngine):
            raise RuntimeError("real rig: push the free tip along each axis in turn (Record +x, +y, +z)")
        self._require_idle("frame check")
        real = self.config.clock == "real"
        if real:
            self.loop.stop(timeout_s=5.0)  # the check runs the loop itself, paced on the same clock
        self._drain_ring()
        try:
            assert self.ring is not None
            check = push_axes(self.eng.rig, self.loop, self.ring)
        finally:
            self.cursor = self.ring.write_count  # the check's own records are not the loop's timing
            self._after_loop_pause(real)
        for a in check.axes:
            self.publish(m.FrameAxisChecked(a.axis, a.passed, a.describe(), a.to_dict()))
        self._frames_done(check)

    def _frames_done(self, check: FrameCheck) -> None:
        self._record_step("frames", check)
        summary = check.summary()
        mount = self.calibration.mount_angle_deg
        if not check.passed and mount > 5.0:
            summary += f" (the payload calibration finds the sensor {mount:.1f}° from its configured mount)"
        self.publish(m.FrameCheckDone(check.passed, summary, [a.describe() for a in check.axes]))

    def _record_frame_axis(self, cmd: m.RecordFrameAxis) -> None:
        if not isinstance(self.eng, HardwareEngine):
            raise RuntimeError("simulated rig: the pushes run automatically (Run frame check)")
        self._require_idle("frame check")
        if cmd.axis not in AXES:
            raise ValueError(f"axis = {cmd.axis!r}: allowed values are {', '.join(AXES)}")
        if not (math.isfinite(cmd.seconds) and 0.5 <= cmd.seconds <= 10.0):
            raise ValueError(f"record seconds = {cmd.seconds!r}: allowed 0.5 to 10 s")
        if self.tool_cal.payload is None:
            raise RuntimeError("frame check: no payload calibration on record for tool "
                               f"{self.tool_cal.tool!r}; the chain runs in order: calibrate the payload first")
        axis = cmd.axis
        rhb = self._frames_in_use()[1]

        def done(cols: dict[str, np.ndarray]) -> None:
            base = np.stack([cols["base_fx"], cols["base_fy"], cols["base_fz"]], axis=1)
            scaled = np.stack([cols["scaled_fx"], cols["scaled_fy"], cols["scaled_fz"]], axis=1)
            res = check_axis(axis, base, scaled, rhb)
            self._frame_axes[axis] = res
            self.publish(m.FrameAxisChecked(axis, res.passed, res.describe(), res.to_dict()))
            if all(a in self._frame_axes for a in AXES):
                check = FrameCheck(tuple(self._frame_axes[a] for a in AXES), *self._frames_in_use())
                self._frame_axes = {}
                self._frames_done(check)

        self._open_window("RecordFrameAxis", cmd.seconds,
                          ("base_fx", "base_fy", "base_fz", "scaled_fx", "scaled_fy", "scaled_fz"), done)

    def _open_window(self, command: str, seconds: float, cols: tuple[str, ...],
                     done: Callable[[dict[str, np.ndarray]], None], abandoned: Callable[[], None] | None = None) -> None:
        """Collect ``seconds`` of records written after now, then call ``done`` (see :class:`_Window`)."""
        if any(w.command == command for w in self._windows):
            raise RuntimeError(f"{command}: a recording is already running")
        self._drain_ring()
        start = self._last_t_ns + 1 if self.loop.tick_count else 0
        self._windows.append(_Window(command, int(round(seconds * 1000)), start, cols, done, [], abandoned=abandoned))

    def _feed_windows(self, rows: np.ndarray) -> None:
        for w in list(self._windows):
            sel = rows[rows["t_ns"] >= w.start_ns]
            if len(sel):
                if float(np.max(sel["sensor_age_s"])) > POSE_MAX_SENSOR_AGE_S:
                    self._windows.remove(w)
                    again = ("measuring the force at rest (check the Devices tab) — press Start again"
                             if w.command in ("StartSession", "ResumeSession")
                             else "recording (check the Devices tab) — record again")
                    self.publish(m.CommandRefused(w.command, f"the force sensor stalled while {again}"))
                    if w.abandoned is not None:
                        w.abandoned()
                    continue
                w.chunks.append(np.stack([sel[c] for c in w.cols], axis=1))
                w.got += len(sel)
            if w.got >= w.need:
                self._windows.remove(w)
                data = np.concatenate(w.chunks)[: w.need]
                try:
                    w.done({c: data[:, i] for i, c in enumerate(w.cols)})
                except (ValueError, RuntimeError) as exc:
                    self.publish(m.CommandRefused(w.command, str(exc)))

    # -- the session gate (real rig) -----------------------------------------------------------------
    def _gate(self, cmd: m.StartSession | m.ResumeSession) -> bool:
        """The real rig's calibration gate; True when the start waits for its rest check (it comes back later).

        The chain (TCP, payload, frames) must be on record for the mounted tool -- or the experimenter gives a
        reason to start without it -- and then, in every case, the compensated force at rest over
        ``REST_CHECK_S`` must be below ``REST_MAX_FORCE_N``.

        Raises :class:`RuntimeError` (one line, naming the missing step) when the start is refused.
        """
        if not self.real:
            return False
        if cmd is self._gate_passed:
            self._gate_passed = None
            return False
        self._override = None  # a start that failed after its check must not lend its override to this one
        missing = self.tool_cal.missing(*self._frames_in_use())
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
            f = float(math.hypot(*(float(np.mean(cols[c])) for c in ("comp_fx", "comp_fy", "comp_fz"))))
            if not f < REST_MAX_FORCE_N:
                self.publish(m.CommandRefused(type(cmd).__name__, (
                    f"real rig: the compensated force at rest is {f:.3f} N over {REST_CHECK_S:g} s (limit "
                    f"{REST_MAX_FORCE_N:g} N): the tool touches something, or its payload calibration does not match "
                    f"the mounted tool {self.tool_cal.tool!r}; keep it clear and still, or calibrate the payload again"
                    + ("; an override does not waive this check" if reason else ""))))
                return
            if reason:
                self._override = (missing, reason, f)
            self._gate_passed = cmd
            self.handle(cmd)

        def abandoned() -> None:
            self._starting = None  # the measurement was abandoned: Start may be pressed again

        try:
            self._open_window(type(cmd).__name__, REST_CHECK_S, ("comp_fx", "comp_fy", "comp_fz"), done, abandoned)
        except RuntimeError:
            self._starting = None
            raise
        self.publish(m.StartChecking(REST_CHECK_S, f"calibration on record for tool {self.tool_cal.tool!r}; measuring "
                                     f"the compensated force at rest for {REST_CHECK_S:g} s — keep the instrument "
                                     "still and clear of everything"))
        return True

    # -- health extras, the jaw ------------------------------------------------------------------------
    def _health_extra(self) -> dict[str, Any]:
        haptic = self.eng.rig.haptic
        st = haptic.read_state()
        return {"haptic_heat_fraction": float(st.heat_fraction), "haptic_force_limit_n": float(st.force_limit_n),
                "haptic_peak_force_n": float(haptic.peak_force_n),
                "haptic_continuous_force_n": float(haptic.continuous_force_n), "loop_dead": self.loop_dead}

    def _make_jaw(self) -> JawController | None:
        rig = self.eng.rig
        jaw = getattr(rig, "jaw", None)
        if jaw is None:
            return None
        if self.hardware is not None and self.hardware.jaw is not None:
            j = self.hardware.jaw
            ctl = JawController(jaw, close_button=j.close_button, open_button=j.open_button,
                                stylus=self.hardware.robot.mode != "teleop")  # teleoperation claims both buttons
        else:
            ctl = JawController(jaw)
        rig.on_buttons = ctl.buttons
        return ctl

    def _publish_jaw(self, last: str) -> None:
        assert self.jaw is not None
        s = self.jaw.jaw.status
        self.publish(m.JawState(float(s.fraction_open), int(s.pos_us), bool(s.at_limit), str(s.fault), last))

    def _drain_jaw(self) -> None:
        """Every jaw command carried out: to the display, and into the running session's events."""
        assert self.jaw is not None
        runner, recorder = self.runner, self.recorder
        while self.jaw.events:
            ev = self.jaw.events.popleft()
            text = f"{ev.source}: {ev.detail}"
            if runner is not None and recorder is not None and not runner.done:
                recorder.event(runner.session_id, runner.session_time_s(self._last_t_ns), "jaw", text)
            self.publish(m.JawState(ev.fraction_open, ev.pulse_us, ev.at_limit, ev.fault, text))



def check_target(rows: Any) -> Mat3:
    """A requested pose's ``rot_base_sensor`` (validated)."""
    from pipeline.frames import check_rotation

    return check_rotation(rows, "target_rot_base_sensor")


def calibration_verdict(cal: PayloadCalibration) -> str:
    """Empty if the calibration is acceptable, else the reason it is refused."""
    if cal.condition_number > CALIBRATION_MAX_CONDITION:
        return (f"condition number {cal.condition_number:.3g} is above {CALIBRATION_MAX_CONDITION:g}: the poses do not "
                "vary the tool's orientation enough; use the recommended set")
    if cal.rms_force_residual_n > CALIBRATION_MAX_RMS_FORCE_N:
        return (f"RMS force residual {cal.rms_force_residual_n:.3g} N is above {CALIBRATION_MAX_RMS_FORCE_N:g} N: "
                "a pose was in contact or the tool moved; check the tool hangs free and repeat")
    return ""


def list_resumable(db_path: str) -> list[dict[str, Any]]:
    """Interrupted sessions of a database (none if the file does not exist yet)."""
    if not db_path or not os.path.exists(db_path):
        return []
    db = StudyDatabase(db_path, readonly=True)
    try:
        out = []
        busy = db.sessions_being_written()
        for s in db.open_sessions():
            if s.session_id in busy:
                continue  # another process runs it right now: not interrupted
            out.append({
                "session_id": s.session_id, "code": s.code, "kind": s.kind, "started_at": s.started_at,
                "trials_done": len(db.trial_rows(s.session_id)), "trials_total": len(json.loads(s.schedule_json)),
            })
        return out
    finally:
        db.close()


# -- the process --------------------------------------------------------------------------------
class _Detached:
    """Internal marker: the command pipe broke."""


def host_main(config: HostConfig, conn: Any, events: Any) -> None:
    """Entry point of the study engine process."""
    # A pure-Python driver thread must not hold the GIL for the default 5 ms
    # while the 1 kHz loop thread waits for it.
    sys.setswitchinterval(0.0002)
    if config.clock == "real":
        # every thread started from here on (device receivers of the real rig, command receiver, recorder,
        # event feeder, loop) inherits this: none can hold the GIL while preempted by another process
        prepare_helper_thread()
    publish = events.put
    try:
        engine = StudyEngine(config, publish)
    except Exception as exc:  # noqa: BLE001 - reported to the GUI as one line
        publish(m.CommandRefused("connect", str(exc)))
        publish(m.EngineStopped(str(exc), {}))
        return
    cmds: queue.SimpleQueue[object] = queue.SimpleQueue()

    def receive() -> None:
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):
                cmds.put(_Detached())
                return
            cmds.put(msg)
            if isinstance(msg, m.Shutdown):
                return

    threading.Thread(target=receive, name="engine-commands", daemon=True).start()
    real = config.clock == "real"
    if real:
        # freeze what exists now and let the collector run only in the driver's quiet window after a tick
        manual_garbage_collection()
    engine.start()
    detached = False
    # real clock: the driver's regular work runs every ~10 ms just after a loop tick (StudyEngine.quiet_wait_s);
    # a command is applied when it arrives, the work it causes waits for the next quiet moment
    step_at_ns = time.perf_counter_ns()
    try:
        while True:
            try:
                if real:
                    cmd = cmds.get(timeout=max(0.0, (step_at_ns - time.perf_counter_ns()) * 1e-9))
                else:
                    cmd = cmds.get_nowait()
            except queue.Empty:
                cmd = None
            if isinstance(cmd, _Detached):
                detached = True
                break
            if isinstance(cmd, m.Shutdown):
                break
            if cmd is not None:
                engine.handle(cmd)
            if not real:
                engine.step()
            elif time.perf_counter_ns() >= step_at_ns:
                engine.step()
                collect_garbage()
                step_at_ns = time.perf_counter_ns() + int(engine.quiet_wait_s(0.01) * 1e9)
    finally:
        reason = "the experimenter GUI went away (closed or crashed)" if detached else "the experimenter GUI closed"
        engine.close(reason, detached=detached)
        if detached:
            events.cancel_join_thread()  # nobody reads the queue any more: do not block the exit on it
        time.sleep(0.2)  # let a reader copy the last records before the segment goes
        engine.release_ring()
