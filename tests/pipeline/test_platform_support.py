"""The operating system behind one package (``foundation/platform_support/``), and its fallbacks.

The source of every module is scanned with ``ast`` for calls only some systems have (real-time scheduling, CPU
affinity, signals, ``prctl``/``ctypes``, shared-memory names, file modes and owners, ``open`` flags and ``dir_fd``,
``statvfs``, ``sysconf``, the ``fork`` start method, paths in ``/proc`` and ``/sys``): none may stand outside the
platform module; the scan is shown to find
them.  Then each fallback runs on this Linux machine with ``sys.platform`` set to the system that needs it (the
Windows API calls through ``ctypes.windll`` answered by a fake: the branch's logic is tested here, the real
Windows calls are not).
"""

from __future__ import annotations

import ast
import ctypes
import os
import shutil
import signal
import socket
import sys
import threading
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from foundation import outfs
from foundation.outdir import check_output_folder
from foundation.platform_support import files, machine, processes, threads
from pipeline.core.clock import prepare_realtime_thread
from pipeline.runtime.ring import RingBuffer

ROOT = Path(__file__).resolve().parent.parent.parent
SCANNED = ("foundation", "pipeline", "protocol", "analysis", "study_app", "bench")
PLATFORM = "foundation/platform_support/"

_MODULES = {"ctypes", "fcntl", "signal", "resource", "msvcrt", "winreg", "_winapi", "posix", "termios",
            "multiprocessing.shared_memory", "multiprocessing.resource_tracker"}
_OS_NAMES = {"sched_setscheduler", "sched_getscheduler", "sched_getaffinity", "sched_setaffinity", "sched_param",
             "SCHED_FIFO", "SCHED_RR", "mlockall", "munlockall", "kill", "killpg", "setsid", "setpgrp", "getpgid",
             "chmod", "fchmod", "lchmod", "chown", "fchown", "umask", "getuid", "geteuid", "O_NOFOLLOW",
             "O_DIRECTORY", "O_NONBLOCK", "O_CLOEXEC", "statvfs", "fstatvfs", "ST_RDONLY", "sysconf", "getloadavg",
             "nice", "setpriority", "fork"}
_DIR_FD = {"dir_fd", "src_dir_fd", "dst_dir_fd"}

#: Modules allowed one kind of call, each with why (the list may only shrink: an entry with no such call fails).
ALLOWED: dict[tuple[str, str], str] = {
    ("pipeline/backends/hdapi.py", "import ctypes"): "the Touch's own C API (OpenHaptics HD, HD.dll / libHD.so) "
                                                     "through pyOpenHaptics: the device's library, not the OS",
    ("foundation/outfs.py", "dir_fd"): "the output policy's file-descriptor primitives: every walk starts in "
                                     "open_folder, which hands the walk to foundation.outpath (by checked paths) "
                                     "where platform_support.DIR_FD_CALLS is False",
}


def os_calls_in(source: str) -> list[tuple[int, str]]:
    """Where a module's source makes an OS-specific call: (line, kind), kinds as in :data:`ALLOWED`."""
    found: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, f"import {a.name}") for a in node.names
                      if a.name in _MODULES or a.name.split(".")[0] in _MODULES]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names = {f"{node.module}.{a.name}" for a in node.names} | {node.module}
            if node.module == "os":
                found += [(node.lineno, f"os.{a.name}") for a in node.names if a.name in _OS_NAMES]
            elif names & _MODULES or node.module.split(".")[0] in _MODULES:
                found.append((node.lineno, f"import {node.module}"))
        elif (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "os"
              and node.attr in _OS_NAMES):
            found.append((node.lineno, f"os.{node.attr}"))
        elif isinstance(node, ast.Call):
            f = node.func
            args = [a.value for a in node.args if isinstance(a, ast.Constant)]
            if isinstance(f, ast.Name) and f.id in ("getattr", "hasattr") and len(node.args) >= 2 \
                    and isinstance(node.args[0], ast.Name) and node.args[0].id == "os" and args \
                    and args[0] in _OS_NAMES:
                found.append((node.lineno, f"os.{args[0]}"))
            if isinstance(f, ast.Attribute) and f.attr == "get_context" and "fork" in args:
                found.append((node.lineno, "fork"))
            found += [(node.lineno, "dir_fd") for k in node.keywords if k.arg in _DIR_FD]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and "/dev/shm" in node.value:
            found.append((node.lineno, "/dev/shm"))
        if isinstance(node, (ast.Constant, ast.JoinedStr)):
            first = node.values[0] if isinstance(node, ast.JoinedStr) and node.values else node
            text = first.value if isinstance(first, ast.Constant) else None
            if isinstance(text, str) and (text.startswith(("/proc/", "/sys/")) or text in ("/proc", "/sys")):
                found.append((node.lineno, "/proc"))
    return sorted(set(found))


def _modules() -> list[Path]:
    return sorted(p for pkg in SCANNED for p in (ROOT / pkg).rglob("*.py") if ".venv" not in p.parts)


def test_the_scan_finds_os_calls() -> None:
    src = ("import signal, ctypes.util\nfrom multiprocessing import shared_memory\nos.kill(p, signal.SIGKILL)\n"
           "f = getattr(os, 'O_CLOEXEC', 0)\nmp.get_context('fork')\nos.open(n, 0, dir_fd=d)\np = '/dev/shm/x'\n"
           "from os import sched_getaffinity\nos.path.join(a, b)\nopen(f'/proc/{pid}/stat')\n"
           "d = 'the /proc file'\n")
    assert os_calls_in(src) == [(1, "import ctypes.util"), (1, "import signal"),
                                (2, "import multiprocessing"), (3, "os.kill"), (4, "os.O_CLOEXEC"), (5, "fork"),
                                (6, "dir_fd"), (7, "/dev/shm"), (8, "os.sched_getaffinity"),
                                (10, "/proc")]
    assert any(os_calls_in(p.read_text()) for p in (ROOT / PLATFORM).glob("*.py"))  # the platform package makes them


def test_no_os_specific_call_outside_the_platform_module() -> None:
    offenders, used = [], set()
    for path in _modules():
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith(PLATFORM):
            continue
        for line, kind in os_calls_in(path.read_text(encoding="utf-8")):
            if (rel, kind) in ALLOWED:
                used.add((rel, kind))
            else:
                offenders.append(f"{rel}:{line}: {kind}")
    assert not offenders, "OS-specific calls outside foundation/platform_support/:\n" + "\n".join(offenders)
    assert used == set(ALLOWED), f"no such call left in {sorted(set(ALLOWED) - used)}: take them off ALLOWED"


# -- the fallbacks -------------------------------------------------------------------------------------------
@pytest.fixture
def windows(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys, "platform", "win32")


@pytest.fixture
def macos(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys, "platform", "darwin")


def _never(*_: Any, **__: Any) -> None:
    raise AssertionError("a POSIX call on the Windows branch")


def test_no_real_time_scheduling_leaves_the_loop_at_normal_priority(windows: None, monkeypatch) -> None:
    monkeypatch.delenv("HAPTIC_STUDY_REALTIME", raising=False)
    monkeypatch.setattr(os, "sched_setscheduler", _never)
    assert threads.set_timer_slack_ns(1) is False
    assert prepare_realtime_thread() == "normal (no real-time scheduling on this platform)"


def test_timer_slack_and_pread_exist_on_linux_only(macos: None) -> None:
    assert threads.set_timer_slack_ns(1) is False and threads.gil_keeping_pread() is None
    assert processes.die_with_parent() is False


def test_the_pread_reader_reads_a_file_on_linux(tmp_path: Path) -> None:
    read = threads.gil_keeping_pread(8)
    assert read is not None
    (tmp_path / "f").write_bytes(b"123 456 789\n")
    fd = os.open(tmp_path / "f", os.O_RDONLY)
    try:
        assert read(fd) == b"123 456 " and read(-1) == b""
    finally:
        os.close(fd)


def test_cpu_count_without_an_affinity_mask(windows: None) -> None:
    assert threads.usable_cpu_count() == (os.cpu_count() or 1)
    assert threads.usable_cpus() == list(range(os.cpu_count() or 1))


def test_without_affinity_the_loop_runs_on_any_cpu_and_without_a_socket_handover_in_the_engine(
        windows: None, monkeypatch) -> None:
    monkeypatch.setattr(os, "sched_setaffinity", _never, raising=False)
    assert threads.pin_to_cpu(1) == "any CPU (no CPU affinity on this platform)"
    assert processes.socket_handover() is False
    a, b = socket.socketpair()
    try:
        assert processes.spawn_with_socket([sys.executable, "-c", "pass"], a) is None  # the loop stays in the engine
    finally:
        a.close()
        b.close()


def test_the_loop_process_is_pinned_to_the_last_cpu_it_may_use_unless_told(monkeypatch) -> None:
    from pipeline.core.clock import loop_cpu_problem, pin_loop_process

    pinned: list[int] = []
    monkeypatch.setattr(threads, "pin_to_cpu", lambda cpu: pinned.append(cpu) or f"CPU {cpu}")
    monkeypatch.setattr("pipeline.core.clock.pin_to_cpu", threads.pin_to_cpu)
    monkeypatch.setattr("pipeline.core.clock.usable_cpus", lambda: [0, 1, 2, 3])
    monkeypatch.delenv("HAPTIC_STUDY_LOOP_CPU", raising=False)
    assert pin_loop_process() == "CPU 3 of 0-3" and pinned == [3]
    monkeypatch.setenv("HAPTIC_STUDY_LOOP_CPU", "1")
    assert pin_loop_process() == "CPU 1 of 0-3" and loop_cpu_problem() is None
    monkeypatch.setenv("HAPTIC_STUDY_LOOP_CPU", "none")
    assert pin_loop_process() == "any CPU (HAPTIC_STUDY_LOOP_CPU=none)" and pinned == [3, 1]
    monkeypatch.setenv("HAPTIC_STUDY_LOOP_CPU", "7")
    assert loop_cpu_problem() == ("HAPTIC_STUDY_LOOP_CPU = '7': must be 'none' or one of the CPUs this process may "
                                  "use (0-3)")
    monkeypatch.setattr("pipeline.core.clock.usable_cpus", lambda: [0])
    monkeypatch.delenv("HAPTIC_STUDY_LOOP_CPU")
    assert pin_loop_process() == "any CPU (this process may use one only)"


@pytest.mark.parametrize("threads, method", [(1, "fork"), (2, "spawn")])
def test_workers_fork_only_single_threaded_on_linux(monkeypatch, threads: int, method: str) -> None:
    monkeypatch.setattr(threading, "active_count", lambda: threads)
    assert processes.worker_context().get_start_method() == method


@pytest.mark.parametrize("system", ["win32", "darwin"])
def test_workers_spawn_elsewhere(monkeypatch, system: str) -> None:
    monkeypatch.setattr(threading, "active_count", lambda: 1)
    monkeypatch.setattr(sys, "platform", system)
    assert processes.worker_context().get_start_method() == "spawn"


@pytest.mark.parametrize("system, sig", [("linux", signal.SIGKILL), ("win32", signal.SIGTERM)])
def test_the_hard_kill(monkeypatch, system: str, sig: int) -> None:
    sent: list[tuple[int, int]] = []
    monkeypatch.setattr(sys, "platform", system)
    monkeypatch.setattr(os, "kill", lambda pid, s: sent.append((pid, s)))
    processes.kill_hard(4242)
    assert sent == [(4242, sig)]  # Windows: os.kill with SIGTERM is TerminateProcess


@pytest.mark.parametrize("raised, alive", [(None, True), (ProcessLookupError, False), (PermissionError, True),
                                           (OverflowError, False)])
def test_a_process_exists_on_posix(monkeypatch, raised: type[Exception] | None, alive: bool) -> None:
    def kill(pid: int, sig: int) -> None:
        assert sig == 0
        if raised is not None:
            raise raised()
    monkeypatch.setattr(os, "kill", kill)
    assert processes.process_exists(1234) is alive


class _Kernel32:
    """``ctypes.windll.kernel32`` as far as process_exists and free_physical_bytes use it."""

    def __init__(self, handle: int = 7, error: int = 0, exit_code: int = 259, avail: int = 0) -> None:
        self.handle, self.error, self.exit_code, self.avail, self.closed = handle, error, exit_code, avail, []

    def OpenProcess(self, access: int, inherit: bool, pid: int) -> int:
        assert access == 0x1000 and not inherit
        return self.handle

    def GetLastError(self) -> int:
        return self.error

    def GetExitCodeProcess(self, handle: int, ref: Any) -> int:
        ref._obj.value = self.exit_code  # byref(): the c_ulong behind it
        return 1

    def CloseHandle(self, handle: int) -> int:
        self.closed.append(handle)
        return 1

    def GlobalMemoryStatusEx(self, ref: Any) -> int:
        assert ref._obj.dwLength == ctypes.sizeof(ref._obj)
        ref._obj.ullAvailPhys = self.avail
        return 1


@pytest.mark.parametrize("k32, alive", [(_Kernel32(), True), (_Kernel32(exit_code=0), False),
                                        (_Kernel32(handle=0, error=5), True), (_Kernel32(handle=0, error=87), False)])
def test_a_process_exists_on_windows_without_kill(windows: None, monkeypatch, k32: _Kernel32, alive: bool) -> None:
    monkeypatch.setattr(os, "kill", _never)  # os.kill(pid, 0) on Windows would send Ctrl-C
    monkeypatch.setattr(ctypes, "windll", SimpleNamespace(kernel32=k32), raising=False)
    assert processes.process_exists(1234) is alive
    assert k32.closed == ([7] if k32.handle else [])
    assert processes.process_exists(0) is False and processes.process_exists(2**40) is False


def test_free_memory_on_windows(windows: None, monkeypatch) -> None:
    monkeypatch.setattr(ctypes, "windll", SimpleNamespace(kernel32=_Kernel32(avail=3 << 30)), raising=False)
    assert machine.free_physical_bytes() == 3 << 30
    assert machine.load_average() is None


def test_a_ring_attaches_and_frees_through_posix_shm_names_on_macos(macos: None) -> None:
    writer = RingBuffer.create(["t"], 4, shared=True)
    try:
        writer.write([1.5])
        name = writer.name
        assert name is not None
        reader = RingBuffer.attach(name)
        assert reader.latest(1)["t"].tolist() == [1.5]
        reader.close()
    finally:
        writer._owner = False  # the writer dies "killed": it leaves its segment for free_orphaned
        writer.close()
    assert RingBuffer.free_orphaned(name) is True and RingBuffer.free_orphaned(name) is False
    with pytest.raises(FileNotFoundError, match="no ring buffer named"):
        RingBuffer.attach(name)


def test_no_orphaned_segment_on_windows(windows: None) -> None:
    assert RingBuffer.free_orphaned("psm_anything") is False


def test_file_modes_and_owners_on_windows(windows: None, monkeypatch, tmp_path: Path) -> None:
    (tmp_path / "f").write_bytes(b"")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: SimpleNamespace(total=9, used=4, free=5))
    for name in ("chmod", "fchmod", "statvfs"):
        monkeypatch.setattr(os, name, _never)
    files.owner_only(tmp_path / "f")
    files.set_fd_mode(0, 0o600)
    assert files.fs_free_bytes(tmp_path) == 5
    assert files.fs_read_only(tmp_path) is False


def test_the_owner_alone_reads_a_new_study_file_on_linux(tmp_path: Path) -> None:
    (tmp_path / "f").write_bytes(b"")
    os.chmod(tmp_path / "f", 0o644)
    files.owner_only(tmp_path / "f")
    assert (tmp_path / "f").stat().st_mode & 0o777 == 0o600
    mask = os.umask(0o022)
    os.umask(mask)
    assert files.umask() == mask


def test_without_dir_fd_calls_output_folders_are_written_by_checked_paths(monkeypatch, tmp_path: Path) -> None:
    """Windows' fallback (foundation.outpath; its own tests: tests/analysis/test_outdir_pathwalk.py)."""
    from foundation.outdir import write_output_folder
    from foundation.outpath import PathFolder

    monkeypatch.setattr(outfs, "DIR_FD_CALLS", False)
    assert isinstance(outfs.open_folder(str(tmp_path), follow=True), PathFolder)
    check_output_folder(tmp_path / "new", command="report", marker=".haptic-report")
    files = write_output_folder(tmp_path / "new", lambda d: (d / "a.csv").write_text("1"), command="report",
                                marker=".haptic-report")
    assert files == ["a.csv"] and (tmp_path / "new" / "a.csv").stat().st_mode & 0o777 == 0o600


def test_the_dll_folder_is_added_on_windows_only(monkeypatch, tmp_path: Path) -> None:
    added: list[str] = []
    monkeypatch.setattr(os, "add_dll_directory", added.append, raising=False)
    assert files.add_dll_directory(tmp_path) is False and added == []  # Linux: the loader's own path
    monkeypatch.setattr(sys, "platform", "win32")
    assert files.add_dll_directory(tmp_path) is True and added == [str(tmp_path)]


def test_without_proc_every_reader_says_it_cannot_tell(monkeypatch) -> None:
    import builtins
    import io

    from foundation.resources import available_memory_bytes
    from protocol.storage.leases import _pid_alive, process_identity

    def no_proc(real: Any) -> Any:
        def call(path: Any, *args: Any, **kwargs: Any) -> Any:
            if str(path).startswith(("/proc", "/sys")):
                raise FileNotFoundError(2, "No such file or directory", str(path))
            return real(path, *args, **kwargs)
        return call

    for owner, name in ((builtins, "open"), (io, "open"), (os, "open"), (os, "listdir")):
        monkeypatch.setattr(owner, name, no_proc(getattr(owner, name)))
    assert processes.boot_id() == "" and processes.process_stat_fields(os.getpid()) is None
    assert machine.cpu_times() is None
    assert threads.thread_ids() is None and threads.open_schedstat(threading.get_native_id()) == -1
    assert machine.meminfo_available_bytes() is None and machine.cgroup_memory_headroom() is None
    assert process_identity(os.getpid()) == ""  # the lease falls back on heartbeats
    assert _pid_alive(os.getpid()) is True  # by process_exists alone
    assert available_memory_bytes() == machine.free_physical_bytes()  # sysconf's free pages
