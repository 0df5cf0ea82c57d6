"""A Touch for machines without one: the HDAPI with a 1 kHz servo-scheduler thread, behind the real Touch backend.

OpenHaptics is not installed here, so the real-rig tests open the haptic device
through this at the rig-construction seam (``HostConfig.haptic_factory``);
:class:`pipeline.backends.touch.TouchHapticDevice` itself runs unchanged on top:
its servo callback, clamping and error handling are the production code.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from pipeline.backends.hdapi import HD_NOMINAL_MAX_CONTINUOUS_FORCE, HD_NOMINAL_MAX_FORCE
from pipeline.backends.touch import TouchHapticDevice
from pipeline.core.clock import Clock
from pipeline.settings.hardware import HapticSettings

#: Every device opened in this process, newest last (tests inspect the forces it was sent).
OPENED: list[ThreadedHD] = []


class ThreadedHD:
    """The HDAPI of one Touch whose scheduler calls the servo callback about every millisecond, like
    hdStartScheduler."""

    def __init__(self) -> None:
        self.callback: Callable[[], None] | None = None
        self.position = (0.0, -10.0, 0.0)
        self.forces: list[tuple[float, float, float]] = []
        self.closed = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def init_device(self, name: str) -> None:
        pass

    def error_code(self) -> int:
        return 0

    def get_double(self, code: int) -> float:
        return {HD_NOMINAL_MAX_FORCE: 3.3, HD_NOMINAL_MAX_CONTINUOUS_FORCE: 0.88}[code]

    def enable(self, code: int) -> None:
        pass

    def schedule(self, callback: Callable[[], None]) -> None:
        self.callback = callback

    def start_scheduler(self) -> None:
        self._thread = threading.Thread(target=self._servo_loop, name="fake-hd-scheduler", daemon=True)
        self._thread.start()

    def _servo_loop(self) -> None:
        while not self._stop.wait(0.001):  # the device's own 1 kHz servo thread, not a test waiting
            if self.callback is not None:
                self.callback()

    def stop_scheduler(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(1.0)

    def close_device(self) -> None:
        self.closed = True

    def position_mm(self) -> tuple[float, float, float]:
        return self.position

    def buttons(self) -> int:
        return 0

    def set_force(self, fx: float, fy: float, fz: float) -> None:
        if len(self.forces) < 100_000:
            self.forces.append((fx, fy, fz))


def open_fake_touch(settings: HapticSettings, clock: Clock) -> TouchHapticDevice:
    """``pipeline.assembly.real_rig.open_haptic``'s signature, on :class:`ThreadedHD`."""
    api = ThreadedHD()
    OPENED.append(api)
    return TouchHapticDevice(settings.device_name, api=api, clock=clock, command_timeout_s=settings.command_timeout_s)
