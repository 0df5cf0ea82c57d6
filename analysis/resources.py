"""What this machine can give a command: the memory it may still allocate.

A command whose memory grows with its arguments (``power --resamples``,
``sim --seconds``) asks :func:`available_memory_bytes` before it starts, and
refuses in one line (:func:`memory_problem`) a request that would not fit,
rather than dying with a ``MemoryError`` after an hour of work.
"""

from __future__ import annotations

from pathlib import Path

from pipeline.runtime.platform_support import free_physical_bytes

__all__ = ["available_memory_bytes", "memory_problem"]


def _meminfo_available() -> int | None:
    """``MemAvailable`` of /proc/meminfo (Linux ≥ 3.14): what can be allocated without swapping, in bytes."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _sysconf_available() -> int | None:
    """Free physical pages × page size (POSIX ``sysconf``; less than ``MemAvailable``: the page cache not counted)."""
    return free_physical_bytes()  # (Windows: GlobalMemoryStatusEx; platform_support)


def _cgroup_headroom() -> int | None:
    """Memory left under this process's cgroup-v2 limit (a container), or None when there is none."""
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


def available_memory_bytes() -> int | None:
    """Bytes this process may still allocate without swapping (None: the machine does not say).

    ``MemAvailable`` of /proc/meminfo, else ``sysconf``'s free pages; the
    lower of that and what a cgroup-v2 memory limit leaves.
    """
    found = _meminfo_available()
    if found is None:
        found = _sysconf_available()
    headroom = _cgroup_headroom()
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
