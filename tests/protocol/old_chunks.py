"""An open block's chunk as the writers before ``session_chunks`` made it (``HSF1``), and their joined form
(``HSBC``, which they stored in ``session_blocks``): a database of that time holds one for every session killed
mid-block, so the readers must still read them.  Written here from the format, as those writers wrote it."""

from __future__ import annotations

import json
import struct
import zlib
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from protocol.recording import COLUMNS, POSE_COLUMNS, join_chunks

__all__ = ["old_chunk", "old_open_block"]


def _stack8(arrays: Sequence[np.ndarray], n: int) -> bytes:
    """Columns of 8-byte values byte-shuffled as one array: all columns' first bytes, then their second bytes …"""
    if not arrays or n == 0:
        return b""
    table = np.empty((n, len(arrays)), dtype=np.int64)
    for j, a in enumerate(arrays):
        table[:, j] = np.ascontiguousarray(a).view(np.int64)
    return np.ascontiguousarray(table.view(np.uint8).reshape(n, -1).T).tobytes()


def old_chunk(cols: Mapping[str, np.ndarray], poses: Mapping[str, np.ndarray],
              events: Sequence[tuple[int, str, Any]], columns: Sequence[str] | None = None) -> bytes:
    """``HSF1``: every column's bytes (those of ``columns``, default all) shuffled into one deflate stream."""
    names = [c.name for c in COLUMNS] if columns is None else list(columns)
    n, m = len(cols["tick"]), len(poses["tick"])
    recs = [np.asarray(cols[k]) for k in names]
    pose = [np.asarray(poses[c.name]) for c in POSE_COLUMNS]
    packed = zlib.compress(_stack8(recs, n) + _stack8(pose, m), 1)
    header = {"n": n, "m": m, "dtypes": [a.dtype.str for a in recs] + [a.dtype.str for a in pose],
              "events": [list(e) for e in events]}
    head = json.dumps(header, separators=(",", ":")).encode()
    return b"HSF1" + struct.pack("<I", len(head)) + head + packed


def old_open_block(chunks: Sequence[bytes]) -> bytes:
    """``HSBC``: an open block's chunks as those writers stored it (one ``session_blocks`` row, rewritten at each
    commit)."""
    return join_chunks(chunks)
