"""The one definition of a tick's record: every field, its type and what the recording keeps of it.

The 1 kHz loop writes one record per tick (:meth:`pipeline.runtime.loop.HapticLoop.tick`), the ring buffer holds
them in this layout (:class:`pipeline.runtime.ring.RingBuffer`), the session runner reads them from there, the
recorder's codec (:mod:`protocol.recording.codec`) encodes their kept fields, and every reader of a
recording gets those fields back with these types.  Nothing else lists the fields: the loop's output
(:data:`RECORD_FIELDS`), the framework's stages (:data:`STEP_FIELDS`) and the recording's columns
(``protocol.recording.COLUMNS``) are derived from :data:`TICK_FIELDS`, and a reader names a field, never
a position.

Types: an integer is stored as ``int64`` -- ticks, times and durations in integer nanoseconds on the loop
clock, the latched fault flags, the feedback switch, the trial mark -- so it never travels as a float to
be cast back; everything measured (forces, positions, the safety gain) is ``float64``.  Every field is
8 bytes, so a record has no padding and its fields are aligned.

Order: the fields the recording keeps come first, in the order of a recorded block's columns (a format:
a field kept later is appended to them, with the value every record had before it, ``missing``), so the
kept part of a record is one contiguous prefix of its bytes (:data:`KEPT_DTYPE`), which the codec takes as
it is.  The other fields follow; the ring's header carries names and types, so its readers need no order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "KEPT_DTYPE", "KEPT_FIELDS", "RECORD_FIELDS", "STEP_FIELDS", "TICK_DTYPE", "TICK_FIELDS", "TickField",
]

_INT = np.dtype("<i8")
_FLOAT = np.dtype("<f8")


@dataclass(frozen=True, slots=True)
class TickField:
    """One field of a tick's record.

    Attributes
    ----------
    name
        The field's name (units and frames in it: ``*_ns`` integer nanoseconds, ``*_n`` newtons, ``*_m`` metres).
    integer
        ``int64`` if True, else ``float64``.
    keep
        How a recorded block keeps it (None: not recorded): ``"int"`` (int64 differences), ``"small"``
        (int32, plain), ``"float"`` (float64, byte-shuffled), ``"smooth"`` (float64, differences of the bit
        patterns), ``"counts"`` (raw sensor values: integer counts when exact, else as ``"float"``).
    missing
        The value of every record in a block written before the field was recorded (None: every block has it).
    """

    name: str
    integer: bool
    keep: str | None = None
    missing: float | None = None

    @property
    def dtype(self) -> np.dtype:
        """``int64`` or ``float64`` (little-endian)."""
        return _INT if self.integer else _FLOAT


def _ints(*names: str, keep: str | None = None) -> tuple[TickField, ...]:
    return tuple(TickField(n, True, keep) for n in names)


def _floats(*names: str, keep: str | None = None) -> tuple[TickField, ...]:
    return tuple(TickField(n, False, keep) for n in names)


def _xyz(prefix: str, suffix: str) -> tuple[str, ...]:
    return tuple(f"{prefix}{axis}{suffix}" for axis in "xyz")


#: The stages :meth:`pipeline.force.framework.HapticFramework.step` returns, in order: compensated, filtered, tip-,
#: base- and haptic-frame, scaled and rendered force (3 each, N).
STEP_FIELDS: tuple[str, ...] = (
    *_xyz("comp_f", ""), *_xyz("filt_f", ""), *_xyz("tip_f", ""), *_xyz("base_f", ""), *_xyz("haptic_f", ""),
    *_xyz("scaled_f", ""), *_xyz("render_f", ""),
)

#: Every field of a tick's record, in the record's order (kept fields first; see the module docstring).
TICK_FIELDS: tuple[TickField, ...] = (
    # -- kept by the recording, in its columns' order --
    *_ints("tick", "t_ns", "period_ns", keep="int"),  # tick number; time since the first tick; since the last
    *_floats("raw_fx", "raw_fy", "raw_fz", "raw_tx", "raw_ty", "raw_tz", keep="counts"),  # the F/T sample, sensor frame
    *_ints("sensor_age_ns", "pose_age_ns", keep="int"),  # the sample's and the pose's age at the tick
    *_ints("latency_ns", keep="int"),  # sample arrival to command hand-over, loop clock
    *_ints("faults", "haptic_on", "trial_index", "phase", keep="small"),  # latched Fault bits; feedback 0/1; the mark
    *_floats("gain", keep="float"),  # the safety stage's ramp gain, 0..1
    *_floats(*_xyz("render_f", ""), "force_n", keep="float"),  # rendered force; |filtered force| (the task force)
    *_floats(*_xyz("stylus_", "_m"), keep="smooth"),  # stylus position, haptic device frame
    # the fraction of the designed force the haptic device's thermal derating let through (1: not cut);
    # recordings from before derating have none, and nothing was cut then
    TickField("derate", False, "float", missing=1.0),
    # -- not recorded (replay recomputes the stages from the kept fields) --
    *_floats("t_s"),  # t_ns in seconds, for displays
    *_floats(*(f for f in STEP_FIELDS if not f.startswith("render_"))),
    *_floats(*_xyz("tip_", "_m"), *_xyz("true_f", "")),  # robot tip position, base frame; simulated true contact force
)

#: The record's field names, in order.
RECORD_FIELDS: tuple[str, ...] = tuple(f.name for f in TICK_FIELDS)
#: The record as a NumPy structured type (the ring's rows, the session runner's input).
TICK_DTYPE = np.dtype([(f.name, f.dtype) for f in TICK_FIELDS])
#: The fields a recorded block keeps, in its columns' order: a prefix of :data:`TICK_FIELDS`.
KEPT_FIELDS: tuple[TickField, ...] = tuple(f for f in TICK_FIELDS if f.keep is not None)
#: The kept prefix of a record as its own structured type (what the recorder takes).
KEPT_DTYPE = np.dtype([(f.name, f.dtype) for f in KEPT_FIELDS])


def _check() -> None:
    """The layout's invariants, checked once at import: a broken definition fails at once, not in a study."""
    if TICK_FIELDS[: len(KEPT_FIELDS)] != KEPT_FIELDS:
        raise AssertionError("the kept fields must lead the tick record (the codec takes them as one prefix)")
    if len(set(RECORD_FIELDS)) != len(RECORD_FIELDS) or not set(STEP_FIELDS) <= set(RECORD_FIELDS):
        raise AssertionError("tick record fields must be unique and hold every framework stage")
    if any(f.integer != (f.keep in ("int", "small")) for f in KEPT_FIELDS):
        raise AssertionError("the integer codecs keep the int64 fields, the others the float64 ones")


_check()
