"""The study databases an analysis is asked to read, checked before anything heavy is imported.

Light on purpose (no pandas, SciPy or Matplotlib): ``report``, ``power`` and the readers call
:func:`check_databases` first, so a wrong ``--db`` is one line at once instead of after seconds of imports, and
:func:`analysis.reading.load.load_study` calls it too, so the rules and their words are defined here only.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from analysis.reading.errors import AnalysisError
from protocol.storage import StorageError, StudyReader

__all__ = ["check_databases"]


def check_databases(paths: Sequence[str | os.PathLike[str]], *, open_each: bool = True) -> list[str]:
    """The paths as strings, once each shown to name a study database.

    Parameters
    ----------
    paths
        The ``--db`` values, in order.
    open_each
        Also open each one read-only, unchecked: a file that is not SQLite, a foreign SQLite file or a newer
        schema is refused here.  Damage inside a good file is found by the full read (SQLite's quick check).

    Raises
    ------
    AnalysisError
        No path, a path that does not exist, one database given twice (also through another name), or a file
        that is not a haptic-study database.
    """
    if not paths:
        raise AnalysisError("--db: give at least one study database")
    seen: dict[tuple[int, int], str] = {}
    out = []
    for raw in paths:
        path = str(raw)
        if not Path(path).exists():
            raise AnalysisError(f"{path}: no such database")
        st = os.stat(path)
        key = (st.st_dev, st.st_ino)
        if key in seen:
            raise AnalysisError(f"{path}: the same database is given twice (also as {seen[key]})")
        seen[key] = path
        if open_each:
            try:
                StudyReader(path, check=False).close()
            except StorageError as exc:
                raise AnalysisError(str(exc)) from None
        out.append(path)
    return out
