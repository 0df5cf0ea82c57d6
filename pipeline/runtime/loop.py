"""The 1 kHz haptic loop: one thread that owns the devices, paced by absolute deadlines.

Each tick:

1. advance the rig (simulated physics; a no-op on hardware) and apply queued commands;
2. read the newest F/T sample, robot pose (held between its 125 Hz updates) and stylus state;
3. watchdog: stale sensor (> 5 ms) or pose (> 50 ms), non-finite values, a bad
   sensor status, saturation, a haptic-device error → latch a fault;
4. run Algorithm 1 (:class:`pipeline.force.framework.HapticFramework`); the safety
   stage ramps the output to zero within 50 ms while a fault is latched or
   feedback is off;
5. command the haptic device and append one record with every stage to the ring buffer
   (with ``latency_ns``: from the F/T sample's arrival to the moment the force command was handed over,
   on the loop's clock -- on a virtual clock, where computing takes no time, the sample's age).

The loop does only I/O and arithmetic: no logging, no allocation beyond a
few tuples, no locks.  Commands arrive through a deque (thread-safe append /
popleft) and are applied at the start of the next tick.  Faults are latched
until :class:`ResetFaults` clears them -- and a reset only clears conditions
that have gone away.  Whenever the latched set changes the rig's optional
``on_faults`` hook is called (a teleoperated robot stops; see :class:`pipeline.devices.rig.Rig`).
Every latch (with the value that tripped it), every condition that goes away
while latched, and every reset is a :class:`LoopEvent` for the record.

**When the loop itself fails.**  The haptic device renders a command only
while it is fresh (its own watchdog, :mod:`pipeline.devices.touch_output`): a loop
that dies or freezes leaves no force on the hand.  A tick that comes later
than the device's command timeout restarts the output from zero (no kick
back to the old force); one later than ``WatchdogConfig.loop_stall_s`` (50 ms)
latches ``LOOP_STALLED``.  The zero command at the end of :meth:`HapticLoop.ramp_down`
is issued whatever went wrong before it, and a loop thread that dies keeps
its exception in :attr:`HapticLoop.crash` for whoever watches it
(:class:`pipeline.runtime.supervisor.LoopSupervisor`).

**Thermal derating.**  The device reports the force it may render now
(``HapticState.force_limit_n``, lowered as its motors warm); the loop clamps
the safety stage to it and records, per tick, the fraction of the designed
(scaled) force it could render (``derate``, 1 when not limited), which the
session runner checks.  Derating starting and ending are events.
"""

from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING

from pipeline.devices.interfaces import Fault, HapticState, PoseSample, WrenchSample
from pipeline.devices.rig import Rig
from pipeline.devices.touch_output import DEFAULT_COMMAND_TIMEOUT_S
from pipeline.force.framework import HapticFramework
from pipeline.runtime.clock import Clock, prepare_realtime_thread
from pipeline.runtime.loop_messages import (
    RECORD_FIELDS,
    AllowBiasRefinement,
    Command,
    ControllerDetached,
    LatchFault,
    LoopEvent,
    Mark,
    OperatorStop,
    ResetFaults,
    SetCalibration,
    SetHaptics,
    StartRecording,
    StopRecording,
)
from pipeline.runtime.loop_stats import LoopStats
from pipeline.runtime.pacing import PacedTicks
from pipeline.runtime.watchdog import (
    WatchdogConfig,
    derating_detail,
    derating_ended_detail,
    fault_detail,
    output_restarted_detail,
    stall_detail,
)

if TYPE_CHECKING:
    from pipeline.runtime.ring import RingBuffer

# The commands, events, record columns, statistics and watchdog limits are defined in
# pipeline.runtime.loop_messages, pipeline.runtime.loop_stats and pipeline.runtime.watchdog; they are named here
# too because the loop's callers import them from this module.  The devices the loop
# owns are pipeline.devices.rig.Rig.
__all__ = [
    "HapticLoop",
]

_NAN3 = (math.nan, math.nan, math.nan)
_HYPOT = math.hypot


class HapticLoop(PacedTicks):
    """Runs the rig and Algorithm 1 at a fixed rate and records every tick.

    Parameters
    ----------
    rig
        Devices (real or simulated).
    framework
        The force path (calibration, filter, rotations, scaling, safety).
    clock
        Time source; :class:`pipeline.runtime.clock.VirtualClock` for deterministic runs.
    ring
        Where each tick's record goes (anything with ``write(values)``), or None.
    period_ns
        Tick period (1 ms).
    watchdog
        Age/range limits.
    on_event
        Called (from the loop thread) for faults and resets; keep it cheap.
    """

    def __init__(
        self,
        rig: Rig,
        framework: HapticFramework,
        clock: Clock,
        ring: RingBuffer | None = None,
        *,
        period_ns: int = 1_000_000,
        watchdog: WatchdogConfig | None = None,
        on_event: Callable[[LoopEvent], None] | None = None,
    ) -> None:
        self.rig = rig
        self.framework = framework
        self.clock = clock
        self.ring = ring
        self.period_ns = int(period_ns)
        self.watchdog = watchdog or WatchdogConfig()
        self.on_event = on_event
        self.events: deque[LoopEvent] = deque(maxlen=1000)
        self.stats = LoopStats(self.period_ns)
        self._inbox: deque[Command] = deque()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        #: How the loop thread is scheduled once :meth:`start` ran (``"SCHED_FIFO/20"`` or why not).
        self.scheduling = "not started"
        self.tick_count = 0
        self.haptic_on = False
        self.trial_index = -1
        self.phase = 0
        self.faults = 0  # latched
        self.active_faults = 0  # this tick's conditions
        self._gone_reported = 0  # latched faults whose condition was reported gone
        self.refine_bias = False
        self._last_ns: int | None = None
        #: Clock reading of the first tick; records carry time since then
        #: (``t_ns`` exact in float64 for 104 days, ``t_s`` in seconds).
        self.t0_ns = 0
        self._pose_t_ns: int | None = None
        self._sensor_age_ns = int(self.watchdog.sensor_max_age_s * 1e9)
        self._pose_age_ns = int(self.watchdog.pose_max_age_s * 1e9)
        rng = rig.sensor.range_n
        frac = self.watchdog.saturation_fraction
        self._sat = tuple(frac * r for r in rng)
        self._last_record: tuple[float | int, ...] | None = None
        #: What replay needs beyond the records, while recording (see :class:`StartRecording`); its reader drains it.
        self.replay_log: deque[tuple[int, str, object]] = deque()
        self.recording = False
        self._snapshot_due: int | None = None
        # optional rig hooks (see Rig); resolved once so the tick pays nothing for them
        self._rig_on_faults: Callable[[Fault], None] | None = getattr(rig, "on_faults", None)
        self._rig_stop_motion: Callable[[str], None] | None = getattr(rig, "stop_motion", None)
        #: The loop thread's exception if it died (``repr``), else "".
        self.crash = ""
        self._stall_ns = int(self.watchdog.loop_stall_s * 1e9)
        timeout_s = getattr(rig.haptic, "command_timeout_s", None)
        #: The device drops a command older than this (its own watchdog); a later tick restarts from zero.
        self.command_timeout_ns = int((timeout_s if timeout_s is not None else DEFAULT_COMMAND_TIMEOUT_S) * 1e9)
        self._resync = True  # the next tick's period is not a stall (first tick, or after a ramp-down)
        self._peak_n = float(rig.haptic.peak_force_n)
        self._device_limit_n = math.inf  # the device's derated force limit as last seen
        self._derating = False
        self._derate_check = False  # the thermal limit is below the safety stage's own: measure what it cuts

    # -- control (any thread) ----------------------------------------------------------------
    def submit(self, command: Command) -> None:
        """Queue a command; applied at the start of the next tick."""
        self._inbox.append(command)

    @property
    def last_record(self) -> dict[str, float | int] | None:
        """The newest record as a dict (for tests and status displays)."""
        r = self._last_record
        return None if r is None else dict(zip(RECORD_FIELDS, r, strict=True))

    # -- one tick -----------------------------------------------------------------------------
    def tick(self) -> None:
        """Run one cycle at the clock's current time."""
        now = self.clock.now_ns()
        last = self._last_ns
        if last is None:
            self.t0_ns = now
            period = self.period_ns
        else:
            period = now - last
            self.stats.add(period)
        self._last_ns = now
        dt_s = period * 1e-9
        rig = self.rig
        rig.advance(now)
        if self._inbox or period > self.command_timeout_ns or self._snapshot_due is not None:
            self._start_of_tick(now, period)
        self._resync = False

        w = rig.sensor.read_wrench()
        pose = rig.robot.read_pose()
        hs = rig.haptic.read_state()
        fw = self.framework

        # -- watchdog --
        cond = 0
        _, fx, fy, fz, tx, ty, tz = w[:7]
        sensor_age = now - w.t_ns
        if sensor_age > self._sensor_age_ns:
            cond |= Fault.SENSOR_STALE
        if w.status:
            cond |= Fault.SENSOR_STATUS
        if (fx - fx) + (fy - fy) + (fz - fz) + (tx - tx) + (ty - ty) + (tz - tz) != 0.0:
            cond |= Fault.NON_FINITE
        else:
            s = self._sat
            if (abs(fx) > s[0] or abs(fy) > s[1] or abs(fz) > s[2]
                    or abs(tx) > s[3] or abs(ty) > s[4] or abs(tz) > s[5]):
                cond |= Fault.SENSOR_SATURATION
        pose_age = now - pose.t_ns
        if pose_age > self._pose_age_ns:
            cond |= Fault.POSE_STALE
        if pose.t_ns != self._pose_t_ns:  # a new robot pose (125 Hz)
            cond |= self._take_pose(pose)
        if hs.error_code:
            cond |= Fault.HAPTIC_DEVICE
        if hs.force_limit_n != self._device_limit_n:  # the device derates (rare; a compare per tick otherwise)
            self._device_limit(now, hs)
        latched = self.faults
        if cond != self.active_faults or cond & ~latched:  # (fault-free steady state: both false)
            latched = self._conditions_changed(cond, now, w, pose, hs, sensor_age, pose_age)

        if self.refine_bias and not latched:
            fw.refine_bias(fx, fy, fz, tx, ty, tz)

        enabled = self.haptic_on and not latched
        (comp_fx, comp_fy, comp_fz, filt_fx, filt_fy, filt_fz, tip_fx, tip_fy, tip_fz, base_fx, base_fy, base_fz,
         haptic_fx, haptic_fy, haptic_fz, scaled_fx, scaled_fy, scaled_fz, render_fx, render_fy, render_fz,
         ) = fw.step(fx, fy, fz, enabled, dt_s)  # the stages of pipeline.runtime.tick_record.STEP_FIELDS, by name
        # stamped with this tick's time: should the tick have frozen half-way, the device drops the old force
        rig.haptic.command_force(render_fx, render_fy, render_fz, now)
        derate = self._derate(scaled_fx, scaled_fy, scaled_fz) if self._derate_check and enabled else 1.0
        # sample arrival to command hand-over on the loop's clock (on a virtual clock: the sample's age)
        latency_ns = self.clock.now_ns() - w.t_ns
        true_fx, true_fy, true_fz = rig.true_contact_force() or _NAN3
        tip_x_m, tip_y_m, tip_z_m = pose.position_m
        stylus_x_m, stylus_y_m, stylus_z_m = hs.position_m
        t_ns = now - self.t0_ns
        # one record, in pipeline.runtime.tick_record.TICK_FIELDS' order (the ring refuses a float for an int64)
        rec = (
            self.tick_count, t_ns, period, fx, fy, fz, tx, ty, tz, sensor_age, pose_age, latency_ns, latched,
            1 if self.haptic_on else 0, self.trial_index, self.phase, fw.safety.gain, render_fx, render_fy, render_fz,
            _HYPOT(filt_fx, filt_fy, filt_fz), stylus_x_m, stylus_y_m, stylus_z_m, derate, t_ns * 1e-9, comp_fx,
            comp_fy, comp_fz, filt_fx, filt_fy, filt_fz, tip_fx, tip_fy, tip_fz, base_fx, base_fy, base_fz, haptic_fx,
            haptic_fy, haptic_fz, scaled_fx, scaled_fy, scaled_fz, tip_x_m, tip_y_m, tip_z_m, true_fx, true_fy, true_fz,
        )
        self._last_record = rec
        if self.ring is not None:
            self.ring.write(rec)
        self.tick_count += 1

    def _start_of_tick(self, now: int, period: int) -> None:
        """Apply the queued commands, restart the output after a late tick, take a due replay snapshot.

        Rare work, so :meth:`tick` calls this only when one of the three is due (the same three tests it
        would make itself).
        """
        inbox = self._inbox
        while inbox:
            self._apply(inbox.popleft(), now)
        if period > self.command_timeout_ns and not self._resync:
            self._late_tick(now, period)
        if self._snapshot_due is not None:
            self._take_snapshot()

    def _take_pose(self, pose: PoseSample) -> int:
        """Hand a new robot pose to the framework; a non-finite one is refused: ``Fault.NON_FINITE``, else 0."""
        rot = pose.rot_base_tip
        if all(v - v == 0.0 for v in rot) and all(v - v == 0.0 for v in pose.position_m):
            self._pose_t_ns = pose.t_ns
            self.framework.set_pose(rot)
            if self.recording:
                self.replay_log.append((self.tick_count, "pose", (rot, pose.position_m, pose.t_ns)))
            return 0
        return Fault.NON_FINITE

    def _conditions_changed(
        self, cond: int, now: int, w: WrenchSample, pose: PoseSample, hs: HapticState, sensor_age: int, pose_age: int,
    ) -> int:
        """This tick's fault conditions differ from the last tick's: latch the new ones, report the gone ones.

        Returns the latched set.
        """
        prev = self.active_faults
        self.active_faults = cond
        latched = self.faults
        new = cond & ~latched
        if new:
            # a plain int, not a Fault: IntFlag's ~ and & run in Python (~1 µs per tick)
            latched = int(latched | new)
            self.faults = latched
            self._gone_reported &= ~new
            self._faults_changed(now)
            self._emit(LoopEvent(now - self.t0_ns, "fault", latched,
                                 fault_detail(new, w, pose, hs, sensor_age, pose_age, self.watchdog, self._sat)))
        if cond != prev:
            gone = latched & prev & ~cond & ~self._gone_reported
            if gone:
                self._gone_reported |= gone
                self._emit(LoopEvent(now - self.t0_ns, "fault_cleared", latched,
                                     f"{Fault(gone).describe()}: the condition is gone (latched until a reset)"))
        return latched

    def _derate(self, scaled_fx: float, scaled_fy: float, scaled_fz: float) -> float:
        """The fraction of the designed force (scaled, within the safety stage's own limit) the derated limit lets
        through.

        Only asked while the thermal limit is below the safety stage's own (and feedback is enabled).
        """
        want = _HYPOT(scaled_fx, scaled_fy, scaled_fz)
        safety = self.framework.safety
        lim = safety.limit_n
        if want > lim:
            designed = want if want < safety.static_limit_n else safety.static_limit_n
            return lim / designed
        return 1.0

    def _late_tick(self, now: int, period: int) -> None:
        """This tick came after the device's command watchdog dropped the force: restart from zero; latch a stall."""
        self.framework.safety.force_zero()  # the device renders zero now: ramp in from there, never jump back
        if self.recording:
            self.replay_log.append((self.tick_count, "zero", "late_tick"))
        t = now - self.t0_ns
        if period > self._stall_ns:
            if not self.faults & Fault.LOOP_STALLED:
                self._latch(Fault.LOOP_STALLED, now)
                self._emit(LoopEvent(t, "fault", self.faults,
                                     stall_detail(period, self.watchdog, self.command_timeout_ns)))
        else:
            self._emit(LoopEvent(t, "output_restarted", self.faults,
                                 output_restarted_detail(period, self.command_timeout_ns)))

    def _device_limit(self, now: int, hs: HapticState) -> None:
        """The device changed the force it may render (thermal derating): clamp to it; report derating."""
        lim = float(hs.force_limit_n)
        self._device_limit_n = lim
        safety = self.framework.set_device_limit(lim)
        if self.recording:
            self.replay_log.append((self.tick_count, "device_limit", lim))
        self._derate_check = safety.limit_n < safety.static_limit_n
        frac = float(hs.heat_fraction)
        t = now - self.t0_ns
        if not self._derating and lim < self._peak_n:
            self._derating = True
            cont = float(getattr(self.rig.haptic, "continuous_force_n", math.nan))
            self._emit(LoopEvent(t, "derating", self.faults, derating_detail(frac, self._peak_n, cont)))
        elif self._derating and lim >= self._peak_n:
            self._derating = False
            self._emit(LoopEvent(t, "derating_ended", self.faults, derating_ended_detail(frac, lim)))

    def _apply(self, cmd: Command, now: int) -> None:
        if isinstance(cmd, Mark):
            self.trial_index = int(cmd.trial_index)  # int64 fields of the record
            self.phase = int(cmd.phase)
        elif isinstance(cmd, SetHaptics):
            self.haptic_on = bool(cmd.on)
        elif isinstance(cmd, ResetFaults):
            before = self.faults
            # Only conditions that are gone can be cleared; the operator
            # stop and device errors are cleared by the reset itself.
            persisting = self.active_faults & ~(Fault.OPERATOR_STOP | Fault.HAPTIC_DEVICE)
            if before & Fault.HAPTIC_DEVICE and not self.rig.haptic.rearm():
                persisting |= Fault.HAPTIC_DEVICE
            self.faults = int(persisting)
            self._gone_reported &= persisting
            if before and not persisting:
                self.framework.reset()
                if self.recording:
                    self.replay_log.append((self.tick_count, "reset", None))
            if persisting != before:
                self._faults_changed(now)
            self._emit(LoopEvent(now - self.t0_ns, "faults_reset", persisting, Fault(before).describe()))
        elif isinstance(cmd, OperatorStop):
            self._latch(Fault.OPERATOR_STOP, now)
            self._emit(LoopEvent(now - self.t0_ns, "fault", self.faults,
                                 "OPERATOR_STOP: the experimenter stopped the force"))
        elif isinstance(cmd, ControllerDetached):
            self._latch(Fault.ENGINE_DETACHED, now)
            self._emit(LoopEvent(now - self.t0_ns, "fault", self.faults,
                                 "ENGINE_DETACHED: the controlling process went away"))
        elif isinstance(cmd, LatchFault):
            self.framework.safety.force_zero()
            if self.recording:
                self.replay_log.append((self.tick_count, "zero", "latch_fault"))
            self._latch(Fault(cmd.fault), now)
        elif isinstance(cmd, AllowBiasRefinement):
            if self.recording and bool(cmd.allowed) != self.refine_bias:
                self.replay_log.append((self.tick_count, "refine", bool(cmd.allowed)))
            self.refine_bias = bool(cmd.allowed)
        elif isinstance(cmd, SetCalibration):
            self.framework.set_calibration(cmd.calibration)
            if self.recording:
                self.replay_log.append((self.tick_count, "calibration", cmd.calibration.to_dict()))
        elif isinstance(cmd, StartRecording):
            self._snapshot_due = int(cmd.token)  # taken once this tick's commands are all applied
        elif isinstance(cmd, StopRecording):
            self.recording = False
        else:  # pragma: no cover - typed callers cannot get here
            raise TypeError(f"unknown loop command {cmd!r}")

    def _take_snapshot(self) -> None:
        token, self._snapshot_due = self._snapshot_due, None
        self.recording = True
        self.replay_log.append((self.tick_count, "snapshot", {
            "token": token, "framework": self.framework.snapshot(), "refine_bias": self.refine_bias,
        }))

    def fail_safe(self, detail: str, *, thread_dead: bool) -> LoopEvent:
        """The loop has stopped ticking: latch ``LOOP_STALLED``, report it, and zero the device from this thread.

        Called by whoever watches the loop (:class:`pipeline.runtime.supervisor.LoopSupervisor`), not by the loop.
        The event goes through the same path as the loop's own (:attr:`on_event`), on the records' time
        axis just after the last tick.  With ``thread_dead`` (nothing else touches the loop any more) the
        fault is latched here and the rig told (a teleoperated robot stops now, before its own 50 ms
        watchdog); a loop that is only frozen latches it itself, through a :class:`LatchFault` command,
        when it ticks again.  The device's own watchdog has zeroed its output already; the zero command
        here is a second line.
        """
        last = self._last_ns
        t = 0 if last is None else last - self.t0_ns + self.period_ns
        if thread_dead:
            new = not self.faults & Fault.LOOP_STALLED
            self.faults = int(self.faults | Fault.LOOP_STALLED)
            self.haptic_on = False
            self.framework.safety.force_zero()
            if self.recording:  # before the next tick, should the loop ever tick again
                self.replay_log.append((self.tick_count, "zero", "fail_safe"))
            if new:
                self._faults_changed(t + self.t0_ns)
        else:
            self.submit(LatchFault(Fault.LOOP_STALLED))
        ev = LoopEvent(t, "fault", int(self.faults | Fault.LOOP_STALLED), f"LOOP_STALLED: {detail}")
        self._emit(ev)
        try:
            self.rig.haptic.command_force(0.0, 0.0, 0.0)
        except Exception as exc:  # the device's own watchdog zeroes it anyway; say so
            self._emit(LoopEvent(t, "fault", ev.faults, f"the haptic device refused the zero command ({exc!r}); "
                                 "its command watchdog drops the force"))
        return ev

    def _latch(self, fault: Fault, now: int) -> None:
        if not self.faults & fault:
            self.faults = int(self.faults | fault)
            self._faults_changed(now)

    def _faults_changed(self, now: int) -> None:
        """Tell the rig the latched set changed (it stops a teleoperated robot); only on a change."""
        hook = self._rig_on_faults
        if hook is None:
            return
        try:
            hook(Fault(self.faults))
        except Exception as exc:  # the loop must keep ramping the force down; report it
            self._emit(LoopEvent(now - self.t0_ns, "fault", self.faults,
                                 f"the rig could not act on the faults: {exc!r}"))

    def _emit(self, ev: LoopEvent) -> None:
        self.events.append(ev)
        if self.on_event is not None:
            try:
                self.on_event(ev)
            except Exception:  # an observer must never stop the loop (bluesky Dispatcher)
                pass

    # -- running (the pacing: pipeline.runtime.pacing.PacedTicks) ----------------------------------------
    def ramp_down(self, max_ticks: int = 200) -> None:
        """Bring the rendered force to zero through the safety ramp, then command zero.

        Commands still queued (e.g. a ``ControllerDetached`` submitted together
        with the stop) are applied first, so their faults and events are not
        lost; a queued ``SetHaptics(True)`` cannot undo the ramp-down.  A rig
        with a ``stop_motion`` hook is told to stop its robot before the ramp.
        """
        clock = self.clock
        try:
            inbox = self._inbox
            while inbox:
                self._apply(inbox.popleft(), clock.now_ns())
            self.haptic_on = False
            if self._rig_stop_motion is not None:
                # nobody drives a teleoperated robot once the loop stops: stop it before the ramp
                try:
                    self._rig_stop_motion("haptic loop stopped")
                except Exception as exc:  # still ramp the force down; report it
                    self._emit(LoopEvent(clock.now_ns() - self.t0_ns, "fault", self.faults,
                                         f"the rig could not stop the robot: {exc!r}"))
            # ramp ticks continue the period grid: the next slot after the last tick, not one later
            last = self._last_ns
            deadline = clock.now_ns() if last is None else max(clock.now_ns(), last + self.period_ns)
            for _ in range(max_ticks):
                if self.framework.safety.gain == 0.0:
                    break
                clock.sleep_until(deadline)
                self.tick()
                deadline += self.period_ns
        finally:
            # whatever failed above (a tick raising, a device gone), the last command is zero -- and should even
            # this fail, the device's command watchdog drops the force within its timeout
            self._resync = True
            self.rig.haptic.command_force(0.0, 0.0, 0.0)

    def start(self) -> None:
        """Run the loop in its own thread (real-time use)."""
        if self._thread is not None:
            raise RuntimeError("loop already started")
        self._stop.clear()

        def _target() -> None:
            self.scheduling = prepare_realtime_thread()
            try:
                self.run(self._stop)
            except BaseException as exc:  # kept for the supervisor, which reports and stores it
                first = exc.__context__  # the exception the ramp-down was handling when this one struck
                why = repr(exc)
                self.crash = why + (f" while handling {first!r}" if first is not None and repr(first) != why else "")

        self.crash = ""
        self._thread = threading.Thread(target=_target, name="haptic-loop", daemon=True)
        self._thread.start()

    @property
    def thread_alive(self) -> bool | None:
        """Whether the loop thread runs: None if it was never started (or was stopped)."""
        t = self._thread
        return None if t is None else t.is_alive()

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop the thread (it ramps the force to zero first) and wait for it."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None
