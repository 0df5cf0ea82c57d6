"""Every operating-system-specific call of the product, and what each does where the OS lacks it.

The product is developed and tested on Linux; a lab may run it on Windows
(where OpenHaptics and the Touch's drivers are most at home) or macOS.  So
nothing outside this module calls what only some systems have -- real-time
scheduling, CPU affinity, ``prctl``, POSIX shared-memory names, signals,
file modes and owners, ``O_NOFOLLOW`` and the other ``open`` flags,
``statvfs``/``sysconf``, ``ctypes`` into the C library
(``tests/pipeline/test_platform_support.py`` scans the source for them).
Each function here makes the Linux call exactly as the product always did,
and elsewhere does the documented fallback below; ``mypy --platform win32``
checks the Windows branches.

=========================== ============================== ===================================================
call                        elsewhere (Windows, macOS)      what the user loses there
=========================== ============================== ===================================================
timer slack (``prctl``)     nothing                        about 50 µs more median wake-up lateness of the loop
``SCHED_FIFO`` (loop and    normal priority; the loop's    the loop can be preempted by any process: a busy
helper threads)             ``scheduling`` says why (GUI)  machine shows in the loop's jitter figures
usable CPUs (affinity)      ``os.cpu_count()``             a CPU mask (``taskset``) is not honoured
worker processes            ``spawn``                      each worker imports the product afresh (slower
(``fork``)                                                  start of a parallel study)
die with the parent         nothing                        a killed command leaves its worker processes to
(``PR_SET_PDEATHSIG``;                                      finish their task (``run``: their participant,
:func:`die_with`)                                           each under its own session's lease)
hard kill (``SIGKILL``)     Windows: ``TerminateProcess``  nothing: both end the process with no clean-up
process exists (kill 0)     Windows: ``OpenProcess``       nothing (Windows' ``kill(pid, 0)`` would send
                                                            Ctrl-C, so it is never used there)
shared memory by name       ``SharedMemory(name)``         Windows: nothing (a segment dies with its last
(``/dev/shm``)                                              handle, so no orphan is left); macOS: the same
                                                            calls through ``shm_open``
owner-only study file       Windows: nothing               the file keeps its folder's access rights (ACL)
(``chmod 0600``)
file modes, umask,          Windows: no ``*at`` calls:     the same policy, but each step is a look then an
``O_NOFOLLOW``, ``dir_fd``  :data:`DIR_FD_CALLS` False:    act: a process that changes the output folder
                            the output policy walks paths, between the two (puts a link or junction where a
                            ``lstat``-checking each part   checked folder was) can win that race; the ``*at``
                            (no link, no junction: see     calls leave no such window.  New files keep the
                            :func:`redirects`) right       folder's access rights (no 0600)
                            before each open, rename and
                            remove (:mod:`foundation.outpath`)
free disk space             ``shutil.disk_usage``          nothing
(``statvfs``)
read-only mount             not detected ahead             the write fails instead, with the OS's error in
(``ST_RDONLY``)                                            one line
free memory (``sysconf``)   Windows: ``GlobalMemory-       nothing (untested on Windows)
                            StatusEx``
load average                None                           benchmarks print no load
jitter tracing (``pread``   nothing (tracer reads zeros)   ``--explain`` names no cause for a late tick
of ``/proc``, GIL kept)
process identity (boot id,  "" (``/proc`` absent)          a reused process id is not told apart from the
start time in ``/proc``)                                   lease's writer: the lease trusts its heartbeat
zombie check (``/proc``)    ``process_exists`` alone       a killed writer not yet reaped counts as alive
free memory (MemAvailable,  free physical memory only      the memory check is stricter (page cache not
cgroup v2 limit)                                           counted) and blind to a container's limit
CPU times (``/proc/stat``)  None                           benchmarks print no hypervisor steal
DLL search path             Linux, macOS: nothing (the     nothing: ``[haptic] dll_dir`` only tells Windows
(``add_dll_directory``)     loader's own path)             where HD.dll is
=========================== ============================== ===================================================

The garbage-collector and switch-interval settings of the loop's process
(:func:`pipeline.core.clock.manual_garbage_collection`, ``sys.setswitchinterval``)
are CPython's, the same on every system, so they are not here.
"""

from __future__ import annotations

import mmap
import os
import signal
import stat
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # multiprocessing is imported where it is used: a command that never needs it loads faster
    from multiprocessing.shared_memory import SharedMemory as SharedSegment  # the ring's segment

__all__ = [
    "DIR_FD_CALLS", "O_BINARY", "O_CLOEXEC", "O_DIRECTORY", "O_NOFOLLOW", "O_NOINHERIT", "O_NONBLOCK",
    "SharedSegment", "add_dll_directory", "attach_segment", "boot_id", "cgroup_memory_headroom", "cpu_times",
    "create_segment", "die_with", "die_with_parent", "free_orphaned_segment", "free_physical_bytes",
    "fs_free_bytes", "fs_read_only", "gil_keeping_pread", "kill_hard", "load_average", "may_write",
    "meminfo_available_bytes", "open_schedstat", "owner_only", "process_exists", "process_stat_fields", "redirects",
    "set_fd_mode", "set_fifo_priority", "set_folder_mode", "set_timer_slack_ns", "signal_name", "thread_ids",
    "umask", "usable_cpu_count", "worker_context", "worker_pool",
]

def _linux() -> bool:
    return sys.platform.startswith("linux")


def _libc() -> Any:
    import ctypes.util

    return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)


# -- the loop's threads ----------------------------------------------------------------------------------------
def set_timer_slack_ns(slack_ns: int = 1) -> bool:
    """Ask Linux to wake this thread's sleeps within ``slack_ns`` (``PR_SET_TIMERSLACK``; the default is 50 µs).

    Halves the median wake-up lateness of the loop (science.md §7).  Returns
    False where unsupported (not Linux), which only costs precision.
    """
    if not _linux():
        return False
    import ctypes

    try:
        PR_SET_TIMERSLACK = 29
        return bool(_libc().prctl(PR_SET_TIMERSLACK, ctypes.c_ulong(slack_ns), 0, 0, 0) == 0)
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


def gil_keeping_pread(size: int = 128) -> Callable[[int], bytes] | None:
    """Linux: a reader of the first ``size`` bytes of an open file by libc's ``pread``; None elsewhere.

    Through ``PyDLL``: the call keeps the GIL (no hand-over mid-tick).  The
    reader returns ``b""`` when nothing could be read.
    """
    if not _linux():
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


# -- processes -------------------------------------------------------------------------------------------------
if sys.platform != "win32":
    if TYPE_CHECKING:
        from multiprocessing.context import ForkContext, SpawnContext

    def worker_context() -> ForkContext | SpawnContext:
        """Linux: ``fork`` (workers inherit the imported modules) while this is the only thread; else ``spawn``."""
        import multiprocessing as mp

        if _linux() and threading.active_count() == 1:
            return mp.get_context("fork")
        return mp.get_context("spawn")
else:
    if TYPE_CHECKING:
        from multiprocessing.context import SpawnContext

    def worker_context() -> SpawnContext:
        """Windows has no ``fork``: ``spawn``."""
        import multiprocessing as mp

        return mp.get_context("spawn")


def die_with_parent() -> bool:
    """Linux: the kernel SIGKILLs this process when its parent dies (``PR_SET_PDEATHSIG``); False elsewhere."""
    if sys.platform == "win32" or not _linux():
        return False
    try:
        PR_SET_PDEATHSIG = 1
        return bool(_libc().prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0)
    except (OSError, AttributeError):  # pragma: no cover - no libc
        return False


def die_with(parent_pid: int) -> None:
    """A worker process's first act: die with ``parent_pid`` (:func:`die_with_parent`), or exit now if it is gone.

    The initializer of every pool of worker processes (:func:`worker_pool`, ``ProcessPoolExecutor(initializer=
    die_with, initargs=(os.getpid(),))``): a ``kill -9`` of a command leaves no orphaned worker computing on
    (and holding its memory) for ever.  The parent may die before the request takes effect: then the worker's
    parent is already another process, and it exits at once.
    """
    die_with_parent()  # (nothing where the OS cannot; the check below still catches a parent gone before the start)
    if os.getppid() != parent_pid:
        os._exit(1)


def worker_pool(processes: int, context: Any = None) -> Any:
    """A ``multiprocessing`` pool whose workers die with this process (:func:`die_with`).

    ``context``: the start method's context (default :func:`worker_context`).
    """
    ctx = worker_context() if context is None else context
    return ctx.Pool(processes, initializer=die_with, initargs=(os.getpid(),))


def kill_hard(pid: int) -> None:
    """End process ``pid`` at once, with no clean-up -- as ``kill -9`` or a crash would."""
    if sys.platform == "win32":
        os.kill(pid, signal.SIGTERM)  # Windows: TerminateProcess, as abrupt as SIGKILL
    else:
        os.kill(pid, signal.SIGKILL)


def signal_name(signum: int) -> str:
    """The name of signal ``signum`` (``SIGSEGV``), or ``an unknown signal`` where this OS has none of that number
    (a process's negative exit code names the signal that ended it, on POSIX)."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        return "an unknown signal"


def process_exists(pid: int) -> bool:
    """Whether a process of that id exists (one of another user's too); False for an impossible id."""
    if sys.platform == "win32":
        return _windows_process_exists(pid)
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # it exists, owned by someone else
        return True
    except (OverflowError, ValueError):
        return False
    return True


def boot_id() -> str:
    """This boot of the machine (Linux's ``boot_id``); empty where the OS does not say."""
    try:
        with open("/proc/sys/kernel/random/boot_id", encoding="ascii") as fh:
            return fh.read().strip()
    except OSError:
        return ""


def process_stat_fields(pid: int) -> list[str] | None:
    """The fields of ``/proc/<pid>/stat`` after the command name (field 3, the state, first); None without /proc."""
    try:
        with open(f"/proc/{int(pid)}/stat", encoding="ascii", errors="replace") as fh:
            stat = fh.read()
    except (OSError, ValueError, OverflowError):
        return None
    # the command name (field 2) may hold spaces and parentheses: count fields after the last ')'
    return stat[stat.rindex(")") + 2 :].split()


def _windows_process_exists(pid: int) -> bool:
    """``OpenProcess`` + ``GetExitCodeProcess`` (``os.kill(pid, 0)`` on Windows sends Ctrl-C instead)."""
    if sys.platform != "win32" or not 0 < pid < 2**32:
        return False
    import ctypes

    kernel32 = ctypes.windll.kernel32
    handle = kernel32.OpenProcess(0x1000, False, pid)  # PROCESS_QUERY_LIMITED_INFORMATION
    if not handle:
        return bool(kernel32.GetLastError() == 5)  # ERROR_ACCESS_DENIED: it exists, another user's
    try:
        code = ctypes.c_ulong()
        ok = kernel32.GetExitCodeProcess(handle, ctypes.byref(code))
        return bool(ok) and code.value == 259  # STILL_ACTIVE
    finally:
        kernel32.CloseHandle(handle)


# -- shared memory ---------------------------------------------------------------------------------------------
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
    if _linux():
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
    if _linux():
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


# -- files -----------------------------------------------------------------------------------------------------
if sys.platform != "win32":
    O_NOFOLLOW: int = os.O_NOFOLLOW
    O_DIRECTORY: int = os.O_DIRECTORY
    O_NONBLOCK: int = os.O_NONBLOCK
else:  # Windows has none of them; the output policy checks each path with lstat there (foundation.outpath)
    O_NOFOLLOW = O_DIRECTORY = O_NONBLOCK = 0
#: Close the descriptor in a child process (0 where the OS has no such flag: Windows does not inherit by default).
O_CLOEXEC: int = getattr(os, "O_CLOEXEC", 0)
#: Windows: bytes as they are (no newline translation) and no inheritance by a child; 0 elsewhere.
O_BINARY: int = getattr(os, "O_BINARY", 0)
O_NOINHERIT: int = getattr(os, "O_NOINHERIT", 0)
#: ``FILE_ATTRIBUTE_REPARSE_POINT``, and the tag bit of a reparse point that names another path (Windows).
_REPARSE_POINT = 0x400
_NAME_SURROGATE = 0x20000000
#: Whether the OS has the ``*at`` calls (``openat``, ``renameat``, ``O_NOFOLLOW``) the output policy is built on.
DIR_FD_CALLS: bool = (sys.platform != "win32" and os.open in os.supports_dir_fd and os.rename in os.supports_dir_fd
                      and hasattr(os, "O_NOFOLLOW"))


def redirects(path: str | os.PathLike[str], st: os.stat_result) -> bool:
    """Whether the entry at ``path`` (its ``lstat`` result ``st``) leads elsewhere: a symbolic link, or a junction.

    Windows: a junction (``os.path.isjunction`` from Python 3.12), or any
    reparse point whose tag names another path (junctions, symbolic links,
    mount points; the tag's name-surrogate bit); a reparse point that only
    stores data (a cloud placeholder, a deduplicated file) is an ordinary entry.
    """
    if stat.S_ISLNK(st.st_mode):
        return True
    if sys.platform != "win32":
        return False
    isjunction = getattr(os.path, "isjunction", None)
    if isjunction is not None and isjunction(path):
        return True
    return bool(st.st_file_attributes & _REPARSE_POINT and st.st_reparse_tag & _NAME_SURROGATE)


def set_folder_mode(path: str | os.PathLike[str], mode: int) -> None:
    """Set a folder's mode by path, never through a link (opened ``O_NOFOLLOW``, ``fchmod``); Windows: nothing."""
    if sys.platform == "win32":
        return
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | O_CLOEXEC)
    try:
        os.fchmod(fd, mode)
    finally:
        os.close(fd)


def add_dll_directory(path: str | os.PathLike[str]) -> bool:
    """Add ``path`` to the folders Windows searches for a DLL (``os.add_dll_directory``); False elsewhere.

    The Touch's Python binding (pyOpenHaptics) loads ``HD.dll`` by name; since
    Python 3.8 Windows no longer looks in ``PATH`` for the DLLs of an extension,
    so a lab that installed OpenHaptics outside the system folders names that
    folder (``[haptic] dll_dir``).  Linux and macOS find ``libHD`` through the
    loader's own path (``LD_LIBRARY_PATH``, ``ldconfig``): nothing to do there.
    The directory stays added for the life of the process.
    """
    if sys.platform != "win32":
        return False
    _DLL_DIRECTORIES.append(os.add_dll_directory(os.fspath(path)))  # kept: closing the handle removes it
    return True


_DLL_DIRECTORIES: list[object] = []


def owner_only(path: str | os.PathLike[str]) -> None:
    """Make a file this user owns readable by the user only (0600); Windows: nothing (the folder's ACL holds)."""
    if sys.platform == "win32":
        return
    if os.stat(path).st_uid == os.getuid():
        os.chmod(path, 0o600)


def umask() -> int:
    """The process's umask: read from /proc where Linux shows it (setting it to read it races with threads)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o077)
    os.umask(mask)
    return mask


def set_fd_mode(fd: int, mode: int) -> None:
    """``fchmod``; Windows has no file modes beyond read-only: nothing."""
    if sys.platform != "win32":
        os.fchmod(fd, mode)


def fs_free_bytes(folder: str | os.PathLike[str]) -> int | None:
    """Bytes an unprivileged user may still write in ``folder``'s file system (None: unknown)."""
    if sys.platform != "win32" and hasattr(os, "statvfs"):
        try:
            st = os.statvfs(folder)
        except OSError:
            return None
        return int(st.f_bavail * st.f_frsize)
    import shutil

    try:
        return shutil.disk_usage(folder).free
    except OSError:
        return None


def fs_read_only(folder: str | os.PathLike[str]) -> bool:
    """Whether ``folder`` lies on a file system mounted read-only (False where the OS cannot tell)."""
    if sys.platform == "win32" or not hasattr(os, "statvfs"):
        return False
    try:
        return bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def may_write(path: str | os.PathLike[str], mode: int = os.W_OK) -> bool:
    """Whether this user may write ``path`` (``mode``: ``os.W_OK``, with ``os.X_OK`` for a folder to create in).

    ``os.access``, and one thing more for the superuser, whom it always allows: a file or folder without any write
    bit (``chmod a-w``, an archive) is not written by root either -- in a container everyone is root, and the mode
    is the owner's word that this is not to be changed.
    """
    if not os.access(path, mode):
        return False
    if sys.platform != "win32" and os.geteuid() == 0:
        try:
            return bool(os.stat(path).st_mode & 0o222)
        except OSError:
            return False
    return True


# -- the machine -----------------------------------------------------------------------------------------------
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
