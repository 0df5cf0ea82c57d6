"""Every character a command prints reaches a terminal whose encoding cannot hold it as a readable stand-in.

The commands print typographic characters ("→", "–", "≤", "×", "…") in their summaries and help.  A terminal
that is not UTF-8 (``PYTHONIOENCODING=latin-1``, a Windows console on a legacy code page, ``LANG=C`` with an
older Python) cannot encode them; Python's standard output is *strict* by default, so the command would end in
a ``UnicodeEncodeError`` traceback after its work was stored.  Here the standard streams get an error handler
that writes each such character as its plain-text look-alike ("->", "-", "<=", "x", "...") and anything else as
"?": the line stays readable, and the command's exit status is its own.
"""

from __future__ import annotations

import codecs
import io
import sys

__all__ = ["PLAIN_ERRORS", "safe_standard_streams"]

#: The name under which :func:`_plain_stand_in` is registered with :mod:`codecs`.
PLAIN_ERRORS = "haptic_plain"

#: Plain-text look-alikes of the characters the product prints (each stand-in is ASCII, so every encoding a
#: terminal uses holds it).
_STAND_INS = {
    "→": "->", "←": "<-", "↔": "<->", "⇒": "=>",
    "–": "-", "—": "--", "−": "-", "‐": "-", "‑": "-",
    "≤": "<=", "≥": ">=", "≠": "!=", "≈": "~", "±": "+/-", "×": "x", "·": ".", "÷": "/",
    "…": "...", "‘": "'", "’": "'", "“": '"', "”": '"', "«": '"', "»": '"',
    "µ": "u", "°": " deg", "²": "^2", "³": "^3", "√": "sqrt", "∞": "inf", "Δ": "d", "σ": "sd",
    "✓": "ok", "✗": "x", "•": "*", "\u00a0": " ", "\u2009": " ", "\u202f": " ",
}


def _plain_stand_in(exc: UnicodeError) -> tuple[str, int]:
    """The codec error handler: the unencodable run as look-alikes ("?" where there is none)."""
    if not isinstance(exc, UnicodeEncodeError):
        raise exc
    bad = exc.object[exc.start:exc.end]
    return "".join(_STAND_INS.get(ch, "?") for ch in bad), exc.end


codecs.register_error(PLAIN_ERRORS, _plain_stand_in)


def safe_standard_streams() -> None:
    """Give standard output and standard error the look-alike handler (streams that are not text files, e.g.
    replaced by a caller, are left as they are; UTF-8 streams never call it)."""
    for stream in (sys.stdout, sys.stderr):
        if isinstance(stream, io.TextIOWrapper):
            stream.reconfigure(errors=PLAIN_ERRORS)
