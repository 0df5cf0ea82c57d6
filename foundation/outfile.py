"""One output file (``plot-trial``, ``plot-session``, ``export samples``): checked before the work, written whole
or not at all, never replacing anything.

The rules are those of the whole output policy (:mod:`foundation.outdir`): a file that exists -- a link, even a
dangling one, included -- is refused; the new file is made in a private temporary folder beside it, given the study
database's mode (0600), fsynced and put in place with ``link``, which never replaces, so one that appears while the
command runs is not overwritten either.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable
from pathlib import Path

from foundation.outfs import (
    Folder,
    OutputError,
    chmod_at,
    close_folder,
    file_mode,
    fsync_dir,
    is_write_failure,
    kind_of,
    lstat_at,
    mkdir_at,
    open_folder,
    os_error_line,
    parent_of,
    place,
    rmtree_at,
    writable_problem,
)

__all__ = ["check_output_file", "write_output_file"]


def check_output_file(out_file: str | os.PathLike[str], *, command: str, need_bytes: int = 0,
                      option: str = "--out") -> Path:
    """Refuse an output file the command must not write: one that exists (a link included), or a folder it cannot write.

    Raises
    ------
    OutputError
        One line naming the file and what is wrong; nothing was touched.
    """
    out = Path(out_file)
    try:
        st = os.lstat(out)
    except FileNotFoundError:
        pass
    except OSError as exc:
        raise OutputError(os_error_line(exc, f"{option} {out}", "cannot use it")) from None
    else:
        what = "" if stat.S_ISREG(st.st_mode) else f" (it is {kind_of(st.st_mode)})"
        raise OutputError(f"{option} {out}: exists{what}; {command} writes a new file only and never replaces one: "
                          "choose another name (nothing was written)")
    parent = parent_of(out)
    if not parent.is_dir():
        raise OutputError(f"{option} {out}: the folder {parent} does not exist")
    problem = writable_problem(parent, f"{option} {out}", need_bytes)
    if problem:
        raise OutputError(problem)
    return out


def write_output_file(out_file: str | os.PathLike[str], fill: Callable[[Path], object], *, command: str,
                      need_bytes: int = 0, option: str = "--out") -> Path:
    """Write one new file: ``fill(path)`` writes it in a private temporary folder beside it, then it is linked in.

    The file gets the output mode (0600), is fsynced, and appears whole or not
    at all; it never replaces anything (a file that appeared meanwhile is
    refused, not overwritten).

    Raises
    ------
    OutputError
        The file must not be written, or writing failed; nothing is left behind.
    """
    out = check_output_file(out_file, command=command, need_bytes=need_bytes, option=option)
    parent, name = parent_of(out), out.name
    tmp_name = f".{name[:64]}.tmp-{os.getpid()}-{os.urandom(4).hex()}"
    parent_fd: Folder | None = None
    try:
        try:
            parent_fd = open_folder(str(parent), follow=True)
            mkdir_at(parent_fd, tmp_name, 0o700)
        except OSError as exc:
            raise OutputError(os_error_line(exc, f"{option} {out}", "cannot write it"), status=1) from None
        tmp = parent / tmp_name
        try:
            fill(tmp / name)
        except OSError as exc:
            if not is_write_failure(exc, tmp):
                raise
            raise OutputError(os_error_line(exc, f"{option} {out}", "cannot write it"), status=1) from None
        try:
            _put_file_inplace(parent_fd, tmp_name, name, out, command, option)
        except OSError as exc:
            raise OutputError(os_error_line(exc, f"{option} {out}", "cannot write it"), status=1) from None
    finally:
        if parent_fd is not None:
            rmtree_at(parent_fd, tmp_name)
            close_folder(parent_fd)
    return out


def _put_file_inplace(parent_fd: Folder, tmp_name: str, name: str, out: Path, command: str, option: str) -> None:
    """The one file ``fill`` made: given the output mode, fsynced, and linked in beside the temporary folder."""
    tmp_fd = open_folder(tmp_name, parent_fd)
    try:
        try:
            mode = lstat_at(tmp_fd, name).st_mode
        except FileNotFoundError:
            raise OutputError(f"{option} {out}: {command} wrote nothing (nothing was written)", status=1) from None
        if not stat.S_ISREG(mode):
            raise OutputError(f"{option} {out}: {command} made {kind_of(mode)}, not a file (nothing was written)",
                              status=1)
        chmod_at(tmp_fd, name, file_mode(), sync=True)
        try:
            place(tmp_fd, parent_fd, name, replace=False)
        except OutputError:
            raise OutputError(f"{option} {out}: appeared while {command} ran; it was not overwritten (nothing was "
                              "written)", status=1) from None
        fsync_dir(parent_fd)
    finally:
        close_folder(tmp_fd)
