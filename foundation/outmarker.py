"""The marker of an output folder: the files a command wrote there, each with its SHA-256.

A folder a command writes (:mod:`foundation.outdir`) holds a marker (``.haptic-study-report``,
``.haptic-study-power``, ...) listing each file with its hash, so that ``--force`` replaces only the command's own,
unedited files.  A marker written while files were being moved into place (``pending``) accepts the old and the new
hash of each, so a crash between two renames leaves a folder ``--force`` may still replace.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from foundation.outfs import Folder, OutputError, close_folder, open_folder, read_regular_at, sha256_at

__all__ = ["marker_bytes", "parse_marker", "read_marker", "read_marker_at", "sha256_file"]


def sha256_file(path: str | os.PathLike[str]) -> str:
    """SHA-256 of a regular file's bytes, read in 1 MiB blocks (a simulated pool may be gigabytes)."""
    p = Path(path)
    fd = open_folder(str(p.parent), follow=True)
    try:
        digest = sha256_at(fd, p.name)
    finally:
        close_folder(fd)
    if digest is None:
        raise OutputError(f"{path}: not a regular file")
    return digest


def parse_marker(raw: bytes) -> dict[str, set[str]] | None:
    """A marker's files, each with the hashes accepted for it; None when ``raw`` is not a marker."""
    try:
        data = json.loads(raw.decode("utf-8"))
        listed = data["files"]
        pending = data.get("pending", {})
    except (ValueError, KeyError, TypeError, AttributeError):
        return None
    if not isinstance(listed, dict) or not isinstance(pending, dict):
        return None
    accepted: dict[str, set[str]] = {str(f): {str(h)} for f, h in listed.items() if _inside(str(f))}
    for f, h in pending.items():
        if _inside(str(f)):
            accepted.setdefault(str(f), set()).add(str(h))
    return accepted


def _inside(rel: str) -> bool:
    """Whether a marker's entry names a file inside the folder: plain names joined by ``/`` (no ``..``, no root).

    A marker is a file in the folder anyone who may write there can edit: an
    entry ``../x`` with x's hash would otherwise let ``--force`` remove a file
    outside the folder.
    """
    return all(part not in ("", ".", "..") and "\\" not in part for part in rel.split("/"))


def read_marker_at(dir_fd: Folder, marker: str) -> dict[str, set[str]] | None:
    """:func:`read_marker` in an open folder."""
    raw = read_regular_at(dir_fd, marker, 16 << 20)
    return None if raw is None else parse_marker(raw)


def read_marker(out: Path, marker: str) -> dict[str, set[str]] | None:
    """The files a previous run listed in ``out/marker``, each with the hashes accepted for it.

    None when there is no readable marker (a link in its place is not one).  A
    marker written while files were being moved into place (``pending``)
    accepts the old and the new hash.
    """
    try:
        fd = open_folder(str(out), follow=True)
    except OSError:
        return None
    try:
        return read_marker_at(fd, marker)
    finally:
        close_folder(fd)


def marker_bytes(command: str, files: dict[str, str], pending: dict[str, str] | None = None) -> bytes:
    """A marker's bytes: ``files`` (name -> hash) written by ``command``, and those being moved in (``pending``)."""
    from foundation.version import software_version

    data: dict[str, object] = {"written_by": f"haptic-study {software_version()} {command}", "files": files}
    if pending:
        data["pending"] = pending
    return json.dumps(data, indent=1, sort_keys=True).encode("utf-8")
