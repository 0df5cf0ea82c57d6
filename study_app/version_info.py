"""The version as people are told it: the installed version, and the git commit when run from a checkout.

Its own small module so that ``--version`` (:mod:`study_app.cli.main`) and the GUI's Help → About both use it
without the GUI importing the command line.
"""

from __future__ import annotations

__all__ = ["version_text"]


def version_text() -> str:
    """``0.1.0 (commit 1a2b3c4d, with uncommitted changes)`` in a git checkout; else it says it is not one.

    The same answer every new session stores (:func:`foundation.version.software_provenance`). An install from a
    wheel (or a source tree without git) has no commit to name:
    ``0.1.0 (installed package, not a git checkout: /…/site-packages)``.
    """
    from pathlib import Path

    from foundation.version import software_provenance

    provenance = software_provenance()
    root = Path(__file__).resolve().parents[1]
    if provenance.commit is None and not (root / ".git").exists():
        return f"{provenance.version} (installed package, not a git checkout: {root})"
    return provenance.describe()
