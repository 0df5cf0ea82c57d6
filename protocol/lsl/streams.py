"""One session run's LSL: its clock link stored, its outlets and its stream taps, opened and closed together.

:func:`open_session_streams` is called once a run's session is open (its runner made) and before its first
record; :meth:`SessionStreams.close` when the run ends, before its writer closes.  The session runner hands it its
records (:meth:`samples`) and its markers (:meth:`mark`); nothing here is on the loop's path.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from protocol.lsl.bus import ClockLink, measure_link, pylsl
from protocol.lsl.inlets import StreamTap, TapPlace
from protocol.lsl.outlets import SessionIds, SessionOutlets, force_info, marker_info
from protocol.storage import Recorder
from protocol.storage.lsl_streams import insert_run
from protocol.study.design import TrialSpec
from protocol.study.lsl_settings import LslSettings
from protocol.tasks.base import Task

__all__ = ["SessionStreams", "open_session_streams"]


@dataclass
class SessionStreams:
    """A run's outlets (None: off) and stream taps, on one clock link."""

    link: ClockLink
    outlets: SessionOutlets | None
    taps: tuple[StreamTap, ...]

    def samples(self, rows: np.ndarray) -> None:
        """The session's records of one block (the force stream, the band entry)."""
        if self.outlets is not None:
            self.outlets.samples(rows)

    def mark(self, t_ns: int, kind: str, detail: str = "", spec: TrialSpec | None = None) -> None:
        """A marker at the records' time ``t_ns``."""
        if self.outlets is not None:
            self.outlets.mark(t_ns, kind, detail, spec)

    def close(self) -> None:
        """The taps' last samples handed to the writer, the outlets closed."""
        for tap in self.taps:
            tap.stop()
        if self.outlets is not None:
            self.outlets.close()


def _outlet_words(lib: Any, ids: SessionIds) -> list[dict[str, str]]:
    return [{"name": i.name(), "type": i.type(), "source_id": i.source_id()}
            for i in (force_info(lib, ids), marker_info(lib, ids))]


def open_session_streams(
    settings: LslSettings, ids: SessionIds, task: Task, *, recorder: Recorder, segment: int, loop_t0_ns: int,
    infos: Sequence[Any], event: Callable[[int, str, str], None], now_event: Callable[[str, str], None],
) -> SessionStreams:
    """Open a run's LSL: the clock link measured and stored (``lsl_runs``), the outlets if ``settings.outlets``, a tap
    per resolved stream of ``infos`` (one per ``settings.record``, in order).

    ``event(t_ns, kind, detail)`` stores an event at a record's time (an outlet that failed); ``now_event(kind,
    detail)`` one at the present (a stream lost, from its tap's thread).
    """
    lib = pylsl()
    link = measure_link(loop_t0_ns, lib.local_clock)
    outlets = SessionOutlets(lib, link, ids, task, lambda t, why: event(t, "lsl", why)) if settings.outlets else None
    words = _outlet_words(lib, ids) if settings.outlets else []
    sid = ids.session_id
    recorder.call(lambda db: insert_run(db.conn, sid, segment, link.records_to_lsl_s, link.uncertainty_s, words))
    taps = tuple(StreamTap(lib, info, sel, TapPlace(sid, segment, k), recorder, now_event)
                 for k, (sel, info) in enumerate(zip(settings.record, infos, strict=True)))
    for tap in taps:
        tap.start()
    return SessionStreams(link, outlets, taps)
