"""The output policy's primitives by path, for systems without the ``*at`` calls (Windows).

:mod:`foundation.outfs` works relative to open folder descriptors (``openat``,
``renameat``, ``O_NOFOLLOW``): once a folder is open, nothing another process
does to the path above it or to the links beside it can redirect a step.
Windows has none of these calls (``platform_support.DIR_FD_CALLS`` is False),
so there :func:`foundation.outfs.open_folder` returns a :class:`PathFolder`
instead, and every step below is taken here, by path, in the same way:

* the folder the user named is resolved once (links in it followed, as the
  ``*at`` path follows them), and its identity (device, file number) is kept;
* right before each open, rename, link and removal, the folder's identity is
  checked again and every part of the path below it is ``lstat``-ed: a
  symbolic link or a junction (:func:`foundation.platform_support.redirects`)
  or a part that is no folder is an ``OSError`` (``ELOOP``/``ENOTDIR``), never
  a way out;
* a file is opened only when ``lstat`` shows a regular file, with the flags
  the system has (``O_BINARY``, ``O_NOINHERIT``; ``O_NOFOLLOW`` where it
  exists), and the file opened must be the one looked at (``fstat`` against
  ``lstat``), so a swap in between is caught; a new file is created with
  ``O_EXCL``, which never opens an existing entry (a link included).

**The race this leaves.**  Each step is a look and then an act.  A hostile
process that changes the output folder in between -- puts a link or a
junction where a checked folder was, after the check and before the rename or
removal -- can win that race and redirect the step; the ``*at`` path has no
such window.  The policy holds against everything that is already in the
folder (a link someone left, an edited file, a FIFO): the same refusals, word
for word.  It does not hold against another program rewriting the folder at
the moment the command writes it.
"""

from __future__ import annotations

import errno
import os
import shutil
import stat
from dataclasses import dataclass

from foundation.platform_support.files import (
    O_BINARY,
    O_CLOEXEC,
    O_DIRECTORY,
    O_NOFOLLOW,
    O_NOINHERIT,
    O_NONBLOCK,
    redirects,
    set_fd_mode,
    set_folder_mode,
)

__all__ = [
    "PathFolder",
    "chmod_at",
    "fsync_dir",
    "fsync_tolerant",
    "link_at",
    "listdir",
    "lstat_at",
    "mkdir_at",
    "open_at",
    "open_folder",
    "rename_at",
    "rename_new",
    "rmdir_at",
    "rmtree_at",
    "scan",
    "set_mode_and_close",
    "unlink_at",
]

#: The flags every open here adds: those of them the system has (0 elsewhere).
_OPEN_FLAGS = O_BINARY | O_NOINHERIT | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK


@dataclass(frozen=True)
class PathFolder:
    """An "open" folder by path: the named folder (resolved once), its identity, and the parts below it."""

    root: str
    root_id: tuple[int, int]
    parts: tuple[str, ...] = ()

    @property
    def path(self) -> str:
        """The folder's path (not checked: :func:`verify` checks it)."""
        return os.path.join(self.root, *self.parts)


def _ident(st: os.stat_result) -> tuple[int, int]:
    return st.st_dev, st.st_ino


def _error(code: int, path: str, why: str = "") -> OSError:
    return OSError(code, why or os.strerror(code), path)


def _name(name: str) -> str:
    """One entry's name: never empty, ``.``, ``..``, a drive or anything with a separator (no way out by name)."""
    seps = {"/", os.sep, os.altsep or "/"} | ({":"} if os.sep == "\\" else set())  # Windows: no drive, no stream
    if name in ("", ".", "..") or any(c in name for c in seps):
        raise _error(errno.EINVAL, name, "not a plain file name")
    return name


def verify(folder: PathFolder) -> str:
    """The folder's path, checked now: the named folder is still the one opened, no part below it a link or junction.

    Raises
    ------
    OSError
        ``ELOOP`` for a link or junction, ``ENOTDIR`` for a part that is no
        folder, ``ENOENT`` when the named folder is gone or was replaced.
    """
    if _ident(os.stat(folder.root)) != folder.root_id:
        raise _error(errno.ENOENT, folder.root, "the folder was replaced while the command ran")
    path = folder.root
    for part in folder.parts:
        path = os.path.join(path, part)
        _require_folder(path, os.lstat(path))
    return path


def _require_folder(path: str, st: os.stat_result) -> None:
    """Refuse an entry that is a link or junction (``ELOOP``, never followed) or not a folder (``ENOTDIR``)."""
    if redirects(path, st):
        raise _error(errno.ELOOP, path, "a symbolic link or junction, not followed")
    if not stat.S_ISDIR(st.st_mode):
        raise _error(errno.ENOTDIR, path)


def _entry(folder: PathFolder, name: str) -> tuple[str, os.stat_result | None]:
    """(path of ``name`` in the checked folder, its ``lstat``; None when there is no such entry)."""
    path = os.path.join(verify(folder), _name(name))
    try:
        return path, os.lstat(path)
    except FileNotFoundError:
        return path, None


def open_folder(name: str, parent: PathFolder | None, *, follow: bool) -> PathFolder:
    """The folder ``name`` (with no ``parent``: a path, links followed with ``follow``), never through a link."""
    if parent is None:
        path = os.path.realpath(name) if follow else os.path.abspath(name)
        st = os.stat(path) if follow else os.lstat(path)
        if not follow and redirects(path, st):
            raise _error(errno.ELOOP, path, "a symbolic link or junction, not followed")
        if not stat.S_ISDIR(st.st_mode):
            raise _error(errno.ENOTDIR, path)
        return PathFolder(path, _ident(st))
    path, found = _entry(parent, name)  # below a folder a link is never followed (``follow`` or not)
    if found is None:
        raise _error(errno.ENOENT, path)
    _require_folder(path, found)
    return PathFolder(parent.root, parent.root_id, (*parent.parts, name))


def scan(folder: PathFolder) -> list[tuple[str, int]]:
    """The folder's entries as (name, ``lstat`` mode), a junction shown as a symbolic link (never walked into)."""
    out = []
    with os.scandir(verify(folder)) as it:
        for e in it:
            st = e.stat(follow_symlinks=False)
            mode = stat.S_IFLNK | stat.S_IMODE(st.st_mode) if redirects(e.path, st) else st.st_mode
            out.append((e.name, mode))
    return out


def listdir(folder: PathFolder) -> list[str]:
    """The names in the checked folder."""
    return os.listdir(verify(folder))


def lstat_at(folder: PathFolder, name: str) -> os.stat_result:
    """``lstat`` of ``name`` in the checked folder (``FileNotFoundError`` when there is none)."""
    path, st = _entry(folder, name)
    if st is None:
        raise _error(errno.ENOENT, path)
    return st


def open_at(folder: PathFolder, name: str, flags: int, mode: int = 0o600) -> int:
    """``os.open`` of a regular file in the folder: never a link (``ELOOP``), a FIFO or device (``ENXIO``).

    With ``O_CREAT | O_EXCL`` a new file is made (an existing entry, a link
    included, is ``FileExistsError``); otherwise the file opened must be the
    one ``lstat`` saw just before.
    """
    path, before = _entry(folder, name)
    if flags & os.O_CREAT and flags & os.O_EXCL:
        return os.open(path, flags | _OPEN_FLAGS, mode)
    if before is None:
        raise _error(errno.ENOENT, path)
    if redirects(path, before):
        raise _error(errno.ELOOP, path, "a symbolic link or junction, not followed")
    if not stat.S_ISREG(before.st_mode):
        raise _error(errno.ENXIO, path)
    fd = os.open(path, flags | _OPEN_FLAGS)
    if _ident(os.fstat(fd)) != _ident(before):
        os.close(fd)
        raise _error(errno.ELOOP, path, "the entry was replaced while the command opened it")
    return fd


def chmod_at(folder: PathFolder, name: str, mode: int, *, sync: bool) -> None:
    """Set the mode of a file or folder in the folder, never through a link; with ``sync`` make the file durable."""
    path, st = _entry(folder, name)
    if st is None:
        raise _error(errno.ENOENT, path)
    if stat.S_ISDIR(st.st_mode) and not redirects(path, st):
        set_folder_mode(path, mode)  # (Windows: nothing; a folder cannot be opened as a file there)
        return
    # (Windows flushes only a writable handle)
    set_mode_and_close(open_at(folder, name, os.O_RDWR if sync else os.O_RDONLY), mode, sync=sync)


def set_mode_and_close(f: int, mode: int, *, sync: bool) -> None:
    """Give the open file ``f`` its ``mode``, with ``sync`` make that durable, and close it (whatever happens)."""
    try:
        set_fd_mode(f, mode)
        if sync:
            os.fsync(f)
    finally:
        os.close(f)


def rename_at(src: PathFolder, src_name: str, dst: PathFolder, dst_name: str) -> None:
    """Rename an entry over whatever entry has the new name (``os.replace``: a link there is replaced, not followed)."""
    os.replace(_entry(src, src_name)[0], _entry(dst, dst_name)[0])


def rename_new(src: PathFolder, dst: PathFolder, name: str) -> None:
    """Rename ``name`` into ``dst`` where nothing has that name (Windows refuses an existing one itself)."""
    src_path, dst_path = _entry(src, name)[0], _entry(dst, name)
    if dst_path[1] is not None:
        raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST), dst_path[0])
    os.rename(src_path, dst_path[0])


def link_at(src: PathFolder, dst: PathFolder, name: str) -> None:
    """A hard link of the regular file ``name`` in ``dst`` (never replaces; the link itself is never followed)."""
    src_path, st = _entry(src, name)
    if st is None or not stat.S_ISREG(st.st_mode) or redirects(src_path, st):
        raise _error(errno.EPERM, src_path, "not a regular file")
    dst_path = _entry(dst, name)[0]
    try:
        if os.link in os.supports_follow_symlinks:
            os.link(src_path, dst_path, follow_symlinks=False)
        else:
            os.link(src_path, dst_path)
    except OSError as exc:
        if exc.errno == errno.EINVAL:  # Windows on FAT/exFAT (ERROR_INVALID_FUNCTION): no hard links there
            raise _error(errno.ENOTSUP, dst_path, "the file system has no hard links") from None
        raise


def unlink_at(folder: PathFolder, name: str) -> None:
    """Remove the entry ``name`` (a link itself, never its target)."""
    os.unlink(_entry(folder, name)[0])


def mkdir_at(folder: PathFolder, name: str, mode: int) -> None:
    """Make the folder ``name`` in the checked folder."""
    os.mkdir(_entry(folder, name)[0], mode)


def rmdir_at(folder: PathFolder, name: str) -> None:
    """Remove the empty folder ``name``, never through a link."""
    path, st = _entry(folder, name)
    if st is not None and redirects(path, st):
        raise _error(errno.ELOOP, path, "a symbolic link or junction, not followed")
    os.rmdir(path)


def rmtree_at(folder: PathFolder, name: str) -> None:
    """Remove the command's own temporary folder ``name`` and all in it; errors ignored, links never followed.

    ``shutil.rmtree`` removes a link or junction inside as an entry (it does
    not walk into it); the folder itself must not be one.
    """
    try:
        path, st = _entry(folder, name)
    except OSError:
        return
    if st is None or redirects(path, st) or not stat.S_ISDIR(st.st_mode):
        return
    shutil.rmtree(path, ignore_errors=True)


def fsync_dir(folder: PathFolder) -> None:
    """Make the folder's entries durable where a folder can be opened (POSIX); Windows: nothing (NTFS journals them)."""
    try:
        fd = os.open(verify(folder), os.O_RDONLY | O_DIRECTORY | O_CLOEXEC)
    except (PermissionError, IsADirectoryError):  # Windows opens no folder as a file
        return
    try:
        fsync_tolerant(fd)
    finally:
        os.close(fd)


def fsync_tolerant(fd: int) -> None:
    """``fsync`` an open folder; a file system that cannot sync a folder (EINVAL, EBADF, ENOTSUP) is not an error."""
    try:
        os.fsync(fd)
    except OSError as exc:
        if exc.errno not in (errno.EINVAL, errno.EBADF, errno.ENOTSUP):
            raise
