"""Participant codes: what a code may be, and when two codes name the same participant.

A code is compared as a person reads it: ``p01``, ``P01``, `` P01 `` and the full-width ``Ｐ０１`` are one
participant.  :func:`code_key` is that one normalisation (Unicode NFKC, surrounding spaces stripped, case folded);
the study database's uniqueness check, the GUI's form and every command that takes a code use it, so a
near-duplicate of a code already in a study is refused naming the code it clashes with, and never becomes a second
participant (with the other's counterbalanced number suggested, training proposed, nothing said).

A new code is stored as typed, normalised only as far as its characters go (:func:`normalise_code`: NFKC and
stripped, its case kept).  Codes already stored stay as they are: a database that holds both ``P01`` and ``p01``
from before keeps both, and each is found by its exact spelling.
"""

from __future__ import annotations

import re
import sqlite3
import unicodedata
from collections.abc import Iterable

from protocol.storage.common import StorageError, has_table

__all__ = ["CODE_PATTERN", "clash_of", "code_key", "near_duplicate", "normalise_code", "stored_clash",
           "validate_code"]

CODE_PATTERN = re.compile(r"^[A-Za-z0-9_-]{1,32}\Z")  # \Z, not $: "$" also matches before a final newline
#: How the refusals say what "the same" means.
_COMPARED = "codes are compared ignoring letter case, surrounding spaces and look-alike characters"


def normalise_code(text: str) -> str:
    """``text`` as a code is stored: Unicode compatibility forms folded (NFKC: a full-width ``Ｐ０１`` is ``P01``)
    and surrounding spaces stripped; the letters' case is kept."""
    return unicodedata.normalize("NFKC", text).strip() if isinstance(text, str) else text


def code_key(code: str) -> str:
    """What two codes are compared by: NFKC, stripped, case-folded (``p01`` and ``P01`` have one key)."""
    return unicodedata.normalize("NFKC", normalise_code(code).casefold())


def validate_code(code: str) -> str:
    """Check a participant code: 1–32 of ``A–Z a–z 0–9 _ -`` (pseudonymous, no personal data), after
    :func:`normalise_code`; returns the normalised code."""
    norm = normalise_code(code)
    if not isinstance(norm, str) or not CODE_PATTERN.match(norm):
        raise StorageError(f"participant code = {code!r}: must be 1–32 characters from A–Z, a–z, 0–9, '_' and '-'")
    return norm


def near_duplicate(code: str, stored: Iterable[str]) -> str | None:
    """The stored code that ``code`` reads as without being it (``P01`` for ``p01``), or None: when ``code`` itself
    is stored (an existing database may hold both spellings), or nothing reads the same."""
    stored = list(stored)
    if code in stored:
        return None
    key = code_key(code)
    return next((s for s in stored if code_key(s) == key), None)


def clash_of(code: str, other: str, where: str) -> str:
    """The refusal of ``code`` because ``other`` (stored in ``where``) reads the same: one line."""
    return (f"participant code = {code!r}: reads as {other}, already in {where} ({_COMPARED}); give {other} to "
            f"mean that participant, or a code that differs for a new one")


def stored_clash(conn: sqlite3.Connection, code: str, where: str) -> None:
    """Refuse ``code`` if a participant (or a withdrawn one) in the database behind ``conn`` reads the same
    without being it (:func:`near_duplicate`); ``where`` names the database in the refusal."""
    codes = [str(r[0]) for r in conn.execute("SELECT code FROM participants")]
    if has_table(conn, "withdrawals"):
        codes += [str(r[0]) for r in conn.execute("SELECT code FROM withdrawals")]
    other = near_duplicate(code, codes)
    if other is not None:
        raise StorageError(clash_of(code, other, where) + "; nothing was changed")
