"""Engine events → Qt signals: a monitor thread blocks on the engine's queue and emits (pymeasure's Monitor).

The engine process is spawned from the monitor thread too, so neither the
spawn nor any wait for the engine ever runs on the GUI thread.  :meth:`restart`
replaces a dead (or loop-dead) engine by a new one the same way: the old one is
shut down, reaped and its events dropped on a worker thread, then a new one is
spawned.
"""

from __future__ import annotations

import dataclasses
import threading

from PySide6.QtCore import QObject, Qt, Signal, Slot

from study_app.engine import messages as m
from study_app.engine.client import EngineClient

__all__ = ["QtEngineBridge"]


class QtEngineBridge(QObject):
    """Owns the :class:`EngineClient`; re-emits each engine event as ``event_received`` (on the GUI thread)."""

    event_received = Signal(object)
    #: (generation, event) from a monitor thread; only the current engine's events are passed on.
    _raw = Signal(int, object)

    def __init__(self, client: EngineClient, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.client = client
        self._closing = threading.Event()
        self._thread: threading.Thread | None = None
        #: Which engine is current: events of an engine that was replaced (still queued) are dropped.
        self.generation = 0
        self._raw.connect(self._relay, Qt.ConnectionType.QueuedConnection)

    @Slot(int, object)
    def _relay(self, generation: int, ev: object) -> None:
        if generation == self.generation:
            self.event_received.emit(ev)

    def start(self) -> None:
        """Spawn the engine and start relaying its events."""
        gen, client = self.generation, self.client
        self._thread = threading.Thread(target=self._run, args=(gen, client), name="engine-monitor", daemon=True)
        self._thread.start()

    def restart(self, sim_arms: tuple[str, ...] = ()) -> None:
        """Replace the engine by a new one (the old one is asked to close its records and exit, else killed); with
        ``sim_arms``, a simulated rig of those arms in that order (the protocol's task arm first).

        Returns at once; the new engine's :class:`study_app.engine.messages.EngineReady` arrives as an event.
        """
        old_client, old_thread = self.client, self._thread
        self.generation += 1
        config = dataclasses.replace(old_client.config, sim_arms=sim_arms) if sim_arms else old_client.config
        self.client = EngineClient(config)
        gen, client = self.generation, self.client

        def run() -> None:
            _stop(old_client, old_thread, timeout_s=15.0)
            if not self._closing.is_set():
                self._run(gen, client)

        self._thread = threading.Thread(target=run, name="engine-monitor", daemon=True)
        self._thread.start()

    def release(self, timeout_s: float = 15.0) -> None:
        """Stop the engine and let its devices go (``haptic-study qualify`` opens them itself); nothing of it reaches
        the window any more, and :meth:`restart` starts a new one."""
        self.generation += 1
        thread, self._thread = self._thread, None
        _stop(self.client, thread, timeout_s)

    def _run(self, gen: int, client: EngineClient) -> None:
        try:
            client.start()
        except Exception as exc:  # shown to the experimenter
            self._raw.emit(gen, m.CommandRefused("connect", f"cannot start the study engine: {exc}"))
            self._raw.emit(gen, m.EngineStopped(f"cannot start the study engine: {exc}", {}))
            return
        asked_to_stop = False
        while True:
            if self._closing.is_set() and not asked_to_stop and client.alive:
                # spawned while the window was shutting down: it must not outlive the window
                asked_to_stop = client.send(m.Shutdown())
            ev = client.get(0.1)
            if ev is not None:
                self._raw.emit(gen, ev)
                continue
            if not client.alive:
                # the engine exited (shutdown or crash): pick up anything still queued, then stop
                while (ev := client.get(0.05)) is not None:
                    self._raw.emit(gen, ev)
                if not self._closing.is_set():
                    # how it ended (a crash in a device library is a signal) goes in the notice's detail
                    self._raw.emit(gen, m.EngineStopped(
                        f"the study engine exited unexpectedly ({client.exit_status})", {}))
                return

    def send(self, cmd: object) -> bool:
        """Send a command to the engine (a short pipe write)."""
        return self.client.started and self.client.alive and self.client.send(cmd)

    def shutdown(self, timeout_s: float = 15.0) -> None:
        """Ask the engine to close the session's records and exit; wait for it and the monitor thread."""
        self._closing.set()
        self.generation += 1  # nothing more from it reaches the window
        thread, self._thread = self._thread, None
        _stop(self.client, thread, timeout_s)


def _stop(client: EngineClient, thread: threading.Thread | None, timeout_s: float) -> None:
    """Shut an engine down (ask, wait, kill), wait for its monitor thread, release it."""
    if client.alive:
        client.send(m.Shutdown())
        client.join(timeout_s)
    if thread is not None:
        thread.join(timeout_s)
    client.kill()
