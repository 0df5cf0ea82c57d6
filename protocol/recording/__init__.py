"""The whole session at full rate, compactly, in the study database: per-column blocks of about one second.

Every 1 kHz record of a session -- training, pauses, trials, waits, every
resumed run -- is kept with what replay needs (:mod:`pipeline.force.replay`): the
loop's inputs (the raw F/T wrench, the tick period and the sensor's age, the
robot pose at its own 125 Hz), its outputs (the rendered force, the feedback
gain, the latched faults), the stylus position, the trial and phase marks,
and the task force the metrics are computed from.  What replay recomputes (the
compensated, filtered and rotated stages) is not stored.

**Storage.**  A run of a session (its first run, then one per resume) is a
*segment*: a ``recordings`` row holds the framework's snapshot at its first
record and the segment's place on the session clock.  Its records are cut
into blocks of :data:`BLOCK_RECORDS` (one ``session_blocks`` row each); a block
stores every column as one compressed array, losslessly:

* integers (times, counts, marks) as differences, byte-shuffled, deflated;
* raw wrench values as the sensor's integer counts when they are exactly
  ``counts / counts_per_unit`` (the Net F/T and its twin send counts),
  otherwise as float64;
* other floats byte-shuffled (smooth ones as differences of their bit patterns).

Every decoding is checked bit for bit before a block is written, so a value
the codec cannot keep exactly is stored as plain float64 instead: nothing is
ever rounded.  About 40 bytes a record, where a ``samples`` row took ~150.

**Crash safety.**  The writer (:class:`protocol.storage.Recorder`) appends records
to the open block and, at each commit (at least every 100 ms), writes what the
block gained since the last one as a *chunk* (a ``session_chunks`` row: the
records' own bytes, uncompressed); when the block fills, or its segment ends,
the block is encoded once and replaces its chunks in the same transaction.  A
``kill -9`` loses at most the records since the last commit; a killed
segment's open block reads back from its chunks.

**Integrity.**  Each block carries the CRC-32 of its bytes (schema version 4);
every reader verifies it, and a damaged block is named in one line -- session,
time range, trials -- never a decoding traceback (:mod:`protocol.recording.integrity`).

**Floors.**  This package is the format: encoding, decoding and a block's own checks, below the database that
stores it (:mod:`protocol.storage`).  Reading a session's records back (:mod:`protocol.storage.recordings`) and
scanning a database for damage (:mod:`protocol.storage.damage`) go through the database's one reader, so they
are the storage floor's.
"""

from protocol.recording.codec import (
    BLOCK_RECORDS,
    COLUMNS,
    LIMIT_COLUMNS,
    POSE_COLUMNS,
    Column,
    decode_block,
    decode_columns,
    encode_block,
    join_blocks,
    join_chunks,
    kept_records,
)
from protocol.recording.integrity import BlockDamage, RecordingDamaged
from protocol.recording.open_block import BlockBuilder, Chunk

__all__ = [
    "BLOCK_RECORDS", "COLUMNS", "LIMIT_COLUMNS", "POSE_COLUMNS", "BlockBuilder", "BlockDamage", "Chunk", "Column",
    "RecordingDamaged", "decode_block", "decode_columns", "encode_block", "join_blocks", "join_chunks", "kept_records",
]
