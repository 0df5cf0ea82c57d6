"""Which code is running: the installed version and, from a git checkout, its commit (a light import).

:func:`software_provenance` is the one answer, used by ``haptic-study --version``, by every new session
(``sessions.software_version``, ``software_commit``, ``software_dirty``) and by the report.  It is asked once
per process and remembered: the code a process runs is the code it loaded, whatever happens to the checkout
afterwards.
"""

from __future__ import annotations

import functools
import subprocess
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

__all__ = ["COMMIT_UNKNOWN", "Provenance", "software_provenance", "software_version"]

#: What is said of a session whose commit is not known (the package was not run from a git checkout).
COMMIT_UNKNOWN = "not known (installed from a wheel)"


def software_version() -> str:
    """Installed version of haptic-study."""
    try:
        return version("haptic-study")
    except PackageNotFoundError:  # pragma: no cover - running from a bare checkout
        return "0+unknown"


@dataclass(frozen=True, slots=True)
class Provenance:
    """The software a process runs.

    Attributes
    ----------
    version
        The package version (``0.1.0``).
    commit
        The full git commit of the checkout the code was loaded from, or None when it was not loaded from a
        checkout (installed from a wheel) or git could not tell.
    dirty
        True when that checkout had uncommitted changes to tracked files; None when ``commit`` is None.
    """

    version: str
    commit: str | None
    dirty: bool | None

    def describe(self) -> str:
        """``0.1.0 (commit 1a2b3c4d, with uncommitted changes)``, or the version alone when no commit is known."""
        if self.commit is None:
            return self.version
        return f"{self.version} (commit {self.commit[:8]}{', with uncommitted changes' if self.dirty else ''})"


def _git(root: Path, *args: str) -> str:
    return subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=10,
                          check=True).stdout.strip()


def checkout_provenance(root: Path) -> tuple[str | None, bool | None]:
    """(commit, dirty) of the git checkout at ``root``; (None, None) when ``root`` is not one or git cannot tell.

    Only a checkout whose top folder is ``root`` counts (``root/.git``, a folder or a worktree's file): a
    package installed into a folder that happens to sit inside some other repository is not that repository.
    """
    if not (root / ".git").exists():
        return None, None
    try:
        commit = _git(root, "rev-parse", "HEAD")
        dirty = bool(_git(root, "status", "--porcelain", "--untracked-files=no"))
    except (OSError, subprocess.SubprocessError):
        return None, None
    return (commit, dirty) if len(commit) >= 40 else (None, None)


@functools.cache
def software_provenance() -> Provenance:
    """The version, commit and uncommitted-changes flag of the running code (asked once per process).

    Returns
    -------
    Provenance
        ``commit`` and ``dirty`` are None when the package was not loaded from a git checkout (an installed
        wheel): the report then says :data:`COMMIT_UNKNOWN`.
    """
    commit, dirty = checkout_provenance(Path(__file__).resolve().parents[1])
    return Provenance(software_version(), commit, dirty)
