"""The version as people are told it: the installed version, and the git commit when run from a checkout.

Its own small module so that ``--version`` (:mod:`study_app.cli`) and the GUI's Help → About both use it
without the GUI importing the command line.
"""

from __future__ import annotations

__all__ = ["version_text"]


def version_text() -> str:
    """``0.1.0 (commit 1a2b3c4d, with uncommitted changes)`` in a git checkout; else it says it is not one.

    An install from a wheel (or a source tree without git) has no commit to name:
    ``0.1.0 (installed package, not a git checkout: /…/site-packages)``.
    """
    import subprocess
    from pathlib import Path

    from protocol.version import software_version

    text = software_version()
    root = Path(__file__).resolve().parent.parent
    if not (root / ".git").exists():  # an installed copy, not a checkout
        return f"{text} (installed package, not a git checkout: {root})"
    try:
        def git(*args: str) -> str:
            return subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=5,
                                  check=True).stdout.strip()

        commit = git("rev-parse", "--short=8", "HEAD")
        dirty = bool(git("status", "--porcelain", "--untracked-files=no"))
    except (OSError, subprocess.SubprocessError):
        return text
    return f"{text} (commit {commit}{', with uncommitted changes' if dirty else ''})"
