"""Files: the ``open`` flags and ``*at`` calls of the output policy, modes and owners, free space, read-only mounts.

One job of the operating-system layer: :mod:`foundation.platform_support` says, for every call, what it does
where the OS lacks it and what the user loses there.
"""

from __future__ import annotations

import os
import stat
import sys

__all__ = ["DIR_FD_CALLS", "O_BINARY", "O_CLOEXEC", "O_DIRECTORY", "O_NOFOLLOW", "O_NOINHERIT", "O_NONBLOCK",
           "add_dll_directory", "fs_free_bytes", "fs_read_only", "may_write", "owner_only", "redirects",
           "set_fd_mode", "set_folder_mode", "umask"]

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
