"""3D Systems Touch through OpenHaptics (HDAPI): the device, the servo scheduler several share, and its backend.

The HDAPI calls go through :mod:`pipeline.backends.hdapi` (pyOpenHaptics,
imported only when a Touch is opened).

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

:class:`TouchBackend` is the Touch's backend in the device registry
(:mod:`pipeline.devices.registry`): one arm's Touch opened with a scheduler of
its own, two or more arms' into one shared :class:`TouchScheduler`.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence

from pipeline.backends.hdapi import (
    HD_FORCE_OUTPUT,
    HD_MAX_FORCE_CLAMPING,
    HD_NOMINAL_MAX_CONTINUOUS_FORCE,
    HD_NOMINAL_MAX_FORCE,
    DeviceCalls,
    HDApi,
    MultiHDApi,
    PyOpenHapticsApi,
)
from pipeline.core.clock import Clock, MonotonicClock
from pipeline.devices.interfaces import DeviceError, HapticDevice, HapticState
from pipeline.devices.registry import HapticConnection, HapticModel, haptic_model
from pipeline.devices.touch_output import DEFAULT_COMMAND_TIMEOUT_S, HD_WARM_MOTORS, HapticLimits, TouchOutput

__all__ = ["TouchBackend", "TouchHapticDevice", "TouchScheduler", "read_back_force"]

#: The motors' thermal budget of a Touch opened without its model (the peak and continuous rating are the device's
#: own report; the budget is not a device property OpenHaptics reports).
_TOUCH_BUDGET_N2S = haptic_model("touch").limits.thermal_budget_n2s


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
        Heat budget of the motor-heat model, N²·s (None: the Touch model's; peak and continuous rating are the
        device's own).
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
        thermal_budget_n2s: float | None = None,
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
            self.api: DeviceCalls = self._own
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
        budget = _TOUCH_BUDGET_N2S if thermal_budget_n2s is None else thermal_budget_n2s
        self.output = TouchOutput(HapticLimits(peak, cont, budget), command_timeout_s)
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



def read_back_force(device_name: str, dll_dir: str | None = None) -> tuple[float, float, float]:
    """What the Touch renders now (``HD_CURRENT_FORCE``), N, read by opening it without starting a servo scheduler:
    a scheduler of ours would write a force itself (``haptic-study qualify`` reads what the device does alone)."""
    api = PyOpenHapticsApi(dll_dir)
    api.init_device(device_name)
    try:
        return api.current_force()
    finally:
        api.close_device()


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
             thermal_budget_n2s: float | None = None) -> TouchHapticDevice:
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


class TouchBackend:
    """The Touch's backend in the device registry (:class:`pipeline.devices.registry.HapticBackend`).

    One arm's Touch is opened with a servo scheduler of its own; two or more arms' Touch devices are opened by
    their OpenHaptics names into one :class:`TouchScheduler` (OpenHaptics serves every device of a process from one
    scheduler), made when the first is opened and started by :meth:`start` once every one is open.

    Parameters
    ----------
    model
        The model opened (its thermal budget is the devices'; their peak and continuous rating are their own report).
    settings
        Every arm's ``[haptic]`` settings of this model.
    """

    def __init__(self, model: HapticModel, settings: Sequence[HapticConnection]) -> None:
        self.model = model
        self.shared = len(settings) > 1
        self.dll_dir = next((s.dll_dir for s in settings if s.dll_dir is not None), None)
        self.start_step: str | None = "haptic servo scheduler" if self.shared else None
        self.scheduler: TouchScheduler | None = None

    def open(self, settings: HapticConnection, clock: Clock) -> HapticDevice:
        """Open one arm's Touch (into the shared scheduler when there are several)."""
        budget = self.model.limits.thermal_budget_n2s
        if not self.shared:
            return TouchHapticDevice(settings.device_name, clock=clock, command_timeout_s=settings.command_timeout_s,
                                     thermal_budget_n2s=budget, dll_dir=settings.dll_dir)
        if self.scheduler is None:
            self.scheduler = TouchScheduler(dll_dir=self.dll_dir)
        return self.scheduler.open(settings.device_name, clock, settings.command_timeout_s, budget)

    def start(self) -> None:
        """Start the shared scheduler (nothing with one arm: its Touch runs from its opening)."""
        if self.scheduler is not None:
            self.scheduler.start()
