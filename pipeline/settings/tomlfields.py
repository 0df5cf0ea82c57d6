"""Field checks shared by the TOML files a user edits: the protocol file and the hardware file.

Each check returns the value converted to its Python type, or raises the
file's own error (``ProtocolError``, ``HardwareError``) with one line::

    <file>: <field> = <value>: <what is allowed>

Types are checked exactly.  In Python ``True`` is an ``int`` (``True == 1``),
so every number check refuses booleans explicitly and :meth:`Fields.choice`
compares types as well as values (``version = true`` is not version 1,
``baud = 115200.0`` is not a baud rate).  TOML integers have no size limit in
:mod:`tomllib`; ranges are compared without converting to float, so a
100-digit integer is refused like any other out-of-range value.

This module sits on the lowest floor (``pipeline``) so that ``protocol`` can
use it too.
"""

from __future__ import annotations

import ipaddress
import json
import math
import os
import re
import reprlib
import stat
import tomllib
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

from pipeline.force.frames import Mat3, Vec3, check_rotation

__all__ = ["SQLITE_INTEGER_MAX", "Fields", "host_problem", "parse_toml", "read_toml", "show"]

#: The largest SQLite INTEGER (signed 64-bit): a larger Python int cannot be stored.
SQLITE_INTEGER_MAX = 2**63 - 1

T = TypeVar("T")

_REPR = reprlib.Repr()
_REPR.maxstring = 80
_REPR.maxother = 80
_REPR.maxlist = 12
_REPR.maxdict = 8
_REPR.maxlevel = 3

# RFC 1123 §2.1: labels of letters, digits and hyphens, 1–63 characters, not starting or ending with a hyphen.
_LABEL = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?\Z")
_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+\Z")


def show(value: Any) -> str:
    """``repr(value)`` for an error line: shortened, and safe for integers too long to print.

    A boolean is shown as TOML writes it (``true``, ``false``): the user typed it so in the file.
    """
    if isinstance(value, bool):
        return "true" if value else "false"
    try:
        return _REPR.repr(value)
    except ValueError:  # int longer than sys.get_int_max_str_digits()
        return f"<a {type(value).__name__} too long to print>"


def parse_toml(text: str, source: str, error: type[ValueError]) -> dict[str, Any]:
    """Parse TOML text; a syntax error is one line ``<source>: not valid TOML (…)`` raised as ``error``."""
    try:
        return tomllib.loads(text)
    except ValueError as exc:  # TOMLDecodeError, and an integer too long for Python to read
        raise error(f"{source}: not valid TOML ({exc})") from None


def read_toml(path: Path, error: type[ValueError], what: str, missing_hint: str = "") -> dict[str, Any]:
    """Read and parse the TOML file ``path`` (a ``what``, e.g. "protocol file"); failures raise ``error``.

    A FIFO, socket or device is refused before it is opened (reading a FIFO would wait for a writer for ever).
    """
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        mode = 0
    if stat.S_ISFIFO(mode) or stat.S_ISSOCK(mode) or stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        kind = "a FIFO (named pipe)" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode) else "a device"
        raise error(f"{path}: is {kind}, not a {what}; give the path of a regular file")
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error(f"{path}: no such {what}{missing_hint}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{path}: cannot read the {what} ({exc})") from None
    return parse_toml(text, str(path), error)


def _is_real(v: Any) -> bool:
    """An int or float, not a bool (``True`` is an ``int`` in Python)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _finite(v: Any) -> bool:
    """A finite real number; huge ints are finite even where ``float(v)`` would overflow."""
    return _is_real(v) and (isinstance(v, int) or math.isfinite(v))


def host_problem(text: Any, *, ipv6: bool = True) -> str | None:
    """None if ``text`` is an IP address or an RFC 1123 host name, else what is allowed.

    Parameters
    ----------
    text
        The configured host.
    ipv6
        Accept IPv6 addresses (False for devices that speak IPv4 only).
    """
    allowed = ("an IPv4 address (e.g. 192.168.1.1) or a host name (letters, digits, '-', separated by '.'); "
               "this device speaks IPv4 only") if not ipv6 else (
               "an IP address (e.g. 192.168.1.1 or fe80::1) or a host name (letters, digits, '-', separated by '.')")
    if not isinstance(text, str):
        return f"must be {allowed}"
    try:
        addr = ipaddress.ip_address(text)
    except ValueError:
        pass
    else:
        return None if ipv6 or addr.version == 4 else f"must be {allowed}"
    name = text[:-1] if text.endswith(".") else text
    labels = name.split(".")
    if (
        not 1 <= len(name) <= 253 or not all(_LABEL.match(label) for label in labels)
        # an all-digit last label is a mistyped IPv4 address (10.0.0.256, 10.0.0), not a name
        or labels[-1].isdigit()
    ):
        return f"must be {allowed}"
    return None


class Fields:
    """The checks of one file, raising ``error`` with the file's name.

    Parameters
    ----------
    source
        The file (or other origin) named at the start of every message.
    error
        The exception class to raise (a ``ValueError`` subclass).
    """

    __slots__ = ("error", "source")

    def __init__(self, source: str, error: type[ValueError]) -> None:
        self.source = source
        self.error = error

    def fail(self, field: str, value: Any, allowed: str) -> ValueError:
        """The one-line error naming the file, the field, the value and what is allowed."""
        return self.error(f"{self.source}: {field} = {show(value)}: {allowed}")

    def table(self, field: str, v: Any, allowed_keys: set[str]) -> dict[str, Any]:
        """A TOML table whose keys are all in ``allowed_keys`` (``field`` "" for the top level)."""
        if not isinstance(v, dict):
            raise self.fail(field, v, "must be a table")
        extra = sorted(set(v) - allowed_keys)
        if extra:
            key = extra[0]
            # a key that is not a TOML bare key is shown quoted, as TOML writes it (escapes keep the line one line)
            name = key if _BARE_KEY.match(key) else json.dumps(key)
            raise self.fail(f"{field}.{name}" if field else name, v[key],
                            f"unknown field; allowed: {', '.join(sorted(allowed_keys))}")
        return v

    def section(self, top: dict[str, Any], name: str, allowed_keys: set[str]) -> dict[str, Any]:
        """The optional top-level table ``[name]`` of ``top`` (empty when absent), keys all in ``allowed_keys``."""
        return self.table(name, top.get(name, {}), allowed_keys)

    def required(self, t: dict[str, Any], field: str, key: str, allowed: str) -> None:
        """Refuse a table ``t`` (at ``field``; "" for the top level) without ``key``: ``<field>.<key> = None:
        <allowed>``."""
        if key not in t:
            raise self.fail(f"{field}.{key}" if field else key, None, allowed)

    def version(self, top: dict[str, Any], what: str) -> None:
        """The file's ``version``: absent or exactly the integer 1 (``this software reads <what> version 1``)."""
        self.choice("version", top.get("version", 1), (1,), f"this software reads {what} version 1")

    def number(self, field: str, v: Any, *, lo: float, hi: float, lo_open: bool = True, note: str = "") -> float:
        """A finite real number in ``(lo, hi]`` (``lo_open``) or ``[lo, hi]``, as a float."""
        ok = _finite(v) and (v > lo if lo_open else v >= lo) and v <= hi
        if not ok:
            rng = f"> {lo:g} and ≤ {hi:g}" if lo_open else f"from {lo:g} to {hi:g}"
            raise self.fail(field, v, f"must be a number {rng}" + (f" {note}" if note else ""))
        return float(v)

    def integer(self, field: str, v: Any, *, lo: int, hi: int, what: str = "a whole number") -> int:
        """An ``int`` (not a bool, not a float) from ``lo`` to ``hi``."""
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            raise self.fail(field, v, f"must be {what} from {lo} to {hi}")
        return v

    def boolean(self, field: str, v: Any) -> bool:
        """``true`` or ``false``."""
        if not isinstance(v, bool):
            raise self.fail(field, v, "must be true or false")
        return v

    def choice(self, field: str, v: Any, allowed: Sequence[T], message: str = "") -> T:
        """One of ``allowed``, of the same type (``True`` is not ``1``, ``1.0`` is not ``1``)."""
        for a in allowed:
            if type(v) is type(a) and v == a:
                return a
        raise self.fail(field, v, message or f"allowed values: {', '.join(str(a) for a in allowed)}")

    def string(self, field: str, v: Any, *, what: str = "a non-empty string", pattern: re.Pattern[str] | None = None,
               spaces: bool = True) -> str:
        """A non-empty string (surrounding white space removed) matching ``pattern``, if given, in full."""
        ok = isinstance(v, str) and bool(v.strip())
        if ok and pattern is not None:
            ok = pattern.match(v) is not None
        if ok and not spaces:
            ok = not any(c.isspace() for c in v.strip())
        if not ok:
            raise self.fail(field, v, f"must be {what}")
        text: str = v
        return text.strip() if pattern is None else text

    def list_of(self, field: str, v: Any, item: Callable[[str, Any], T], *, min_len: int, max_len: int,
                what: str) -> list[T]:
        """A list of ``min_len`` to ``max_len`` items, each checked by ``item(field_of_item, value)``."""
        if not isinstance(v, list) or not min_len <= len(v) <= max_len:
            raise self.fail(field, v, f"must be {what}")
        return [item(f"{field}[{i}]", x) for i, x in enumerate(v)]

    def vec3(self, field: str, v: Any, *, limit: float, what: str) -> Vec3:
        """Three finite real numbers, each within ``±limit``."""
        if not isinstance(v, list) or len(v) != 3 or not all(_finite(x) and abs(x) <= limit for x in v):
            raise self.fail(field, v, what)
        return (float(v[0]), float(v[1]), float(v[2]))

    def rotation(self, field: str, v: Any) -> Mat3:
        """A rotation matrix: 3 rows of 3 real numbers (not strings, not booleans), orthonormal, det +1."""
        if (
            not isinstance(v, list) or len(v) != 3
            or not all(isinstance(row, list) and len(row) == 3 and all(_finite(x) for x in row) for row in v)
        ):
            raise self.fail(field, v,
                            "must be a rotation matrix: 3 rows of 3 numbers, e.g. [[1, 0, 0], [0, 1, 0], [0, 0, 1]]")
        if any(abs(x) > 2 for row in v for x in row):  # (and an int too large for a float stops here)
            raise self.fail(field, v, "is not a rotation: every entry of a rotation matrix lies within ±1")
        try:
            return check_rotation(v, field)
        except ValueError as exc:
            raise self.error(f"{self.source}: {exc}") from None

    def host(self, field: str, v: Any, *, ipv6: bool = True) -> str:
        """An IP address or an RFC 1123 host name."""
        problem = host_problem(v, ipv6=ipv6)
        if problem is not None:
            raise self.fail(field, v, problem)
        name: str = v  # host_problem accepts only a str
        return name
