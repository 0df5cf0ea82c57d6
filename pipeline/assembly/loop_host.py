"""The 1 kHz loop alone in its process: the loop ticks in the process's main thread and talks to its driver between
ticks.

Why: a loop that shares its interpreter with other Python threads (a session runner, a recorder committing every
100 ms, the GUI's message feeder, a device library that holds the interpreter lock for 50 ms while it reconnects)
waits for the lock whenever one of them holds it -- and no real-time priority helps a thread that waits for a lock
held by a thread the scheduler has preempted.  In the loop's own process the only Python threads besides the loop
are the device receivers its ticks need (the F/T sensor's UDP receiver, the Touch's servo callback); everything else
runs in the study engine's process and talks to the loop through the link (:mod:`pipeline.runtime.loop_link`):

* between two ticks (:meth:`LoopHost.service`, a few µs when nothing came) the host takes the driver's messages --
  loop commands, calls on a device (a robot pose for the calibration wizard, a rehearsed fault, the simulated
  participant's cue) -- and sends what the loop produced (its events, replay-log entries, the stylus buttons'
  changes), then writes the status record that says how far the driver may read the rings;
* a job (a calibration step that drives the rig itself) runs with the loop paused: its force ramped to zero;
* **when the driver goes away** (its process died: the socket closes; or it stopped reading: its backlog passes
  the writer's limit) the host latches ``ENGINE_DETACHED`` on every arm -- the force ramps to zero within the
  safety stage's 40 ms -- closes the devices and ends the process.  Should this process die itself, each haptic
  device's own command watchdog (:mod:`pipeline.devices.touch_output`, 10 ms) and its driver end the force, and
  the engine reports the death as ``LOOP_STALLED`` (:class:`pipeline.runtime.supervisor.LoopSupervisor`).
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from pipeline.assembly.engine import Engine, arm_devices
from pipeline.assembly.loop_jobs import JOBS
from pipeline.core.clock import collect_garbage
from pipeline.devices.rig import rig_arms
from pipeline.runtime.loop_link import (
    STATUS_DTYPE,
    Assembled,
    Call,
    Closed,
    Entries,
    FrameReader,
    FrameWriter,
    Job,
    LinkClosed,
    Progress,
    Reply,
    Start,
    Stop,
    Submit,
    wait_readable,
)
from pipeline.runtime.loop_messages import ControllerDetached, LoopEvent
from pipeline.runtime.ring import RingBuffer

__all__ = ["DRIVER", "TRACER", "LoopHost"]

#: :class:`pipeline.runtime.loop_link.Call` targets beside the arms' names: the simulated stylus's driver (its
#: participant's cues in the rig's own time), and the late-tick tracer.
DRIVER, TRACER = "*driver", "*tracer"
#: The haptic device's heat and force limit go into the status record every this many ticks (they change slowly).
_HEAT_EVERY = 50


class _Participant:
    """The simulated stylus's driver as the engine's session runner drives it: the cues are stamped with the rig's
    own simulated time here, where the rig is (the runner's process has no such clock)."""

    def __init__(self, eng: Engine) -> None:
        self.rig = eng.rig

    def install(self, participant: Any) -> None:
        self.rig.driver.participant = participant

    def set_mode(self, mode: str) -> None:
        self.rig.driver.set_mode(mode)

    def set_manual_y(self, y_m: float) -> None:
        self.rig.driver.set_manual_y(y_m)

    def begin_trial(self, aim: Any) -> None:
        self.rig.driver.begin_trial(aim, self.rig.sim_time_s)

    def end_trial(self) -> None:
        self.rig.driver.end_trial(self.rig.sim_time_s)


class LoopHost:
    """Runs an assembled engine's loop in this process's thread and serves its driver over ``sock``.

    Parameters
    ----------
    eng
        The assembled rig, frameworks, loop and rings (the rings in shared memory).
    writer, reader
        The link's two directions, on one socket (the driver's process holds the other end).
    tracer
        The late-tick tracer wrapped around the loop's clock, if any (its report is a :data:`TRACER` call).
    """

    def __init__(self, eng: Engine, writer: FrameWriter, reader: FrameReader, *, tracer: Any = None) -> None:
        self.eng = eng
        self.loop = eng.loop
        self.writer = writer
        self.reader = reader
        self.tracer = tracer
        #: The status record (see :mod:`pipeline.runtime.loop_link`); the driver attaches it by name.
        self.status = RingBuffer.create(STATUS_DTYPE, 4, shared=True)
        self._ring = self.loop.ring
        self._logs = [ch.replay_log for ch in self.loop.arms]
        self._events: list[LoopEvent] = []
        self.loop.on_event = self._events.append
        self._buttons: list[tuple[int, int, int]] = []
        self._masks = [0] * len(self.loop.arms)
        self._hook_buttons()
        self._stop = threading.Event()  # PacedTicks.run's stop flag (no other thread sets it)
        self._jobs: deque[Job] = deque()
        self._started = False
        self._ticking = 0
        #: Why the host is ending (None while it serves).
        self.exit_reason: str | None = None
        self._sent = 0
        self._ticks_since_heat = _HEAT_EVERY
        self._heat = (0.0, math.inf)
        self._participant = _Participant(eng) if eng.simulated else None

    def _hook_buttons(self) -> None:
        """Each arm's stylus buttons: their changes go to the driver (its jaw controllers)."""
        for i, arm in enumerate(rig_arms(self.eng.rig)):
            dev = arm_devices(self.eng, arm.name)
            if hasattr(dev, "on_buttons"):
                dev.on_buttons = self._button_hook(i)

    def _button_hook(self, i: int) -> Callable[[int, int], None]:
        masks, out = self._masks, self._buttons

        def hook(now_ns: int, mask: int) -> None:  # every tick: a compare, unless the buttons changed
            if mask != masks[i]:
                masks[i] = mask
                out.append((i, now_ns, mask))

        return hook

    def assembled(self, scheduling: str) -> Assembled:
        """What the driver needs to know of the assembled engine (plain data), and how the loop is scheduled."""
        eng = self.eng
        arms = []
        for ch in self.loop.arms:
            dev = arm_devices(eng, ch.name)
            facts: dict[str, Any] = {
                "counts_per_unit": getattr(dev.sensor, "counts_per_unit", None),
                "peak_force_n": float(dev.haptic.peak_force_n),
                "continuous_force_n": float(getattr(dev.haptic, "continuous_force_n", math.nan)),
                "sim_config": dev.config if eng.simulated else None,
            }
            ring = eng.rings[ch.name]
            arms.append((ch.name, (ring.name or "") if ring is not None else "", eng.frameworks[ch.name].config,
                         eng.calibrations[ch.name], facts))
        return Assembled(tuple(arms), self.status.name or "", eng.simulated, eng.tool, self.loop.period_ns,
                         self.loop.watchdog, scheduling, os.getpid())

    # -- the process's life ---------------------------------------------------------------------------------------
    def serve(self) -> str:
        """Tick until told to stop or the driver goes away; run each job between runs; return why it ended.

        The devices are closed and :class:`pipeline.runtime.loop_link.Closed` sent before it returns.
        """
        crash = ""
        try:
            self._wait_for_start()
            while self.exit_reason is None:
                self._stop.clear()
                self._ticking = 1
                try:
                    self.loop.run(self._stop, between_ticks=self.service)  # ramps every arm to zero when it returns
                finally:
                    self._ticking = 0
                self._status()
                while self._jobs and self.exit_reason is None:
                    self._run_job(self._jobs.popleft())
                self.service()  # messages that came during the job (a Stop)
        except BaseException as exc:  # reported to the driver, then the process ends
            first = exc.__context__
            crash = repr(exc) + (f" while handling {first!r}" if first is not None and repr(first) != repr(exc)
                                 else "")
            self.exit_reason = self.exit_reason or f"the haptic loop failed: {crash}"
        error = ""
        try:
            self.eng.rig.close()
        except Exception as exc:  # the force is already zero; say what did not close cleanly
            error = str(exc)
        self._send_final(Closed(error, crash))
        for ring in self.eng.rings.values():  # the driver and the GUI keep their mappings; the names go
            if ring is not None:
                ring.close()
        return self.exit_reason or ""

    def _wait_for_start(self) -> None:
        """Serve calls and queue commands until :class:`Start` (or :class:`Stop`) comes."""
        while not self._started and self.exit_reason is None:
            wait_readable(self.reader.sock, 0.1)
            self._take()
            self._flush()

    def _send_final(self, msg: object) -> None:
        """Send ``msg`` after everything else, trying for a moment (the driver may be gone)."""
        self._flush()
        try:
            self.writer.put(msg)
            for _ in range(50):
                if self.writer.flush():
                    break
                time.sleep(0.01)
        except LinkClosed:
            pass
        self.status.close()

    # -- between two ticks ------------------------------------------------------------------------------------------
    def service(self) -> None:
        """What the host does after every tick: the collector's due pass, the driver's messages, the loop's output,
        the status."""
        collect_garbage()
        self._take()
        self._flush()

    def _take(self) -> None:
        try:
            msgs = self.reader.take()
        except LinkClosed:
            self._detached("the study engine's process went away (its end of the link closed)")
            return
        for msg in msgs:
            self._apply(msg)

    def _apply(self, msg: object) -> None:
        if isinstance(msg, Submit):
            self.loop.submit(msg.command)
        elif isinstance(msg, Call):
            self._call(msg)
        elif isinstance(msg, Start):
            self._started = True
        elif isinstance(msg, Job):
            self._jobs.append(msg)
            self._stop.set()  # the loop ramps down and returns; the job runs then
        elif isinstance(msg, Stop):
            self.exit_reason = msg.reason or "stopped by the study engine"
            self._stop.set()

    def _detached(self, why: str) -> None:
        """The driver is gone: every arm latches ENGINE_DETACHED (the force ramps to zero), then the host ends."""
        if self.exit_reason is None:
            self.loop.submit(ControllerDetached())
            self.exit_reason = why
        self._stop.set()

    def _flush(self) -> None:
        """Send the loop's events, replay-log entries and button changes; then say how far the rings may be read."""
        replay: list[tuple[int, tuple[int, str, object]]] = []
        for i, log in enumerate(self._logs):
            while log:
                replay.append((i, log.popleft()))
        if self._events or replay or self._buttons:
            self.writer.put(Entries(tuple(self._events), tuple(replay), tuple(self._buttons)))
            self._events.clear()
            self._buttons.clear()
        try:
            done = self.writer.flush()
        except LinkClosed:
            self._detached("the study engine's process went away (its end of the link closed)")
            done = False
        if self.writer.over_limit:
            self._detached(f"the study engine stopped reading the loop's link ({self.writer.pending_bytes} bytes "
                           "waiting)")
        if done and self._ring is not None:
            self._sent = self._ring.write_count
        self._status()

    def _status(self) -> None:
        self._ticks_since_heat += 1
        if self._ticks_since_heat >= _HEAT_EVERY:
            self._ticks_since_heat = 0
            st = self.eng.rig.haptic.read_state()
            self._heat = (float(st.heat_fraction), float(st.force_limit_n))
        loop = self.loop
        self.status.write((self._sent, loop.tick_count, loop.t0_ns, loop.stats.missed_slots, self._ticking,
                           *self._heat))

    # -- calls and jobs ---------------------------------------------------------------------------------------------
    def _target(self, arm: str) -> Any:
        if arm == DRIVER:
            if self._participant is None:
                raise RuntimeError("real rig: a person holds the stylus; there is no simulated driver")
            return self._participant
        if arm == TRACER:
            if self.tracer is None:
                raise RuntimeError("no late-tick tracer runs in the loop's process")
            return self.tracer
        return arm_devices(self.eng, arm)

    def _call(self, msg: Call) -> None:
        try:
            obj = self._target(msg.arm)
            *path, last = msg.attr.split(".")
            for part in path:
                obj = getattr(obj, part)
            if msg.assign:
                setattr(obj, last, msg.args[0])
                value = None
            else:
                attr = getattr(obj, last)
                value = attr(*msg.args) if callable(attr) else attr
            reply = Reply(msg.call_id, value)
        except Exception as exc:  # the driver raises it again, in its process
            reply = Reply(msg.call_id, error=str(exc), error_type=type(exc).__name__)
        if msg.call_id:
            self.writer.put(reply)

    def _run_job(self, job: Job) -> None:
        """Run a job with the loop paused (its force at zero); answer with its value or its exception."""
        def progress(done: int, total: int) -> None:
            self.writer.put(Progress(job.call_id, done, total))
            try:
                self.writer.flush()
            except LinkClosed:
                pass

        try:
            reply = Reply(job.call_id, JOBS[job.name].run(self.eng, progress, **job.kwargs))
        except Exception as exc:  # the driver raises it again, in its process
            reply = Reply(job.call_id, error=str(exc), error_type=type(exc).__name__)
        self.writer.put(reply)
        self._flush()
