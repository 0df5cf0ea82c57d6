"""A block's columns encoded together, in a few whole-table NumPy operations: the bytes of the column-by-column codec.

:func:`protocol.recording.codec.encode_block` keeps every column with its own codec
(:class:`protocol.recording.codec.Column`).  One column at a time that is ~6 small NumPy calls a column, 39 columns
a block (records and poses), and a byte transpose NumPy does one byte at a time.  Every column is 64 bits a value,
so a block is one table of 64-bit words: here each transform (differences, sensor counts, int32) runs once over
the columns that use it, and the byte planes of every shuffled column come from eight shifts of the whole table.
The bytes are the column-by-column encoder's, which stays the reference (a test compares both on every codec's
edge cases).
"""

from __future__ import annotations

import zlib
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["column_words", "encode_table", "record_words"]

_INTEGER = ("int", "small")  # codecs of integer values (the others keep float64)


def record_words(records: np.ndarray, codecs: Sequence[str]) -> npt.NDArray[np.int64] | None:
    """Records of one 8-byte little-endian field per codec, in a row with no gap, each of its codec's type (int64
    for an integer codec, float64 for the others), as a ``(len(codecs), n)`` table of their 64-bit words (one row a
    column); None when they are not laid out so, or there are none (the caller then converts column by column)."""
    dtype = records.dtype
    names = dtype.names or ()
    n_columns = len(codecs)
    if len(records) == 0 or len(names) != n_columns or dtype.itemsize != 8 * n_columns:
        return None
    for j, (name, codec) in enumerate(zip(names, codecs, strict=True)):
        field_dtype, offset = dtype.fields[name][:2]  # type: ignore[index]  # (names are this dtype's fields)
        # the words are read as they lie: a float field under an integer codec (or the reverse) would need converting
        if offset != 8 * j or field_dtype.str != ("<i8" if codec in _INTEGER else "<f8"):
            return None
    words = np.ndarray((len(records), n_columns), np.int64, np.ascontiguousarray(records))
    return np.ascontiguousarray(words.T)


def column_words(columns: Mapping[str, np.ndarray], names: Sequence[str],
                 codecs: Sequence[str]) -> npt.NDArray[np.int64] | None:
    """Columns by name as a ``(len(names), n)`` table of 64-bit words; None unless each is int64 (an integer codec)
    or float64 (the others) and there is at least one value."""
    first = columns[names[0]]
    n = len(first)
    if n == 0:
        return None
    out = np.empty((len(names), n), np.int64)
    for i, (name, codec) in enumerate(zip(names, codecs, strict=True)):
        values = columns[name]
        if not isinstance(values, np.ndarray) or values.shape != (n,):
            return None
        if values.dtype != (np.int64 if codec in _INTEGER else np.float64) or not values.dtype.isnative:
            return None
        out[i] = values.view(np.int64)
    return out


def encode_table(data: np.ndarray | Mapping[str, np.ndarray], names: Sequence[str], codecs: Sequence[str],
                 scales: Mapping[str, Any], level: int) -> list[tuple[dict[str, Any], bytes]] | None:
    """Each column's (header entry, compressed bytes), as the column-by-column encoder makes them; None when the
    columns cannot be read as 64-bit words as they lie (the caller then encodes column by column).

    Parameters
    ----------
    data
        Records with a field per column, in order (:func:`record_words`), or the columns by name
        (:func:`column_words`).
    names, codecs
        Each column's name and declared codec (``"int"``, ``"small"``, ``"counts"``, ``"float"``, ``"smooth"``).
    scales
        Counts per unit of the ``"counts"`` columns, by name, as the recording's row holds them (a value is
        written to the header as it is).
    level
        zlib's level.
    """
    if isinstance(data, np.ndarray):
        words = record_words(data, codecs) if data.dtype.names == tuple(names) else None
    else:
        words = column_words(data, names, codecs)
    if words is None:
        return None
    k = len(words)
    final = list(codecs)  # each column's codec as written (a column its declared one cannot keep falls back)
    entries: list[dict[str, Any]] = [{} for _ in range(k)]
    table = words.copy()  # what is byte-shuffled: the words, transformed column by column below
    small = [j for j, c in enumerate(codecs) if c == "small"]
    if small:
        v = words[small]
        fits = (v.min(axis=1) >= -(2**31)) & (v.max(axis=1) < 2**31)
        for j, ok in zip(small, fits.tolist(), strict=True):
            final[j] = "small" if ok else "int"  # (an int32 cannot hold it: differences of int64)
    counts = [j for j, c in enumerate(codecs) if c == "counts"]
    for j in counts:
        final[j] = "float"  # unless exactly counts (below)
    scaled = [j for j in counts if scales.get(names[j]) is not None]
    if scaled:
        _counts(words, table, scaled, [scales[names[j]] for j in scaled], final, entries)
    deltas = [j for j, c in enumerate(final) if c in ("int", "smooth")]
    if deltas:
        d = words[deltas]
        table[deltas, 1:] = d[:, 1:] - d[:, :-1]  # wraps like the int64 arithmetic that undoes it
    planes = _byte_planes(table)
    ints = [j for j in small if final[j] == "small"]
    as_int32 = dict(zip(ints, words[ints].astype(np.int32), strict=True)) if ints else {}
    # a column whose values after the first are all one value (times and ticks as differences, marks, a derate of
    # 1, a pose's rotation at rest): most of a block's, and the same few inputs block after block
    flat = (table[:, 1:] == table[:, 1:2]).all(axis=1).tolist()
    out = []
    for j, codec in enumerate(final):
        entries[j].setdefault("codec", codec)
        deflated = as_int32[j] if codec == "small" else planes[j]
        if not flat[j]:
            out.append((entries[j], zlib.compress(deflated.data, level)))
            continue
        # deflate is deterministic: an input deflated before gives the bytes it gave then (~10 µs an input saved);
        # the key is all its bytes depend on (int32 bytes, else byte planes; values; first value; the others; level)
        key = (codec == "small", len(deflated.T), int(table[j, 0]), int(table[j, -1]), level)
        got = _FLAT.get(key)
        if got is None:
            if len(_FLAT) >= _FLAT_MAX:
                _FLAT.clear()
            got = _FLAT[key] = zlib.compress(deflated.data, level)
        out.append((entries[j], got))
    return out


#: Deflated inputs of one value after the first (:func:`encode_table`): the input's key -> its deflated bytes.
_FLAT: dict[tuple[bool, int, int, int, int], bytes] = {}
_FLAT_MAX = 1024  # keys kept (a key is a few dozen bytes, its value a few dozen more)


def _byte_planes(table: npt.NDArray[np.int64]) -> npt.NDArray[np.uint8]:
    """Each row's byte planes (``[j, b]``: byte ``b`` of every value of row ``j``, little-endian): by eight shifts of
    the whole table, ~2.5x faster than NumPy's byte-by-byte transpose (35 against 88 µs for a block)."""
    k, n = table.shape
    words = table.view(np.uint64)
    planes = np.empty((k, 8, n), np.uint8)
    shifted = np.empty_like(words)
    for b in range(8):
        np.right_shift(words, np.uint64(8 * b), out=shifted)
        planes[:, b] = shifted  # (the low byte: a cast to uint8 keeps it)
    return planes


def _counts(words: npt.NDArray[np.int64], table: npt.NDArray[np.int64], columns: list[int], scales: list[Any],
            final: list[str], entries: list[dict[str, Any]]) -> None:
    """The raw sensor columns that are exactly integer counts (``counts / scale`` gives back every bit): their counts
    into ``table``, their codec ``"counts"``; the others stay ``"float"``."""
    values = words[columns].view(np.float64)
    per_unit = np.array([float(s) for s in scales], np.float64)[:, None]
    with np.errstate(invalid="ignore", over="ignore"):
        counts = np.rint(values * per_unit)
    finite = np.isfinite(counts).all(axis=1) & (np.abs(counts) < 2.0**62).all(axis=1)
    ok = [i for i, f in enumerate(np.asarray(finite).tolist()) if f]
    if not ok:
        return
    as_ints = counts[ok].astype(np.int64)
    back = as_ints / per_unit[ok]
    exact = (back.view(np.int64) == values[ok].view(np.int64)).all(axis=1)
    for i, row, same in zip(ok, as_ints, exact.tolist(), strict=True):
        if same:
            j = columns[i]
            final[j] = "counts"
            entries[j]["codec"] = "counts"
            entries[j]["scale"] = scales[i]
            table[j] = row
