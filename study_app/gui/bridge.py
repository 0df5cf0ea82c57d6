"""Engine events → Qt signals: a monitor thread blocks on the engine's queue and emits (pymeasure's Monitor).

The engine process is spawned from the monitor thread too, so neither the
spawn nor any wait for the engine ever runs on the GUI thread.
"""

from __future__ import annotations

import threading

from PySide6.QtCore import QObject, Signal

from study_app import messages as m
from study_app.engine_client import EngineClient

__all__ = ["QtEngineBridge"]


class QtEngineBridge(QObject):
    """Owns the :class:`EngineClient`; re-emits each engine event as ``event_received`` (queued to the GUI thread)."""

    event_received = Signal(object)

    def __init__(self, client: EngineClient, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.client = client
        self._closing = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Spawn the engine and start relaying its events."""
        self._thread = threading.Thread(target=self._run, name="engine-monitor", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            self.client.start()
        except Exception as exc:  # noqa: BLE001 - shown to the experimenter
            self.event_received.emit(m.CommandRefused("connect", f"cannot start the study engine: {exc}"))
            return
        while True:
            ev = self.client.get(0.1)
            if ev is not None:
                self.event_received.emit(ev)
                continue
            if not self.client.alive:
                # the engine exited (shutdown or crash): pick up anything still queued, then stop
                while (ev := self.client.get(0.05)) is not None:
                    self.event_received.emit(ev)
                if not self._closing.is_set():
                    self.event_received.emit(m.EngineStopped("the study engine exited unexpectedly", {}))
                return

    def send(self, cmd: object) -> bool:
        """Send a command to the engine (a short pipe write)."""
        return self.client.started and self.client.send(cmd)

    def shutdown(self, timeout_s: float = 15.0) -> None:
        """Ask the engine to close the session's records and exit; wait for it and the monitor thread."""
        self._closing.set()
        if self.client.alive:
            self.client.send(m.Shutdown())
            self.client.join(timeout_s)
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None
        self.client.kill()
