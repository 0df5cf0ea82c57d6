"""The study engine: rig + 1 kHz loop + session runner + recorder, in a process of its own (no Qt).

Why a separate process: a Qt window painting curves in the loop's process
holds the GIL for milliseconds per curve and breaks the 1 kHz loop
(science.md §7).  The GUI therefore only talks to this process:

* commands (:mod:`study_app.engine.messages`) arrive over a pipe and are applied by
  one driver thread, so session state has a single owner;
* events are published on a queue (trial started/ended with metrics, phases,
  faults, health, calibration results);
* samples go through the shared-memory :class:`pipeline.runtime.ring.RingBuffer` the
  loop writes and the GUI pulls from at ~30 Hz.

If the pipe breaks (the GUI closed or crashed) the engine latches
``ENGINE_DETACHED`` (the force ramps to zero), aborts the running trial so its
row is stored with the reason (the session stays resumable), commits, and exits.

:class:`StudyEngine` is usable in-process on a virtual clock (tests);
:func:`host_main` is the process entry point, started by
:class:`study_app.engine.client.EngineClient`.
"""

from __future__ import annotations

import math
import queue
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from pipeline.assembly.engine import Engine
from pipeline.core.clock import MonotonicClock, collect_garbage, manual_garbage_collection, prepare_helper_thread
from pipeline.devices.interfaces import DeviceError
from pipeline.force.frames import as_mat3
from pipeline.force.payload_compensator import PayloadCalibration
from pipeline.runtime.jitter_trace import LateTickTracer
from pipeline.runtime.loop_messages import ControllerDetached, LoopEvent
from pipeline.runtime.loop_messages import OperatorStop as LoopOperatorStop
from pipeline.runtime.loop_messages import ResetFaults as LoopResetFaults
from pipeline.runtime.supervisor import LoopSupervisor
from pipeline.settings.hardware import HardwareConfig
from protocol.runner.session import SessionRunner
from protocol.runner.session_driver import SessionDriver
from protocol.storage import Recorder, StorageError, new_owner_token
from protocol.study.config import ProtocolError
from protocol.study.trial import TrialPhase
from study_app.engine import messages as m
from study_app.engine.commissioning import Commissioning
from study_app.engine.jaws import arm_jaws, other_arm_jaw_events
from study_app.engine.period_stats import PeriodStats
from study_app.engine.session_list import list_sessions, list_withdrawn
from study_app.engine.sessions import EngineSessions, list_resumable
from study_app.engine.setup import HostConfig, SwitchableDriver, build_engine

__all__ = ["QUIET_OFFSET_NS", "StudyEngine", "host_main"]

#: The driver thread wakes this long after a loop tick starts (a tick takes ~50 µs): see StudyEngine.quiet_wait_s.
QUIET_OFFSET_NS = 150_000


class StudyEngine:
    """Owns the rig, the loop and the driver thread's work; applies commands; publishes events.

    The session being run is :attr:`sessions` (:class:`study_app.engine.sessions.EngineSessions`),
    the calibration steps and the real rig's gate are :attr:`commissioning`
    (:class:`study_app.engine.commissioning.Commissioning`); this class keeps the
    lifetime, the dispatch of commands and the loop's records, events and health.

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
        self.eng: Engine
        self.hardware: HardwareConfig | None
        self.eng, self.hardware, self.hardware_text = build_engine(
            config, self.driver, shared_ring=shared_ring, on_open=lambda device: publish(m.EngineOpening(device)))
        self.calibration: PayloadCalibration = self.eng.calibration
        assert self.eng.ring is not None
        self.ring = self.eng.ring
        self.loop = self.eng.loop
        #: Reads the ring from here on and feeds the running session (the loop's events and replay log with it).
        #: The other arms' rings are read too (a rig of several arms): a session records every arm, as run's do.
        others = tuple((name, rg, self.loop.arm(name).replay_log) for name, rg in self.eng.rings.items()
                       if rg is not None and rg is not self.ring)
        self.ring_driver = SessionDriver(self.ring, self.loop.replay_log, others)
        self.loop.on_event = self._on_loop_event
        self.tracer: LateTickTracer | None = None
        if config.trace_jitter and config.clock == "real":
            self.tracer = LateTickTracer(MonotonicClock())
            self.loop.clock = self.tracer
        self.stats = PeriodStats()
        #: This engine's lease token (one per engine process).
        self.lease_owner = new_owner_token()
        self._last_health = 0.0
        self._anchor_wall = time.monotonic()
        self._anchor_ticks = 0
        self._ticks_run = 0
        self._running = False
        self.last_t_ns = 0
        self._stats_from_tick = 0
        self.closed = False
        #: Watches the loop thread and its tick counter (real clock; the virtual clock runs the loop in step()).
        self.supervisor = LoopSupervisor(self.loop)
        #: Why the haptic loop died ("" while it runs): nothing that needs the loop can be done any more.
        self.loop_dead = ""
        #: The session being run (at most one), and the commissioning chain (calibration steps, the real rig's gate).
        self.commissioning = Commissioning(self)
        self.sessions = EngineSessions(self, self.commissioning)
        jaws = arm_jaws(self.eng, self.hardware, self.commissioning.devices)
        #: The first arm's jaw (the simulated one, or the Arduino of the hardware file): the window's jaw box drives
        #: it too; None: there is none.  The other arms' jaws follow their own stylus buttons only.
        self.jaw = jaws.pop(self.commissioning.arms[0], None)
        self.other_jaws = jaws
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
        return self.ring_driver.cursor

    @cursor.setter
    def cursor(self, value: int) -> None:
        self.ring_driver.cursor = value

    # -- lifetime -------------------------------------------------------------------------------
    def start(self) -> None:
        """Start the loop (its own thread on the real clock) and announce the engine."""
        if self.config.clock == "real":
            self.loop.start()
        self._running = True
        if self.eng.simulated:
            rc = self.eng.rig.config
            surface_z_m, tip_home_m, rot_tip_sensor = rc.surface_z_m, tuple(rc.tip_home_m), rc.rot_tip_sensor
        else:
            surface_z_m, tip_home_m = math.nan, (math.nan, math.nan, math.nan)
            rot_tip_sensor = self.eng.framework.config.rot_tip_sensor
        self.publish(m.EngineReady(
            ring_name=self.ring.name or "", rig=self.config.rig, clock=self.config.clock,
            calibration=self.calibration.to_dict(), surface_z_m=surface_z_m,
            tip_home_m=tip_home_m, driver=self.driver_name,
            rot_tip_sensor=as_mat3(rot_tip_sensor),
            devices=self._device_summary(),
            arm_rings=tuple((n, r.name or "") for n, r in self.eng.rings.items() if r is not None)
            if len(self.eng.rings) > 1 else (),
            arm_mounts=tuple((n, as_mat3(fw.config.rot_tip_sensor)) for n, fw in self.eng.frameworks.items())
            if len(self.eng.frameworks) > 1 else (),
        ))
        self.commissioning.publish_status()
        for ctl in self.other_jaws.values():
            ctl.start()
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
        for ctl in (self.jaw, *self.other_jaws.values()):
            if ctl is not None:
                ctl.close()
        self.drain_ring()
        try:
            self.eng.rig.close()
        except DeviceError as exc:  # the force is already zero; say what did not close cleanly
            reason = f"{reason}; {exc}"
        self.closed = True
        self.publish(m.EngineStopped(reason, self.stats.summary()))

    def release_ring(self) -> None:
        """Free the shared rings, every arm's (after the GUI had a chance to copy the last records)."""
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
            try:
                self.loop.run_ticks(n)
            except Exception as exc:  # the loop died in this thread: make safe, report, store
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
        self.drain_ring()
        if any(ctl.events for ctl in (self.jaw, *self.other_jaws.values()) if ctl is not None):
            self._drain_jaw()
        now = time.monotonic()
        if now - self._last_health >= self.config.health_period_s:
            self._last_health = now
            if self.tracer is not None:
                self.tracer.refresh()
            self.publish(self.health())

    def _store_loop_events(self) -> None:
        """Hand the pending loop events to the session runner without records (the loop writes none)."""
        runner = self.sessions.runner
        if runner is not None:
            self.ring_driver.flush_events(runner)

    def _loop_died(self, why: str) -> None:
        """The haptic loop is dead (its fault is latched and reported): store it, leave the session resumable."""
        self.loop_dead = why
        self.drain_ring()  # the records it wrote before it died
        self._store_loop_events()
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
        last_tick = self.loop.t0_ns + self.last_t_ns
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

    def drain_ring(self) -> None:
        """Read the loop's new records: the timing statistics, the commissioning chain, the running session."""
        block = self.ring_driver.take()
        rows = block.rows
        if len(rows):
            if self._stats_from_tick:
                # the first tick after a calibration carries the calibration's gap: not a loop overrun
                keep = rows["tick"] >= self._stats_from_tick
                self.stats.add(rows["period_ns"][keep] * 1e-9)
            else:
                self.stats.add(rows["period_ns"] * 1e-9)
            self.last_t_ns = int(rows["t_ns"][-1])
            self.commissioning.feed(rows)
        elif not block.lost:
            return
        runner = self.sessions.runner
        if runner is None:
            return
        self.ring_driver.feed(runner, block, self.sessions.trigger)
        if runner.done:
            self.sessions.end(runner.status, runner.stop_reason)

    def health(self) -> m.Health:
        """The engine's state and loop timing since the last stats reset."""
        s = self.stats.summary()
        runner = self.sessions.runner
        return m.Health(
            loop_rate_hz=s["rate_hz"], period_p50_us=s["period_p50_us"], period_p99_us=s["period_p99_us"],
            abs_dev_p99_us=s["abs_dev_p99_us"], periods_over_2ms=int(s["periods_over_2ms"]),
            missed_slots=int(self.loop.stats.missed_slots), ticks=int(s["ticks"]), faults=int(self.loop.faults),
            haptic_on=bool(self.loop.haptic_on), driver=self.driver_name,
            session_running=runner is not None and not runner.done, paused=bool(runner is not None and runner.paused),
            abs_dev_p50_us=s["abs_dev_p50_us"], period_max_us=s["period_max_us"],
            late_periods=None if self.tracer is None else self.tracer.summary(),
            waiting=runner.state.waiting if runner is not None and not runner.done else "",
            scheduling=self.loop.scheduling if self.config.clock == "real" else "virtual clock",
            **self._health_extra(),
        )

    def _on_loop_event(self, ev: LoopEvent) -> None:
        # called from the loop thread: only hand the event on (to the GUI, and to the runner for the record)
        self.ring_driver.on_loop_event(ev)  # for the runner: taken by the driver thread (a deque's ops are atomic)
        runner = self.sessions.runner
        session_t = math.nan
        if runner is not None and not runner.done and runner.clock is not None:
            session_t = runner.session_time_s(ev.t_ns)  # what the events table will say
        # a rig of several arms: the arm named, as the events table stores it (protocol.runner.session)
        detail = f"arm {ev.arm}: {ev.detail}" if len(self.eng.calibrations) > 1 else ev.detail
        self.publish(m.EngineFault(ev.t_ns * 1e-9, ev.kind, int(ev.faults), detail, session_t))

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
        """Which object applies which command (the sessions, the commissioning chain, the engine itself)."""
        s, c = self.sessions, self.commissioning
        return {
            m.StartSession: s.start, m.ResumeSession: s.resume, m.InjectFault: s.inject_fault,
            m.ListSessions: lambda cmd: self.publish(m.SessionsListed(
                cmd.db_path, list_resumable(cmd.db_path), list_sessions(cmd.db_path, check=False),
                list_withdrawn(cmd.db_path))),
            m.Pause: self._session_command, m.Resume: self._session_command, m.AbortTrial: self._session_command,
            m.AbortSession: self._session_command,
            m.ResetFaults: self._reset_faults,
            m.OperatorStop: lambda cmd: self.loop.submit(LoopOperatorStop()),
            m.Calibrate: self._calibrate, m.RecordPose: c.record_pose, m.IdentifyPoses: c.identify,
            m.CalibrateTcp: lambda cmd: c.calibrate_tcp(cmd.pose_set, cmd.arm), m.RecordPivot: c.record_pivot,
            m.IdentifyTcp: c.identify_tcp, m.CheckFrames: lambda cmd: c.check_frames(cmd.arm),
            m.RecordFrameAxis: c.record_frame_axis, m.JawCommand: self._jaw_command,
            m.SetDriver: self._driver_command, m.ManualTarget: self._driver_command,
            m.ResetStats: self._reset_stats,
        }

    def _reset_faults(self, cmd: m.ResetFaults) -> None:
        self._require_loop("reset faults")
        self.loop.submit(LoopResetFaults())

    def _session_command(self, cmd: m.Pause | m.Resume | m.AbortTrial | m.AbortSession) -> None:
        runner = self.sessions.runner
        if runner is None or runner.done:
            raise RuntimeError("no session is running")
        if isinstance(cmd, m.Pause):
            runner.pause()
        elif isinstance(cmd, m.Resume):
            runner.resume()
        elif isinstance(cmd, m.AbortTrial):
            if cmd.trial_index is not None and runner.trial_ended(cmd.trial_index):
                # confirmed for a trial that has ended since: never abort the next one instead
                raise RuntimeError(f"trial {cmd.trial_index + 1} had already ended: nothing was aborted")
            if runner.running_trial is None:
                raise RuntimeError("no trial is running (between trials or paused)")
            runner.abort_trial(cmd.reason, trial_index=cmd.trial_index)
        else:
            if cmd.session_id is not None and cmd.session_id != runner.session_id:
                raise RuntimeError(f"session {cmd.session_id} had already ended: nothing was aborted")
            runner.abort_session(cmd.reason)

    def _calibrate(self, cmd: m.Calibrate) -> None:
        if self.real:
            raise RuntimeError("real rig: the poses are recorded one at a time in the calibration wizard "
                               "(move the robot, then Record pose)")
        self.commissioning.calibrate(cmd.pose_set, cmd.arm)

    def _jaw_command(self, cmd: m.JawCommand) -> None:
        if self.jaw is None:
            raise RuntimeError("jaw: no jaw actuator on this rig (add a [jaw] table to the hardware file)")
        self.jaw.submit(cmd.action)

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
        self.stats.reset()
        if self.tracer is not None:
            self.tracer.reset()


    def require_idle(self, what: str) -> None:
        self._require_loop(what)
        if self.sessions.runner is not None and not self.sessions.runner.done:
            raise RuntimeError(f"{what}: a session is running (end or abort it first)")

    def after_loop_pause(self, restart: bool) -> None:
        """The loop ran the rig for a calibration step: restart its timing statistics (and its thread)."""
        self.stats.reset()
        self._stats_from_tick = self.loop.tick_count + 1
        self._reanchor()
        if restart:
            if self.tracer is not None:
                self.tracer.restart()
            self.loop.start()

    # -- health extras, the jaw ------------------------------------------------------------------------
    def _health_extra(self) -> dict[str, Any]:
        haptic = self.eng.rig.haptic
        st = haptic.read_state()
        return {"haptic_heat_fraction": float(st.heat_fraction), "haptic_force_limit_n": float(st.force_limit_n),
                "haptic_peak_force_n": float(haptic.peak_force_n),
                "haptic_continuous_force_n": float(haptic.continuous_force_n), "loop_dead": self.loop_dead,
                "arms": self._arm_health()}

    def _arm_health(self) -> tuple[tuple[str, float, int], ...]:
        """A rig of several arms: each arm's largest task force over its newest 50 ms and its latched faults."""
        if len(self.eng.calibrations) < 2:
            return ()
        out = []
        for name, ring in self.eng.rings.items():
            rows = ring.latest(50) if ring is not None else None
            force = float(np.nanmax(np.abs(rows["force_n"]))) if rows is not None and len(rows) else math.nan
            out.append((name, force, int(self.loop.arm(name).faults)))
        return tuple(out)

    def _publish_jaw(self, last: str) -> None:
        assert self.jaw is not None
        s = self.jaw.jaw.status
        self.publish(m.JawState(float(s.fraction_open), int(s.pos_us), bool(s.at_limit), str(s.fault), last))

    def _drain_jaw(self) -> None:
        """Every jaw command carried out: to the display (the first arm's), and into the running session's events."""
        runner, recorder = self.sessions.runner, self.sessions.recorder

        def store(text: str) -> None:
            if runner is not None and recorder is not None and not runner.done:
                recorder.event(runner.session_id, runner.session_time_s(self.last_t_ns), "jaw", text)

        for text in other_arm_jaw_events(self.other_jaws):
            store(text)
        while self.jaw is not None and self.jaw.events:
            ev = self.jaw.events.popleft()
            text = f"{ev.source}: {ev.detail}"
            store(text)
            self.publish(m.JawState(ev.fraction_open, ev.pulse_us, ev.at_limit, ev.fault, text))


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
    except Exception as exc:  # reported to the GUI as one line
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
