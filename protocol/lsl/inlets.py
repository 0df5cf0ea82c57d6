"""The external streams a session records: each read by a thread of its own, stored through the session's writer.

Each stream the protocol names (``[[lsl.record]]``, found before the session started:
:func:`protocol.lsl.bus.resolve_streams`) gets a :class:`StreamTap`: a daemon thread that opens an inlet on it,
pulls its samples as they come, and about every :data:`FLUSH_S` hands what it took to the session's recorder as one
chunk (:mod:`protocol.storage.lsl_streams`) with the clock offset measured then (``time_correction``): the
timestamps stay as the source stamped them, on its clock, and the offset beside them puts them on ours.

None of this runs on the loop's thread or waits on it.  A stream that stops -- its outlet closed, its machine gone
-- is one ``lsl`` event of the session at the time it was found lost, and the tap ends; the session goes on.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

from protocol.storage import Recorder
from protocol.storage.lsl_streams import LslChunk, LslStream, insert_chunk, insert_stream
from protocol.study.lsl_settings import StreamSelector

__all__ = ["FLUSH_S", "StreamTap", "TapPlace"]

#: How often a tap hands its samples to the writer, s (the recorder's own commit deadline is 0.1 s).
FLUSH_S = 0.5
#: One pull waits at most this long for samples, s (how soon a tap sees it is asked to stop).
_PULL_WAIT_S = 0.1
#: How long the clock offset's measurement may take, s (the first takes a few round trips).
_CORRECTION_WAIT_S = 2.0


@dataclass(frozen=True, slots=True)
class TapPlace:
    """Where a tap's rows go: the session, its run's segment, the stream's place in the protocol's list."""

    session_id: int
    segment: int
    stream: int


def stream_row(place: TapPlace, selector: StreamSelector, info: Any) -> LslStream:
    """The ``lsl_streams`` row of a resolved ``StreamInfo``."""
    return LslStream(place.session_id, place.segment, place.stream, selector.words(), info.name(), info.type(),
                     info.source_id(), info.hostname(), int(info.channel_count()), float(info.nominal_srate()),
                     _FORMATS.get(int(info.channel_format()), "undefined"), info.as_xml())


#: pylsl's channel formats by number (cf_float32 = 1 ... cf_int64 = 7).
_FORMATS = {1: "float32", 2: "double64", 3: "string", 4: "int32", 5: "int16", 6: "int8", 7: "int64"}


class StreamTap(threading.Thread):
    """Records one external stream into the session until :meth:`stop` (or the stream is lost).

    Parameters
    ----------
    lib
        pylsl.
    info
        The stream, as resolved.
    selector
        How the protocol named it.
    place
        Where its rows go.
    recorder
        The session's writer (its calls are queued: safe from this thread).
    on_event
        Stores an event of the session now (``kind``, ``detail``): the stream lost or failed.
    """

    def __init__(self, lib: ModuleType, info: Any, selector: StreamSelector, place: TapPlace, recorder: Recorder,
                 on_event: Callable[[str, str], None]) -> None:
        super().__init__(name=f"lsl-tap-{place.stream}", daemon=True)
        self.lib, self.info, self.selector, self.place = lib, info, selector, place
        self.recorder, self.on_event = recorder, on_event
        self.string = int(info.channel_format()) == 3
        self._stop_asked = threading.Event()
        self._chunk = 0
        #: Samples taken so far (read by tests and the run's summary).
        self.samples = 0

    def stop(self, wait_s: float = 2.0) -> None:
        """Ask the tap to hand what it holds to the writer and end; wait for it at most ``wait_s``."""
        self._stop_asked.set()
        if self.is_alive():
            self.join(wait_s)

    def run(self) -> None:
        row = stream_row(self.place, self.selector, self.info)
        self.recorder.call(lambda db: insert_stream(db.conn, row))
        try:
            inlet = self.lib.StreamInlet(self.info, max_buflen=60, recover=False)
            inlet.open_stream(timeout=_CORRECTION_WAIT_S)
            self._pull(inlet)
        except self.lib.util.LostError:
            self.on_event("lsl", f"stream {self.selector.words()} ({row.source_id}) lost: its outlet stopped; "
                                 f"{self.samples} samples recorded")
        except Exception as exc:  # an LSL failure is an event, never a fault of the session
            self.on_event("lsl", f"stream {self.selector.words()}: recording stopped: {type(exc).__name__}: {exc}")

    def _pull(self, inlet: Any) -> None:
        """Pull until asked to stop; a flush about every :data:`FLUSH_S` (and a last one)."""
        stamps: list[float] = []
        values: list[Any] = []
        due = time.monotonic() + FLUSH_S
        try:
            while not self._stop_asked.is_set():
                chunk, ts = inlet.pull_chunk(timeout=_PULL_WAIT_S)
                if ts:
                    stamps.extend(ts)
                    values.extend(chunk)
                if time.monotonic() >= due:
                    self._flush(inlet, stamps, values)
                    stamps, values = [], []
                    due = time.monotonic() + FLUSH_S
            chunk, ts = inlet.pull_chunk(timeout=0.0)
            stamps.extend(ts)
            values.extend(chunk)
        finally:
            self._flush(inlet, stamps, values)  # (what was taken before a loss is stored too)

    def _flush(self, inlet: Any, stamps: list[float], values: list[Any]) -> None:
        if not stamps:
            return
        try:
            correction = float(inlet.time_correction(timeout=_CORRECTION_WAIT_S))
        except Exception:  # a lost stream answers no more: its last offset stands
            correction = self._last_correction
        self._last_correction = correction
        p = self.place
        data: Any = [[str(v) for v in s] for s in values] if self.string else np.asarray(values, dtype=np.float64)
        c = LslChunk(p.session_id, p.segment, p.stream, self._chunk, np.asarray(stamps, dtype=np.float64), data,
                     correction)
        self._chunk += 1
        self.samples += len(stamps)
        self.recorder.call(lambda db: insert_chunk(db.conn, c))

    _last_correction = 0.0
