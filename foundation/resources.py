"""What this machine can give a command: the memory it may still allocate.

A command whose memory grows with its arguments (``power --resamples``,
``sim --seconds``) asks :func:`available_memory_bytes` before it starts, and
refuses in one line (:func:`memory_problem`) a request that would not fit,
rather than dying with a ``MemoryError`` after an hour of work.
"""

from __future__ import annotations

from foundation.platform_support.machine import cgroup_memory_headroom, free_physical_bytes, meminfo_available_bytes

__all__ = ["available_memory_bytes", "memory_problem"]


def available_memory_bytes() -> int | None:
    """Bytes this process may still allocate without swapping (None: the machine does not say).

    ``MemAvailable`` of /proc/meminfo, else ``sysconf``'s free pages; the
    lower of that and what a cgroup-v2 memory limit leaves (each read by
    :mod:`foundation.platform_support`, None where the OS lacks it).
    """
    found = meminfo_available_bytes()
    if found is None:
        found = free_physical_bytes()  # sysconf's free pages (Windows: GlobalMemoryStatusEx)
    headroom = cgroup_memory_headroom()
    if headroom is not None:
        found = headroom if found is None else min(found, headroom)
    return found


def memory_problem(need_bytes: float, what: str, advice: str) -> str | None:
    """One line when ``need_bytes`` will not fit in the available memory (None: it fits, or nobody can say).

    Parameters
    ----------
    need_bytes
        What the request will allocate at its peak.
    what
        The request, e.g. ``"power: --n 10000 with --resamples 1000000"``.
    advice
        What to do instead, e.g. ``"ask for fewer --resamples"``.
    """
    have = available_memory_bytes()
    if have is None or need_bytes <= have:
        return None
    return (f"{what} needs about {_size(need_bytes)} of memory; this machine has {_size(have)} available; "
            f"{advice}")


def _size(n: float) -> str:
    for unit, scale in (("GiB", 2**30), ("MiB", 2**20)):
        if n >= scale:
            return f"{n / scale:,.1f} {unit}"
    return f"{n / 1024:,.0f} KiB"
