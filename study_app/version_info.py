"""The version as people are told it: the installed version, and the git commit when run from a checkout.

Its own small module so that ``--version`` (:mod:`study_app.cli`) and the GUI's Help → About both use it
without the GUI importing the command line.
"""

from __future__ import annotations

__all__ = ["version_text"]


def version_text() -> str:
    """``0.1.0``, or ``0.1.0 (commit 1a2b3c4d, with uncommitted changes)`` in a git checkout.

    The same answer every new session stores (:func:`protocol.version.software_provenance`).
    """
    from protocol.version import software_provenance

    return software_provenance().describe()
