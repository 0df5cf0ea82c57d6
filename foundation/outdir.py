"""One output policy for every command that writes files.

``report``, ``power``, ``replay --out`` and ``gui --screenshot`` write a
folder (:func:`write_output_folder`); ``plot-trial``, ``plot-session`` and
``export samples`` write one file (:func:`foundation.outfile.write_output_file`).  The rules (the folder's
marker is :mod:`foundation.outmarker`):

* **Nothing outside the folder, never through a link.**  Below the folder the
  user named, every step is taken by file descriptor with ``O_NOFOLLOW``: a
  symbolic link inside it (``R/figures`` pointing at someone's folder) is an
  entry the command did not make, never a way out.  The folder itself (or a
  single output file's folder) may be reached through a link the user typed.
  Where the OS has no ``*at`` calls (Windows) each step is taken by path
  instead, every part ``lstat``-checked (no link, no junction) right before it
  (:mod:`foundation.outpath`): the same rules and refusals, with a race window
  against a process that rewrites the folder during the write.
* **Nothing overwritten that the command did not make.**  A folder holds a
  marker (``.haptic-study-report``, ``.haptic-study-power``, ...) listing each
  file the command wrote with its SHA-256.  An existing, non-empty folder is
  refused unless ``force``, and ``force`` replaces only the files the marker
  lists, unedited: any other entry (someone's notes, a link, a FIFO), an
  edited file or a folder without a marker is a refusal naming it, nothing
  touched.  Files the command keeps (``power``'s simulated pool) never count
  and are never touched.  An input database inside the folder is refused.  A
  single output file must not exist at all (a link, even a dangling one,
  included); it is put in place with ``link`` (which never replaces), so one
  that appears while the command runs is not overwritten either.
* **Permissions kept, and private.**  An existing folder is written into,
  never replaced, so its mode and owner stay; new files get the study
  database's mode ``0600`` and new folders ``0700`` (stricter where the umask
  says so).
* **Atomic.**  Outputs are made in a private temporary folder inside the
  output folder (the same file system, so this works on the root of a mount
  point too), fsynced, and renamed into place only when complete: a run that
  fails half-way leaves the old output as it was.  Replacing files is one
  rename per file with the marker first accepting the old and the new hash of
  every file, so even a crash between two renames leaves a folder ``force``
  may replace.
* **Checked before the work, one line after it.**  :func:`check_output_folder`
  and :func:`foundation.outfile.check_output_file` refuse (exit 2) a folder that is read-only,
  not writable, or full before any long work; an ``OSError`` while writing
  (ENOSPC, EROFS, EIO, ...) is one line naming the path and what to do (exit
  1), and leaves nothing of the run behind.

Every refusal is an :class:`foundation.outfs.OutputError` (an
:class:`foundation.errors.InputRefused`) whose message is one line.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TypedDict, Unpack

from foundation.outfs import (
    Folder,
    OutputError,
    chmod_at,
    close_folder,
    dir_mode,
    entries,
    file_mode,
    folder_at,
    fsync_dir,
    is_write_failure,
    kind_of,
    listdir_at,
    mkdir_at,
    open_folder,
    os_error_line,
    parent_of,
    place,
    rmdir_at,
    rmtree_at,
    sha256_at,
    sha256_at_or_none,
    unlink_at,
    writable_problem,
    write_bytes_at,
)
from foundation.outmarker import marker_bytes, read_marker_at
from foundation.platform_support.processes import process_exists

__all__ = ["REPORT_MARKER", "FolderRules", "OutputError", "check_output_folder", "ensure_output_folder",
           "write_output_folder"]

#: The marker of ``report``'s output folder (here, so that the command line checks ``--out`` before it imports
#: the analysis).
REPORT_MARKER = ".haptic-study-report"
#: Decides whether a file (its path relative to the folder, with ``/``) belongs to what the command keeps.
Keep = Callable[[str], bool]


def _keep_nothing(_: str) -> bool:
    return False


# -- what a folder holds --------------------------------------------------------------------------------------------
def _ours_transient(name: str, marker: str) -> bool:
    """A top-level entry the policy itself makes while it works: its temporary folder, the marker's temporary file."""
    return name.startswith(f"{marker}.tmp-") or (name.startswith(f".{marker}.") and name.endswith(".new"))


def _present(dir_fd: Folder, marker: str, keep: Keep) -> list[tuple[str, int]]:
    """Every entry that makes the folder non-empty: (relative path, lstat mode); folders only by what they hold."""
    out = []
    skip: list[str] = []
    for rel, mode in entries(dir_fd):
        top = rel.split("/", 1)[0]
        if top in skip or (rel == top and (rel in (marker, marker + ".new") or _ours_transient(rel, marker))):
            if stat.S_ISDIR(mode) and rel == top:
                skip.append(top)
            continue
        if stat.S_ISDIR(mode) or keep(rel):
            continue
        out.append((rel, mode))
    return out


def _refuse_inputs_inside(out: Path, inputs: Sequence[str | os.PathLike[str]], option: str) -> None:
    root = out.resolve()
    for db in inputs:
        p = Path(db).resolve()
        if root == p or root in p.parents:
            raise OutputError(f"{option} {out}: holds the input database {db}; write to another folder "
                              "(nothing was changed)")


def _judge(out: Path, dir_fd: Folder, *, command: str, marker: str, force: bool, keep: Keep, option: str) -> None:
    """Refuse a folder whose entries the command may not replace (the rules of the module)."""
    present = _present(dir_fd, marker, keep)
    if not present:
        return
    names = [rel for rel, _ in present]
    if not force:
        more = f" and {len(names) - 1} more" if len(names) > 1 else ""
        raise OutputError(f"{option} {out}: the folder exists and holds {names[0]}{more}; choose another folder, or "
                          f"pass --force to replace a folder {command} wrote before (--force replaces only "
                          f"{command}'s own unedited files)")
    listed = read_marker_at(dir_fd, marker)
    if listed is None:
        raise OutputError(f"{option} {out}: not a folder {command} wrote (no readable {marker} in it); --force "
                          f"replaces only {command}'s own files: choose another folder (nothing was deleted)")
    foreign = [(rel, mode) for rel, mode in present if rel not in listed or not stat.S_ISREG(mode)]
    if foreign:
        rel, mode = foreign[0]
        what = "" if stat.S_ISREG(mode) else f" ({kind_of(mode)})"
        raise OutputError(f"{option} {out}: holds {rel}{what}, which {command} did not write"
                          f"{f' (and {len(foreign) - 1} more)' if len(foreign) > 1 else ''}; move it or choose "
                          "another folder (nothing was deleted)")
    edited = [rel for rel, _ in present if sha256_at(dir_fd, rel) not in listed[rel]]
    if edited:
        raise OutputError(f"{option} {out}: {edited[0]} was changed since {command} wrote it"
                          f"{f' (and {len(edited) - 1} more)' if len(edited) > 1 else ''}; keep your edits "
                          "elsewhere or choose another folder (nothing was deleted)")


class FolderRules(TypedDict, total=False):
    """What a command allows of its output folder, beside its name and marker: the keywords
    :func:`check_output_folder` and :func:`write_output_folder` share (each optional, with the default named).

    Attributes
    ----------
    inputs
        Input databases: none may lie inside the folder (default: none).
    force
        Allow replacing the command's own, unedited files (default False).
    keep
        Files (relative paths) the command keeps and reuses: never replaced, never deleted, and they alone do not
        make the folder non-empty (default: none).
    need_bytes
        Free space the outputs need, roughly (default 0: only that the disk is not full).
    option
        The option that named the folder, for the messages (default ``--out``; ``--screenshot``).
    """

    inputs: Sequence[str | os.PathLike[str]]
    force: bool
    keep: Keep
    need_bytes: int
    option: str


def check_output_folder(out_dir: str | os.PathLike[str], *, command: str, marker: str,
                        **rules: Unpack[FolderRules]) -> Path:
    """Refuse an output folder the command must not write (before any work is done).

    Parameters
    ----------
    out_dir
        The ``--out`` folder; it may not exist yet (its parent must).
    command
        The command's name, for the messages (``"report"``, ``"power"``).
    marker
        The marker file's name.
    **rules
        What the command allows of the folder (:class:`FolderRules`).

    Returns
    -------
    Path
        ``out_dir``.

    Raises
    ------
    OutputError
        One line naming the folder and what is wrong; nothing was touched.
    """
    inputs, force, keep = rules.get("inputs", ()), rules.get("force", False), rules.get("keep", _keep_nothing)
    need_bytes, option = rules.get("need_bytes", 0), rules.get("option", "--out")
    out = Path(out_dir)
    try:
        st = os.stat(out)  # the folder the user named may be a link to a folder
    except FileNotFoundError:
        if os.path.lexists(out):
            raise OutputError(f"{option} {out}: is a symbolic link to nothing; choose another folder") from None
        _refuse_inputs_inside(out, inputs, option)
        parent = parent_of(out)
        if not parent.is_dir():
            raise OutputError(f"{option} {out}: the folder {parent} does not exist") from None
        problem = writable_problem(parent, f"{option} {out}", need_bytes)
        if problem:
            raise OutputError(problem) from None
        return out
    except OSError as exc:
        raise OutputError(os_error_line(exc, f"{option} {out}", "cannot use it")) from None
    if not stat.S_ISDIR(st.st_mode):
        raise OutputError(f"{option} {out}: exists and is not a folder (it is {kind_of(st.st_mode)})")
    _refuse_inputs_inside(out, inputs, option)
    problem = writable_problem(out, f"{option} {out}", need_bytes)
    if problem:
        raise OutputError(problem)
    try:
        fd = open_folder(str(out), follow=True)
        try:
            _judge(out, fd, command=command, marker=marker, force=force, keep=keep, option=option)
        finally:
            close_folder(fd)
    except OSError as exc:
        raise OutputError(os_error_line(exc, f"{option} {out}", "cannot read the folder")) from None
    return out


def ensure_output_folder(out: Path, option: str = "--out") -> bool:
    """Create ``out`` (owner-only, as :func:`foundation.outfs.dir_mode`) if missing; True when this call made it."""
    try:
        os.mkdir(out, dir_mode())
    except FileExistsError:
        return False
    except OSError as exc:
        raise OutputError(os_error_line(exc, f"{option} {out}", "cannot create the folder"), status=1) from None
    return True


# -- writing a folder ------------------------------------------------------------------------------------------------
def _seal(tmp_fd: Folder) -> dict[str, str]:
    """The files ``fill`` made, each given the output mode, fsynced and hashed; folders given the folder mode."""
    hashes: dict[str, str] = {}
    for rel, mode in list(entries(tmp_fd)):
        if stat.S_ISDIR(mode):
            chmod_at(tmp_fd, rel, dir_mode())
            continue
        if not stat.S_ISREG(mode):
            raise OutputError(f"{rel}: the command made {kind_of(mode)} where a file belongs (nothing was written)")
        chmod_at(tmp_fd, rel, file_mode(), sync=True)
        digest = sha256_at(tmp_fd, rel)
        assert digest is not None
        hashes[rel] = digest
    return hashes








def _move_in(out_fd: Folder, tmp_fd: Folder, hashes: dict[str, str], *, command: str, marker: str) -> None:
    """Put the files of the temporary folder in place, the marker first accepting old and new (the folder was
    judged)."""
    old = read_marker_at(out_fd, marker) or {}
    old_present = {f: h for f in old if (h := sha256_at_or_none(out_fd, f)) is not None and h in old[f]}
    write_bytes_at(out_fd, marker, marker_bytes(command, old_present, pending=hashes))
    for rel in hashes:
        folder, _, name = rel.rpartition("/")
        dst = folder_at(out_fd, folder, make=True)
        src = folder_at(tmp_fd, folder, make=False)
        try:
            place(src, dst, name, replace=rel in old_present)
            fsync_dir(dst)
        finally:
            close_folder(dst)
            close_folder(src)
    for rel in sorted(set(old_present) - set(hashes), reverse=True):
        parts = rel.split("/")
        dst = folder_at(out_fd, "/".join(parts[:-1]), make=False)
        try:
            unlink_at(dst, parts[-1])
        finally:
            close_folder(dst)
        for k in range(len(parts) - 1, 0, -1):  # folders only ours (figures/) go with their last file; others stay
            up = folder_at(out_fd, "/".join(parts[:k - 1]), make=False)
            try:
                rmdir_at(up, parts[k - 1])
            except OSError:
                break
            finally:
                close_folder(up)
    write_bytes_at(out_fd, marker, marker_bytes(command, hashes))
    fsync_dir(out_fd)




def _remove_stale_temporaries(out_fd: Folder, marker: str) -> None:
    """Temporary folders of this command left by a killed run (its process gone): they were never output."""
    for name in listdir_at(out_fd):
        if not name.startswith(f"{marker}.tmp-"):
            continue
        try:
            pid = int(name[len(marker) + 5:].split("-", 1)[0])
            alive = process_exists(pid)  # (platform_support: Windows asks OpenProcess)
        except (ValueError, OSError):
            continue
        if not alive:
            rmtree_at(out_fd, name)


def write_output_folder(out_dir: str | os.PathLike[str], fill: Callable[[Path], object], *, command: str, marker: str,
                        **rules: Unpack[FolderRules]) -> list[str]:
    """Write a command's outputs into ``out_dir`` by the policy of this module.

    Parameters
    ----------
    out_dir
        The ``--out`` folder.
    fill
        ``fill(folder)`` writes every output into the (temporary, private) folder it is given.
    command, marker, **rules
        As in :func:`check_output_folder` (which runs here, and once more when the outputs are ready, so the
        folder is judged as it is then).

    Returns
    -------
    list of str
        The files written (relative paths), the marker not included.

    Raises
    ------
    OutputError
        The folder must not be written, or writing failed (one line; the
        folder is as it was, and a folder this call created is removed again).
    """
    out = check_output_folder(out_dir, command=command, marker=marker, **rules)
    force, keep, option = rules.get("force", False), rules.get("keep", _keep_nothing), rules.get("option", "--out")
    created = ensure_output_folder(out, option)
    tmp_name = f"{marker}.tmp-{os.getpid()}-{os.urandom(4).hex()}"
    out_fd: Folder | None = None
    failed = f"cannot write {command}'s outputs"
    try:
        try:
            out_fd = open_folder(str(out), follow=True)
            _remove_stale_temporaries(out_fd, marker)
            mkdir_at(out_fd, tmp_name, 0o700)
        except OSError as exc:
            raise OutputError(os_error_line(exc, f"{option} {out}", failed), status=1) from None
        tmp = out / tmp_name
        try:
            fill(tmp)
        except OSError as exc:
            if not is_write_failure(exc, tmp):
                raise
            raise OutputError(os_error_line(exc, f"{option} {out}", failed), status=1) from None
        try:
            tmp_fd = open_folder(tmp_name, out_fd)
            try:
                hashes = _seal(tmp_fd)
                # as it is now
                _judge(out, out_fd, command=command, marker=marker, force=force, keep=keep, option=option)
                _move_in(out_fd, tmp_fd, hashes, command=command, marker=marker)
            finally:
                close_folder(tmp_fd)
        except OSError as exc:
            raise OutputError(os_error_line(exc, f"{option} {out}", failed), status=1) from None
    finally:
        if out_fd is not None:
            rmtree_at(out_fd, tmp_name)
            close_folder(out_fd)
        if created and not _safe_listdir(out):
            try:
                os.rmdir(out)
            except OSError:
                pass
    return list(hashes)


def _safe_listdir(out: Path) -> list[str]:
    try:
        return os.listdir(out)
    except OSError:
        return ["?"]


