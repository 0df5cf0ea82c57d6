"""What a protocol asks of the Lab Streaming Layer: its ``[lsl]`` table (docs/lsl.md).

```toml
[lsl]
outlets = true                  # publish the force streams and the trial markers (off by default)
resolve_timeout_s = 5.0         # how long a named stream is looked for before the session is refused
[[lsl.record]]                  # an external stream recorded with each session, by name ...
name = "EMG forearm"
[[lsl.record]]                  # ... or by type (the first stream of that type found)
type = "EEG"
```

A protocol without the table asks nothing of LSL and stores what it always stored (:meth:`LslSettings.to_dict` is
None then, and the protocol's stored JSON has no ``lsl`` key).  ``haptic-study run --lsl`` turns the outlets on for
a run whatever its protocol says.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import Any

from pipeline.settings.tomlfields import Fields

__all__ = ["LslSettings", "StreamSelector", "lsl_from_table", "parse_selector"]

#: What a stream's name or type may be: printable, no control characters, at most 64 characters.
_STREAM_WORD = re.compile(r"[^\x00-\x1f\x7f]{1,64}")
#: How long a named stream is looked for at most (s): a stream on the network answers in well under a second.
MAX_RESOLVE_TIMEOUT_S = 60.0


@dataclass(frozen=True, slots=True)
class StreamSelector:
    """One external stream to record: the LSL property it is found by (``name`` or ``type``) and its value."""

    prop: str
    value: str

    def words(self) -> str:
        """``name = 'EMG forearm'``: how a message names it."""
        return f"{self.prop} = {self.value!r}"


@dataclass(frozen=True, slots=True)
class LslSettings:
    """The ``[lsl]`` table: outlets on or off, the external streams recorded, the resolution's timeout."""

    outlets: bool = False
    record: tuple[StreamSelector, ...] = ()
    resolve_timeout_s: float = 5.0
    #: The table was in the file (stored with the session then, absent otherwise).
    given: bool = False

    @property
    def on(self) -> bool:
        """Anything of LSL is asked for: the outlets or a stream to record."""
        return self.outlets or bool(self.record)

    def with_outlets(self) -> LslSettings:
        """The same settings with the outlets on (``run --lsl``)."""
        return replace(self, outlets=True, given=True)

    def to_dict(self) -> dict[str, Any] | None:
        """The table as the protocol file has it (None when the file had none)."""
        if not self.given:
            return None
        return {"outlets": self.outlets, "resolve_timeout_s": self.resolve_timeout_s,
                "record": [{s.prop: s.value} for s in self.record]}


def _selector(f: Fields, field: str, v: Any) -> StreamSelector:
    t = f.table(field, v, {"name", "type"})
    if len(t) != 1:
        raise f.fail(field, v, "one of name = \"…\" or type = \"…\" (the stream's LSL name or type)")
    prop, value = next(iter(t.items()))
    return StreamSelector(prop, f.string(f"{field}.{prop}", value, pattern=_STREAM_WORD,
                                         what="1 to 64 printable characters"))


def lsl_from_table(f: Fields, top: dict[str, Any]) -> LslSettings:
    """The protocol's ``[lsl]`` table checked (none: LSL off); a bad value is ``f``'s one line naming the field."""
    if "lsl" not in top:
        return LslSettings()
    t = f.section(top, "lsl", {"outlets", "record", "resolve_timeout_s"})
    record = f.list_of("lsl.record", t.get("record", []), lambda field, v: _selector(f, field, v), min_len=0,
                       max_len=16, what="a list of 0 to 16 [[lsl.record]] tables")
    if len(set(record)) != len(record):
        raise f.fail("lsl.record", [s.words() for s in record], "each stream named once")
    return LslSettings(outlets=f.boolean("lsl.outlets", t.get("outlets", False)), record=tuple(record),
                       resolve_timeout_s=f.number("lsl.resolve_timeout_s", t.get("resolve_timeout_s", 5.0), lo=0.0,
                                                  hi=MAX_RESOLVE_TIMEOUT_S),
                       given=True)


def parse_selector(text: str) -> StreamSelector:
    """``name=EMG`` or ``type=EEG`` (``run --lsl-record``); ``ValueError`` (one line) otherwise."""
    prop, sep, value = text.partition("=")
    prop, value = prop.strip(), value.strip()
    if not sep or prop not in ("name", "type") or not _STREAM_WORD.fullmatch(value):
        raise ValueError(f"--lsl-record = {text!r}: give name=STREAM or type=TYPE (1 to 64 printable characters)")
    return StreamSelector(prop, value)
