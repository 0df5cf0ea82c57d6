"""What the study engine's rooms (its sessions, its commissioning chain and the chain's parts) use of the engine
they belong to.

A :class:`typing.Protocol`, so that :mod:`study_app.engine.sessions`, :mod:`study_app.engine.commissioning`,
:mod:`study_app.engine.tool_records`, :mod:`study_app.engine.ring_windows` and :mod:`study_app.engine.start_gate`
name what they need without importing :mod:`study_app.engine.host`, which builds them (no circle, not even for
typing).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from pipeline.assembly.engine_view import EngineView
from pipeline.force.payload_compensator import PayloadCalibration
from pipeline.runtime.loop_view import LoopView
from pipeline.runtime.ring import RingBuffer
from pipeline.settings.hardware import HardwareConfig
from study_app.engine.latency_report import LatencyReport
from study_app.engine.setup import HostConfig, StylusControl

__all__ = ["EngineCore"]


class EngineCore(Protocol):
    """The study engine as its rooms see it (driver thread only)."""

    config: HostConfig
    eng: EngineView
    loop: LoopView
    ring: RingBuffer
    #: The ring's read cursor (a room that ran the loop itself moves it past its own records).
    cursor: int
    real: bool
    hardware: HardwareConfig | None
    hardware_text: str
    #: The payload calibration in use (a room that identifies a new one installs it here).
    calibration: PayloadCalibration
    #: The simulated stylus's driver (the session's simulated participant is installed in it).
    driver: StylusControl
    #: The end-to-end latency's breakdown (real clock), stored with each session; None on the virtual clock.
    latency: LatencyReport | None
    lease_owner: str
    #: Loop time of the newest record the driver has read, ns.
    last_t_ns: int
    publish: Callable[[object], None]

    def handle(self, cmd: object) -> None:
        """Apply a command as if it had just arrived."""

    def drain_ring(self) -> None:
        """Read every new record now (and hand it to whoever waits for it)."""

    def require_idle(self, what: str) -> None:
        """Raise :class:`RuntimeError` naming ``what`` if the loop is dead or a session runs."""

    def after_loop_pause(self, restart: bool) -> None:
        """The loop ran the rig for a step of its own: restart the timing statistics (and the loop thread)."""

    def run_paused(self, job: str, progress: Callable[[int, int], None] | None = None, **kwargs: Any) -> Any:
        """Run a calibration step that drives the rig itself (:data:`pipeline.assembly.loop_jobs.JOBS`) with the
        loop paused, wherever the loop runs; return its result."""
