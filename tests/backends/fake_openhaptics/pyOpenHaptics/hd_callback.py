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


class _Lib:
    def __init__(self):
        self.hdInitDevice = _Fn(_init_device)
        self.hdEnable = _Fn(lambda code: None)
        self.hdMakeCurrentDevice = _Fn(_make_current)


_lib_hd = _Lib()


def hdAsyncSheduler(cfunc):
    global CALLBACK
    CALLBACK = cfunc
