CALLBACK = None


class _Fn:
    def __init__(self, fn):
        self.fn = fn
        self.argtypes = None
        self.restype = None

    def __call__(self, *a):
        return self.fn(*a)


class _Lib:
    def __init__(self):
        self.hdInitDevice = _Fn(lambda name: 1)
        self.hdEnable = _Fn(lambda code: None)


_lib_hd = _Lib()


def hdAsyncSheduler(cfunc):
    global CALLBACK
    CALLBACK = cfunc
