"""File-system primitives of the output policy (:mod:`analysis.outdir`): safe by file descriptor, one-line errors.

Everything here works relative to an open folder (``dir_fd``) and never
follows a symbolic link below the folder the user named: a link is an entry
like any other, never a way out.  Files are created with ``O_EXCL`` (nothing
existing is ever opened for writing), with the mode of the study database
(``0600``, or stricter when the umask says so), and made durable with
``fsync`` before they are renamed into place.

:func:`os_error_line` turns the ``OSError`` a lab meets (a full disk, a
read-only mount, a permission, a failing disk, a device where a file was
expected) into one line naming the path and what to do.
"""

from __future__ import annotations

import errno
import hashlib
import os
import stat
import sys
from collections.abc import Iterator
from pathlib import Path

from analysis.errors import AnalysisError
from analysis.oserrors import kind_of, os_error_line
from pipeline.runtime.platform_support import (
    DIR_FD_CALLS,
    O_CLOEXEC,
    O_DIRECTORY,
    O_NOFOLLOW,
    O_NONBLOCK,
    fs_free_bytes,
    fs_read_only,
    set_fd_mode,
    umask,
)

__all__ = [
    "OutputError",
    "chmod_at",
    "dir_mode",
    "entries",
    "file_mode",
    "folder_at",
    "free_bytes",
    "fsync_dir",
    "kind_of",
    "open_folder",
    "os_error_line",
    "place",
    "sha256_at",
    "sha256_at_or_none",
    "writable_problem",
    "write_bytes_at",
]


#: The refusal where the OS lacks the ``*at`` calls (Windows): the output policy never writes by path.
NO_DIR_FD_CALLS = (f"writing output files is not supported on this operating system yet ({sys.platform}): the "
                   "output policy needs file-descriptor-relative calls (openat, O_NOFOLLOW) it lacks; run the "
                   "command on Linux or macOS (nothing was written)")


class OutputError(AnalysisError):
    """An output the command must not, or could not, write: one line naming the path and what to do.

    ``status`` is the command's exit status: 2 for a refusal before any work
    (like bad input), 1 when the file system failed while the outputs were written.
    """

    def __init__(self, message: str, status: int = 2) -> None:
        super().__init__(message)
        self.status = status


def file_mode() -> int:
    """The mode of a new output file: that of the study database (0600), stricter if the umask says so."""
    return 0o600 & ~umask()


def dir_mode() -> int:
    """The mode of a new output folder: owner-only (0700), stricter if the umask says so."""
    return 0o700 & ~umask()


def open_folder(name: str, dir_fd: int | None = None, *, follow: bool = False) -> int:
    """Open a folder for ``*at`` calls; never through a symbolic link unless ``follow`` (the folder the user named)."""
    if not DIR_FD_CALLS:  # (Windows) the policy is built on *at calls; refuse rather than follow links
        raise OutputError(NO_DIR_FD_CALLS)
    flags = os.O_RDONLY | O_DIRECTORY | O_CLOEXEC
    if not follow:
        flags |= O_NOFOLLOW
    return os.open(name, flags, dir_fd=dir_fd)


def entries(dir_fd: int, prefix: str = "") -> Iterator[tuple[str, int]]:
    """Every entry below an open folder as (relative path with ``/``, ``lstat`` mode); links are never followed.

    A folder is listed itself and then walked (opened with ``O_NOFOLLOW``);
    everything else -- files, links, FIFOs, devices -- is listed only.
    """
    with os.scandir(dir_fd) as it:
        listed = sorted((e.name, e.stat(follow_symlinks=False).st_mode) for e in it)
    for name, mode in listed:
        rel = prefix + name
        yield rel, mode
        if stat.S_ISDIR(mode):
            fd = open_folder(name, dir_fd)
            try:
                yield from entries(fd, rel + "/")
            finally:
                os.close(fd)


def _walk_to(dir_fd: int, rel: str) -> tuple[int, str]:
    """(an open fd of the folder holding ``rel``, its last component); the caller closes the fd."""
    *folders, name = rel.split("/")
    fd = os.dup(dir_fd)
    try:
        for part in folders:
            nxt = open_folder(part, fd)
            os.close(fd)
            fd = nxt
    except BaseException:
        os.close(fd)
        raise
    return fd, name


def sha256_at(dir_fd: int, rel: str) -> str | None:
    """SHA-256 of the regular file ``rel`` below ``dir_fd``, never through a link (None: not a regular file)."""
    fd, name = _walk_to(dir_fd, rel)
    try:
        try:
            f = os.open(name, os.O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC, dir_fd=fd)
        except OSError as exc:
            if exc.errno in (errno.ELOOP, errno.ENOENT, errno.ENXIO):
                return None
            raise
        try:
            if not stat.S_ISREG(os.fstat(f).st_mode):
                return None
            h = hashlib.sha256()
            while block := os.read(f, 1 << 20):
                h.update(block)
            return h.hexdigest()
        finally:
            os.close(f)
    finally:
        os.close(fd)


def write_bytes_at(dir_fd: int, name: str, data: bytes) -> None:
    """Write ``name`` in an open folder atomically: a new temporary file (``O_EXCL``), fsync, rename over ``name``.

    ``name`` is replaced as an entry: a link there is replaced, never written through.
    """
    tmp = f".{name}.{os.getpid()}.{os.urandom(4).hex()}.new"
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | O_NOFOLLOW | O_CLOEXEC,
                 file_mode(), dir_fd=dir_fd)
    try:
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view):]
            os.fsync(fd)
        finally:
            os.close(fd)
        os.rename(tmp, name, src_dir_fd=dir_fd, dst_dir_fd=dir_fd)
    except BaseException:
        try:
            os.unlink(tmp, dir_fd=dir_fd)
        except OSError:
            pass
        raise


def fsync_dir(dir_fd: int) -> None:
    """Make the folder's entries (renames, new names) durable; a file system that cannot is not an error."""
    try:
        os.fsync(dir_fd)
    except OSError as exc:
        if exc.errno not in (errno.EINVAL, errno.EBADF, errno.ENOTSUP):
            raise


def free_bytes(folder: str | os.PathLike[str]) -> int | None:
    """Bytes an unprivileged user may still write in ``folder``'s file system (None: unknown)."""
    return fs_free_bytes(folder)  # statvfs (Windows: shutil.disk_usage; platform_support)


def read_only(folder: str | os.PathLike[str]) -> bool:
    """Whether ``folder`` lies on a file system mounted read-only."""
    return fs_read_only(folder)  # statvfs (False where the OS cannot tell; platform_support)


def writable_problem(folder: Path, shown: str, need_bytes: int = 0) -> str | None:
    """Why the command cannot create files in ``folder`` (None: it can), checked before any work.

    ``shown`` is the path as the user gave it; ``need_bytes`` the least free
    space the outputs need (0: only that some space is left).
    """
    if not DIR_FD_CALLS:
        return f"{shown}: {NO_DIR_FD_CALLS}"
    if read_only(folder):
        return (f"{shown}: the file system is read-only; write to a folder on a writable disk "
                "(nothing was written)")
    if not os.access(folder, os.W_OK | os.X_OK):
        return f"{shown}: permission denied (cannot create files in {folder}); choose a folder you may write to"
    free = free_bytes(folder)
    if free is not None and free < max(need_bytes, 1):
        mb = f"about {need_bytes / 1e6:,.0f} MB are needed, " if need_bytes >= 1e6 else ""
        return (f"{shown}: no space left on the device ({mb}{free / 1e6:,.1f} MB free); free some space or write "
                "to another disk (nothing was written)")
    return None


def chmod_at(dir_fd: int, rel: str, mode: int, *, sync: bool = False) -> None:
    """Set the mode of the file ``rel`` below ``dir_fd`` (never through a link), and with ``sync`` make it durable."""
    fd, name = _walk_to(dir_fd, rel)
    try:
        f = os.open(name, os.O_RDONLY | O_NOFOLLOW | O_NONBLOCK, dir_fd=fd)
        try:
            set_fd_mode(f, mode)
            if sync:
                os.fsync(f)
        finally:
            os.close(f)
    finally:
        os.close(fd)


def folder_at(dir_fd: int, rel_dir: str, *, make: bool) -> int:
    """Open (and with ``make`` create, owner-only) the folder ``rel_dir`` below ``dir_fd``, never through a link."""
    fd = os.dup(dir_fd)
    try:
        for part in filter(None, rel_dir.split("/")):
            if make:
                try:
                    os.mkdir(part, dir_mode(), dir_fd=fd)
                except FileExistsError:
                    pass
            nxt = open_folder(part, fd)
            os.close(fd)
            fd = nxt
    except BaseException:
        os.close(fd)
        raise
    return fd

def place(src_fd: int, dst_fd: int, name: str, *, replace: bool) -> None:
    """Move ``name`` from one folder to another: over the command's own file (``replace``), or never over anything."""
    if replace:
        os.rename(name, name, src_dir_fd=src_fd, dst_dir_fd=dst_fd)
        return
    try:
        os.link(name, name, src_dir_fd=src_fd, dst_dir_fd=dst_fd, follow_symlinks=False)
    except FileExistsError:
        raise OutputError(f"{name}: appeared while the command ran; it was not overwritten (run it again, or "
                          "choose another name)", status=1) from None
    except OSError as exc:
        if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EMLINK, errno.EXDEV):
            raise
        # a file system without hard links (FAT, some network shares): look, then rename
        try:
            os.lstat(name, dir_fd=dst_fd)
        except FileNotFoundError:
            os.rename(name, name, src_dir_fd=src_fd, dst_dir_fd=dst_fd)
            return
        raise OutputError(f"{name}: appeared while the command ran; it was not overwritten (run it again, or "
                          "choose another name)", status=1) from None
    os.unlink(name, dir_fd=src_fd)

def sha256_at_or_none(dir_fd: int, rel: str) -> str | None:
    """:func:`analysis.outfs.sha256_at`, None also where a folder on the way is missing or a link."""
    try:
        return sha256_at(dir_fd, rel)
    except OSError:
        return None
