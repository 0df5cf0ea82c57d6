"""The command line's one error type, in a module of its own.

Every subcommand module raises it and ``study_app.cli.main`` catches it; kept
apart from ``study_app.cli.main`` so that the command modules import it at load
time without importing the module that imports them (no circle).
"""

from __future__ import annotations

__all__ = ["CliError"]


class CliError(Exception):
    """A user-facing error: printed as one line; exit status 2 (a refusal), or ``status`` (1: the system failed).

    Parameters
    ----------
    message
        The line.
    status
        The exit status: 2 for bad input or a refusal before any work, 1 when the
        machine failed the command (a full disk, a failing device, too little memory).
    """

    def __init__(self, message: str, status: int = 2) -> None:
        super().__init__(message)
        self.status = status

