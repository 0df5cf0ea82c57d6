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

**Arms.**  A rig has one or more named arms (:func:`pipeline.devices.rig.rig_arms`); each tick runs the
same tick body for each, in the rig's order, from that arm's own sensor and pose
(:class:`pipeline.runtime.arm_channel.ArmChannel`: its framework, watchdog state, latched faults and ring).
The first arm's framework, ring, faults and replay log are the loop's own
(:attr:`HapticLoop.framework`, :attr:`HapticLoop.ring`, ...), so a caller that knows one arm sees the first.
A fault on one arm ramps that arm to zero; the loop's ``fault_policy`` says what the others do: ``"both"``
(the default: they latch ``Fault.OTHER_ARM`` and ramp to zero too -- a person's two hands are on the rig)
or ``"independent"`` (they keep rendering).  Every event names its arm (``LoopEvent.arm``).  The operator
stop, a detached controller and a stalled loop latch on every arm.

**Thermal derating.**  The device reports the force it may render now
(``HapticState.force_limit_n``, lowered as its motors warm); the loop clamps
the safety stage to it and records, per tick, the fraction of the designed
(scaled) force it could render (``derate``, 1 when not limited), which the
session runner checks.  Derating starting and ending are events.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from pipeline.core.clock import Clock, prepare_realtime_thread
from pipeline.devices.interfaces import Fault
from pipeline.devices.rig import Rig, rig_arms
from pipeline.force.framework import HapticFramework
from pipeline.runtime.arm_channel import RIG_WIDE_FAULTS, ArmChannel, own_faults
from pipeline.runtime.loop_messages import (
    RECORD_FIELDS,
    AllowBiasRefinement,
    Command,
    CommandForce,
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
from pipeline.runtime.watchdog import WatchdogConfig, output_restarted_detail, stall_detail

if TYPE_CHECKING:
    from pipeline.runtime.ring import RingBuffer

# The commands, events, record columns, statistics and watchdog limits are defined in
# pipeline.runtime.loop_messages, pipeline.runtime.loop_stats and pipeline.runtime.watchdog; they are named here
# too because the loop's callers import them from this module.  The devices the loop
# owns are pipeline.devices.rig.Rig; one arm's part of a tick is pipeline.runtime.arm_channel.ArmChannel.
__all__ = [
    "FAULT_POLICIES",
    "HapticLoop",
]

#: What a fault on one arm does to the other arms (see the module's docstring).
FAULT_POLICIES = ("both", "independent")


class HapticLoop(PacedTicks):
    """Runs the rig and Algorithm 1 (one pipeline per arm) at a fixed rate and records every tick.

    Parameters
    ----------
    rig
        Devices (real or simulated), one or more arms (:func:`pipeline.devices.rig.rig_arms`).
    framework
        The first arm's force path (calibration, filter, rotations, scaling, safety).
    clock
        Time source; :class:`pipeline.core.clock.VirtualClock` for deterministic runs.
    ring
        Where the first arm's records go (anything with ``write(values)``), or None.
    period_ns
        Tick period (1 ms).
    watchdog
        Age/range limits (the same for every arm).
    on_event
        Called (from the loop thread) for faults and resets; keep it cheap.
    arm_pipelines
        The other arms' force paths and rings, in the rig's order after the first: ``(framework, ring)`` each.
    fault_policy
        ``"both"`` or ``"independent"`` (:data:`FAULT_POLICIES`).
    """

    #: Where the loop runs, as :class:`pipeline.runtime.loop_view.LoopView` says it: a thread of its driver's process.
    runs_in = "thread"

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
        arm_pipelines: Sequence[tuple[HapticFramework, RingBuffer | None]] = (),
        fault_policy: str = "both",
    ) -> None:
        if fault_policy not in FAULT_POLICIES:
            raise ValueError(f"fault_policy = {fault_policy!r}: allowed values are 'both' and 'independent'")
        self.rig = rig
        self.clock = clock
        self.period_ns = int(period_ns)
        self.watchdog = watchdog or WatchdogConfig()
        self.on_event = on_event
        self.fault_policy = fault_policy
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
        self.refine_bias = False
        self._last_ns: int | None = None
        #: Clock reading of the first tick; records carry time since then
        #: (``t_ns`` exact in float64 for 104 days, ``t_s`` in seconds).
        self.t0_ns = 0
        self.recording = False
        self._snapshot_due: int | None = None
        arms = rig_arms(rig)
        if len(arm_pipelines) != len(arms) - 1:
            raise ValueError(f"arm_pipelines: {len(arm_pipelines)} given; the rig has {len(arms)} arms "
                             f"({', '.join(a.name for a in arms)}): give one (framework, ring) per arm after the first")
        pipelines = [(framework, ring), *arm_pipelines]
        #: One channel per arm, the first arm first.
        self.arms: tuple[ArmChannel, ...] = tuple(ArmChannel(a, fw, rg, self)
                                                  for a, (fw, rg) in zip(arms, pipelines, strict=True))
        self._first = self.arms[0]
        self._multi = len(self.arms) > 1
        self._stop_motion = [(ch, ch.arm.stop_motion) for ch in self.arms if ch.arm.stop_motion is not None]
        #: The loop thread's exception if it died (``repr``), else "".
        self.crash = ""
        self._stall_ns = int(self.watchdog.loop_stall_s * 1e9)
        #: The devices drop a command older than this (their own watchdog); a later tick restarts from zero.
        self.command_timeout_ns = min(ch.command_timeout_ns for ch in self.arms)
        self._resync = True  # the next tick's period is not a stall (first tick, or after a ramp-down)

    # -- the first arm's state, as the loop's own (one-arm callers) ---------------------------------
    @property
    def framework(self) -> HapticFramework:
        """The first arm's force path."""
        return self._first.framework

    @property
    def ring(self) -> RingBuffer | None:
        """The first arm's ring."""
        return self._first.ring

    @ring.setter
    def ring(self, ring: RingBuffer | None) -> None:
        self._first.ring = ring

    @property
    def faults(self) -> int:
        """The first arm's latched faults."""
        return self._first.faults

    @faults.setter
    def faults(self, value: int) -> None:
        self._first.faults = int(value)

    @property
    def active_faults(self) -> int:
        """The first arm's fault conditions at the last tick."""
        return self._first.active_faults

    @property
    def replay_log(self) -> deque[tuple[int, str, object]]:
        """The first arm's replay log (what replay needs beyond its records, see :class:`StartRecording`)."""
        return self._first.replay_log

    def arm(self, name: str) -> ArmChannel:
        """The channel of the arm called ``name``."""
        for ch in self.arms:
            if ch.name == name:
                return ch
        raise KeyError(f"no arm {name!r}; the rig's arms: {', '.join(ch.name for ch in self.arms)}")

    # -- control (any thread) ----------------------------------------------------------------
    def submit(self, command: Command) -> None:
        """Queue a command; applied at the start of the next tick."""
        self._inbox.append(command)

    @property
    def last_record(self) -> dict[str, float | int] | None:
        """The first arm's newest record as a dict (for tests and status displays)."""
        r = self._first.last_record
        return None if r is None else dict(zip(RECORD_FIELDS, r, strict=True))

    # -- one tick -----------------------------------------------------------------------------
    def tick(self) -> None:
        """Run one cycle at the clock's current time: every arm's pipeline from its own sensor and pose."""
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
        self.rig.advance(now)
        self.arms_tick(now, period, dt_s)

    def arms_tick(self, now: int, period: int, dt_s: float) -> None:
        """The tick after the rig's step: the queued commands (and what else is due at its start), then every arm's
        part (:meth:`tick`'s; a simulated rig's compiled block, :mod:`pipeline.sim.block`, calls it for a tick whose
        arm's part needs Python)."""
        if self._inbox or period > self.command_timeout_ns or self._snapshot_due is not None:
            self._start_of_tick(now, period)
        self._resync = False
        for ch in self.arms:
            ch.tick(now, period, dt_s)
        self.tick_count += 1

    @property
    def tick_due_work(self) -> bool:
        """Whether the next tick has work of its start to do in Python (queued commands, a replay snapshot, a period
        longer than the devices' command timeout), or is the first: what a compiled block of ticks
        (:mod:`pipeline.sim.block`) leaves to :meth:`tick`."""
        return (bool(self._inbox) or self._snapshot_due is not None or self._last_ns is None
                or self.period_ns > self.command_timeout_ns)

    @property
    def last_tick_ns(self) -> int | None:
        """The clock reading of the last tick (None before the first)."""
        return self._last_ns

    def ticked_elsewhere(self, started: int, completed: int, last_ns: int) -> None:
        """``started`` ticks at the nominal period ran outside :meth:`tick` (a simulated rig's compiled block), the
        last at ``last_ns``, ``completed`` of them whole (the rest's arms' part is :meth:`arms_tick`'s): count
        them as :meth:`tick` does."""
        if started:
            self.stats.add_nominal(started)
            self._last_ns = last_ns
            self._resync = False
        self.tick_count += completed

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
            token, self._snapshot_due = self._snapshot_due, None
            self.recording = True
            for ch in self.arms:
                ch.snapshot(token)

    def arm_faulted(self, ch: ArmChannel, new: int, now: int) -> None:
        """Arm ``ch`` latched ``new`` faults: under the ``"both"`` policy every other arm ramps to zero too."""
        own = own_faults(new) & ~RIG_WIDE_FAULTS
        if not self._multi or not own or self.fault_policy != "both":
            return
        for other in self.arms:
            if other is not ch and other.latch(Fault.OTHER_ARM, now):
                other.emit(now - self.t0_ns, "fault",
                           f"OTHER_ARM: arm {ch.name!r} latched {Fault(own).describe()}; the rig's fault policy "
                           "'both' ramps this arm to zero too")

    def _late_tick(self, now: int, period: int) -> None:
        """This tick came after the devices' command watchdog dropped the force: restart from zero; latch a stall."""
        t = now - self.t0_ns
        for ch in self.arms:
            ch.force_zero("late_tick")  # the device renders zero now: ramp in from there, never jump back
            if period > self._stall_ns:
                if ch.latch(Fault.LOOP_STALLED, now):
                    ch.emit(t, "fault", stall_detail(period, self.watchdog, self.command_timeout_ns))
            else:
                ch.emit(t, "output_restarted", output_restarted_detail(period, self.command_timeout_ns))

    def _apply(self, cmd: Command, now: int) -> None:
        if isinstance(cmd, Mark):
            self.trial_index = int(cmd.trial_index)  # int64 fields of the record
            self.phase = int(cmd.phase)
        elif isinstance(cmd, SetHaptics):
            self.haptic_on = bool(cmd.on)
        elif isinstance(cmd, ResetFaults):
            self._reset(now)
        elif isinstance(cmd, OperatorStop):
            self._latch_all(Fault.OPERATOR_STOP, now, "OPERATOR_STOP: the experimenter stopped the force")
        elif isinstance(cmd, ControllerDetached):
            self._latch_all(Fault.ENGINE_DETACHED, now, "ENGINE_DETACHED: the controlling process went away")
        elif isinstance(cmd, LatchFault):
            for ch in self.arms:
                ch.force_zero("latch_fault")
                ch.latch(int(cmd.fault), now)
        elif isinstance(cmd, AllowBiasRefinement):
            if self.recording and bool(cmd.allowed) != self.refine_bias:
                for ch in self.arms:
                    ch.log("refine", bool(cmd.allowed))
            self.refine_bias = bool(cmd.allowed)
        elif isinstance(cmd, SetCalibration):
            ch = self.arm(cmd.arm) if cmd.arm else self._first
            ch.framework.set_calibration(cmd.calibration)
            if self.recording:
                ch.log("calibration", cmd.calibration.to_dict())
        elif isinstance(cmd, StartRecording):
            self._snapshot_due = int(cmd.token)  # taken once this tick's commands are all applied
        elif isinstance(cmd, StopRecording):
            self.recording = False
        elif isinstance(cmd, CommandForce):  # the first arm's device: the one the participant holds
            self._first.command(cmd.program, now)
        else:  # pragma: no cover - typed callers cannot get here
            raise TypeError(f"unknown loop command {cmd!r}")

    def _reset(self, now: int) -> None:
        """Clear the latched faults whose condition is gone, on every arm; under ``"both"`` an arm keeps
        ``OTHER_ARM`` while another arm keeps a fault of its own."""
        persisting = [ch.reset_persisting() for ch in self.arms]
        if self._multi and self.fault_policy == "both":
            own = [own_faults(p) & ~RIG_WIDE_FAULTS for p in persisting]
            persisting = [p | (Fault.OTHER_ARM if any(o for j, o in enumerate(own) if j != i) else 0)
                          for i, p in enumerate(persisting)]
        for ch, p in zip(self.arms, persisting, strict=True):
            ch.reset(int(p), now)

    def _latch_all(self, fault: Fault, now: int, detail: str) -> None:
        for ch in self.arms:
            ch.latch(fault, now)
            ch.emit(now - self.t0_ns, "fault", detail)

    def fail_safe(self, detail: str, *, thread_dead: bool) -> LoopEvent:
        """The loop has stopped ticking: latch ``LOOP_STALLED``, report it, and zero every arm's device from this
        thread.

        Called by whoever watches the loop (:class:`pipeline.runtime.supervisor.LoopSupervisor`), not by the loop.
        The event goes through the same path as the loop's own (:attr:`on_event`), on the records' time
        axis just after the last tick, once per arm; the first arm's is returned.  With ``thread_dead``
        (nothing else touches the loop any more) the fault is latched here and the rig told (a
        teleoperated robot stops now, before its own 50 ms watchdog); a loop that is only frozen latches
        it itself, through a :class:`LatchFault` command, when it ticks again.  The devices' own
        watchdogs have zeroed their output already; the zero commands here are a second line.
        """
        last = self._last_ns
        t = 0 if last is None else last - self.t0_ns + self.period_ns
        if thread_dead:
            self.haptic_on = False
            for ch in self.arms:
                ch.force_zero("fail_safe")  # before the next tick, should the loop ever tick again
                ch.latch(Fault.LOOP_STALLED, t + self.t0_ns)
        else:
            self.submit(LatchFault(Fault.LOOP_STALLED))
        first: LoopEvent | None = None
        for ch in self.arms:
            ev = ch.emit(t, "fault", f"LOOP_STALLED: {detail}", int(ch.faults | Fault.LOOP_STALLED))
            first = first or ev
        for ch in self.arms:
            exc = ch.zero_device()
            if exc is not None:  # the device's own watchdog zeroes it anyway; say so
                ch.emit(t, "fault", f"the haptic device refused the zero command ({exc!r}); its command watchdog "
                        "drops the force", int(ch.faults | Fault.LOOP_STALLED))
        assert first is not None
        return first

    def emit(self, ev: LoopEvent) -> None:
        """Record an event and pass it to :attr:`on_event` (an observer's exception never stops the loop)."""
        self.events.append(ev)
        if self.on_event is not None:
            try:
                self.on_event(ev)
            except Exception:  # an observer must never stop the loop (bluesky Dispatcher)
                pass

    # -- running (the pacing: pipeline.runtime.pacing.PacedTicks) ----------------------------------------
    def ramp_down(self, max_ticks: int = 200) -> None:
        """Bring every arm's rendered force to zero through the safety ramp, then command zero.

        Commands still queued (e.g. a ``ControllerDetached`` submitted together
        with the stop) are applied first, so their faults and events are not
        lost; a queued ``SetHaptics(True)`` cannot undo the ramp-down.  An arm
        with a ``stop_motion`` hook is told to stop its robot before the ramp.
        """
        clock = self.clock
        try:
            inbox = self._inbox
            while inbox:
                self._apply(inbox.popleft(), clock.now_ns())
            self.haptic_on = False
            for ch, stop_motion in self._stop_motion:
                # nobody drives a teleoperated robot once the loop stops: stop it before the ramp
                try:
                    stop_motion("haptic loop stopped")
                except Exception as exc:  # still ramp the force down; report it
                    ch.emit(clock.now_ns() - self.t0_ns, "fault", f"the rig could not stop the robot: {exc!r}")
            # ramp ticks continue the period grid: the next slot after the last tick, not one later
            last = self._last_ns
            deadline = clock.now_ns() if last is None else max(clock.now_ns(), last + self.period_ns)
            for _ in range(max_ticks):
                if all(ch.framework.safety.gain == 0.0 for ch in self.arms):
                    break
                clock.sleep_until(deadline)
                self.tick()
                deadline += self.period_ns
        finally:
            # whatever failed above (a tick raising, a device gone), the last command is zero on every arm -- and
            # should even this fail, the device's command watchdog drops the force within its timeout
            self._resync = True
            errors = [exc for exc in (ch.zero_device() for ch in self.arms) if exc is not None]
            if errors:
                raise errors[0]

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
