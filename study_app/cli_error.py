"""The command line's one error type, in a module of its own.

Every subcommand module raises it and ``study_app.cli.main`` catches it; kept
apart from ``study_app.cli`` so that the command modules import it at load
time without importing the module that imports them (no circle).
"""

from __future__ import annotations

__all__ = ["CliError"]


class CliError(Exception):
    """A user-facing error: printed as one line, exit status 2."""
