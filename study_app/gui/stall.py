"""Find what blocks the GUI thread: a heartbeat timer plus a sampling watchdog thread.

A 5 ms :class:`QTimer` in the GUI's event loop stamps a heartbeat; a watchdog
thread checks it every few milliseconds and, while the heartbeat is overdue,
samples the GUI thread's Python stack (``sys._current_frames``).  When the
heartbeat comes back, the gap is one stall; the samples taken during it say
which callback was running (the innermost frame of our code or of pyqtgraph,
with its caller chain).  A stall spent entirely inside Qt's C++ (painting,
layout) shows the Python frame that entered Qt (e.g. ``QApplication.exec``).

The bookkeeping (:class:`StallRecorder`) is Qt-free and driven by explicit
timestamps, so its attribution is tested deterministically; the timer and the
thread (:class:`StallDetector`) are a thin shell used by ``haptic-study bench gui``.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from types import FrameType

from PySide6.QtCore import QObject

from study_app.gui.timers import tracked_timer

__all__ = ["Stall", "StallDetector", "StallRecorder", "stack_of"]

#: Frames from these directories (relative to the repository) name a culprit; library frames only give context.
_OURS = ("study_app", "protocol", "pipeline", "analysis")
_ENTRY_POINTS = ("study_app/cli/main.py", "study_app/gui/stall.py", "study_app/gui/app.py")
_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _short(path: str) -> str:
    if path.startswith(_ROOT + os.sep):
        return path[len(_ROOT) + 1:]
    parts = path.split(os.sep)
    for lib in ("pyqtgraph", "PySide6", "numpy"):
        if lib in parts:
            return os.sep.join(parts[parts.index(lib):])
    return os.path.basename(path)


def stack_of(frame: FrameType | None, depth: int = 40) -> tuple[str, ...]:
    """``file:line function`` of a frame and its callers, innermost first."""
    out: list[str] = []
    while frame is not None and len(out) < depth:
        code = frame.f_code
        out.append(f"{_short(code.co_filename)}:{frame.f_lineno} {code.co_name}")
        frame = frame.f_back
    return tuple(out)


def culprit(stack: tuple[str, ...], context: int = 2) -> str:
    """Name the callback of a sampled stack: the innermost frame of our GUI code (with ``context`` callers) and,
    when a library was running below it, the innermost library frame.

    Entry points that merely run the event loop (the CLI, benchmarks, the stall detector) never count as the culprit.
    """
    ours = [i for i, s in enumerate(stack)
            if s.split("/")[0] in _OURS and not s.startswith(_ENTRY_POINTS)]
    if not ours:
        return f"event loop (Qt painting/layout) in {stack[0]}" if stack else "event loop (Qt painting/layout)"
    first = ours[0]
    chain = " ← ".join([stack[first]] + [stack[i] for i in ours[1:1 + context]])
    return chain + (f" [in {stack[0]}]" if first > 0 else "")


@dataclass(frozen=True, slots=True)
class Stall:
    """One overdue heartbeat: how long, in which phase, and the most-sampled culprit."""

    phase: str
    gap_ms: float
    culprit: str
    samples: int


@dataclass
class StallRecorder:
    """Stall bookkeeping on explicit timestamps (seconds).

    Parameters
    ----------
    interval_s
        The heartbeat's nominal interval; a gap is the time between beats minus this.
    threshold_s
        Samples are taken (and stalls kept) when the heartbeat is at least this overdue.
    """

    interval_s: float = 0.005
    threshold_s: float = 0.03
    phase: str = "idle"
    worst_ms: dict[str, float] = field(default_factory=dict)
    stalls: list[Stall] = field(default_factory=list)
    _last_beat: float | None = None
    _samples: list[tuple[str, ...]] = field(default_factory=list)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def set_phase(self, phase: str, now_s: float) -> None:
        """Start attributing gaps to ``phase`` (the heartbeat restarts: setup work is not a stall)."""
        with self._lock:
            self.phase = phase
            self.worst_ms.setdefault(phase, 0.0)
            self._last_beat = now_s
            self._samples = []

    def beat(self, now_s: float) -> None:
        """The heartbeat ran (GUI thread)."""
        with self._lock:
            last, self._last_beat = self._last_beat, now_s
            samples, self._samples = self._samples, []
            if last is None:
                return
            gap_ms = max(0.0, (now_s - last - self.interval_s) * 1e3)
            self.worst_ms[self.phase] = max(self.worst_ms.get(self.phase, 0.0), gap_ms)
            if gap_ms >= self.threshold_s * 1e3:
                counts = Counter(culprit(s) for s in samples)
                top = counts.most_common(1)[0][0] if counts else "(not sampled: the GUI thread held the GIL)"
                self.stalls.append(Stall(self.phase, round(gap_ms, 1), top, len(samples)))

    def overdue(self, now_s: float) -> bool:
        """The heartbeat is late by at least the threshold (watchdog thread)."""
        last = self._last_beat
        return last is not None and now_s - last - self.interval_s >= self.threshold_s

    def sample(self, stack: tuple[str, ...]) -> None:
        """A stack of the GUI thread taken while the heartbeat was overdue (watchdog thread)."""
        with self._lock:
            self._samples.append(stack)

    def worst(self, phase: str | None = None) -> Stall | None:
        """The longest recorded stall (of ``phase``, or of all)."""
        cands = [s for s in self.stalls if phase is None or s.phase == phase]
        return max(cands, key=lambda s: s.gap_ms) if cands else None


class StallDetector:
    """Heartbeat timer (GUI thread) + watchdog thread sampling the GUI thread's stack during a stall.

    Call :meth:`stop` before the parent goes away (it joins the thread).
    """

    def __init__(self, parent: QObject, interval_ms: int = 5, threshold_ms: float = 30.0, poll_ms: float = 3.0) -> None:
        self.recorder = StallRecorder(interval_ms / 1e3, threshold_ms / 1e3)
        self._gui_thread = threading.get_ident()
        self._poll_s = poll_ms / 1e3
        self._stop = threading.Event()
        self._timer = tracked_timer(parent, interval_ms, lambda: self.recorder.beat(time.perf_counter()),
                                    name="stall-heartbeat")
        self._thread = threading.Thread(target=self._watch, name="stall-watchdog", daemon=True)

    def start(self, phase: str = "idle") -> None:
        """Start the heartbeat and the watchdog."""
        self.recorder.set_phase(phase, time.perf_counter())
        self._timer.start()
        self._thread.start()

    def set_phase(self, phase: str) -> None:
        """Attribute what follows to ``phase``."""
        self.recorder.set_phase(phase, time.perf_counter())

    def stop(self) -> None:
        """Stop the heartbeat and join the watchdog."""
        self._timer.stop()
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)

    def _watch(self) -> None:
        rec = self.recorder
        while not self._stop.wait(self._poll_s):
            if rec.overdue(time.perf_counter()):
                frame = sys._current_frames().get(self._gui_thread)
                rec.sample(stack_of(frame))
