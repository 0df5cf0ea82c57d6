"""3D Systems Touch through OpenHaptics (HDAPI) via the optional ``pyOpenHaptics`` package.

``pip install 'haptic-study[touch]'`` plus the OpenHaptics SDK and Touch
driver from 3D Systems; ``pyOpenHaptics`` loads ``libHD.so`` at import time,
so it is imported only when a Touch is actually opened, and a machine without
OpenHaptics gets one clear error naming what to install (docs/hardware.md §3d).

The servo callback runs ~1 kHz in OpenHaptics' scheduler thread: it reads the
stylus transform and buttons, checks ``hdGetError``, and writes what
:class:`pipeline.devices.touch_output.TouchOutput` renders from the latest command --
zero once the command is ``command_timeout_s`` old (10 ms: the loop
thread died or froze), clamped to the device's reported peak and derated by
the motor-heat model of its reported continuous rating (the same model as the
simulated Touch).  A few float operations per tick, no allocation beyond a
tuple.  Unlike pyOpenHaptics'
``hd_callback`` decorator -- which returns ``HD_CALLBACK_DONE`` on the first
error and so stops the servo loop for good -- our callback keeps running
after an HD error (exceeded force, warm motors) with the output disabled:
the error is reported through :class:`HapticState.error_code` (the loop's
``HAPTIC_DEVICE`` fault) and only :meth:`rearm` -- the experimenter's reset --
enables output again.

Several Touch devices (both arms of the rig) share ONE OpenHaptics servo
scheduler, :class:`TouchScheduler`: each device is opened by its OpenHaptics
name (``hdInitDevice``), and the one scheduled callback makes each device
current in turn (``hdMakeCurrentDevice``), frames it, reads it and writes its
force -- pyOpenHaptics' own callback serves only the current device (its issue
#10).  Every device keeps its own command watchdog, clamp, heat model and HD
errors: an error is charged to the device ``hdGetError`` names (``hHD``), so one
device's error disables that device's output only (what the other arms do is
the loop's ``fault_policy``).

The thin :class:`HDApi` / :class:`MultiHDApi` adapters are the seam to the C
library: tests drive the backend through fakes implementing them (no libHD on CI
machines).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from typing import Any, Protocol

from foundation.platform_support.files import add_dll_directory
from pipeline.core.clock import Clock, MonotonicClock
from pipeline.devices.interfaces import DeviceError, HapticState
from pipeline.devices.touch_output import (
    DEFAULT_COMMAND_TIMEOUT_S,
    DEFAULT_THERMAL_BUDGET_N2S,
    HD_WARM_MOTORS,
    TouchOutput,
    TouchSpec,
)
from pipeline.force.frames import Vec3

__all__ = [
    "HD_DEVICE_FAULT",
    "HD_FORCE_OUTPUT",
    "HD_MAX_FORCE_CLAMPING",
    "HD_NOMINAL_MAX_CONTINUOUS_FORCE",
    "HD_NOMINAL_MAX_FORCE",
    "TOUCH_INSTALL_HINT",
    "HDApi",
    "MultiHDApi",
    "PyOpenHapticsApi",
    "TouchHapticDevice",
    "TouchScheduler",
    "load_pyopenhaptics",
]

# HDAPI enums (pyOpenHaptics hd_define.py)
HD_FORCE_OUTPUT = 0x4000
HD_MAX_FORCE_CLAMPING = 0x4001
HD_NOMINAL_MAX_FORCE = 0x2603
HD_NOMINAL_MAX_CONTINUOUS_FORCE = 0x2604
HD_DEVICE_FAULT = 0x0300
HD_CALLBACK_DONE = 0
HD_CALLBACK_CONTINUE = 1

TOUCH_INSTALL_HINT = (
    "the 3D Systems Touch needs OpenHaptics: install the OpenHaptics SDK (3.4+) and the Touch device driver "
    "from 3D Systems (libHD.so on the library path; Windows: HD.dll in a system folder or [haptic] dll_dir), "
    "then pip install 'haptic-study[touch]' "
    "(pyOpenHaptics); or choose the simulated Touch"
)


class _DeviceCalls(Protocol):
    """The HDAPI calls on the current device, with one device or several."""

    def get_double(self, code: int) -> float:
        """``hdGetDoublev`` of a scalar."""
        ...

    def enable(self, code: int) -> None:
        """``hdEnable``."""
        ...

    def position_mm(self) -> Vec3:
        """Stylus position from ``HD_CURRENT_TRANSFORM``, mm, device frame."""
        ...

    def buttons(self) -> int:
        """``HD_CURRENT_BUTTONS`` bitmask."""
        ...

    def set_force(self, fx: float, fy: float, fz: float) -> None:
        """``hdSetDoublev(HD_CURRENT_FORCE)``, N, device frame."""
        ...


class MultiHDApi(_DeviceCalls, Protocol):
    """The HDAPI calls for several devices in one servo scheduler (:class:`TouchScheduler`), by handle."""

    def open_device(self, name: str) -> int:
        """``hdInitDevice``: the device's handle (it is now the current device); :class:`DeviceError` on failure."""
        ...

    def make_current(self, handle: int) -> None:
        """``hdMakeCurrentDevice``: the calls that follow read and write this device."""
        ...

    def begin_frame(self, handle: int) -> None:
        """``hdBeginFrame``."""
        ...

    def end_frame(self, handle: int) -> None:
        """``hdEndFrame``: the frame's force goes to the device."""
        ...

    def next_error(self) -> tuple[int, int]:
        """``hdGetError``: ``(errorCode, hHD)`` of the oldest error, popped; ``(0, 0)`` when there is none."""
        ...

    def schedule_frames(self, callback: Callable[[], None]) -> None:
        """``hdScheduleAsynchronous`` of a callback run every servo tick that frames each device itself."""
        ...

    def start_scheduler(self) -> None:
        """``hdStartScheduler``."""
        ...

    def stop_scheduler(self) -> None:
        """``hdStopScheduler``."""
        ...

    def close_handle(self, handle: int) -> None:
        """``hdDisableDevice(handle)``."""
        ...


class HDApi(_DeviceCalls, Protocol):
    """The HDAPI calls the backend uses for a Touch with a scheduler of its own (handle-less; one device)."""

    def init_device(self, name: str) -> None:
        """``hdInitDevice``; raises :class:`DeviceError` on failure."""
        ...

    def error_code(self) -> int:
        """``hdGetError().errorCode`` (0 = none); pops the error."""
        ...

    def schedule(self, callback: Callable[[], None]) -> None:
        """``hdScheduleAsynchronous`` of a callback run every servo tick between begin/end frame."""
        ...

    def start_scheduler(self) -> None:
        """``hdStartScheduler``."""
        ...

    def stop_scheduler(self) -> None:
        """``hdStopScheduler``."""
        ...

    def close_device(self) -> None:
        """``hdDisableDevice``."""
        ...


def load_pyopenhaptics(dll_dir: str | None = None) -> Any:
    """Import pyOpenHaptics (which loads libHD); :class:`DeviceError` with the install hint if it cannot.

    ``dll_dir`` (``[haptic] dll_dir``) is added to Windows' DLL search path
    first (:func:`foundation.platform_support.add_dll_directory`; nothing
    elsewhere): pyOpenHaptics loads ``HD.dll`` by name as it is imported, and
    Windows does not look on ``PATH`` for it.
    """
    if dll_dir is not None:
        try:
            add_dll_directory(dll_dir)
        except OSError as exc:
            raise DeviceError(f"haptic.dll_dir {dll_dir}: Windows refused it as a DLL folder ({exc}); give the "
                              "folder that holds HD.dll") from None
    try:
        import pyOpenHaptics.hd as hd  # loads libHD.so / HD.dll
        import pyOpenHaptics.hd_callback as hd_callback
        import pyOpenHaptics.hd_define as hd_define
    except ImportError as exc:
        raise DeviceError(f"{TOUCH_INSTALL_HINT} (pyOpenHaptics is not installed: {exc})") from None
    except OSError as exc:
        where = f"not in {dll_dir}" if dll_dir else "on Windows set [haptic] dll_dir to the folder holding HD.dll"
        raise DeviceError(f"{TOUCH_INSTALL_HINT} (OpenHaptics library not found: {exc}; {where})") from None
    return hd, hd_callback, hd_define


class PyOpenHapticsApi:
    """:class:`HDApi` and :class:`MultiHDApi` over pyOpenHaptics 1.0.1 (ctypes around libHD)."""

    def __init__(self, dll_dir: str | None = None) -> None:
        self._hd, self._cb, self._def = load_pyopenhaptics(dll_dir)
        self._handle: int | None = None
        self._cfunc: Any = None  # keep the ctypes callback alive while scheduled

    def open_device(self, name: str) -> int:
        """Open the device by its OpenHaptics name; pyOpenHaptics prints and returns None on failure, so check both."""
        import ctypes

        lib = self._cb._lib_hd
        lib.hdInitDevice.argtypes = [ctypes.c_char_p]
        lib.hdInitDevice.restype = self._def.HHD
        handle = lib.hdInitDevice(name.encode())
        code = self.error_code()
        if code or handle == self._def.HD_BAD_HANDLE:
            raise DeviceError(
                f"OpenHaptics could not open the haptic device {name!r} (HD error 0x{code:04x}); "
                "check the USB cable and the device name, and run Touch_Setup/Touch_Diagnostic"
            )
        return int(handle)

    def init_device(self, name: str) -> None:
        """Open the one device (:meth:`open_device`) and keep its handle."""
        self._handle = self.open_device(name)

    def error_code(self) -> int:
        return int(self._hd._get_error().errorCode)

    def next_error(self) -> tuple[int, int]:
        info = self._hd._get_error()
        code = int(info.errorCode)
        return (code, int(getattr(info, "hHD", 0))) if code else (0, 0)

    def make_current(self, handle: int) -> None:
        lib = self._cb._lib_hd
        lib.hdMakeCurrentDevice.argtypes = [self._def.HHD]
        lib.hdMakeCurrentDevice.restype = None
        lib.hdMakeCurrentDevice(handle)

    def begin_frame(self, handle: int) -> None:
        self._hd.begin_frame(handle)

    def end_frame(self, handle: int) -> None:
        self._hd.end_frame(handle)

    def get_double(self, code: int) -> float:
        import ctypes

        return float(self._hd._get_doublev(code, ctypes.c_double).value)

    def enable(self, code: int) -> None:
        lib = self._cb._lib_hd
        lib.hdEnable.argtypes = [self._def.HDenum]
        lib.hdEnable.restype = None
        lib.hdEnable(code)

    def schedule(self, callback: Callable[[], None]) -> None:
        hd = self._hd

        def _framed() -> None:
            dev = hd.get_current_device()
            hd.begin_frame(dev)
            callback()
            hd.end_frame(dev)

        self.schedule_frames(_framed)

    def schedule_frames(self, callback: Callable[[], None]) -> None:
        import ctypes

        def _tick(_user: Any) -> int:
            callback()
            return HD_CALLBACK_CONTINUE  # never DONE: an error must not end the servo loop for good

        self._cfunc = ctypes.CFUNCTYPE(self._def.HDCallbackCode, ctypes.POINTER(ctypes.c_void_p))(_tick)
        self._cb.hdAsyncSheduler(self._cfunc)

    def start_scheduler(self) -> None:
        self._hd.start_scheduler()

    def stop_scheduler(self) -> None:
        self._hd.stop_scheduler()

    def close_device(self) -> None:
        if self._handle is not None:
            self.close_handle(self._handle)
            self._handle = None

    def close_handle(self, handle: int) -> None:
        self._hd.close_device(handle)

    def position_mm(self) -> Vec3:
        t = self._hd.get_transform()  # column-major 4x4: translation in the last column
        return (float(t[3][0]), float(t[3][1]), float(t[3][2]))

    def buttons(self) -> int:
        return int(self._hd.get_buttons())

    def set_force(self, fx: float, fy: float, fz: float) -> None:
        self._hd.set_force([fx, fy, fz])


class TouchHapticDevice:
    """A :class:`pipeline.devices.interfaces.HapticDevice` for the 3D Systems Touch.

    Parameters
    ----------
    device_name
        OpenHaptics device name (Touch_Setup), ``"Default Device"`` by default.
    api
        The HDAPI adapter (default: :class:`PyOpenHapticsApi`, imported lazily); not with ``scheduler``.
    clock
        The loop's clock: stylus-state timestamps, and the command ages the servo judges freshness by.
    command_timeout_s
        A command this old renders as zero (the device-side watchdog), s.
    thermal_budget_n2s
        Heat budget of the motor-heat model, N²·s (peak and continuous rating are the device's own).
    dll_dir
        The folder holding ``HD.dll`` (``[haptic] dll_dir``), added to Windows' DLL search path before
        pyOpenHaptics is imported (when ``api`` is not given); None: the system's folders.
    scheduler
        Open the device into this shared servo scheduler (:meth:`TouchScheduler.open`) instead of starting one of
        its own; it is served once the scheduler starts.
    """

    def __init__(
        self,
        device_name: str = "Default Device",
        *,
        api: HDApi | None = None,
        clock: Clock | None = None,
        command_timeout_s: float = DEFAULT_COMMAND_TIMEOUT_S,
        thermal_budget_n2s: float = DEFAULT_THERMAL_BUDGET_N2S,
        dll_dir: str | None = None,
        scheduler: TouchScheduler | None = None,
    ) -> None:
        self.device_name = device_name
        self.clock: Clock = clock or MonotonicClock()
        self._scheduler = scheduler
        self._own: HDApi | None = None
        #: The device's handle in a shared scheduler (None with a scheduler of its own).
        self.handle: int | None = None
        if scheduler is None:
            self._own = api if api is not None else PyOpenHapticsApi(dll_dir)
            self._own.init_device(device_name)
            self.api: _DeviceCalls = self._own
        else:
            self.handle = scheduler.api.open_device(device_name)  # now the current device: enable/get act on it
            self.api = scheduler.api
        peak = self.api.get_double(HD_NOMINAL_MAX_FORCE)
        cont = self.api.get_double(HD_NOMINAL_MAX_CONTINUOUS_FORCE)
        if not (math.isfinite(peak) and peak > 0 and math.isfinite(cont) and 0 < cont <= peak):
            self._release()
            raise DeviceError(f"{device_name!r} reports nominal max force {peak!r} N / continuous {cont!r} N; expected "
                              "numbers > 0, the continuous one at most the peak")
        self._peak = peak
        self._cont = cont
        #: What the servo renders from the latest command (watchdog, clamp, derating, heat).
        self.output = TouchOutput(TouchSpec(peak, cont, thermal_budget_n2s), command_timeout_s)
        self._armed = True
        self._error = 0
        self.errors: list[int] = []  # every HD error seen, for the experimenter's log
        self.ticks = 0
        self._last_servo_ns: int | None = None
        self._state = HapticState(self.clock.now_ns(), (0.0, 0.0, 0.0), 0, 0, peak, 0.0)
        self._lock = threading.Lock()  # only rearm/servo hand-over; the servo never waits on the loop
        self.api.enable(HD_FORCE_OUTPUT)
        self.api.enable(HD_MAX_FORCE_CLAMPING)  # the device's own clamp as a second line of defence
        if self._own is not None:
            self._own.schedule(self._servo)
            self._own.start_scheduler()

    def _release(self) -> None:
        if self._own is not None:
            self._own.close_device()
        elif self._scheduler is not None and self.handle is not None:
            self._scheduler.api.close_handle(self.handle)

    # -- servo thread -------------------------------------------------------------------------
    def _servo(self) -> None:
        api = self.api
        x, y, z = api.position_mm()
        buttons = api.buttons()
        assert self._own is not None
        self._render(x, y, z, buttons, self._own.error_code())

    def hd_error(self, code: int) -> None:
        """An HD error of this device (servo thread): output off until :meth:`rearm`."""
        self._error = code
        self._armed = False
        self.errors.append(code)

    def _render(self, x: float, y: float, z: float, buttons: int, err: int) -> None:
        """One servo tick of this device, which is the current one: render the latest command, write it."""
        if err:
            self.hd_error(err)
        now = self.clock.now_ns()
        last = self._last_servo_ns
        self._last_servo_ns = now
        out = self.output
        fx, fy, fz = out.render(now, 0.0 if last is None else (now - last) * 1e-9, self._armed)
        if out.warm and self._armed:  # our own heat model passed the budget: as the device's HD_WARM_MOTORS
            self.hd_error(HD_WARM_MOTORS)
        self.api.set_force(fx, fy, fz)
        self.ticks += 1
        self._state = HapticState(now, (x * 1e-3, y * 1e-3, z * 1e-3), buttons, self._error, out.limit_n,
                                  out.heat.fraction)

    # -- HapticDevice -------------------------------------------------------------------------
    @property
    def peak_force_n(self) -> float:
        """Peak force the device reports (``HD_NOMINAL_MAX_FORCE``), N."""
        return self._peak

    @property
    def command_timeout_s(self) -> float:
        """A command this old renders as zero (the device-side watchdog), s."""
        return self.output.command_timeout_s

    @property
    def continuous_force_n(self) -> float:
        """Continuous force the device reports (``HD_NOMINAL_MAX_CONTINUOUS_FORCE``), N."""
        return self._cont

    def command_force(self, fx: float, fy: float, fz: float, t_ns: int | None = None) -> None:
        """Latest force to render, N, device frame, computed at ``t_ns`` on the loop's clock (default now).

        Rendered while fresh; clamped; non-finite → zero (:class:`pipeline.devices.touch_output.TouchOutput`).
        """
        self.output.command(fx, fy, fz, self.clock.now_ns() if t_ns is None else t_ns)

    def read_state(self) -> HapticState:
        """Newest stylus state from the servo callback (position in m)."""
        return self._state

    def rearm(self) -> bool:
        """Re-enable output after an HD error (the experimenter's reset); the command restarts from zero.

        After ``HD_WARM_MOTORS`` from the heat model, only once the motors have cooled to half the budget.
        """
        with self._lock:
            if not self.output.rearm():
                return False
            self._error = 0
            self._armed = True
            st = self._state
            self._state = st._replace(error_code=0)
        return True

    def close(self) -> None:
        """Zero the force, stop the servo loop and release the device.

        In a shared scheduler the device renders zero until the last of its devices is closed, which stops the
        scheduler and releases them all (:meth:`TouchScheduler.release`).
        """
        self.output.clear()
        self._armed = False
        if self._scheduler is not None:
            self._scheduler.release(self)
            return
        assert self._own is not None
        try:
            self._own.stop_scheduler()
        finally:
            self._own.close_device()



class TouchScheduler:
    """One OpenHaptics servo scheduler for several Touch devices (one per arm), selected by their device names.

    :meth:`open` each device (``hdInitDevice``; it is enabled while current), then :meth:`start` once
    (``hdStartScheduler``).  Every servo tick the one callback takes each device in turn: makes it current
    (``hdMakeCurrentDevice``), frames it, reads its stylus, charges the HD errors pending to the devices they name,
    and writes that device's own force -- its own command watchdog, clamp and heat model
    (:class:`TouchHapticDevice`).  An error naming no open device is charged to every device: whose it was is unknown,
    and the loop's fault policy decides what the arms do.

    Parameters
    ----------
    api
        The HDAPI adapter (default: :class:`PyOpenHapticsApi`, imported lazily).
    dll_dir
        As :class:`TouchHapticDevice`'s, when ``api`` is not given.
    """

    #: At most this many errors are drained per device and tick (the library's error stack is bounded anyway).
    MAX_ERRORS_PER_TICK = 8

    def __init__(self, api: MultiHDApi | None = None, dll_dir: str | None = None) -> None:
        self.api: MultiHDApi = api if api is not None else PyOpenHapticsApi(dll_dir)
        self.devices: list[TouchHapticDevice] = []
        self._by_handle: dict[int, TouchHapticDevice] = {}
        self._open: set[int] = set()
        self.running = False
        self._released = False

    def open(self, device_name: str, clock: Clock, command_timeout_s: float = DEFAULT_COMMAND_TIMEOUT_S,
             thermal_budget_n2s: float = DEFAULT_THERMAL_BUDGET_N2S) -> TouchHapticDevice:
        """Open the device called ``device_name`` into this scheduler (before :meth:`start`)."""
        if self.running or self._released:
            raise DeviceError(f"haptic device {device_name!r}: open every Touch before the servo scheduler starts")
        names = [d.device_name for d in self.devices]
        if device_name in names:
            raise DeviceError(f"haptic device {device_name!r} is opened already; each arm needs its own Touch")
        dev = TouchHapticDevice(device_name, clock=clock, command_timeout_s=command_timeout_s,
                                thermal_budget_n2s=thermal_budget_n2s, scheduler=self)
        assert dev.handle is not None
        self.devices.append(dev)
        self._by_handle[dev.handle] = dev
        self._open.add(id(dev))
        return dev

    def start(self) -> None:
        """Schedule the callback and start the servo loop (``hdStartScheduler``) for every device opened."""
        if not self.devices:
            raise DeviceError("no Touch opened: nothing for the servo scheduler to serve")
        self.api.schedule_frames(self._tick)
        self.api.start_scheduler()
        self.running = True

    def _tick(self) -> None:
        api = self.api
        for dev in self.devices:
            handle = dev.handle
            assert handle is not None
            api.make_current(handle)
            api.begin_frame(handle)
            try:
                x, y, z = api.position_mm()
                buttons = api.buttons()
                self._charge_errors()
                dev._render(x, y, z, buttons, 0)
            finally:
                api.end_frame(handle)

    def _charge_errors(self) -> None:
        for _ in range(self.MAX_ERRORS_PER_TICK):
            code, handle = self.api.next_error()
            if not code:
                return
            dev = self._by_handle.get(handle)
            for d in (dev,) if dev is not None else self.devices:
                d.hd_error(code)

    def release(self, dev: TouchHapticDevice) -> None:
        """``dev`` was closed: when it was the last open one, stop the scheduler and release every device."""
        self._open.discard(id(dev))
        if self._open or self._released:
            return
        self._released = True
        try:
            if self.running:
                self.running = False
                self.api.stop_scheduler()
        finally:
            for d in self.devices:
                assert d.handle is not None
                self.api.close_handle(d.handle)
