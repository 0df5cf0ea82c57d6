"""Every QTimer of the app is made here, so tests can check none is left running (napari's leak fixture idea)."""

from __future__ import annotations

import weakref

from PySide6.QtCore import QObject, QTimer

__all__ = ["active_timers", "tracked_timer"]

_TIMERS: weakref.WeakSet[QTimer] = weakref.WeakSet()


def tracked_timer(parent: QObject, interval_ms: int, slot, *, name: str) -> QTimer:
    """A repeating timer owned by ``parent`` (not started)."""
    t = QTimer(parent)
    t.setObjectName(name)
    t.setInterval(interval_ms)
    t.timeout.connect(slot)
    _TIMERS.add(t)
    return t


def active_timers() -> list[str]:
    """Names of tracked timers that are still running."""
    out = []
    for t in list(_TIMERS):
        try:
            if t.isActive():
                out.append(t.objectName())
        except RuntimeError:  # the C++ object is gone
            pass
    return out
