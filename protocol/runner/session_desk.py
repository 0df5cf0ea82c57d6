"""What every part of the session runner writes through: the session's clock and events, the loop's commands
between trials, the progress for displays, the listeners, and the session's end.

The session runner (:mod:`protocol.runner.session`) is split by responsibility -- the experimenter's requests
(:mod:`protocol.runner.requests`), the fault waiting and reset policy (:mod:`protocol.runner.fault_wait`), the trials
over the task (:mod:`protocol.runner.trial_loop`) with what the loop delivered to them
(:mod:`protocol.runner.deliveries`) -- and each part stores, commands and reports through one :class:`SessionDesk`,
so there is one session clock, one event writer and one end.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from pipeline.runtime.loop_messages import AllowBiasRefinement, Command, Mark, SetHaptics, StopRecording
from protocol.storage import Recorder
from protocol.study.clock import SessionClock
from protocol.study.config import ProtocolConfig
from protocol.study.design import TrialSpec
from protocol.study.trial import PHASE_CODES, TrialPhase
from protocol.tasks.base import Answered

__all__ = ["SessionDesk", "SessionPlan", "SessionState", "trial_words"]


def trial_words(trial_index: int) -> str:
    """How events name a trial: numbered from 1 for people, with the database's index to join on.

    ``trial_words(3)`` is ``"trial 4 (index 3)"``; a pause (index −1) is ``"the pause"``.
    """
    return "the pause" if trial_index < 0 else f"trial {trial_index + 1} (index {trial_index})"


@dataclass(frozen=True)
class SessionPlan:
    """What one run of a stored session follows (:meth:`protocol.runner.session_setup.OpenedSession.plan`).

    Attributes
    ----------
    session_id
        The session's database id.
    protocol
        The protocol it runs (a training session's own), its task included.
    schedule
        The whole trial order, as stored.
    start_position
        First schedule position to run (resume).
    clock_offset_s
        Session-clock time at the first record processed (resume continues the clock).
    initial_pause_s
        Hold the first cue this long (a resumed session begins with the protocol's pause).
    segment
        The recording's segment this run writes (0, then one more per resume).
    seed
        The study's seed (seeds the ``reinsert`` abort policy).
    live_force_aid
        Training with the participant's live force gauge (the task's training aid).
    arms
        The rig's arms by name (() or one: events stored as ever); the task arm's records are the runner's.
    answered
        The questionnaires (name, block) the session has answers of (a resume asks them not again).
    trial_answers
        The trials answered so far, for a task that asks (its procedure continues from them on resume).
    answers_seed
        Who answers the questionnaires: the simulated participant with this seed, by its rule
        (:mod:`protocol.study.sim_answers`), or a person on the participant screen (None).
    """

    session_id: int
    protocol: ProtocolConfig
    schedule: list[TrialSpec]
    start_position: int = 0
    clock_offset_s: float = 0.0
    initial_pause_s: float = 0.0
    segment: int = 0
    seed: int = 0
    live_force_aid: bool = False
    arms: tuple[str, ...] = ()
    answered: tuple[tuple[str, str], ...] = ()
    answers_seed: int | None = None
    #: The session's answered trials so far (a task that asks: its procedure is rebuilt from them on resume).
    trial_answers: tuple[Answered, ...] = ()
    #: A score card after each block (the protocol's ``[feedback]`` allows it in this session's kind).
    score_cards: bool = False
    #: The participant's earlier trials a card compares with: (session id, haptic mode, metrics, outcome) each.
    earlier: tuple[tuple[int, str, dict[str, Any], str], ...] = ()
    #: The blocks (haptic modes) the session has shown its card for (a resume shows none twice).
    cards_shown: tuple[str, ...] = ()


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
    #: Why the next cue is held back ("" = not held): a latched fault, the pause after one.
    waiting: str = ""


@dataclass
class SessionDesk:
    """The session's clock, event writer, loop commands, progress, listeners and end, shared by the runner's parts.

    Parameters
    ----------
    recorder
        The database writer.
    session_id
        The session's database id.
    submit
        Sends a command to the haptic loop.
    clock_offset_s
        Session-clock time at the first record processed.
    state
        The progress displays read.
    """

    recorder: Recorder
    session_id: int
    submit: Callable[[Command], None]
    clock_offset_s: float = 0.0
    state: SessionState = field(default_factory=SessionState)
    #: Session time of loop timestamps, from this run's first record on (None before it).
    clock: SessionClock | None = field(default=None, init=False)
    #: Called with each phase change, finished trial record and session end (a display's error never stops it).
    listeners: list[Callable[[object], None]] = field(default_factory=list, init=False)
    paused: bool = field(default=False, init=False)
    done: bool = field(default=False, init=False)
    status: str = field(default="running", init=False)
    #: Why the session stopped early as interrupted (headless fault timeout, trials not delivered), else "".
    stop_reason: str = field(default="", init=False)
    #: Told every marker of the session -- each stored event and each trial's outcome, at its records' time, with
    #: the trial it falls in -- when the session publishes them (:mod:`protocol.lsl`); None: nobody listens.
    on_mark: Callable[[int, str, str, TrialSpec | None], None] | None = field(default=None, init=False)

    def time_s(self, t_ns: int) -> float:
        """Session-clock time of a loop timestamp."""
        clock = self.clock if self.clock is not None else SessionClock(self.clock_offset_s, t_ns)
        return clock.seconds(t_ns)

    def event(self, t_ns: int, kind: str, detail: str = "") -> None:
        """Store an event at loop time ``t_ns``."""
        self.recorder.event(self.session_id, self.time_s(t_ns), kind, detail)
        if self.on_mark is not None:
            running = self.state.phase in ("cued", "active") or kind == "cue"
            self.mark(t_ns, kind, detail, self.state.current if running else None)

    def mark(self, t_ns: int, kind: str, detail: str = "", spec: TrialSpec | None = None) -> None:
        """Tell :attr:`on_mark` of a marker that is not a stored event (the session's start, a trial's outcome)."""
        if self.on_mark is not None:
            try:
                self.on_mark(t_ns, kind, detail, spec)
            except Exception:  # a publisher never stops the session (its own failures are its events)
                pass

    def emit(self, ev: object) -> None:
        """Tell the listeners."""
        for fn in list(self.listeners):
            try:
                fn(ev)
            except Exception:  # a display must never stop the session
                pass

    def set_paused(self, paused: bool) -> None:
        """Hold (or release) the next cue, and say so to the displays."""
        self.paused = self.state.paused = paused

    def rest(self) -> None:
        """The loop's state between trials: feedback off, the pause's mark, the bias estimator free."""
        self.submit(SetHaptics(False))
        self.submit(Mark(-1, PHASE_CODES[TrialPhase.PAUSE]))
        # the tool rests in free space between trials: let the bias estimator track drift
        self.submit(AllowBiasRefinement(True))

    def _stopped(self, status: str) -> None:
        self.done = self.state.done = True
        self.status = self.state.status = status

    def end(self, status: str, reason: str, t_ns: int) -> None:
        """End the session (``completed`` or ``aborted``): its end event and its row's status commit together."""
        self.rest()
        self.submit(StopRecording())
        sid = self.session_id
        with self.recorder.atomic():
            self.event(t_ns, "session_end", f"{status}: {reason}")
            self.recorder.call(lambda db: db.end_session(sid, status, reason))
        self._stopped(status)
        self.emit(("session_end", status, reason))

    def interrupt(self, t_ns: int, reason: str) -> None:
        """Stop the session here, resumable later: the reason is stored as an event and is :attr:`stop_reason`."""
        self.stop_reason = reason
        self.event(t_ns, "session_interrupted", reason)
        self.rest()
        self.submit(StopRecording())
        self._stopped("interrupted")
        self.emit(("session_end", "interrupted", reason))
