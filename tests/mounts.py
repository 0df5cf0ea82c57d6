"""Small file systems for tests: a tmpfs of a few hundred KiB (a full disk) or mounted read-only.

Mounting needs root (or CAP_SYS_ADMIN) and a kernel that allows it here; where
it is not possible, :func:`can_mount` says why, and the tests that need a mount
skip with that reason.
"""

from __future__ import annotations

import functools
import os
import subprocess
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["can_mount", "tmpfs"]


@functools.lru_cache(maxsize=1)
def can_mount() -> str:
    """"" when this process may mount a tmpfs, else why not (the reason a test skips with)."""
    if os.name != "posix":
        return "mounting a tmpfs needs Linux"
    if os.geteuid() != 0:
        return "mounting a tmpfs needs root"
    d = tempfile.mkdtemp(prefix="haptic-mount-probe-")
    try:
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", d], capture_output=True, text=True)
        if r.returncode != 0:
            return f"this machine does not let the tests mount a tmpfs ({r.stderr.strip() or r.returncode})"
        subprocess.run(["umount", d], check=True)
        return ""
    except OSError as exc:
        return f"no mount command ({exc})"
    finally:
        os.rmdir(d)


def mount_tmpfs(where: Path, size_kib: int, *, read_only: bool = False, mode: int = 0o755) -> None:
    """Mount a tmpfs of ``size_kib`` KiB on the existing folder ``where`` (read-only: with nothing on it)."""
    opts = f"size={size_kib}k,mode={mode:o}" + (",ro" if read_only else "")
    subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(where)], check=True, capture_output=True)


def unmount(where: Path) -> None:
    """Unmount ``where`` (lazily: a subprocess still in it does not keep it)."""
    subprocess.run(["umount", "-l", str(where)], capture_output=True)


@contextmanager
def tmpfs(where: Path, size_kib: int, *, read_only: bool = False, mode: int = 0o755) -> Iterator[Path]:
    """A tmpfs mounted on ``where`` (created if missing) for the ``with`` block."""
    where.mkdir(exist_ok=True)
    mount_tmpfs(where, size_kib, read_only=read_only, mode=mode)
    try:
        yield where
    finally:
        unmount(where)
