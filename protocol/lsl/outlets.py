"""The session's LSL outlets: the force streams at 1 kHz and the trial markers, each stamped with its tick's time.

Two streams, named and described as the LSL and XDF conventions ask (``desc/channels/channel`` with ``label``,
``unit``, ``type``; ``desc/acquisition``; the study, the participant and the session by their pseudonymous codes
only):

* ``haptic-study force`` (type ``Force``, 1000 Hz nominal, float32): the task force (``force_n``, the magnitude of
  the filtered force the trial is judged on) and the rendered force (``render_fx``, ``render_fy``, ``render_fz``, in
  the haptic device's frame), newtons; one sample per loop tick, stamped with the tick's own time on LSL's clock
  (:class:`protocol.lsl.bus.ClockLink`), pushed as a chunk per block the session reads from the loop's ring -- by the
  session's driver, never by the 1 kHz loop, which does not know LSL exists;
* ``haptic-study markers`` (type ``Markers``, irregular, string): one JSON object per marker, ``{"event": …,
  "trial": N, "condition": …, "detail": …}`` -- ``session_start``, ``cue``, ``band_entry`` (the trial's first sample
  in its task's band), ``success``, ``timeout``, ``abort``, every stored event of the session (faults, the
  experimenter's requests, waits; its kind as ``event``; phase changes are the cue, band entry and outcome markers)
  and ``session_end`` -- each stamped with the time the session stores it at.

An outlet that fails is one ``lsl`` event and is closed: the session and the force path go on.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

from foundation.version import software_provenance
from protocol.lsl.bus import ClockLink
from protocol.study.design import TrialSpec
from protocol.study.trial import PHASE_CODES, TrialPhase
from protocol.tasks.base import Task

__all__ = ["FORCE_CHANNELS", "SessionIds", "SessionOutlets", "marker_text"]

#: The force stream's channels: (label, the tick record's field, unit, type).
FORCE_CHANNELS = (
    ("task_force", "force_n", "newtons", "Force"),
    ("render_fx", "render_fx", "newtons", "Force"),
    ("render_fy", "render_fy", "newtons", "Force"),
    ("render_fz", "render_fz", "newtons", "Force"),
)
FORCE_STREAM = "haptic-study force"
MARKER_STREAM = "haptic-study markers"
#: The loop's rate (the force stream's nominal rate), Hz.
LOOP_RATE_HZ = 1000.0
#: Outcomes as marker words.
_OUTCOME_WORDS = {"success": "success", "timeout": "timeout", "aborted": "abort"}
#: The markers that name a trial and its condition.
TRIAL_EVENTS = frozenset({"cue", "band_entry", "success", "timeout", "abort"})
#: The markers of the session itself (a fault or a request names the trial it fell in, if one was running).
SESSION_EVENTS = frozenset({"session_start", "session_end", "session_interrupted"})
_ACTIVE = PHASE_CODES[TrialPhase.ACTIVE]
#: How long the outlets stay open after the session's end when someone listens, s (the last samples reach them).
LINGER_S = 0.5


@dataclass(frozen=True, slots=True)
class SessionIds:
    """Who and what the streams are of, by pseudonymous codes only (never a name)."""

    study: str
    participant: str
    session_id: int
    kind: str

    def source_id(self, stream: str) -> str:
        """A stable source id, unique to the study's session (LabRecorder and inlets reconnect to the same source
        after a break)."""
        return f"haptic-study/{self.study}/{self.participant}/session-{self.session_id}/{stream}"


def condition_words(spec: TrialSpec) -> str:
    """A trial's condition: ``GENTLE 0.6 N, haptics on``."""
    return f"{spec.target_label} {spec.target_force_n:g} N, haptics {spec.haptic_mode}"


def marker_text(event: str, spec: TrialSpec | None = None, detail: str = "") -> str:
    """One marker's JSON (the trial numbered from 1 as people count, its schedule index beside it)."""
    m: dict[str, Any] = {"event": event}
    if spec is not None:
        m.update(trial=spec.index + 1, trial_index=spec.index, condition=condition_words(spec),
                 target=spec.target_label, target_force_n=spec.target_force_n, haptics=str(spec.haptic_mode))
    if detail:
        m["detail"] = detail
    return json.dumps(m, sort_keys=True)


def _describe(lib: ModuleType, info: Any, ids: SessionIds, channels: tuple[tuple[str, str, str, str], ...]) -> Any:
    desc = info.desc()
    chans = desc.append_child("channels")
    for label, _, unit, kind in channels:
        ch = chans.append_child("channel")
        ch.append_child_value("label", label)
        ch.append_child_value("unit", unit)
        ch.append_child_value("type", kind)
    acq = desc.append_child("acquisition")
    acq.append_child_value("manufacturer", "haptic-study")
    acq.append_child_value("software_version", software_provenance().version)
    session = desc.append_child("session")
    session.append_child_value("study", ids.study)
    session.append_child_value("participant", ids.participant)
    session.append_child_value("session_id", str(ids.session_id))
    session.append_child_value("kind", ids.kind)
    return info


def force_info(lib: ModuleType, ids: SessionIds) -> Any:
    """The force stream's description."""
    info = lib.StreamInfo(FORCE_STREAM, "Force", len(FORCE_CHANNELS), LOOP_RATE_HZ, "float32", ids.source_id("force"))
    return _describe(lib, info, ids, FORCE_CHANNELS)


def marker_info(lib: ModuleType, ids: SessionIds) -> Any:
    """The markers stream's description."""
    info = lib.StreamInfo(MARKER_STREAM, "Markers", 1, lib.IRREGULAR_RATE, "string", ids.source_id("markers"))
    return _describe(lib, info, ids, (("event", "", "json", "Marker"),))


class SessionOutlets:
    """The force and marker outlets of one session run.

    Parameters
    ----------
    lib
        pylsl (:func:`protocol.lsl.bus.pylsl`).
    link
        The records' times on LSL's clock.
    ids
        The streams' pseudonymous ids.
    task
        The session's task: its band over trial time finds the band entry.
    on_failure
        Told once, in words, when an outlet fails (the caller stores it as an event); the outlets are closed then.
    """

    def __init__(self, lib: ModuleType, link: ClockLink, ids: SessionIds, task: Task,
                 on_failure: Callable[[int, str], None]) -> None:
        self.link, self.task, self._on_failure = link, task, on_failure
        self.force: Any = lib.StreamOutlet(force_info(lib, ids), 0, 30)  # (a 30 s buffer for a slow receiver)
        self.markers: Any = lib.StreamOutlet(marker_info(lib, ids))
        self.closed = False
        self._fields = [field for _, field, _, _ in FORCE_CHANNELS]
        self._trial: TrialSpec | None = None
        self._trial_t0_ns: int | None = None  # the trial's first marked sample (its clock's zero)
        self._entered = False

    def samples(self, rows: np.ndarray) -> None:
        """Push a block of the session's records (rows of the tick record) as one chunk, and the band entry's marker
        if the running trial's force entered its band in it."""
        if self.closed or len(rows) == 0:
            return
        try:
            self._band_entry(rows)
            chunk = np.column_stack([rows[f] for f in self._fields]).astype(np.float32)
            stamps = (rows["t_ns"] * 1e-9 + self.link.records_to_lsl_s).tolist()
            self.force.push_chunk(chunk, stamps)
        except Exception as exc:  # an LSL failure is an event, never a fault of the session
            self._fail(int(rows["t_ns"][-1]), exc)

    def mark(self, t_ns: int, kind: str, detail: str = "", spec: TrialSpec | None = None) -> None:
        """A marker at the records' time ``t_ns``: a stored event's ``kind`` (phase changes are left out: the cue, band
        entry and outcome markers say them) or an outcome (``success``, ``timeout``, ``aborted``)."""
        if self.closed or kind == "phase":
            return
        event = _OUTCOME_WORDS.get(kind, kind)
        if event == "cue" and spec is not None:
            self._trial, self._trial_t0_ns, self._entered = spec, None, False
        elif event in ("success", "timeout", "abort"):
            self._trial = None
        self._push_marker(t_ns, event, None if event in SESSION_EVENTS else spec, detail)

    def _push_marker(self, t_ns: int, event: str, spec: TrialSpec | None, detail: str) -> None:
        try:
            self.markers.push_sample([marker_text(event, spec, detail)], self.link.lsl_s(t_ns))
        except Exception as exc:  # an LSL failure is an event, never a fault of the session
            self._fail(t_ns, exc)

    def _band_entry(self, rows: np.ndarray) -> None:
        """The running trial's first sample in its task's band (its marker at that sample's time)."""
        spec = self._trial
        if spec is None or self._entered:
            return
        mine = np.flatnonzero((rows["trial_index"] == spec.index) & (rows["phase"] == _ACTIVE))
        if len(mine) == 0:
            return
        t_ns = rows["t_ns"][mine]
        if self._trial_t0_ns is None:
            self._trial_t0_ns = int(t_ns[0])
        edges = self.task.screen(spec).band_over((t_ns - self._trial_t0_ns) * 1e-9)
        if edges is None:
            self._entered = True  # a task without a band has no entry
            return
        force = rows["force_n"][mine]
        inside = np.flatnonzero((force >= edges[0]) & (force <= edges[1]))
        if len(inside):
            self._entered = True
            self._push_marker(int(t_ns[inside[0]]), "band_entry", spec, "")

    def _fail(self, t_ns: int, exc: Exception) -> None:
        self.close()
        self._on_failure(t_ns, f"LSL outlets stopped: {type(exc).__name__}: {exc}; the session goes on without them")

    def close(self) -> None:
        """Close both outlets (their receivers see the streams end), after :data:`LINGER_S` if anyone listens: a
        closing outlet drops what it has not sent yet, the session's last marker among it."""
        if self.closed:
            return
        try:
            if self.markers.have_consumers() or self.force.have_consumers():
                time.sleep(LINGER_S)
        except Exception:  # (closing never fails the session)
            pass
        self.closed = True
        self.force = self.markers = None  # (pylsl destroys an outlet with its last reference)
