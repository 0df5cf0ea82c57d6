"""The seam to OpenHaptics' C library (HDAPI): the calls the Touch backend makes, and their pyOpenHaptics adapter.

``pip install 'haptic-study[touch]'`` plus the OpenHaptics SDK and Touch
driver from 3D Systems; ``pyOpenHaptics`` loads ``libHD.so`` at import time,
so it is imported only when a Touch is actually opened (:func:`load_pyopenhaptics`),
and a machine without OpenHaptics gets one clear error naming what to install
(docs/hardware.md §3d).

:class:`HDApi` (one device with a servo scheduler of its own) and
:class:`MultiHDApi` (several devices in one scheduler, by handle) are the
calls :mod:`pipeline.backends.touch` makes; :class:`PyOpenHapticsApi` makes
them through pyOpenHaptics (ctypes around libHD).  Tests drive the backend
through fakes implementing the same calls (no libHD on CI machines).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from foundation.platform_support.files import add_dll_directory
from pipeline.devices.interfaces import DeviceError
from pipeline.force.frames import Vec3

__all__ = [
    "HD_CALLBACK_CONTINUE",
    "HD_CURRENT_FORCE",
    "HD_DEVICE_FAULT",
    "HD_FORCE_OUTPUT",
    "HD_MAX_FORCE_CLAMPING",
    "HD_NOMINAL_MAX_CONTINUOUS_FORCE",
    "HD_NOMINAL_MAX_FORCE",
    "TOUCH_INSTALL_HINT",
    "DeviceCalls",
    "HDApi",
    "MultiHDApi",
    "PyOpenHapticsApi",
    "load_pyopenhaptics",
]

# HDAPI enums (pyOpenHaptics hd_define.py)
HD_FORCE_OUTPUT = 0x4000
HD_MAX_FORCE_CLAMPING = 0x4001
HD_NOMINAL_MAX_FORCE = 0x2603
HD_NOMINAL_MAX_CONTINUOUS_FORCE = 0x2604
#: ``HD_CURRENT_FORCE`` (hdDefines.h): the force the device renders now, N, three doubles.
HD_CURRENT_FORCE = 0x2700
HD_DEVICE_FAULT = 0x0300
HD_CALLBACK_DONE = 0
HD_CALLBACK_CONTINUE = 1

TOUCH_INSTALL_HINT = (
    "the 3D Systems Touch needs OpenHaptics: install the OpenHaptics SDK (3.4+) and the Touch device driver "
    "from 3D Systems (libHD.so on the library path; Windows: HD.dll in a system folder or [haptic] dll_dir), "
    "then pip install 'haptic-study[touch]' "
    "(pyOpenHaptics); or choose the simulated Touch"
)


class DeviceCalls(Protocol):
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


class MultiHDApi(DeviceCalls, Protocol):
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


class HDApi(DeviceCalls, Protocol):
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
    first (:func:`foundation.platform_support.files.add_dll_directory`; nothing
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

    def current_force(self) -> Vec3:
        """The force the current device renders now (``hdGetDoublev(HD_CURRENT_FORCE)``), N, device frame."""
        import ctypes

        lib = self._cb._lib_hd
        out = (ctypes.c_double * 3)()
        lib.hdGetDoublev.argtypes = [self._def.HDenum, ctypes.POINTER(ctypes.c_double)]
        lib.hdGetDoublev.restype = None
        lib.hdGetDoublev(HD_CURRENT_FORCE, out)
        return (float(out[0]), float(out[1]), float(out[2]))

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
