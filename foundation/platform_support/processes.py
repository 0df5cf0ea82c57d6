"""Processes: worker pools whose workers die with their parent, the hard kill, a process's existence and identity.

One job of the operating-system layer: :mod:`foundation.platform_support` says, for every call, what it does
where the OS lacks it and what the user loses there.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from foundation.platform_support.system import c_library, on_linux

__all__ = ["boot_id", "die_with", "die_with_parent", "exit_description", "ignore_interrupts", "kill_hard",
           "process_exists",
           "process_stat_fields", "signal_name", "socket_handover", "spawn_with_socket", "worker_context",
           "worker_pool"]


if sys.platform != "win32":
    if TYPE_CHECKING:
        from multiprocessing.context import ForkContext, SpawnContext

    def worker_context() -> ForkContext | SpawnContext:
        """Linux: ``fork`` (workers inherit the imported modules) while this is the only thread; else ``spawn``."""
        import multiprocessing as mp

        if on_linux() and threading.active_count() == 1:
            return mp.get_context("fork")
        return mp.get_context("spawn")
else:
    if TYPE_CHECKING:
        from multiprocessing.context import SpawnContext

    def worker_context() -> SpawnContext:
        """Windows has no ``fork``: ``spawn``."""
        import multiprocessing as mp

        return mp.get_context("spawn")


def die_with_parent(on: bool = True) -> bool:
    """Linux: the kernel SIGKILLs this process when its parent dies (``PR_SET_PDEATHSIG``; ``on=False`` withdraws
    it); False elsewhere."""
    if sys.platform == "win32" or not on_linux():
        return False
    try:
        PR_SET_PDEATHSIG = 1
        return bool(c_library().prctl(PR_SET_PDEATHSIG, signal.SIGKILL if on else 0, 0, 0, 0) == 0)
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


def socket_handover() -> bool:
    """Whether :func:`spawn_with_socket` can start a process with a socket open in it (POSIX: yes; Windows: no)."""
    return sys.platform != "win32"


def spawn_with_socket(argv: Sequence[str], sock: socket.socket,
                      env: dict[str, str] | None = None) -> subprocess.Popen[bytes] | None:
    """Start ``argv`` with ``sock`` open in it; None where a socket cannot be handed to a new process this way.

    POSIX: the socket's descriptor stays open in the child under the same number (``pass_fds``); the child
    adopts it with ``socket.socket(fileno=N)`` (append N to ``argv`` yourself).  Windows hands sockets over
    differently (``socket.share`` with the child's id): not done, so the caller keeps the work in its own process.
    """
    if sys.platform == "win32" or not socket_handover():
        return None
    return subprocess.Popen(list(argv), pass_fds=(sock.fileno(),), env=env)


def ignore_interrupts() -> None:
    """Ignore Ctrl-C (``SIGINT``) in this process: it ends when the process that drives it says so, or goes away
    (a terminal's Ctrl-C reaches every process of its group at once)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


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


def exit_description(exitcode: int | None) -> str:
    """How a process ended, for a lab's bug report: ``killed by SIGSEGV (signal 11)``, ``exit status 1``."""
    if exitcode is None:
        return "still running"
    if exitcode < 0:
        return f"killed by {signal_name(-exitcode)} (signal {-exitcode})"
    return f"exit status {exitcode}"


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
