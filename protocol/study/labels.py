"""What the recorded codes mean, in words: the trial phase code and the watchdog's fault bits.

The recording stores each 1 kHz record's trial phase as a small integer (:data:`protocol.study.trial.PHASE_CODES`)
and the latched faults as a bitmask (:class:`pipeline.devices.interfaces.Fault`).  Analysis (which does not import the
pipeline) and the exports name them through here.
"""

from __future__ import annotations

from pipeline.devices.interfaces import Fault
from protocol.study.trial import PHASE_CODES

__all__ = ["FAULT_BITS", "PHASE_NAMES", "fault_names", "phase_name", "plural"]

#: Phase code -> name (``idle``, ``cued``, ``active``, ``pause``).
PHASE_NAMES: dict[int, str] = {code: phase.value for phase, code in PHASE_CODES.items()}
#: Fault bit -> name (``SENSOR_STALE`` …), every bit the watchdog latches.
FAULT_BITS: dict[int, str] = {int(f): str(f.name) for f in Fault if f}


def phase_name(code: int) -> str:
    """The phase of a recorded phase code; ``unknown (N)`` for a code this version does not know."""
    return PHASE_NAMES.get(int(code), f"unknown ({int(code)})")


def fault_names(bits: int) -> str:
    """The latched faults of a bitmask joined by ``|`` (``SENSOR_STALE|NON_FINITE``); ``none`` for 0 (as
    :meth:`pipeline.devices.interfaces.Fault.describe`; never empty, so a table reads the same in SQL and pandas).

    A bit this version does not know is named by its value (``bit 1024``), never dropped.
    """
    bits = int(bits)
    names = [name for bit, name in FAULT_BITS.items() if bits & bit]
    rest = bits & ~sum(FAULT_BITS)
    k = 0
    while rest:
        if rest & 1:
            names.append(f"bit {1 << k}")
        rest >>= 1
        k += 1
    return "|".join(names) or "none"


def plural(n: int, word: str, many: str | None = None) -> str:
    """A count with its noun for people: ``1 participant``, ``2 participants``, ``20,250 records`` (``many`` for
    irregular plurals)."""
    return f"{n:,} {word if n == 1 else (many or word + 's')}"
