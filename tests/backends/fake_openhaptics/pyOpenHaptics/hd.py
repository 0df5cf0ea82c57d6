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
