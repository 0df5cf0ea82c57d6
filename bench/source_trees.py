"""Running another version of haptic-study from its source tree, beside ours, for a benchmark that compares them.

A benchmark that compares versions (``bench report --reference TREE``, ``bench pipeline --reference-tree TREE``)
runs the other version in a fresh process with its tree first on the import path (``PYTHONPATH=TREE``) and our
interpreter and installed libraries, so neither version imports the other.  The process runs in a folder of its
own: ``python -m`` puts the working directory first on the path, so run from our checkout the "reference" would be
our code; :func:`check_tree` makes sure each side imports ``study_app`` from where it should.
"""

from __future__ import annotations

import os
import subprocess
import sys

__all__ = ["check_tree", "imported_from", "source_env"]


def source_env(source: str | None) -> dict[str, str] | None:
    """The environment that puts the source tree ``source`` first on the import path (None: ours)."""
    if source is None:
        return None
    return {**os.environ, "PYTHONPATH": os.pathsep.join([os.path.abspath(source),
                                                         os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)}


def imported_from(source: str | None, cwd: str) -> str:
    """Where a fresh process set up with :func:`source_env`, run in ``cwd``, imports ``study_app`` from."""
    out = subprocess.run([sys.executable, "-c", "import study_app; print(study_app.__file__)"], check=True,
                         capture_output=True, text=True, env=source_env(source), cwd=cwd)
    return out.stdout.strip()


def check_tree(source: str, cwd: str, flag: str) -> None:
    """:class:`RuntimeError` unless a process in ``cwd`` with ``source`` first imports its ``study_app``."""
    where = imported_from(source, cwd)
    if not os.path.abspath(where).startswith(os.path.join(os.path.abspath(source), "")):
        raise RuntimeError(f"{flag} {source}: it would import study_app from {where}, not from the tree "
                           "(is it a source tree of haptic-study?)")
