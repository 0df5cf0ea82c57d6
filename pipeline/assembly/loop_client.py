"""The driver's side of a loop that runs alone in its own process: the link, and stand-ins for the loop and its rig.

:mod:`pipeline.assembly.loop_host` runs the rig, Algorithm 1 and the 1 kHz loop in a process of their own.  The
process that drives it (the study engine) sees them through the stand-ins here, which offer what that process
used of an in-process :class:`pipeline.assembly.engine.Engine`:

* :class:`RemoteLoop` is a :class:`pipeline.runtime.loop_view.LoopView`: commands go over the link, the loop's
  events and replay logs come back over it (:meth:`RemoteLoop.pump`, called where the driver reads the rings), its
  tick count, first tick and missed slots come from the status record, its faults from the newest record;
* :meth:`LoopLink.call` calls a device there between two ticks, :meth:`LoopLink.job` runs a calibration step that
  drives the rig itself, with the loop paused;
* the assembled engine's stand-in, its arms' devices and the attaching are :mod:`pipeline.assembly.remote_engine`.
"""

from __future__ import annotations

import math
import socket
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from foundation.platform_support.processes import exit_description
from pipeline.core.clock import Clock, MonotonicClock
from pipeline.devices.interfaces import Fault
from pipeline.runtime.loop_link import (
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
from pipeline.runtime.loop_messages import RECORD_FIELDS, Command, LatchFault, LoopEvent, SetHaptics
from pipeline.runtime.ring import RingBuffer
from pipeline.runtime.watchdog import WatchdogConfig

__all__ = ["LoopLink", "RemoteArm", "RemoteLoop", "Settings"]

_ERRORS: dict[str, type[Exception]] = {"ValueError": ValueError, "RuntimeError": RuntimeError, "KeyError": KeyError}


class LoopLink:
    """The driver's end of the link (:mod:`pipeline.runtime.loop_link`) and the loop's process.

    Parameters
    ----------
    sock
        The driver's end of the socket.
    process
        The loop's process (``poll()``, ``returncode``, ``pid``, ``kill()``, ``wait(timeout)``: a ``Popen``).
    """

    def __init__(self, sock: socket.socket, process: Any) -> None:
        self.sock = sock
        self.process = process
        self.writer = FrameWriter(sock)
        self.reader = FrameReader(sock)
        #: Where every message that is no :class:`Reply` goes (the loop's stand-in dispatches them).
        self.handle: Callable[[object], None] = lambda msg: None
        self._replies: dict[int, Reply] = {}
        self._next_id = 1
        #: The socket is closed: the loop's process ended (or closed it).
        self.gone = False
        #: The loop's process's last word, once it came.
        self.closed: Closed | None = None

    # -- sending ----------------------------------------------------------------------------------------------------
    def send(self, msg: object) -> None:
        """Send ``msg`` (what the socket does not take now goes with the next send or pump)."""
        self.writer.put(msg)
        self._flush()

    def _flush(self) -> None:
        try:
            self.writer.flush()
        except LinkClosed:
            self.gone = True

    def notify(self, arm: str, attr: str, *args: Any) -> None:
        """Call ``attr`` on an arm's devices (or :data:`pipeline.assembly.loop_host.DRIVER`) without an answer."""
        self.send(Call(0, arm, attr, args))

    def call(self, arm: str, attr: str, *args: Any, assign: bool = False, timeout_s: float = 2.0) -> Any:
        """Call (or set) ``attr`` on an arm's devices between two ticks and return what it returned.

        Raises
        ------
        RuntimeError
            The loop's process did not answer within ``timeout_s``, or is gone; the call's own ``ValueError``,
            ``RuntimeError`` or ``KeyError`` is raised again here, any other exception as a RuntimeError.
        """
        call_id = self._id()
        self.send(Call(call_id, arm, attr, args, assign))
        return self._answer(call_id, f"{attr}", timeout_s)

    def job(self, name: str, kwargs: dict[str, Any], timeout_s: float) -> Any:
        """Run the job ``name`` (:data:`pipeline.assembly.loop_jobs.JOBS`) with the loop paused; its value."""
        call_id = self._id()
        self.send(Job(call_id, name, kwargs))
        return self._answer(call_id, f"the {name} step", timeout_s)

    def _id(self) -> int:
        self._next_id += 1
        return self._next_id

    def _answer(self, call_id: int, what: str, timeout_s: float) -> Any:
        if not self.wait(lambda: call_id in self._replies, timeout_s):
            why = "its process is gone" if self.gone or not self.alive else f"no answer within {timeout_s:g} s"
            raise RuntimeError(f"the haptic loop's process did not carry out {what} ({why})")
        reply = self._replies.pop(call_id)
        if reply.error_type:
            raise _ERRORS.get(reply.error_type, RuntimeError)(
                reply.error if reply.error_type in _ERRORS else f"{reply.error_type}: {reply.error}")
        return reply.value

    # -- receiving --------------------------------------------------------------------------------------------------
    def pump(self) -> None:
        """Take every message that has come: replies are kept for their caller, the rest handed to :attr:`handle`."""
        self._flush()
        if self.gone:
            return
        try:
            msgs = self.reader.take()
        except LinkClosed:
            self.gone = True
            return
        for msg in msgs:
            if isinstance(msg, Reply):
                self._replies[msg.call_id] = msg
            else:
                if isinstance(msg, Closed):
                    self.closed = msg
                self.handle(msg)

    def wait(self, done: Callable[[], bool], timeout_s: float) -> bool:
        """Pump until ``done()`` or ``timeout_s`` passed or the link closed; True if ``done()``."""
        end = time.monotonic() + timeout_s
        while True:
            self.pump()
            if done():
                return True
            left = end - time.monotonic()
            if left <= 0 or self.gone:
                return False
            wait_readable(self.sock, min(left, 0.05))

    # -- the process ------------------------------------------------------------------------------------------------
    @property
    def alive(self) -> bool:
        """The loop's process runs."""
        return bool(self.process.poll() is None)

    @property
    def exit_status(self) -> str:
        """How the loop's process ended (``killed by SIGKILL (signal 9)``, ``exit status 0``, ``still running``); its
        link closing comes a moment before the process is gone: waited for, briefly."""
        code = self.process.poll()
        if code is None and self.gone:
            try:
                code = self.process.wait(1.0)
            except Exception:  # subprocess.TimeoutExpired: it closed the link and lives on
                code = None
        return exit_description(code)

    def end(self, timeout_s: float) -> None:
        """Wait up to ``timeout_s`` for the process to end; kill it if it does not."""
        try:
            self.process.wait(timeout_s)
        except Exception:  # subprocess.TimeoutExpired: it hangs; as a crash would
            self.process.kill()
            self.process.wait(5.0)
        self.sock.close()


@dataclass
class _Missed:
    missed_slots: int = 0


@dataclass(frozen=True)
class Settings:
    """An arm's Algorithm 1 settings as the driver holds them (the loop's process holds the framework)."""

    config: Any


@dataclass
class RemoteArm:
    """One arm of a :class:`RemoteLoop`: its name, ring (its newest record's faults) and replay log."""

    name: str
    ring: RingBuffer
    loop: RemoteLoop
    replay_log: deque[tuple[int, str, object]] = field(default_factory=deque)

    @property
    def faults(self) -> int:
        """The arm's latched faults: its newest record's, with what the driver latched for a dead loop."""
        rows = self.ring.latest(1)
        return (int(rows["faults"][0]) if len(rows) else 0) | self.loop.latched


class RemoteLoop:
    """The loop that runs in its own process, as its driver sees it (a :class:`pipeline.runtime.loop_view.LoopView`).

    Parameters
    ----------
    link
        The link to its process.
    assembled
        What the process said it built.
    rings
        Every arm's ring by name, the first first (attached; capped here).
    status
        The status ring (attached).
    """

    runs_in = "process"

    def __init__(self, link: LoopLink, assembled: Assembled, rings: Mapping[str, RingBuffer],
                 status: RingBuffer) -> None:
        self.link = link
        self.period_ns = int(assembled.period_ns)
        self.watchdog: WatchdogConfig = assembled.watchdog
        self.clock: Clock = MonotonicClock()
        self.scheduling = assembled.scheduling
        #: The loop's process's id.
        self.pid = int(assembled.pid)
        self.on_event: Callable[[LoopEvent], None] | None = None
        self.arms = tuple(RemoteArm(name, ring, self) for name, ring in rings.items())
        self._first = self.arms[0]
        self.framework = Settings(assembled.arms[0][2])
        self.status = status
        self._sent = 0
        for ring in rings.values():
            ring.cap(self._sent_through)
        #: Faults the driver latched itself: ``LOOP_STALLED`` once the loop's process was found dead.
        self.latched = 0
        self._started = False
        self._stopped = False
        #: The stylus buttons' hooks by arm index (the jaws' controllers), set by :class:`RemoteDevices`.
        self.button_hooks: dict[int, Callable[[int, int], None] | None] = {}
        self._buttons: dict[int, int] = {}
        self.progress: Callable[[int, int], None] | None = None
        link.handle = self._handle

    def _sent_through(self) -> int:
        return self._sent

    # -- reading --------------------------------------------------------------------------------------------------
    def pump(self) -> None:
        """Take what the loop's process sent, then let the rings be read as far as it had sent it.

        The status is read first: every event and replay-log entry of the ticks it counts was in the socket by
        then, so the rings' records up to it never reach a reader before their tick's entries.
        """
        rows = self.status.latest(1)
        self.link.pump()
        if len(rows):
            self._sent = int(rows["sent_through"][0])
        now = self.clock.now_ns()
        for i, mask in self._buttons.items():  # a held button: its controller times the long press
            hook = self.button_hooks.get(i)
            if hook is not None and mask:
                hook(now, mask)

    def _handle(self, msg: object) -> None:
        if isinstance(msg, Entries):
            for i, entry in msg.replay:
                self.arms[i].replay_log.append(entry)
            for i, t_ns, mask in msg.buttons:
                self._buttons[i] = mask
                hook = self.button_hooks.get(i)
                if hook is not None:
                    hook(t_ns, mask)
            for ev in msg.events:
                self._emit(ev)
        elif isinstance(msg, Progress) and self.progress is not None:
            self.progress(msg.done, msg.total)

    def _emit(self, ev: LoopEvent) -> None:
        hook = self.on_event
        if hook is not None:
            hook(ev)

    def _status(self, name: str) -> int:
        """A field of the newest status record (read now: the supervisor watches the tick count move)."""
        rows = self.status.latest(1)
        return int(rows[name][0]) if len(rows) else 0

    @property
    def t0_ns(self) -> int:
        """The loop clock's reading at its first tick."""
        return self._status("t0_ns")

    @property
    def tick_count(self) -> int:
        """Ticks run so far (the status record's)."""
        return self._status("ticks")

    @property
    def stats(self) -> _Missed:
        """The missed slots, as the loop counts them."""
        return _Missed(self._status("missed_slots"))

    @property
    def heat(self) -> tuple[float, float]:
        """The first arm's haptic device's heat fraction and force limit (N), as the status last said."""
        rows = self.status.latest(1)
        if not len(rows):
            return 0.0, math.inf
        return float(rows["heat_fraction"][0]), float(rows["force_limit_n"][0])

    @property
    def faults(self) -> int:
        """The first arm's latched faults."""
        return self._first.faults

    @property
    def haptic_on(self) -> bool:
        """Feedback is on (the newest record says so)."""
        rows = self._first.ring.latest(1)
        return bool(len(rows) and rows["haptic_on"][0])

    @property
    def replay_log(self) -> deque[tuple[int, str, object]]:
        """The first arm's replay log."""
        return self._first.replay_log

    @property
    def last_record(self) -> dict[str, float | int] | None:
        """The first arm's newest record as a dict."""
        rows = self._first.ring.latest(1)
        return None if not len(rows) else {f: rows[f][0].item() for f in RECORD_FIELDS}

    def arm(self, name: str) -> RemoteArm:
        """The arm called ``name``."""
        for a in self.arms:
            if a.name == name:
                return a
        raise KeyError(f"no arm {name!r}; the rig's arms: {', '.join(a.name for a in self.arms)}")

    @property
    def crash(self) -> str:
        """Why the loop's process ended, once it has (its loop's exception, else how the process ended), else ""."""
        closed = self.link.closed
        if closed is not None and closed.crash:
            return closed.crash
        if not self.link.gone and self.link.alive:
            return ""
        return self.link.exit_status

    @property
    def thread_alive(self) -> bool | None:
        """Whether the loop's process runs: None before it started ticking or once stopped on purpose."""
        if not self._started or self._stopped:
            return None
        return self.link.alive and not self.link.gone

    # -- commands ---------------------------------------------------------------------------------------------------
    def submit(self, command: Command) -> None:
        """Queue a loop command (applied at the start of the loop's next tick)."""
        self.link.send(Submit(command))

    def start(self) -> None:
        """Tick (again)."""
        self._started = True
        self.link.send(Start())

    def stop(self, timeout_s: float = 2.0) -> None:
        """Ramp the force to zero, close the devices and end the loop's process; wait for it (kill it after
        ``timeout_s`` more)."""
        if self._stopped:
            return
        self._stopped = True
        self.link.send(Stop("the study engine closed"))
        self.link.wait(lambda: self.link.closed is not None, timeout_s)
        self.status_at_end()
        self.link.end(timeout_s)

    def status_at_end(self) -> None:
        """The last status and entries the loop's process sent (after it closed)."""
        self.pump()

    def ramp_down(self, max_ticks: int = 200) -> None:
        """Switch feedback off: the force ramps to zero in the loop's process (the loop keeps ticking)."""
        self.submit(SetHaptics(False))

    def fail_safe(self, detail: str, *, thread_dead: bool) -> LoopEvent:
        """The loop's process stopped ticking: report ``LOOP_STALLED`` for every arm, on the records' time axis just
        after the newest record.

        A dead process cannot latch it: the driver keeps it (:attr:`latched`); each haptic device's own command
        watchdog, and its driver once the process that opened it is gone, have ended the force.  A frozen one is
        told to latch it when it ticks again (:class:`pipeline.runtime.loop_messages.LatchFault`).
        """
        rows = self._first.ring.latest(1)
        t = int(rows["t_ns"][0]) + self.period_ns if len(rows) else 0
        if thread_dead:
            self.latched |= int(Fault.LOOP_STALLED)
        else:
            self.submit(LatchFault(Fault.LOOP_STALLED))
        first: LoopEvent | None = None
        for a in self.arms:
            ev = LoopEvent(t, "fault", int(a.faults | Fault.LOOP_STALLED), f"LOOP_STALLED: {detail}", a.name)
            self._emit(ev)
            first = first or ev
        assert first is not None
        return first
