"""What every job of the operating-system layer asks first: is this Linux, and the C library's handle."""

from __future__ import annotations

import sys
from typing import Any

__all__ = ["c_library", "on_linux"]


def on_linux() -> bool:
    """This process runs on Linux (the system each call's first branch is for)."""
    return sys.platform.startswith("linux")


def c_library() -> Any:
    """The C library, for the calls Python does not wrap (``prctl``)."""
    import ctypes.util

    return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
