"""File-system primitives of the output policy (:mod:`foundation.outdir`): safe by file descriptor, one-line errors.

Everything here works relative to an open folder (``dir_fd``) and never
follows a symbolic link below the folder the user named: a link is an entry
like any other, never a way out.  Where the OS lacks the ``*at`` calls
(Windows: ``platform_support.DIR_FD_CALLS`` False) an open folder is a
:class:`foundation.outpath.PathFolder` instead of a descriptor, and each
primitive below hands it to :mod:`foundation.outpath`, which takes the same step
by path, checking every part with ``lstat`` (no link, no junction) right
before it acts -- with a race window the descriptors do not have (its
docstring says which).  On Linux and macOS every call is the ``*at`` call.  Files are created with ``O_EXCL`` (nothing
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
import shutil
import stat
from collections.abc import Iterator
from pathlib import Path

from foundation import outpath
from foundation.errors import InputRefused
from foundation.oserrors import kind_of, os_error_line
from foundation.outpath import PathFolder
from foundation.platform_support.files import (
    DIR_FD_CALLS,
    O_CLOEXEC,
    O_DIRECTORY,
    O_NOFOLLOW,
    O_NONBLOCK,
    fs_free_bytes,
    fs_read_only,
    may_write,
    umask,
)

__all__ = [
    "Folder",
    "OutputError",
    "chmod_at",
    "close_folder",
    "dir_mode",
    "entries",
    "file_mode",
    "folder_at",
    "free_bytes",
    "fsync_dir",
    "kind_of",
    "listdir_at",
    "lstat_at",
    "mkdir_at",
    "open_folder",
    "os_error_line",
    "place",
    "read_regular_at",
    "rmdir_at",
    "rmtree_at",
    "sha256_at",
    "sha256_at_or_none",
    "unlink_at",
    "writable_problem",
    "write_bytes_at",
]


#: An open folder: a descriptor for the ``*at`` calls, or (without them: Windows) a path checked at each step.
Folder = int | PathFolder


class OutputError(InputRefused):
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


def open_folder(name: str, dir_fd: Folder | None = None, *, follow: bool = False) -> Folder:
    """Open a folder for ``*at`` calls; never through a symbolic link unless ``follow`` (the folder the user named).

    Without the ``*at`` calls (:data:`DIR_FD_CALLS` False: Windows) the folder
    is a :class:`foundation.outpath.PathFolder`, checked by path at each step.
    """
    if isinstance(dir_fd, PathFolder) or (dir_fd is None and not DIR_FD_CALLS):
        return outpath.open_folder(name, dir_fd, follow=follow)
    flags = os.O_RDONLY | O_DIRECTORY | O_CLOEXEC
    if not follow:
        flags |= O_NOFOLLOW
    return os.open(name, flags, dir_fd=dir_fd)


def close_folder(dir_fd: Folder) -> None:
    """Close an open folder (a path-checked one holds nothing open)."""
    if not isinstance(dir_fd, PathFolder):
        os.close(dir_fd)


def _dup(dir_fd: Folder) -> Folder:
    return dir_fd if isinstance(dir_fd, PathFolder) else os.dup(dir_fd)


def _scan(dir_fd: Folder) -> list[tuple[str, int]]:
    if isinstance(dir_fd, PathFolder):
        return outpath.scan(dir_fd)
    with os.scandir(dir_fd) as it:
        return [(e.name, e.stat(follow_symlinks=False).st_mode) for e in it]


def entries(dir_fd: Folder, prefix: str = "") -> Iterator[tuple[str, int]]:
    """Every entry below an open folder as (relative path with ``/``, ``lstat`` mode); links are never followed.

    A folder is listed itself and then walked (opened with ``O_NOFOLLOW``);
    everything else -- files, links, FIFOs, devices -- is listed only.
    """
    listed = sorted(_scan(dir_fd))
    for name, mode in listed:
        rel = prefix + name
        yield rel, mode
        if stat.S_ISDIR(mode):
            fd = open_folder(name, dir_fd)
            try:
                yield from entries(fd, rel + "/")
            finally:
                close_folder(fd)


def _walk_to(dir_fd: Folder, rel: str) -> tuple[Folder, str]:
    """(an open fd of the folder holding ``rel``, its last component); the caller closes the fd."""
    *folders, name = rel.split("/")
    return folder_at(dir_fd, "/".join(folders), make=False), name


def _open_at(dir_fd: Folder, name: str, flags: int, mode: int = 0o777) -> int:
    """``os.open`` of ``name`` in an open folder (``flags`` as for the ``*at`` call; path-checked without it)."""
    if isinstance(dir_fd, PathFolder):
        return outpath.open_at(dir_fd, name, flags, mode)
    return os.open(name, flags, mode, dir_fd=dir_fd)


def read_regular_at(dir_fd: Folder, name: str, limit: int) -> bytes | None:
    """Up to ``limit`` bytes of the regular file ``name`` in an open folder; None: none there (a link is none)."""
    try:
        fd = _open_at(dir_fd, name, os.O_RDONLY | O_NOFOLLOW | O_NONBLOCK)
    except OSError:
        return None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        raw = b""
        while len(raw) < limit and (block := os.read(fd, 1 << 20)):
            raw += block
    except OSError:
        return None
    finally:
        os.close(fd)
    return raw


def sha256_at(dir_fd: Folder, rel: str) -> str | None:
    """SHA-256 of the regular file ``rel`` below ``dir_fd``, never through a link (None: not a regular file)."""
    fd, name = _walk_to(dir_fd, rel)
    try:
        try:
            f = _open_at(fd, name, os.O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC)
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
        close_folder(fd)


def write_bytes_at(dir_fd: Folder, name: str, data: bytes) -> None:
    """Write ``name`` in an open folder atomically: a new temporary file (``O_EXCL``), fsync, rename over ``name``.

    ``name`` is replaced as an entry: a link there is replaced, never written through.
    """
    tmp = f".{name}.{os.getpid()}.{os.urandom(4).hex()}.new"
    fd = _open_at(dir_fd, tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | O_NOFOLLOW | O_CLOEXEC, file_mode())
    try:
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view):]
            os.fsync(fd)
        finally:
            os.close(fd)
        _rename_at(dir_fd, tmp, dir_fd, name)
    except BaseException:
        try:
            unlink_at(dir_fd, tmp)
        except OSError:
            pass
        raise


def _rename_at(src_fd: Folder, src: str, dst_fd: Folder, dst: str) -> None:
    """Rename an entry over whatever entry has the new name (a link there is replaced, never followed)."""
    if isinstance(src_fd, PathFolder) and isinstance(dst_fd, PathFolder):
        outpath.rename_at(src_fd, src, dst_fd, dst)
    else:
        assert isinstance(src_fd, int) and isinstance(dst_fd, int)
        os.rename(src, dst, src_dir_fd=src_fd, dst_dir_fd=dst_fd)


def unlink_at(dir_fd: Folder, name: str) -> None:
    """Remove the entry ``name`` of an open folder (a link itself, never its target)."""
    if isinstance(dir_fd, PathFolder):
        outpath.unlink_at(dir_fd, name)
    else:
        os.unlink(name, dir_fd=dir_fd)


def mkdir_at(dir_fd: Folder, name: str, mode: int) -> None:
    """Make the folder ``name`` in an open folder."""
    if isinstance(dir_fd, PathFolder):
        outpath.mkdir_at(dir_fd, name, mode)
    else:
        os.mkdir(name, mode, dir_fd=dir_fd)


def rmdir_at(dir_fd: Folder, name: str) -> None:
    """Remove the empty folder ``name`` of an open folder."""
    if isinstance(dir_fd, PathFolder):
        outpath.rmdir_at(dir_fd, name)
    else:
        os.rmdir(name, dir_fd=dir_fd)


def rmtree_at(dir_fd: Folder, name: str) -> None:
    """Remove the command's own folder ``name`` and all in it (errors ignored; links inside removed, not followed)."""
    if isinstance(dir_fd, PathFolder):
        outpath.rmtree_at(dir_fd, name)
    else:
        shutil.rmtree(name, dir_fd=dir_fd, ignore_errors=True)


def listdir_at(dir_fd: Folder) -> list[str]:
    """The names in an open folder."""
    return outpath.listdir(dir_fd) if isinstance(dir_fd, PathFolder) else os.listdir(dir_fd)


def lstat_at(dir_fd: Folder, name: str) -> os.stat_result:
    """``lstat`` of ``name`` in an open folder."""
    if isinstance(dir_fd, PathFolder):
        return outpath.lstat_at(dir_fd, name)
    return os.lstat(name, dir_fd=dir_fd)


def fsync_dir(dir_fd: Folder) -> None:
    """Make the folder's entries (renames, new names) durable; a file system that cannot is not an error."""
    if isinstance(dir_fd, PathFolder):
        outpath.fsync_dir(dir_fd)
        return
    outpath.fsync_tolerant(dir_fd)


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
    if read_only(folder):
        return (f"{shown}: the file system is read-only; write to a folder on a writable disk "
                "(nothing was written)")
    if not may_write(folder, os.W_OK | os.X_OK):
        return f"{shown}: permission denied (cannot create files in {folder}); choose a folder you may write to"
    free = free_bytes(folder)
    if free is not None and free < max(need_bytes, 1):
        mb = f"about {need_bytes / 1e6:,.0f} MB are needed, " if need_bytes >= 1e6 else ""
        return (f"{shown}: no space left on the device ({mb}{free / 1e6:,.1f} MB free); free some space or write "
                "to another disk (nothing was written)")
    return None


def chmod_at(dir_fd: Folder, rel: str, mode: int, *, sync: bool = False) -> None:
    """Set the mode of the file ``rel`` below ``dir_fd`` (never through a link), and with ``sync`` make it durable."""
    fd, name = _walk_to(dir_fd, rel)
    try:
        if isinstance(fd, PathFolder):
            outpath.chmod_at(fd, name, mode, sync=sync)
            return
        outpath.set_mode_and_close(os.open(name, os.O_RDONLY | O_NOFOLLOW | O_NONBLOCK, dir_fd=fd), mode, sync=sync)
    finally:
        close_folder(fd)


def folder_at(dir_fd: Folder, rel_dir: str, *, make: bool) -> Folder:
    """Open (and with ``make`` create, owner-only) the folder ``rel_dir`` below ``dir_fd``, never through a link."""
    fd = _dup(dir_fd)
    try:
        for part in filter(None, rel_dir.split("/")):
            if make:
                try:
                    mkdir_at(fd, part, dir_mode())
                except FileExistsError:
                    pass
            nxt = open_folder(part, fd)
            close_folder(fd)
            fd = nxt
    except BaseException:
        close_folder(fd)
        raise
    return fd

def _link_at(src_fd: Folder, dst_fd: Folder, name: str) -> None:
    if isinstance(src_fd, PathFolder) and isinstance(dst_fd, PathFolder):
        outpath.link_at(src_fd, dst_fd, name)
    else:
        assert isinstance(src_fd, int) and isinstance(dst_fd, int)
        os.link(name, name, src_dir_fd=src_fd, dst_dir_fd=dst_fd, follow_symlinks=False)


def place(src_fd: Folder, dst_fd: Folder, name: str, *, replace: bool) -> None:
    """Move ``name`` from one folder to another: over the command's own file (``replace``), or never over anything."""
    if replace:
        _rename_at(src_fd, name, dst_fd, name)
        return
    try:
        _link_at(src_fd, dst_fd, name)
    except FileExistsError:
        raise OutputError(f"{name}: appeared while the command ran; it was not overwritten (run it again, or "
                          "choose another name)", status=1) from None
    except OSError as exc:
        if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EMLINK, errno.EXDEV):
            raise
        # a file system without hard links (FAT, some network shares): look, then rename
        try:
            if isinstance(src_fd, PathFolder) and isinstance(dst_fd, PathFolder):
                outpath.rename_new(src_fd, dst_fd, name)  # (Windows' rename refuses an existing name itself)
                return
            lstat_at(dst_fd, name)
        except FileNotFoundError:
            _rename_at(src_fd, name, dst_fd, name)
            return
        except FileExistsError:
            pass
        raise OutputError(f"{name}: appeared while the command ran; it was not overwritten (run it again, or "
                          "choose another name)", status=1) from None
    unlink_at(src_fd, name)


def sha256_at_or_none(dir_fd: Folder, rel: str) -> str | None:
    """:func:`foundation.outfs.sha256_at`, None also where a folder on the way is missing or a link."""
    try:
        return sha256_at(dir_fd, rel)
    except OSError:
        return None


#: OSErrors of the file system itself: while outputs are written they are the command's failure to write.
_WRITE_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EIO, errno.EFBIG, errno.EACCES, errno.EPERM}


def parent_of(path: Path) -> Path:
    """The folder an output (file or folder) is made in: its parent, as an absolute path."""
    return Path(os.path.dirname(os.path.abspath(path)))


def is_write_failure(exc: OSError, tmp: Path) -> bool:
    """Whether ``exc``, raised while outputs were made in the temporary folder ``tmp``, is the file system's failure
    to write them (full, read-only, quota, I/O, permissions), not a bug of the code that made them."""
    return exc.errno in _WRITE_ERRNOS or str(exc.filename or "").startswith(str(tmp))
