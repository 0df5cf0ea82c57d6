"""Windows of the ring's records: what a real-rig recording (a pose, a pivot orientation, an axis push, the force
at rest before a start) averages, collected on the study engine's driver thread as the records come."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pipeline.commissioning.steps import sensor_stalled
from study_app.engine import messages as m
from study_app.engine.core import EngineCore

__all__ = ["RingWindow", "RingWindows"]


@dataclass
class RingWindow:
    """Records of the ring collected for a calibration step or the session gate (driver thread).

    ``done(columns)`` gets each column in ``cols`` over exactly ``need`` records; if the recording is
    abandoned instead (the sensor stalled: published as a refusal of ``command``), ``abandoned()`` is called.
    """

    command: str
    need: int
    start_ns: int
    cols: tuple[str, ...]
    done: Callable[[dict[str, np.ndarray]], None]
    chunks: list[np.ndarray]
    got: int = 0
    abandoned: Callable[[], None] | None = None
    label: str = ""  # what is being recorded (a pose's label), for messages
    stalled: str = ""  # the refusal if the sensor stalls ("" for the generic one)
    #: The arm whose ring is read ("": the first's, fed by the engine's drain); another arm's from ``cursor`` on.
    arm: str = ""
    cursor: int = 0


class RingWindows:
    """The recordings under way, at most one per command (driver thread only).

    Parameters
    ----------
    engine
        The engine whose ring (and the other arms' rings) the windows read; it publishes a stalled recording's refusal.
    first_arm
        The arm whose records the engine's drain hands to :meth:`feed`; another arm's window reads its own ring.
    """

    def __init__(self, engine: EngineCore, first_arm: str) -> None:
        self.engine = engine
        self.first_arm = first_arm
        self._windows: list[RingWindow] = []

    def busy(self, command: str) -> RingWindow | None:
        """The recording under way for ``command``, or None."""
        return next((w for w in self._windows if w.command == command), None)

    def open(self, command: str, seconds: float, cols: tuple[str, ...],
             done: Callable[[dict[str, np.ndarray]], None], abandoned: Callable[[], None] | None = None,
             *, label: str = "", stalled: str = "", arm: str = "") -> None:
        """Collect ``seconds`` of an arm's records written after now (the first arm's by default), then call ``done``
        (see :class:`RingWindow`)."""
        if self.busy(command) is not None:
            raise RuntimeError(f"{command}: a recording is already running")
        self.engine.drain_ring()
        start = self.engine.last_t_ns + 1 if self.engine.loop.tick_count else 0
        other = arm if arm and arm != self.first_arm else ""
        ring = self.engine.eng.rings[other] if other else None
        self._windows.append(RingWindow(command, int(round(seconds * 1000)), start, cols, done, [],
                                        abandoned=abandoned, label=label, stalled=stalled, arm=other,
                                        cursor=ring.write_count if ring is not None else 0))

    def feed(self, rows: np.ndarray) -> None:
        """The newest records of the ring: fill the open windows, finish those that are full."""
        for w in list(self._windows):
            sel = rows[rows["t_ns"] >= w.start_ns] if not w.arm else self._arm_rows(w)
            if len(sel):
                if sensor_stalled(sel["sensor_age_ns"]):
                    self._windows.remove(w)
                    again = ("measuring the force at rest (check the Devices tab) — press Start again"
                             if w.command in ("StartSession", "ResumeSession")
                             else "recording (check the Devices tab) — record again")
                    self.engine.publish(m.CommandRefused(w.command,
                                                         w.stalled or f"the force sensor stalled while {again}"))
                    if w.abandoned is not None:
                        w.abandoned()
                    continue
                w.chunks.append(np.stack([sel[c] for c in w.cols], axis=1))
                w.got += len(sel)
            if w.got >= w.need:
                self._windows.remove(w)
                data = np.concatenate(w.chunks)[: w.need]
                try:
                    w.done({c: data[:, i] for i, c in enumerate(w.cols)})
                except (ValueError, RuntimeError) as exc:
                    self.engine.publish(m.CommandRefused(w.command, str(exc)))

    def _arm_rows(self, w: RingWindow) -> np.ndarray:
        """The records another arm's ring got since the window last read it (each arm's loop writes its own)."""
        ring = self.engine.eng.rings[w.arm]
        assert ring is not None
        got = ring.read_since(w.cursor)
        w.cursor = got.cursor
        return got.rows[got.rows["t_ns"] >= w.start_ns]
