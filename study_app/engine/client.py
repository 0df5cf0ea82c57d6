"""The GUI side of the study engine process: spawn it, send commands, receive events (no Qt).

:class:`EngineClient` is deliberately small and blocking-free on the send side
(a pipe write of a few hundred bytes); receiving is a blocking ``get`` meant
for a monitor thread (:class:`study_app.gui.bridge.QtEngineBridge`) that turns
events into Qt signals -- pymeasure's worker → queue → Qt bridge.
"""

from __future__ import annotations

import multiprocessing as mp
import queue
import time
from typing import Any

from foundation.platform_support.processes import exit_description
from pipeline.runtime.ring import RingBuffer
from study_app.engine import messages as m
from study_app.engine.process import host_main
from study_app.engine.setup import HostConfig

__all__ = ["EngineClient", "EngineStartError", "describe_exit"]


#: How a process ended, for a lab's bug report (:func:`foundation.platform_support.processes.exit_description`).
describe_exit = exit_description


class EngineStartError(RuntimeError):
    """The engine could not start (a device failed to open, or it did not become ready in time); one line."""


class EngineClient:
    """Start and talk to the study engine process.

    Parameters
    ----------
    config
        What the engine builds.
    """

    def __init__(self, config: HostConfig) -> None:
        self.config = config
        self._ctx = mp.get_context("spawn")  # never fork a process that holds Qt and threads
        self._conn, self._child_conn = self._ctx.Pipe()
        self._events: Any = self._ctx.Queue()
        self._proc = self._ctx.Process(
            target=host_main, args=(config, self._child_conn, self._events), name="study-engine", daemon=True
        )
        self.ring: RingBuffer | None = None
        #: The shared segment of the engine's ring ("" before EngineReady).
        self.ring_name = ""
        #: A rig of several arms: the other arms' rings by arm name (attached on EngineReady), and the task arm's
        #: name ("" for one arm).
        self.arm_rings: dict[str, RingBuffer] = {}
        self.task_arm = ""
        self.started = False
        #: The device the engine was opening last (real rig; "" before the first :class:`EngineOpening`).
        self.opening = ""
        #: The engine's last words (:class:`EngineStopped`), once it has stopped.
        self.stopped: m.EngineStopped | None = None

    def start(self) -> None:
        """Spawn the engine (returns at once; :class:`EngineReady` arrives as an event)."""
        self._proc.start()
        self._child_conn.close()
        self.started = True

    def send(self, cmd: object) -> bool:
        """Send a command; False if the engine is gone."""
        try:
            self._conn.send(cmd)
            return True
        except (OSError, BrokenPipeError, ValueError):
            return False

    def get(self, timeout_s: float) -> object | None:
        """The next event, or None after ``timeout_s``.  Attaches the ring on :class:`EngineReady`."""
        try:
            ev = self._events.get(timeout=timeout_s)
        except (queue.Empty, EOFError, OSError):
            return None
        if isinstance(ev, m.EngineReady) and ev.ring_name and self.ring is None:
            self.ring = RingBuffer.attach(ev.ring_name)
            self.ring_name = ev.ring_name
            if ev.arm_rings:
                self.task_arm = ev.arm_rings[0][0]
                self.arm_rings = {n: RingBuffer.attach(r) for n, r in ev.arm_rings[1:] if r}
        elif isinstance(ev, m.EngineOpening):
            self.opening = ev.device
        elif isinstance(ev, m.EngineStopped):
            self.stopped = ev
        return ev

    def wait_ready(self, timeout_s: float) -> tuple[m.EngineReady, list[object]]:
        """Start the engine if needed and wait for :class:`EngineReady` (benchmarks, tests, scripts).

        Returns the ready event and the events that came before it.

        Raises
        ------
        EngineStartError
            The engine stopped before it was ready (the message is its reason), or
            ``timeout_s`` passed (naming the device it was still opening); the
            engine is then killed.
        """
        if not self.started:
            self.start()
        before: list[object] = []
        end = time.monotonic() + timeout_s
        while True:
            left = end - time.monotonic()
            ev = self.get(min(0.1, max(0.0, left))) if left > 0 else None
            if isinstance(ev, m.EngineReady):
                return ev, before
            if ev is not None:
                before.append(ev)
            if self.stopped is not None:
                self.kill()
                raise EngineStartError(f"engine could not start: {self.stopped.reason}")
            if left <= 0:
                self.kill()
                still = f" (still opening the {self.opening})" if self.opening else ""
                raise EngineStartError(f"engine did not become ready within {timeout_s:g} s{still}")

    @property
    def pid(self) -> int | None:
        """The engine process's id (None before it is started)."""
        return self._proc.pid

    @property
    def exit_status(self) -> str:
        """How the engine process ended (:func:`describe_exit`)."""
        return describe_exit(self._proc.exitcode if self.started else None)

    @property
    def alive(self) -> bool:
        """True while the engine process runs."""
        return self.started and self._proc.is_alive()

    def join(self, timeout_s: float) -> bool:
        """Wait for the engine to exit; True if it did."""
        if not self.started:
            return True
        self._proc.join(timeout_s)
        return not self._proc.is_alive()

    def shutdown(self, timeout_s: float = 10.0) -> None:
        """Ask the engine to finish the current trial's records, ramp down and exit; kill it if it does not."""
        if self.alive:
            self.send(m.Shutdown())
            # drain events meanwhile: a full queue would block the engine's exit
            end = timeout_s
            while self._proc.is_alive() and end > 0:
                self.get(0.05)
                end -= 0.05
        self.kill()

    def detach(self) -> None:
        """Close our end of the command pipe, as a crashed GUI would."""
        self._conn.close()

    def kill(self) -> None:
        """Terminate the engine if still running and release local resources."""
        if self.started and self._proc.is_alive():
            self._proc.kill()
        if self.started:
            self._proc.join(5.0)
        if self.ring is not None:
            self.ring.close()
            self.ring = None
        for ring in self.arm_rings.values():
            ring.close()
        self.arm_rings = {}
        if self.started and not self._proc.is_alive():
            RingBuffer.free_orphaned(self.ring_name)  # killed: it could not free its own ring
        self._events.close()
        self._events.join_thread()

