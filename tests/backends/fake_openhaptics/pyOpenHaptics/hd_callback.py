CALLBACK = None


class _Fn:
    def __init__(self, fn):
        self.fn = fn
        self.argtypes = None
        self.restype = None

    def __call__(self, *a):
        return self.fn(*a)


def _init_device(name):
    from pyOpenHaptics import hd

    handle = len(hd.STATE["names"]) + 1  # libHD hands out a handle per device; the new device is current
    hd.STATE["names"][handle] = name.decode()
    hd.STATE["current"] = handle
    return handle


def _make_current(handle):
    from pyOpenHaptics import hd

    hd.STATE["current"] = handle


def _get_doublev(code, out):
    from pyOpenHaptics import hd

    if code == 0x2700:  # HD_CURRENT_FORCE
        out[0], out[1], out[2] = hd.current_force()
    else:
        out[0] = {0x2603: 3.3, 0x2604: 0.88}[code]


class _Lib:
    def __init__(self):
        self.hdGetDoublev = _Fn(_get_doublev)
        self.hdInitDevice = _Fn(_init_device)
        self.hdEnable = _Fn(lambda code: None)
        self.hdMakeCurrentDevice = _Fn(_make_current)


_lib_hd = _Lib()


def hdAsyncSheduler(cfunc):
    global CALLBACK
    CALLBACK = cfunc
