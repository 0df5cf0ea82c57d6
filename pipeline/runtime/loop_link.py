"""The link between the 1 kHz loop's own process and the process that drives it: messages both ways, a status word.

On the real clock the loop runs alone in a process of its own (:mod:`pipeline.assembly.loop_host`), so no other
Python thread competes with it for the interpreter lock; the study engine drives it from its own process
(:mod:`pipeline.assembly.loop_client`).  Three channels connect them:

* **the rings**: every tick's record, one shared-memory :class:`pipeline.runtime.ring.RingBuffer` per arm, written by
  the loop, read by the engine and the GUI (as before);
* **messages** over one stream socket, both ways: :class:`FrameWriter` and :class:`FrameReader` carry pickled
  objects, each framed by its length.  Neither side ever blocks on the other: a writer keeps what the socket does not
  take and sends it on its next :meth:`FrameWriter.flush`, a reader takes what has come.  A loop whose driver stops
  reading keeps ticking (its backlog grows, bounded by :attr:`FrameWriter.limit_bytes`: beyond it the driver counts
  as gone, :mod:`pipeline.assembly.loop_host`);
* **the status**: a tiny ring of :data:`STATUS_DTYPE` records the loop writes after every tick -- how many ticks,
  its first tick's clock reading, missed slots, its first arm's haptic device's heat and force limit, and
  ``sent_through``: every loop event and replay-log entry of the ticks before that record count is in the socket
  already.  The engine reads the status, then the socket, then the rings up to ``sent_through``
  (:meth:`pipeline.runtime.ring.RingBuffer.cap`), so a record never reaches the session runner before the events and
  replay-log entries of its tick, as when the two ran in one process.

The messages are the dataclasses below: what the driver sends (:class:`Start`, :class:`Stop`, :class:`Submit`,
:class:`Call`, :class:`Job`) and what the loop's process answers (:class:`Opening`, :class:`Assembled`,
:class:`BuildFailed`, :class:`Entries`, :class:`Reply`, :class:`Progress`, :class:`Closed`).
"""

from __future__ import annotations

import pickle
import select
import socket
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pipeline.runtime.loop_messages import Command, LoopEvent

__all__ = [
    "STATUS_DTYPE",
    "Assembled",
    "BuildFailed",
    "Call",
    "Closed",
    "Entries",
    "FrameReader",
    "FrameWriter",
    "Job",
    "LinkClosed",
    "Opening",
    "Progress",
    "Reply",
    "Start",
    "Stop",
    "Submit",
    "wait_readable",
]

#: One status record of the loop's process (see the module's docstring).
STATUS_DTYPE = np.dtype([
    ("sent_through", "<i8"), ("ticks", "<i8"), ("t0_ns", "<i8"), ("missed_slots", "<i8"), ("running", "<i8"),
    ("heat_fraction", "<f8"), ("force_limit_n", "<f8"),
])

_LENGTH = struct.Struct("<I")
#: A frame longer than this is refused (a corrupt length, never a real message).
_MAX_FRAME = 64 * 1024 * 1024


class LinkClosed(ConnectionError):
    """The other end of the link went away (its process ended or closed the socket)."""


class FrameWriter:
    """Sends pickled objects over a non-blocking stream socket, never waiting for the reader.

    Parameters
    ----------
    sock
        The socket (set non-blocking here).
    limit_bytes
        :attr:`over_limit` once more than this waits unsent.
    """

    def __init__(self, sock: socket.socket, limit_bytes: int = 16 * 1024 * 1024) -> None:
        sock.setblocking(False)
        self.sock = sock
        self.limit_bytes = int(limit_bytes)
        self._out = bytearray()

    def put(self, msg: object) -> None:
        """Queue ``msg`` (sent by the next :meth:`flush`)."""
        data = pickle.dumps(msg, protocol=pickle.HIGHEST_PROTOCOL)
        self._out += _LENGTH.pack(len(data))
        self._out += data

    def flush(self) -> bool:
        """Send what the socket takes now; True when nothing waits any more.

        Raises
        ------
        LinkClosed
            The reader's end is gone.
        """
        out = self._out
        while out:
            try:
                n = self.sock.send(out)
            except (BlockingIOError, InterruptedError):
                return False
            except OSError as exc:  # EPIPE, ECONNRESET: the reader's process is gone
                raise LinkClosed(str(exc)) from None
            del out[:n]
        return True

    @property
    def pending_bytes(self) -> int:
        """Bytes queued and not yet taken by the socket."""
        return len(self._out)

    @property
    def over_limit(self) -> bool:
        """More than :attr:`limit_bytes` waits: the reader has stopped reading."""
        return len(self._out) > self.limit_bytes


class FrameReader:
    """Takes the objects a :class:`FrameWriter` sent, as they come, from a non-blocking stream socket."""

    def __init__(self, sock: socket.socket) -> None:
        sock.setblocking(False)
        self.sock = sock
        self._in = bytearray()

    def take(self) -> list[object]:
        """Every whole message that has come (oldest first; none when nothing came).

        Raises
        ------
        LinkClosed
            The writer's end is gone and nothing whole is left to read.
        """
        closed = False
        while True:
            try:
                chunk = self.sock.recv(1 << 16)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # ECONNRESET: as good as the end
                closed = True
                break
            if not chunk:
                closed = True
                break
            self._in += chunk
        out = list(self._frames())
        if closed and not out:
            raise LinkClosed("the other end of the loop's link closed it")
        return out

    def _frames(self) -> Iterator[object]:
        buf = self._in
        pos = 0
        while len(buf) - pos >= _LENGTH.size:
            (n,) = _LENGTH.unpack_from(buf, pos)
            if n > _MAX_FRAME:
                raise LinkClosed(f"a frame of {n} bytes on the loop's link: the stream is corrupt")
            if len(buf) - pos - _LENGTH.size < n:
                break
            start = pos + _LENGTH.size
            yield pickle.loads(bytes(buf[start:start + n]))
            pos = start + n
        del buf[:pos]


def wait_readable(sock: socket.socket, timeout_s: float) -> bool:
    """Wait up to ``timeout_s`` for something to read on ``sock``; True if there is."""
    readable, _, _ = select.select([sock], [], [], max(0.0, timeout_s))
    return bool(readable)


# -- from the driver to the loop's process --------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Start:
    """Start ticking (or tick again after a job)."""


@dataclass(frozen=True, slots=True)
class Stop:
    """Ramp every arm's force to zero, close the devices and end the process."""

    reason: str = ""


@dataclass(frozen=True, slots=True)
class Submit:
    """A loop command (:data:`pipeline.runtime.loop_messages.Command`), applied at the start of the next tick."""

    command: Command


@dataclass(frozen=True, slots=True)
class Call:
    """Call (or, with ``assign``, set) ``attr`` -- a dotted path -- on an arm's devices, between two ticks.

    ``arm`` names the arm ("" the first; ``"*driver"`` the simulated stylus's driver, ``"*tracer"`` the late-tick
    tracer); ``call_id`` 0 asks for no :class:`Reply`.
    """

    call_id: int
    arm: str
    attr: str
    args: tuple[Any, ...] = ()
    assign: bool = False


@dataclass(frozen=True, slots=True)
class Job:
    """Run the job called ``name`` (:data:`pipeline.assembly.loop_jobs.JOBS`, called as ``job(engine, progress,
    **kwargs)``) with the loop paused: its force ramped to zero, no tick until it returns.  ``progress(done, total)``
    sends :class:`Progress`."""

    call_id: int
    name: str
    kwargs: dict[str, Any] = field(default_factory=dict)


# -- from the loop's process to the driver --------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Opening:
    """The loop's process is opening ``device`` (the real rig; a hang names the device)."""

    device: str


@dataclass(frozen=True, slots=True)
class BuildFailed:
    """The rig could not be assembled: one line."""

    reason: str


@dataclass(frozen=True, slots=True)
class Assembled:
    """The rig, Algorithm 1 and the loop are built; what the driver needs to know of them (plain data).

    ``arms``: per arm, the first first, its name, its ring's shared-memory name, its framework's configuration,
    its calibration, and what is fixed of its devices (``counts_per_unit`` of its sensor, its haptic device's
    peak and continuous force, its simulated rig's configuration or None).
    """

    arms: tuple[tuple[str, str, Any, Any, dict[str, Any]], ...]
    status_ring: str
    simulated: bool
    tool: str
    period_ns: int
    watchdog: Any
    scheduling: str
    pid: int


@dataclass(frozen=True, slots=True)
class Entries:
    """What the loop produced between two flushes: its events, its replay-log entries (arm index, entry), and the
    stylus buttons' changes (arm index, time, buttons)."""

    events: tuple[LoopEvent, ...]
    replay: tuple[tuple[int, tuple[int, str, object]], ...]
    buttons: tuple[tuple[int, int, int], ...] = ()


@dataclass(frozen=True, slots=True)
class Reply:
    """The answer to a :class:`Call` or :class:`Job`: its value, or the exception it raised (its type and text)."""

    call_id: int
    value: Any = None
    error: str = ""
    error_type: str = ""


@dataclass(frozen=True, slots=True)
class Progress:
    """A running :class:`Job` is ``done`` of ``total``."""

    call_id: int
    done: int
    total: int


@dataclass(frozen=True, slots=True)
class Closed:
    """The loop's process is ending: the force is zero, the devices closed (``error``: what did not close cleanly,
    ``crash``: why the loop stopped if it failed)."""

    error: str = ""
    crash: str = ""
