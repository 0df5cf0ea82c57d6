"""``OSError`` in words: one line naming the path, what happened and what to do.

A lab meets a full disk, a read-only mount, a permission, a failing disk, a
device or a FIFO where a file was expected; every command says so in one
line (:func:`os_error_line`) instead of a traceback.  Kept free of heavy
imports: the command line's error path uses it for every command.
"""

from __future__ import annotations

import errno
import os
import stat

__all__ = ["kind_of", "os_error_line"]

_ADVICE = {
    errno.ENOSPC: ("no space left on the device", "free some space or write to another disk"),
    errno.EDQUOT: ("the disk quota is exhausted", "free some space or write to another disk"),
    errno.EROFS: ("the file system is read-only", "write to a folder on a writable disk"),
    errno.EACCES: ("permission denied", "choose a folder you may write to"),
    errno.EPERM: ("operation not permitted", "choose a folder you may write to"),
    errno.EIO: ("input/output error (a failing disk, a removed drive or a lost network share)",
                "check the device, then write to another disk"),
    errno.ENOENT: ("no such file or folder", "check the path"),
    errno.ENOTDIR: ("a part of the path is not a folder", "check the path"),
    errno.EISDIR: ("is a folder", "give a file name"),
    errno.ELOOP: ("a part of the path is a symbolic link, which this command does not follow there",
                  "choose another path"),
    errno.ENAMETOOLONG: ("the name is too long", "choose a shorter name"),
    errno.ENXIO: ("is a device, not a file", "give the path of a regular file"),
    errno.ENODEV: ("is a device, not a file", "give the path of a regular file"),
    errno.ETXTBSY: ("the file is busy", "close the program using it or choose another name"),
    errno.EMFILE: ("too many open files", "close other programs and run it again"),
    errno.EFBIG: ("the file is larger than the file system allows", "write to another disk"),
}


def os_error_line(exc: OSError, path: str | os.PathLike[str], doing: str, *, written: bool = False) -> str:
    """One line for an ``OSError`` met while ``doing`` something with ``path``: what happened and what to do.

    Parameters
    ----------
    exc
        The error.
    path
        The path the user gave (not a temporary file's).
    doing
        What the command was doing, e.g. ``"cannot write"``.
    written
        Whether anything was kept (False: the line ends "nothing was written").
    """
    what, advice = _ADVICE.get(exc.errno or 0, (exc.strerror or str(exc), "check the path and the device"))
    tail = "" if written else " (nothing was written)"
    return f"{path}: {doing}: {what}; {advice}{tail}"


def kind_of(mode: int) -> str:
    """A file's type in words, for messages (``a symbolic link``, ``a FIFO (named pipe)``, ...)."""
    if stat.S_ISLNK(mode):
        return "a symbolic link"
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISSOCK(mode):
        return "a socket"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    return "a file"
