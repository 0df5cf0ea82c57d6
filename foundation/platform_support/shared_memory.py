"""Shared memory by name: the ring buffer's segment, created, attached and freed when orphaned.

One job of the operating-system layer: :mod:`foundation.platform_support` says, for every call, what it does
where the OS lacks it and what the user loses there.
"""

from __future__ import annotations

import mmap
import os
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING

from foundation.platform_support.system import on_linux

if TYPE_CHECKING:  # multiprocessing is imported where it is used: a command that never needs it loads faster
    from multiprocessing.shared_memory import SharedMemory as SharedSegment  # the ring's segment

__all__ = ["SharedSegment", "attach_segment", "create_segment", "free_orphaned_segment"]


def create_segment(size: int) -> SharedSegment:
    """A new shared-memory segment of ``size`` bytes, under a fresh name (the creator unlinks it)."""
    from multiprocessing import shared_memory

    return shared_memory.SharedMemory(create=True, size=size)


def _segment_path(name: str) -> str:
    """Where a POSIX shared-memory segment of that name lives (Linux)."""
    return os.path.join("/dev/shm", name.lstrip("/"))


def attach_segment(name: str) -> tuple[memoryview, Callable[[], None]] | None:
    """Map another process's segment: (its bytes, release); None when there is none of that name.

    Linux maps ``/dev/shm/<name>`` directly rather than through ``SharedMemory``:
    on Python < 3.13 an attached ``SharedMemory`` is registered with the resource
    tracker, which unlinks the writer's segment when the reader exits.
    Elsewhere ``SharedMemory(name)``, unregistered from the tracker on POSIX.
    """
    if on_linux():
        path = _segment_path(name)
        if not os.path.exists(path):
            return None
        fd = os.open(path, os.O_RDWR)
        try:
            mm = mmap.mmap(fd, 0)
        finally:
            os.close(fd)
        return memoryview(mm), mm.close
    from multiprocessing import shared_memory

    try:
        shm = shared_memory.SharedMemory(name=name)
    except FileNotFoundError:
        return None
    if sys.platform != "win32":
        _untrack(name)
    assert shm.buf is not None  # None only once closed
    return shm.buf, shm.close


def _untrack(name: str) -> None:
    try:
        from multiprocessing import resource_tracker

        resource_tracker.unregister("/" + name.lstrip("/"), "shared_memory")
    except Exception:  # the tracker is only told to keep quiet
        pass


def free_orphaned_segment(name: str) -> bool:
    """Unlink the segment ``name`` whose creator died without freeing it; True if freed.

    Windows frees a mapping with its last handle, so no orphan exists there (False).
    """
    if not name or sys.platform == "win32":
        return False
    if on_linux():
        path = _segment_path(name)
        if not os.path.exists(path):
            return False
        try:
            os.unlink(path)
        except OSError:
            return False
        _untrack(name)
        return True
    from multiprocessing import shared_memory

    try:
        shm = shared_memory.SharedMemory(name=name)
    except (FileNotFoundError, OSError):
        return False
    shm.close()
    shm.unlink()  # also unregisters it from the tracker
    return True
