"""The analysis floor's one error type, in a module with no heavy imports.

:mod:`analysis.load` re-exports it (``from analysis.load import AnalysisError``
keeps working); the output policy (:mod:`analysis.outdir`) raises it without
loading pandas, so a refused ``--out`` is said before the analysis is imported.
"""

from __future__ import annotations

__all__ = ["AnalysisError"]


class AnalysisError(ValueError):
    """The input cannot be analysed; the message says which file and why."""
