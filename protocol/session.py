"""The session runner: walks the schedule over the haptic loop.

It reads the loop's records (from the ring buffer), feeds the trial machine,
and acts on what happens: switches haptic feedback per trial, stamps trial and
phase into the samples, allows online bias refinement only between trials,
sends samples, trial summaries and events to the recorder, and tells the
simulated participant (if any) when a trial starts and ends.

It has no thread and no clock of its own: :meth:`SessionRunner.process` is
called with each new block of records, by the headless driver on the virtual
clock or by a thread polling the ring in a live session.  Experimenter
requests (:meth:`pause`, :meth:`resume`, :meth:`abort_trial`,
:meth:`abort_session`) may come from any thread; they take effect at the next
``process`` call, at that block's sample time.

Abort policy: an aborted trial is stored with outcome ``aborted`` and its
reason, and re-run later -- appended at the end of the schedule
(``append``, the default) or re-inserted at a random later position
(``reinsert``) -- so every target × mode cell still gets its full count of
completed trials.  Aborting the session aborts the current trial without
re-queueing it and ends the session with status ``aborted``.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from pipeline.loop import AllowBiasRefinement, Command, Mark, SetHaptics
from protocol.config import ProtocolConfig
from protocol.design import TrialSpec, requeue_aborted, schedule_to_json
from protocol.storage import Recorder, StudyDatabase, trial_id_of
from protocol.trial import PHASE_CODES, PhaseChanged, TrialFinished, TrialMachine, TrialPhase

__all__ = ["SessionRunner", "SessionState", "TrialParticipant"]


class TrialParticipant(Protocol):
    """What the runner tells a simulated participant."""

    def begin_trial(self, target_force_n: float, haptic_on: bool, t_s: float) -> None:
        """The cue appeared."""
        ...

    def end_trial(self, t_s: float) -> None:
        """The trial ended; rest until the next cue."""
        ...


@dataclass
class SessionState:
    """Progress for displays (plain data, read from any thread)."""

    trial_position: int = 0  # trials finished or running (1-based during a trial)
    trials_total: int = 0
    completed: int = 0
    aborted: int = 0
    successes: int = 0
    phase: str = "idle"
    paused: bool = False
    done: bool = False
    status: str = "running"
    current: TrialSpec | None = None
    trial_elapsed_s: float = 0.0


_SAMPLE_SRC = (
    "force_n", "raw_fx", "raw_fy", "raw_fz", "raw_tx", "raw_ty", "raw_tz",
    "comp_fx", "comp_fy", "comp_fz", "render_fx", "render_fy", "render_fz",
)


class SessionRunner:
    """Runs one session (training or experiment) from its stored schedule.

    Parameters
    ----------
    protocol
        The validated protocol (timing, abort policy).
    schedule
        The whole trial order, already stored with the session.
    session_id
        The session's database id.
    recorder
        The database writer.
    submit
        Sends a command to the haptic loop.
    start_position
        First schedule position to run (resume).
    session_clock_offset_s
        Session-clock time at the first record processed (resume continues the clock).
    participant
        Simulated participant to notify, or None for a person.
    participant_time
        The participant's clock (the rig's simulated time), for its notifications.
    seed
        Seeds the ``reinsert`` abort policy.
    """

    def __init__(
        self,
        *,
        protocol: ProtocolConfig,
        schedule: list[TrialSpec],
        session_id: int,
        recorder: Recorder,
        submit: Callable[[Command], None],
        start_position: int = 0,
        session_clock_offset_s: float = 0.0,
        participant: TrialParticipant | None = None,
        participant_time: Callable[[], float] | None = None,
        seed: int = 0,
    ) -> None:
        self.protocol = protocol
        self.schedule = list(schedule)
        self.session_id = session_id
        self.recorder = recorder
        self.submit = submit
        self.position = start_position
        self.participant = participant
        #: Training: the participant sees a live force gauge with the target band.
        self.live_force_aid = False
        self.participant_time = participant_time or (lambda: 0.0)
        self.machine = TrialMachine(protocol.trial)
        self._rng = np.random.default_rng([seed, session_id, 7])
        self._offset_s = session_clock_offset_s
        self._t0_ns: int | None = None
        self._last_t_ns = 0
        self._lock = threading.Lock()
        self._requests: list[tuple[str, str]] = []
        self.paused = False
        self.done = False
        self.status = "running"
        self.state = SessionState(trials_total=len(self.schedule))
        self.finished: list[TrialFinished] = []
        self.listeners: list[Callable[[object], None]] = []
        self._enter_pause_commands()

    # -- experimenter requests (any thread) ----------------------------------------------------
    def pause(self) -> None:
        """Hold before the next trial (a running trial finishes first)."""
        self._request("pause")

    def resume(self) -> None:
        """Continue after :meth:`pause`."""
        self._request("resume")

    def abort_trial(self, reason: str = "aborted by the experimenter") -> None:
        """Abort the running trial; it is re-queued per the protocol's abort policy."""
        self._request("abort_trial", reason)

    def abort_session(self, reason: str = "aborted by the experimenter") -> None:
        """Abort the running trial (not re-queued) and end the session."""
        self._request("abort_session", reason)

    def _request(self, kind: str, detail: str = "") -> None:
        with self._lock:
            self._requests.append((kind, detail))

    # -- helpers ------------------------------------------------------------------------------------
    def session_time_s(self, t_ns: int) -> float:
        """Session-clock time of a loop timestamp."""
        t0 = self._t0_ns if self._t0_ns is not None else t_ns
        return self._offset_s + (t_ns - t0) / 1e9

    def _event(self, t_ns: int, kind: str, detail: str = "") -> None:
        self.recorder.event(self.session_id, self.session_time_s(t_ns), kind, detail)

    def _enter_pause_commands(self) -> None:
        self.submit(SetHaptics(False))
        self.submit(Mark(-1, PHASE_CODES[TrialPhase.PAUSE]))
        # the tool rests in free space between trials: let the bias estimator track drift
        self.submit(AllowBiasRefinement(True))

    def _emit(self, ev: object) -> None:
        for fn in list(self.listeners):
            try:
                fn(ev)
            except Exception:  # a display must never stop the session
                pass

    # -- the work ----------------------------------------------------------------------------------
    def process(self, rows: np.ndarray) -> None:
        """Consume a block of loop records (a structured array with the ring's columns)."""
        if self.done or len(rows) == 0:
            return
        t_ns_all = rows["t_ns"].astype(np.int64)
        if self._t0_ns is None:
            self._t0_ns = int(t_ns_all[0])
        self._handle_requests(int(t_ns_all[0]))
        if self.done:
            return
        m = self.machine
        spec = m.spec
        events = m.feed(zip(t_ns_all.tolist(), rows["force_n"].tolist(), rows["trial_index"].astype(np.int64).tolist()))
        if spec is not None:
            self._store_samples(rows, t_ns_all, spec, events)
        for ev in events:
            self._on_event(ev)
        self._last_t_ns = int(t_ns_all[-1])
        if m.phase is TrialPhase.ACTIVE:
            self.state.trial_elapsed_s = m.elapsed_ns * 1e-9
        if m.phase is TrialPhase.IDLE and not self.done:
            self._start_next(self._last_t_ns)

    def _store_samples(self, rows: np.ndarray, t_ns: np.ndarray, spec: TrialSpec, events: list[Any]) -> None:
        cue = self.machine.cue_ns
        end = next((e.end_ns for e in events if isinstance(e, TrialFinished)), None)
        if cue is None:
            if end is None:
                return
            cue = next(e.cue_ns for e in events if isinstance(e, TrialFinished))
        mask = (rows["trial_index"] == spec.index) & (t_ns >= cue)
        if end is not None:
            mask &= t_ns <= end
        if not mask.any():
            return
        sel = rows[mask]
        n = len(sel)
        cols = [np.full(n, float(trial_id_of(self.session_id, spec.index))), (t_ns[mask] - cue) / 1e9]
        cols.extend(np.asarray(sel[c], dtype=np.float64) for c in _SAMPLE_SRC)
        # one float64 array, not a list of row lists: no garbage-collector-tracked objects per sample
        # (a live session's collector passes would otherwise scan ~1000 such lists, GIL held, loop waiting)
        self.recorder.samples(np.column_stack(cols))

    def _on_event(self, ev: object) -> None:
        if isinstance(ev, PhaseChanged):
            self.state.phase = str(ev.new)
            self._event(ev.t_ns, "phase", f"trial {ev.trial_index}: {ev.old} -> {ev.new}")
        elif isinstance(ev, TrialFinished):
            self._finish_trial(ev)
        self._emit(ev)

    def _finish_trial(self, ev: TrialFinished) -> None:
        spec, met = ev.spec, ev.metrics
        self.recorder.trial(
            {
                "trial_id": trial_id_of(self.session_id, spec.index),
                "session_id": self.session_id,
                "trial_index": spec.index,
                "target_label": spec.target_label,
                "target_force_n": spec.target_force_n,
                "haptic_mode": spec.haptic_mode,
                "outcome": ev.outcome,
                "started_at_s": self.session_time_s(ev.cue_ns),
                "ended_at_s": self.session_time_s(ev.end_ns),
                "tct_s": met.tct_s if ev.outcome == "success" else None,
                "rmse_n": met.rmse_n,
                "max_ae_n": met.max_ae_n,
                "time_in_band_s": met.time_in_band_s,
                "peak_force_n": met.peak_force_n,
                "n_samples": met.n_samples,
                "abort_reason": ev.reason or None,
                "repeat_of": spec.repeat_of,
            }
        )
        self.finished.append(ev)
        st = self.state
        if ev.outcome == "aborted":
            st.aborted += 1
        else:
            st.completed += 1
            st.successes += ev.outcome == "success"
        self._enter_pause_commands()
        if self.participant is not None:
            self.participant.end_trial(self.participant_time())
        self.position = spec.index + 1

    def _start_next(self, t_ns: int) -> None:
        if self.paused:
            return
        if self.position >= len(self.schedule):
            self._end("completed", "all trials done", t_ns)
            return
        spec = self.schedule[self.position]
        self.machine.start(spec, t_ns)
        self.state.current = spec
        self.state.trial_position = self.position + 1
        self.state.trials_total = len(self.schedule)
        self.state.phase = "cued"
        self._event(t_ns, "cue", f"trial {spec.index}: {spec.target_label} {spec.target_force_n:g} N, haptics {spec.haptic_mode}")
        self.submit(AllowBiasRefinement(False))
        self.submit(SetHaptics(spec.haptic_mode == "on"))
        self.submit(Mark(spec.index, PHASE_CODES[TrialPhase.ACTIVE]))
        p = self.participant
        if p is not None:
            if self.live_force_aid and hasattr(p, "practice"):
                p.practice(spec.target_force_n, spec.haptic_mode == "on", self.participant_time(), True)
            else:
                p.begin_trial(spec.target_force_n, spec.haptic_mode == "on", self.participant_time())

    def _handle_requests(self, t_ns: int) -> None:
        with self._lock:
            reqs, self._requests = self._requests, []
        m = self.machine
        for kind, detail in reqs:
            if kind == "pause":
                self.paused = self.state.paused = True
                self._event(t_ns, "experimenter", "pause")
            elif kind == "resume":
                self.paused = self.state.paused = False
                self._event(t_ns, "experimenter", "resume")
            elif kind in ("abort_trial", "abort_session"):
                self._event(t_ns, "experimenter", f"{kind}: {detail}")
                if m.phase in (TrialPhase.CUED, TrialPhase.ACTIVE):
                    spec = m.spec
                    assert spec is not None
                    evs = m.abort(t_ns, detail)
                    for ev in evs:
                        self._on_event(ev)
                    if kind == "abort_trial":
                        self.schedule = requeue_aborted(
                            self.schedule, spec, spec.index + 1, self.protocol.abort_policy, self._rng
                        )
                        sj = schedule_to_json(self.schedule)
                        sid = self.session_id
                        self.recorder.call(lambda db, sj=sj, sid=sid: db.update_schedule(sid, sj))
                        self.state.trials_total = len(self.schedule)
                if kind == "abort_session":
                    self._end("aborted", detail, t_ns)
                    return

    def _end(self, status: str, reason: str, t_ns: int) -> None:
        self._enter_pause_commands()
        self._event(t_ns, "session_end", f"{status}: {reason}")
        sid = self.session_id
        self.recorder.call(lambda db: db.end_session(sid, status, reason))
        self.done = self.state.done = True
        self.status = self.state.status = status
        self._emit(("session_end", status, reason))


def first_unfinished(schedule: list[TrialSpec], trial_rows: list[dict[str, Any]]) -> int:
    """Schedule position of the first trial with no stored row (where a resume continues)."""
    stored = {r["trial_index"] for r in trial_rows}
    for i, spec in enumerate(schedule):
        if spec.index not in stored:
            return i
    return len(schedule)


def has_samples(db: StudyDatabase, session_id: int, trial_index: int) -> bool:
    """True if samples of this trial were committed (it was interrupted mid-trial)."""
    r = db.conn.execute("SELECT 1 FROM samples WHERE trial_id = ? LIMIT 1", (trial_id_of(session_id, trial_index),)).fetchone()
    return r is not None
