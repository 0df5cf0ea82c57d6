import ctypes

HHD = ctypes.c_uint
HDenum = ctypes.c_uint
HDCallbackCode = ctypes.c_uint
HD_BAD_HANDLE = 0xFFFF
