"""The fake libHD's calls (see the package's docstring).

The device outlives the process that drives it (for ``haptic-study qualify``): with ``FAKE_TOUCH_STATE`` naming a
file, every force written is kept there with its time, and ``hdGetDoublev(HD_CURRENT_FORCE)`` -- from this process
or a later one -- reports it, as the Touch's own hardware would: zero once no force has been written for
``DEVICE_WATCHDOG_S`` (a correct device), or the last force for ever with ``FAKE_TOUCH_KEEPS_FORCE=1`` (a device
that keeps its force after its process died).
"""
import os
import struct
import threading
import time
from types import SimpleNamespace

STATE = {"force": [0.0, 0.0, 0.0], "running": False, "buttons": 0, "names": {}, "current": 0, "forces": {},
         "frames": []}


def _get_error():
    return SimpleNamespace(errorCode=0)


def _get_doublev(code, ctype):
    return ctype({0x2603: 3.3, 0x2604: 0.88}[code])


def get_current_device():
    return 1


def _frame(what, dev):
    if len(STATE["frames"]) < 1000:  # the first servo ticks are enough to look at
        STATE["frames"].append((what, dev, STATE["current"]))


def begin_frame(dev):
    _frame("begin", dev)


def end_frame(dev):
    _frame("end", dev)


def _servo():
    from pyOpenHaptics import hd_callback

    while STATE["running"]:
        if hd_callback.CALLBACK is not None:
            hd_callback.CALLBACK(None)
        time.sleep(0.001)


def start_scheduler():
    STATE["running"] = True
    threading.Thread(target=_servo, daemon=True).start()


def stop_scheduler():
    STATE["running"] = False


def close_device(handle):
    pass


def get_transform():
    t = [[0.0] * 4 for _ in range(4)]
    t[3][:3] = [0.0, 10.0, 0.0]
    return t


def get_buttons():
    return STATE["buttons"]


def set_force(f):
    STATE["force"] = list(f)
    STATE["forces"][STATE["current"]] = list(f)  # the current device's, as libHD
    path = os.environ.get("FAKE_TOUCH_STATE")
    if path:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
        try:
            os.pwrite(fd, struct.pack("<4d", *(float(v) for v in f), time.monotonic()), 0)
        finally:
            os.close(fd)


#: The fake device zeroes its motors once the host has written nothing for this long, s.
DEVICE_WATCHDOG_S = 0.010


def current_force():
    """What the device renders now (``HD_CURRENT_FORCE``), from the kept state; see the module docstring."""
    path = os.environ.get("FAKE_TOUCH_STATE")
    if not path or not os.path.exists(path):
        return list(STATE["force"])
    with open(path, "rb") as fh:
        fx, fy, fz, t = struct.unpack("<4d", fh.read(32))
    if os.environ.get("FAKE_TOUCH_KEEPS_FORCE") != "1" and time.monotonic() - t > DEVICE_WATCHDOG_S:
        return [0.0, 0.0, 0.0]
    return [fx, fy, fz]
