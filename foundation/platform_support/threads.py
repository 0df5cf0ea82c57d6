"""The loop's threads: the timer slack, real-time priority, the usable CPUs, and what the jitter tracer reads of them.

One job of the operating-system layer: :mod:`foundation.platform_support` says, for every call, what it does
where the OS lacks it and what the user loses there.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable

from foundation.platform_support.system import c_library, on_linux

__all__ = ["gil_keeping_pread", "open_schedstat", "pin_to_cpu", "set_fifo_priority", "set_timer_slack_ns",
           "thread_ids", "usable_cpu_count", "usable_cpus"]


def set_timer_slack_ns(slack_ns: int = 1) -> bool:
    """Ask Linux to wake this thread's sleeps within ``slack_ns`` (``PR_SET_TIMERSLACK``; the default is 50 µs).

    Halves the median wake-up lateness of the loop (science.md §7).  Returns
    False where unsupported (not Linux), which only costs precision.
    """
    if not on_linux():
        return False
    import ctypes

    try:
        PR_SET_TIMERSLACK = 29
        return bool(c_library().prctl(PR_SET_TIMERSLACK, ctypes.c_ulong(slack_ns), 0, 0, 0) == 0)
    except (OSError, AttributeError):
        return False


def set_fifo_priority(priority: int) -> str:
    """``SCHED_FIFO`` at ``priority`` for the calling thread; ``"SCHED_FIFO/<p>"`` or ``"normal (…why…)"``."""
    if sys.platform == "win32" or not hasattr(os, "sched_setscheduler"):
        return "normal (no real-time scheduling on this platform)"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (PermissionError, OSError) as exc:
        return f"normal ({exc.strerror or exc})"
    return f"SCHED_FIFO/{priority}"


def usable_cpu_count() -> int:
    """The CPUs this process may run on: its affinity mask (Linux), else every CPU."""
    if sys.platform != "win32" and hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def usable_cpus() -> list[int]:
    """The CPUs this process may run on, in order: its affinity mask (Linux), else ``0 .. cpu_count - 1``."""
    if sys.platform != "win32" and hasattr(os, "sched_getaffinity"):
        return sorted(os.sched_getaffinity(0))
    return list(range(os.cpu_count() or 1))


def pin_to_cpu(cpu: int) -> str:
    """Run the calling process (every thread it starts afterwards too) on CPU ``cpu`` only; what it got.

    Returns ``"CPU <n>"``, or ``"any CPU (…why…)"`` where the OS has no affinity call (Windows, macOS: the
    scheduler places the loop as it likes) or refuses the mask.
    """
    if sys.platform == "win32" or not hasattr(os, "sched_setaffinity"):
        return "any CPU (no CPU affinity on this platform)"
    try:
        os.sched_setaffinity(0, {int(cpu)})
    except (OSError, ValueError) as exc:
        return f"any CPU ({getattr(exc, 'strerror', None) or exc})"
    return f"CPU {int(cpu)}"


def gil_keeping_pread(size: int = 128) -> Callable[[int], bytes] | None:
    """Linux: a reader of the first ``size`` bytes of an open file by libc's ``pread``; None elsewhere.

    Through ``PyDLL``: the call keeps the GIL (no hand-over mid-tick).  The
    reader returns ``b""`` when nothing could be read.
    """
    if not on_linux():
        return None
    import ctypes

    try:
        fn = ctypes.PyDLL(None).pread
        fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_size_t, ctypes.c_long]
        fn.restype = ctypes.c_ssize_t
    except (OSError, AttributeError):
        return None
    buf = ctypes.create_string_buffer(size)

    def read(fd: int) -> bytes:
        n = int(fn(fd, buf, size, 0))
        return buf.raw[:n] if n > 0 else b""

    return read


def thread_ids() -> list[int] | None:
    """The kernel's ids of this process's threads (``/proc/self/task``; None where the OS does not list them)."""
    try:
        return [int(x) for x in os.listdir("/proc/self/task")]
    except (OSError, ValueError):
        return None


def open_schedstat(tid: int) -> int:
    """An open descriptor of thread ``tid``'s scheduler counters (``/proc/self/task/<tid>/schedstat``), or -1."""
    try:
        return os.open(f"/proc/self/task/{tid}/schedstat", os.O_RDONLY)
    except OSError:
        return -1
