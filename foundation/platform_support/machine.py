"""The machine: free memory (physical, MemAvailable, a cgroup's limit), CPU times and the load average.

One job of the operating-system layer: :mod:`foundation.platform_support` says, for every call, what it does
where the OS lacks it and what the user loses there.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["cgroup_memory_headroom", "cpu_times", "free_physical_bytes", "load_average", "meminfo_available_bytes"]


def free_physical_bytes() -> int | None:
    """Free physical memory (POSIX ``sysconf``; Windows ``GlobalMemoryStatusEx``), or None."""
    if sys.platform == "win32":
        return _windows_available_physical()
    try:
        pages, size = os.sysconf("SC_AVPHYS_PAGES"), os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, AttributeError):
        return None
    return pages * size if pages > 0 and size > 0 else None


def meminfo_available_bytes() -> int | None:
    """``MemAvailable`` of /proc/meminfo (Linux ≥ 3.14): what can be allocated without swapping; None elsewhere."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def cgroup_memory_headroom() -> int | None:
    """Memory left under this process's cgroup-v2 limit (a Linux container), or None when there is none."""
    try:
        rel = next(line.split(":", 2)[2].strip() for line in Path("/proc/self/cgroup").read_text().splitlines()
                   if line.startswith("0::"))
        base = Path("/sys/fs/cgroup") / rel.lstrip("/")
        limit = (base / "memory.max").read_text().strip()
        if limit == "max":
            return None
        return max(0, int(limit) - int((base / "memory.current").read_text().strip()))
    except (OSError, ValueError, StopIteration, IndexError):
        return None


def cpu_times() -> list[int] | None:
    """The machine's aggregate CPU times (first line of ``/proc/stat``: user … steal), or None off Linux."""
    try:
        with open("/proc/stat", encoding="ascii") as fh:
            return [int(x) for x in fh.readline().split()[1:9]]
    except (OSError, ValueError):
        return None


def _windows_available_physical() -> int | None:
    if sys.platform != "win32":
        return None
    import ctypes

    class _Status(ctypes.Structure):
        _fields_ = [("dwLength", ctypes.c_ulong), ("dwMemoryLoad", ctypes.c_ulong),
                    ("ullTotalPhys", ctypes.c_ulonglong), ("ullAvailPhys", ctypes.c_ulonglong),
                    ("ullTotalPageFile", ctypes.c_ulonglong), ("ullAvailPageFile", ctypes.c_ulonglong),
                    ("ullTotalVirtual", ctypes.c_ulonglong), ("ullAvailVirtual", ctypes.c_ulonglong),
                    ("ullAvailExtendedVirtual", ctypes.c_ulonglong)]

    status = _Status()
    status.dwLength = ctypes.sizeof(_Status)
    if not ctypes.windll.kernel32.GlobalMemoryStatusEx(ctypes.byref(status)):
        return None
    return int(status.ullAvailPhys) or None


def load_average() -> tuple[float, float, float] | None:
    """The 1, 5 and 15 minute load averages (None where the OS keeps none: Windows)."""
    if sys.platform == "win32" or not hasattr(os, "getloadavg"):
        return None
    try:
        return os.getloadavg()
    except OSError:
        return None
