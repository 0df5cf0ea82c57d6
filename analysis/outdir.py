"""One policy for the output folders of ``report --out DIR`` and ``power --out DIR``.

A command that writes a folder of results must never destroy anybody's work,
and a run that fails half-way must never leave half an output behind.  The
rules, the same for every command that uses this module:

* **A marker lists what was written.**  Every output folder holds a marker
  file (``.haptic-study-report``, ``.haptic-study-power``) naming every file
  the command wrote there, with its SHA-256.
* **An existing, non-empty folder is refused** unless ``force`` -- except for
  files the command declares its own to keep (``power``'s simulated pool,
  which it reuses): those alone do not make a folder "non-empty".
* **``force`` replaces only the command's own, unedited files.**  Any file the
  marker does not list (someone's notes, another tool's output), or a listed
  file whose hash no longer matches (someone edited the CSV), or a folder
  without a marker means a refusal naming the file, and nothing is touched.
* **An input database inside the output folder is refused** (``force`` would
  otherwise put it at risk).
* **Outputs are built in a temporary sibling folder** (``.DIR.XXXX.tmp``) and
  moved into place only once complete: an exception (or a crash) while
  writing leaves the old output exactly as it was.  Moving into place is a
  rename of the whole folder when ``DIR`` is new or empty; otherwise it is one
  rename per file, with the marker first accepting the old and the new hash
  of every file, so even a crash between two renames leaves a folder that
  ``force`` may replace.

Every refusal is an :class:`analysis.load.AnalysisError` whose message is one
line naming the folder and the file; the command line turns it into exit 2.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

from analysis.load import AnalysisError

__all__ = ["check_output_folder", "read_marker", "sha256_file", "write_output_folder"]

#: Decides whether a file (its path relative to the folder, with ``/``) belongs to what the command keeps.
Keep = Callable[[str], bool]


def _keep_nothing(_: str) -> bool:
    return False


def sha256_file(path: str | os.PathLike[str]) -> str:
    """SHA-256 of a file's bytes, read in 1 MiB blocks (a simulated pool may be gigabytes)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def read_marker(out: Path, marker: str) -> dict[str, set[str]] | None:
    """The files a previous run listed in ``out/marker``, each with the hashes accepted for it.

    None when there is no readable marker.  A marker written while files were
    being moved into place (``pending``) accepts the old and the new hash.
    """
    try:
        data = json.loads((out / marker).read_text(encoding="utf-8"))
        listed = data["files"]
        pending = data.get("pending", {})
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None
    if not isinstance(listed, dict) or not isinstance(pending, dict):
        return None
    accepted: dict[str, set[str]] = {str(f): {str(h)} for f, h in listed.items()}
    for f, h in pending.items():
        accepted.setdefault(str(f), set()).add(str(h))
    return accepted


def _files(out: Path) -> list[str]:
    return sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if not p.is_dir())


def _refuse_inputs_inside(out: Path, inputs: Sequence[str | os.PathLike[str]]) -> None:
    root = out.resolve()
    for db in inputs:
        p = Path(db).resolve()
        if root == p or root in p.parents:
            raise AnalysisError(f"--out {out}: holds the input database {db}; write to another folder "
                                "(nothing was changed)")


def check_output_folder(
    out_dir: str | os.PathLike[str],
    *,
    command: str,
    marker: str,
    inputs: Sequence[str | os.PathLike[str]] = (),
    force: bool = False,
    keep: Keep = _keep_nothing,
) -> Path:
    """Refuse an output folder the command must not write (before any work is done).

    Parameters
    ----------
    out_dir
        The ``--out`` folder; it may not exist yet (its parent must).
    command
        The command's name, for the messages (``"report"``, ``"power"``).
    marker
        The marker file's name.
    inputs
        Input databases: none may lie inside the folder.
    force
        Allow replacing the command's own, unedited files.
    keep
        Files (relative paths) the command keeps and reuses: never replaced,
        never deleted, and they alone do not make the folder non-empty.

    Returns
    -------
    Path
        ``out_dir``.

    Raises
    ------
    AnalysisError
        One line naming the folder and what is wrong; nothing was touched.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise AnalysisError(f"--out {out}: exists and is not a folder")
    _refuse_inputs_inside(out, inputs)
    parent = out.resolve().parent
    if not parent.is_dir():
        raise AnalysisError(f"--out {out}: the folder {parent} does not exist")
    if not os.access(parent, os.W_OK) or (out.exists() and not os.access(out, os.W_OK)):
        raise AnalysisError(f"--out {out}: cannot write in {out if out.exists() else parent}")
    if not out.exists():
        return out
    present = [f for f in _files(out) if f not in (marker, marker + ".new") and not keep(f)]
    if not present:
        return out
    if not force:
        more = f" and {len(present) - 1} more" if len(present) > 1 else ""
        raise AnalysisError(f"--out {out}: the folder exists and holds {present[0]}{more}; choose another folder, or "
                            f"pass --force to replace a folder {command} wrote before (--force replaces only "
                            f"{command}'s own unedited files)")
    listed = read_marker(out, marker)
    if listed is None:
        raise AnalysisError(f"--out {out}: not a folder {command} wrote (no readable {marker} in it); --force "
                            f"replaces only {command}'s own files: choose another folder (nothing was deleted)")
    foreign = [f for f in present if f not in listed]
    if foreign:
        raise AnalysisError(f"--out {out}: holds {foreign[0]}, which {command} did not write"
                            f"{f' (and {len(foreign) - 1} more)' if len(foreign) > 1 else ''}; move it or choose "
                            "another folder (nothing was deleted)")
    edited = [f for f in present if sha256_file(out / f) not in listed[f]]
    if edited:
        raise AnalysisError(f"--out {out}: {edited[0]} was changed since {command} wrote it"
                            f"{f' (and {len(edited) - 1} more)' if len(edited) > 1 else ''}; keep your edits "
                            "elsewhere or choose another folder (nothing was deleted)")
    return out


def _apply_umask(folder: Path) -> None:
    """mkdtemp makes an owner-only folder: give the outputs the permissions the user's umask asks for."""
    mask = os.umask(0)
    os.umask(mask)
    for p in [folder, *folder.rglob("*")]:
        p.chmod((0o777 if p.is_dir() else 0o666) & ~mask)


def _write_marker(path: Path, command: str, files: dict[str, str], pending: dict[str, str] | None = None) -> None:
    from protocol.version import software_version

    data: dict[str, object] = {"written_by": f"haptic-study {software_version()} {command}", "files": files}
    if pending:
        data["pending"] = pending
    tmp = path.with_name(path.name + ".new")
    tmp.write_text(json.dumps(data, indent=1, sort_keys=True), encoding="utf-8")
    os.replace(tmp, path)


def write_output_folder(
    out_dir: str | os.PathLike[str],
    fill: Callable[[Path], object],
    *,
    command: str,
    marker: str,
    inputs: Sequence[str | os.PathLike[str]] = (),
    force: bool = False,
    keep: Keep = _keep_nothing,
) -> list[str]:
    """Write a command's outputs into ``out_dir`` by the policy of this module.

    Parameters
    ----------
    out_dir
        The ``--out`` folder.
    fill
        ``fill(folder)`` writes every output into the (temporary) folder it is given.
    command, marker, inputs, force, keep
        As in :func:`check_output_folder` (which runs again here, so the
        folder is checked as it is when the outputs are ready).

    Returns
    -------
    list of str
        The files written (relative paths), the marker not included.

    Raises
    ------
    AnalysisError
        The folder must not be written (:func:`check_output_folder`), or it
        changed while the outputs were made; nothing of it was touched.
    """
    out = check_output_folder(out_dir, command=command, marker=marker, inputs=inputs, force=force, keep=keep)
    parent = out.resolve().parent
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=parent))
    except OSError as exc:
        raise AnalysisError(f"--out {out}: cannot write in {parent} ({exc.strerror})") from None
    try:
        fill(tmp)
        files = _files(tmp)
        hashes = {f: sha256_file(tmp / f) for f in files}
        _write_marker(tmp / marker, command, hashes)
        _apply_umask(tmp)
        if not out.exists() or not any(out.iterdir()):
            try:
                os.replace(tmp, out)  # a new or empty folder: one rename, all or nothing
            except OSError:
                raise AnalysisError(f"--out {out}: files appeared in it while {command} ran; nothing was "
                                    "changed (run it again)") from None
            return files
        _move_in(tmp, out, files, hashes, command=command, marker=marker, force=force, keep=keep)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    shutil.rmtree(tmp, ignore_errors=True)
    return files


def _move_in(tmp: Path, out: Path, files: Iterable[str], hashes: dict[str, str], *, command: str, marker: str,
             force: bool, keep: Keep) -> None:
    """Replace the command's own files in ``out`` by those of ``tmp``, file by file (the folder was checked)."""
    check_output_folder(out, command=command, marker=marker, force=force, keep=keep)  # as it is now
    old = read_marker(out, marker) or {}
    old_present = {f: sha256_file(out / f) for f in old if (out / f).is_file()}
    # the marker first accepts both versions of every file: a crash between two renames leaves a replaceable folder
    _write_marker(out / marker, command, old_present, pending=hashes)
    for f in files:
        (out / f).parent.mkdir(parents=True, exist_ok=True)
        os.replace(tmp / f, out / f)
    for f in sorted(set(old_present) - set(hashes), reverse=True):
        (out / f).unlink(missing_ok=True)
        d = (out / f).parent
        while d != out:  # folders only ours (e.g. figures/) go when their last file goes; others stay
            try:
                d.rmdir()
            except OSError:
                break
            d = d.parent
    _write_marker(out / marker, command, hashes)
