"""The HDAPI of several Touch devices on one machine, with ``hdMakeCurrentDevice`` semantics, for
:class:`pipeline.backends.touch.TouchScheduler`.

Every per-device call (position, buttons, limits, ``hdEnable``, the force) acts on the *current* device, as in
libHD: a scheduler that sent one arm's force while the other arm's device was current writes it to the wrong
Touch here too, and a force written outside that device's frame fails at once.  Servo ticks run on demand.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from pipeline.backends.hdapi import HD_NOMINAL_MAX_CONTINUOUS_FORCE, HD_NOMINAL_MAX_FORCE
from pipeline.devices.interfaces import DeviceError


@dataclass
class FakeTouch:
    """One device behind the fake library."""

    name: str
    peak: float = 3.3
    cont: float = 0.88
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    button_mask: int = 0
    enabled: list[int] = field(default_factory=list)
    forces: list[tuple[float, float, float]] = field(default_factory=list)
    closed: bool = False


class FakeMultiHD:
    """libHD with the named devices ``touches`` plugged in (a name not there fails to open)."""

    def __init__(self, *touches: FakeTouch) -> None:
        self.plugged = {t.name: t for t in touches}
        self.handles: dict[int, FakeTouch] = {}
        self.current = 0
        self.frame = 0  # the handle whose frame is open; 0: none
        self.errors: list[tuple[int, int]] = []
        self.callback: Callable[[], None] | None = None
        self.running = False
        self.calls: list[str] = []

    def _cur(self) -> FakeTouch:
        assert self.current in self.handles, "no current device"
        return self.handles[self.current]

    def open_device(self, name: str) -> int:
        if name not in self.plugged:
            raise DeviceError(f"OpenHaptics could not open the haptic device {name!r} (HD error 0x0300)")
        handle = 10 + len(self.handles)
        self.handles[handle] = self.plugged[name]
        self.current = handle  # hdInitDevice makes the new device current
        return handle

    def make_current(self, handle: int) -> None:
        assert handle in self.handles
        self.current = handle

    def begin_frame(self, handle: int) -> None:
        assert self.frame == 0, "frames do not nest"
        self.frame = handle

    def end_frame(self, handle: int) -> None:
        assert self.frame == handle
        self.frame = 0

    def next_error(self) -> tuple[int, int]:
        return self.errors.pop(0) if self.errors else (0, 0)

    def get_double(self, code: int) -> float:
        t = self._cur()
        return {HD_NOMINAL_MAX_FORCE: t.peak, HD_NOMINAL_MAX_CONTINUOUS_FORCE: t.cont}[code]

    def enable(self, code: int) -> None:
        self._cur().enabled.append(code)

    def position_mm(self) -> tuple[float, float, float]:
        return self._cur().position

    def buttons(self) -> int:
        return self._cur().button_mask

    def set_force(self, fx: float, fy: float, fz: float) -> None:
        assert self.frame == self.current, "a force written outside the current device's frame"
        self._cur().forces.append((fx, fy, fz))

    def schedule_frames(self, callback: Callable[[], None]) -> None:
        self.callback = callback

    def start_scheduler(self) -> None:
        self.calls.append("start")
        self.running = True

    def stop_scheduler(self) -> None:
        self.calls.append("stop")
        self.running = False

    def close_handle(self, handle: int) -> None:
        self.calls.append(f"close {self.handles[handle].name}")
        self.handles[handle].closed = True

    def tick(self, n: int = 1) -> None:
        assert self.running and self.callback is not None
        for _ in range(n):
            self.callback()
