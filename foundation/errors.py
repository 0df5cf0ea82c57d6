"""The one error every floor may raise for a request it refuses: a message of one line, an exit status.

A command-line refusal is one line naming the field, the value and what is allowed, with exit status 2, before
any work.  Each floor has its own kind of it (the analysis floor's :class:`analysis.reading.errors.AnalysisError`,
the output policy's :class:`foundation.outfs.OutputError`); the command line catches this base once.
"""

from __future__ import annotations

__all__ = ["InputRefused"]


class InputRefused(ValueError):
    """A request cannot be carried out as given; the message says which input and why, in one line."""
