"""The study engine: rig + 1 kHz loop + session runner + recorder, in a process of its own (no Qt).

Why a separate process: a Qt window painting curves in the loop's process
holds the GIL for milliseconds per curve and breaks the 1 kHz loop
(science.md §7).  For the same reason, on the real clock the loop does not run here either: it runs alone in a
process of its own (:mod:`study_app.engine.loop_process`, :mod:`pipeline.assembly.loop_host`), and this process
drives it through the stand-ins of :mod:`pipeline.assembly.loop_client` -- the session runner, the recorder's
commits and this process's messages never hold the lock the loop needs.  (Where the OS cannot start that process,
Windows, and in-process tests without shared memory, the loop runs in a thread of this process, as on the virtual
clock in :meth:`StudyEngine.step`.)  The GUI only talks to this process:

* commands (:mod:`study_app.engine.messages`) arrive over a pipe and are applied by
  one driver thread, so session state has a single owner;
* events are published on a queue (trial started/ended with metrics, phases,
  faults, health, calibration results);
* samples go through the shared-memory :class:`pipeline.runtime.ring.RingBuffer` the
  loop writes and the GUI pulls from at ~30 Hz.

:class:`StudyEngine` owns the rig and the loop, and is built of rooms, each with one job: the session being run
(:class:`study_app.engine.sessions.EngineSessions`), the calibration steps and the real rig's start gate
(:class:`study_app.engine.commissioning.Commissioning`), the reading of the ring
(:class:`study_app.engine.ring_reader.RingReader`), the jaws (:class:`study_app.engine.jaws.EngineJaws`), the
driver's pace (:class:`study_app.engine.pacing.LoopPacer`) and what the engine reports
(:mod:`study_app.engine.reports`).  It is usable in-process on a virtual clock (tests); the process around it is
:func:`study_app.engine.process.host_main`, started by :class:`study_app.engine.client.EngineClient`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from pipeline.assembly.engine import Engine
from pipeline.assembly.engine_view import EngineView
from pipeline.assembly.loop_jobs import JOBS
from pipeline.assembly.remote_engine import RemoteEngine
from pipeline.core.clock import MonotonicClock
from pipeline.devices.interfaces import DeviceError
from pipeline.force.payload_compensator import PayloadCalibration
from pipeline.runtime.jitter_trace import LateTickTracer
from pipeline.runtime.loop_messages import ControllerDetached, LoopEvent
from pipeline.runtime.loop_messages import OperatorStop as LoopOperatorStop
from pipeline.runtime.loop_messages import ResetFaults as LoopResetFaults
from pipeline.runtime.loop_view import LoopView
from pipeline.runtime.supervisor import LoopSupervisor
from pipeline.settings.hardware import HardwareConfig
from protocol.runner.session import SessionRunner
from protocol.storage import Recorder, StorageError, new_owner_token
from protocol.study.config import ProtocolError
from protocol.study.trial import TrialPhase
from study_app.engine import messages as m
from study_app.engine.commissioning import Commissioning
from study_app.engine.jaws import EngineJaws
from study_app.engine.latency_report import LatencyReport
from study_app.engine.loop_process import RemoteTracer, loop_runs_alone, start_remote_engine
from study_app.engine.pacing import QUIET_OFFSET_NS, LoopPacer
from study_app.engine.reports import HealthReport, engine_ready, fault_event
from study_app.engine.rig_arms import RigArms
from study_app.engine.ring_reader import RingReader
from study_app.engine.sessions import EngineSessions
from study_app.engine.setup import HostConfig, StylusControl, SwitchableDriver, build_engine

__all__ = ["QUIET_OFFSET_NS", "StudyEngine"]


class StudyEngine:
    """Owns the rig and the loop; its lifetime, the driver thread's step, and which room applies which command.

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
        self.eng: EngineView
        self.hardware: HardwareConfig | None
        self.driver: StylusControl
        #: The assembled engine when the loop runs in this process (None: it runs in a process of its own).
        self.local: Engine | None = None
        #: The loop's own process's stand-in for the engine (None: the loop runs here).
        self.remote: RemoteEngine | None = None

        def opening(device: str) -> None:
            publish(m.EngineOpening(device))

        own = start_remote_engine(config, opening) if loop_runs_alone(config) and shared_ring else None
        if own is not None:
            self.remote, self.hardware, self.hardware_text, self.driver = own
            self.eng = self.remote
        else:
            self.driver = SwitchableDriver()
            self.local, self.hardware, self.hardware_text = build_engine(config, self.driver, shared_ring=shared_ring,
                                                                         on_open=opening)
            self.eng = self.local
        self.calibration: PayloadCalibration = self.eng.calibration
        assert self.eng.ring is not None
        self.ring = self.eng.ring
        self.loop: LoopView = self.eng.loop
        self.loop.on_event = self._on_loop_event
        self.tracer: LateTickTracer | RemoteTracer | None = None
        if config.trace_jitter and config.clock == "real":
            if self.remote is not None:
                self.tracer = RemoteTracer(self.remote.loop.link)
            else:
                assert self.local is not None
                self.tracer = LateTickTracer(MonotonicClock())
                self.local.loop.clock = self.tracer
        #: This engine's lease token (one per engine process).
        self.lease_owner = new_owner_token()
        self._last_health = 0.0
        self.closed = False
        #: Watches the loop thread and its tick counter (real clock; the virtual clock runs the loop in step()).
        self.supervisor = LoopSupervisor(self.loop)
        #: Why the haptic loop died ("" while it runs): nothing that needs the loop can be done any more.
        self.loop_dead = ""
        #: The session being run (at most one), and the commissioning chain (calibration steps, the real rig's gate).
        self.arms = RigArms(self.eng, self.hardware)
        self.commissioning = Commissioning(self, self.arms)
        self.sessions = EngineSessions(self, self.commissioning)
        #: Reads the ring from here on: the timing statistics, the commissioning chain, the running session.
        self.reader = RingReader(self.eng, self.commissioning, self.sessions)
        self.pacer = LoopPacer(self.loop, config.speed)
        #: The end-to-end latency's breakdown (real clock: nobody feels a force on the virtual one).
        self.latency = LatencyReport(self.eng, self.hardware) if config.clock == "real" else None
        if self.latency is not None:
            self.latency.measure()
        self.reports = HealthReport(self.eng, config.clock, self.reader.stats, self.tracer,
                                    self.remote.loop.pid if self.remote is not None else 0, self.latency)
        self.jaws = EngineJaws(self.eng, self.hardware, self.arms.devices, self.arms.first, publish)
        self._commands = self._command_table()

    @property
    def runner(self) -> SessionRunner | None:
        """The running (or just ended) session's runner, None when no session was started."""
        return self.sessions.runner

    @property
    def recorder(self) -> Recorder | None:
        """The running session's recorder."""
        return self.sessions.recorder

    @property
    def cursor(self) -> int:
        """The ring's read cursor (a room that ran the loop itself moves it past its own records)."""
        return self.reader.driver.cursor

    @cursor.setter
    def cursor(self, value: int) -> None:
        self.reader.driver.cursor = value

    @property
    def last_t_ns(self) -> int:
        """Loop time of the newest record the driver has read, ns."""
        return self.reader.last_t_ns

    @last_t_ns.setter
    def last_t_ns(self, value: int) -> None:
        self.reader.last_t_ns = value

    @property
    def driver_name(self) -> str:
        """Who drives the stylus: the simulated-rig driver mode, or a person on the real rig."""
        return m.REAL_DRIVER if self.real else self.driver.mode

    # -- lifetime -------------------------------------------------------------------------------
    def start(self) -> None:
        """Start the loop (its own thread on the real clock) and announce the engine."""
        if self.config.clock == "real":
            self.loop.start()
        self.publish(engine_ready(self.eng, self.config, self.driver_name, self.calibration, self.hardware))
        self.commissioning.publish_status()
        self.jaws.start()

    def close(self, reason: str, *, detached: bool = False) -> None:
        """Leave the current session resumable with complete records, ramp the force to zero, stop."""
        if self.closed:
            return
        if detached:
            self.loop.submit(ControllerDetached())  # latches: the force ramps to zero at once
        runner = self.sessions.runner
        if runner is not None and not runner.done:
            if runner.machine.phase in (TrialPhase.CUED, TrialPhase.ACTIVE):
                runner.abort_trial(reason, cause="interrupted")
                self._step_until(lambda: runner.machine.phase not in (TrialPhase.CUED, TrialPhase.ACTIVE))
            t_s = runner.session_time_s(self.last_t_ns)
            assert self.sessions.recorder is not None
            self.sessions.recorder.event(runner.session_id, t_s, "detached" if detached else "closed", reason)
            self.sessions.end("interrupted", reason)
        if self.config.clock == "real":
            self.loop.stop(timeout_s=5.0)
        elif not self.loop_dead:
            self.loop.ramp_down()
        if self.tracer is not None:
            self.tracer.close()
        self.jaws.close()
        self.drain_ring()
        try:
            self.eng.rig.close()
        except DeviceError as exc:  # the force is already zero; say what did not close cleanly
            reason = f"{reason}; {exc}"
        if self.remote is not None and self.remote.loop.link.closed is not None:
            error = self.remote.loop.link.closed.error  # what the loop's process could not close cleanly
            reason = f"{reason}; {error}" if error else reason
        self.closed = True
        self.publish(m.EngineStopped(reason, self.reader.stats.summary()))

    def release_ring(self) -> None:
        """Free the shared rings, every arm's (after the GUI had a chance to copy the last records)."""
        if self.remote is not None:  # the loop's process owns them: close ours, free a dead process's
            self.remote.release()
            return
        for ring in {id(r): r for r in (self.ring, *self.eng.rings.values()) if r is not None}.values():
            ring.close()

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
            assert self.local is not None  # the virtual clock's loop runs here, in this thread
            try:
                self.local.loop.run_ticks(n)
            except Exception as exc:  # the loop died in this thread: make safe, report, store
                self.loop.fail_safe(f"the haptic loop died ({exc!r}); the haptic device's command watchdog dropped "
                                    "the force to zero", thread_dead=True)
                self._loop_died(repr(exc))
                return
            self.pacer.ran(n, throttle=throttle)
        elif self.supervisor.check() is not None:
            if self.supervisor.dead:
                self._loop_died(self.supervisor.dead)
                return
            self.reader.flush_events()  # frozen: no records come, but its event must reach the record now
        self.drain_ring()
        if self.jaws.pending:
            self._drain_jaws()
        now = time.monotonic()
        if now - self._last_health >= self.config.health_period_s:
            self._last_health = now
            if self.tracer is not None:
                self.tracer.refresh()
            self.publish(self.health())

    def _loop_died(self, why: str) -> None:
        """The haptic loop is dead (its fault is latched and reported): store it, leave the session resumable."""
        self.loop_dead = why
        self.drain_ring()  # the records it wrote before it died
        self.reader.flush_events()
        runner = self.sessions.runner
        if runner is not None and not runner.done:
            reason = (f"the haptic loop died ({why}); the session is interrupted: restart the engine (Restart engine "
                      "in the window) and resume it")
            assert self.sessions.recorder is not None
            self.sessions.recorder.event(runner.session_id, runner.session_time_s(self.last_t_ns),
                                         "session_interrupted", reason)
            self.sessions.end("interrupted", reason)
        self.publish(self.health())

    def _require_loop(self, what: str) -> None:
        if self.loop_dead:
            raise RuntimeError(f"{what}: the haptic loop died ({self.loop_dead}); restart the engine (Restart engine "
                               "in the window; an interrupted session can be resumed)")

    def require_idle(self, what: str) -> None:
        """Raise :class:`RuntimeError` naming ``what`` if the loop is dead or a session runs."""
        self._require_loop(what)
        if self.sessions.running:
            raise RuntimeError(f"{what}: a session is running (end or abort it first)")

    def run_paused(self, job: str, progress: Callable[[int, int], None] | None = None, **kwargs: Any) -> Any:
        """Run a calibration step that drives the rig itself (:data:`pipeline.assembly.loop_jobs.JOBS`) with the
        loop paused, where the loop runs; its records (a frame check's) are not read as the loop's."""
        real = self.config.clock == "real"
        if self.remote is not None:
            loop = self.remote.loop
            loop.progress = progress
            try:
                return loop.link.job(job, kwargs, timeout_s=600.0)
            finally:
                loop.progress = None
                loop.pump()  # the status after the job: its ticks and records
                self.cursor = self.ring.write_count
                self.after_loop_pause(False)
        assert self.local is not None
        if real:
            self.loop.stop(timeout_s=5.0)  # ramps the force to zero first
        elif not JOBS[job].ticks_the_loop:
            self.loop.ramp_down()
        self.drain_ring()
        try:
            return JOBS[job].run(self.local, progress or (lambda done, total: None), **kwargs)
        finally:
            self.cursor = self.ring.write_count
            self.after_loop_pause(real)

    def after_loop_pause(self, restart: bool) -> None:
        """The loop ran the rig for a calibration step: restart its timing statistics (and its thread)."""
        self.reader.restart_stats(self.loop.tick_count + 1)
        self.pacer.reanchor()
        if restart:
            if self.tracer is not None:
                self.tracer.restart()
            self.loop.start()

    def quiet_wait_s(self, interval_s: float) -> float:
        """Seconds to wait to wake just after a loop tick, about ``interval_s`` from now (real clock; see
        :meth:`study_app.engine.pacing.LoopPacer.quiet_wait_s`)."""
        return self.pacer.quiet_wait_s(interval_s, self.last_t_ns)

    def drain_ring(self) -> None:
        """Read the loop's new records: the timing statistics, the commissioning chain, the running session."""
        if self.remote is not None:
            self.remote.loop.pump()  # the loop's events and replay log first: then its records up to them
        self.reader.drain()

    def health(self) -> m.Health:
        """The engine's state and loop timing since the last stats reset."""
        return self.reports.health(self.sessions.runner, driver=self.driver_name, loop_dead=self.loop_dead)

    def _on_loop_event(self, ev: LoopEvent) -> None:
        # called from the loop thread: only hand the event on (to the GUI, and to the runner for the record)
        self.reader.driver.on_loop_event(ev)  # for the runner: taken by the driver thread (a deque's ops are atomic)
        self.publish(fault_event(ev, self.sessions.runner, len(self.eng.calibrations) > 1))

    def _drain_jaws(self) -> None:
        """Every jaw command carried out: to the display (the first arm's), and into the running session's events."""
        runner, recorder = self.sessions.runner, self.sessions.recorder

        def store(text: str) -> None:
            if runner is not None and recorder is not None and not runner.done:
                recorder.event(runner.session_id, runner.session_time_s(self.last_t_ns), "jaw", text)

        self.jaws.drain(store)

    # -- commands -------------------------------------------------------------------------------------
    def handle(self, cmd: object) -> None:
        """Apply one command; anything that cannot be done is answered with :class:`CommandRefused`."""
        name = type(cmd).__name__
        try:
            apply = self._commands.get(type(cmd))
            if apply is None:
                raise ValueError(f"unknown command {cmd!r}")
            apply(cmd)
        except (StorageError, ProtocolError, ValueError, RuntimeError) as exc:
            self.publish(m.CommandRefused(name, str(exc)))

    def _command_table(self) -> dict[type, Callable[[Any], None]]:
        """Which room applies which command (the sessions, the commissioning chain, the jaws, the engine itself)."""
        s, c = self.sessions, self.commissioning
        return {
            m.StartSession: s.start, m.ResumeSession: s.resume, m.InjectFault: s.inject_fault,
            m.ListSessions: s.list_sessions, m.ParticipantScreenState: s.participant_screen,
            m.Pause: s.control, m.Resume: s.control, m.AbortTrial: s.control, m.AbortSession: s.control,
            m.Note: s.note, m.AnswerQuestionnaire: s.answer, m.SkipQuestionnaire: s.skip_questionnaire,
            m.AnswerTrial: s.answer_trial,
            m.ResetFaults: self._reset_faults,
            m.OperatorStop: lambda cmd: self.loop.submit(LoopOperatorStop()),
            m.Calibrate: c.calibrate, m.RecordPose: c.record_pose, m.IdentifyPoses: c.identify,
            m.CalibrateTcp: c.calibrate_tcp, m.RecordPivot: c.record_pivot,
            m.IdentifyTcp: c.identify_tcp, m.CheckFrames: c.check_frames,
            m.RecordFrameAxis: c.record_frame_axis, m.JawCommand: self.jaws.command,
            m.SetDriver: self._driver_command, m.ManualTarget: self._driver_command,
            m.ResetStats: self._reset_stats,
        }

    def _reset_faults(self, cmd: m.ResetFaults) -> None:
        self._require_loop("reset faults")
        self.loop.submit(LoopResetFaults())

    def _driver_command(self, cmd: m.SetDriver | m.ManualTarget) -> None:
        if self.real:
            raise RuntimeError("real rig: a person holds the stylus; the simulated participant and manual "
                               "driving exist on the simulated rig only")
        if isinstance(cmd, m.SetDriver):
            self.driver.set_mode(cmd.mode)
            self.publish(self.health())
        else:
            self.driver.set_manual_y(cmd.y_m)

    def _reset_stats(self, cmd: m.ResetStats) -> None:
        self.reader.stats.reset()
        if self.tracer is not None:
            self.tracer.reset()
