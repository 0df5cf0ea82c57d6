"""The analysis floor's one error type, in a module with no heavy imports.

:mod:`analysis.reading.load` re-exports it (``from analysis.reading.load import AnalysisError``
keeps working).  It is the analysis floor's kind of :class:`foundation.errors.InputRefused`, as the output
policy's :class:`foundation.outfs.OutputError` is; the command line catches that base.
"""

from __future__ import annotations

from foundation.errors import InputRefused

__all__ = ["AnalysisError"]


class AnalysisError(InputRefused):
    """The input cannot be analysed; the message says which file and why."""
