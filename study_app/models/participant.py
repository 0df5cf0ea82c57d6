"""What the participant's screen shows -- and, in experiment sessions, what it must never show.

Experiment sessions: the target word at the start of each trial (for the
protocol's ``cue_s``), a neutral screen for the rest of the trial, a rest
screen between trials.  Never any live force: the participant's only cues
are the camera (haptics OFF) and the haptic device (ON), as in the paper.
Training sessions with the live force aid: the word stays, with a force gauge
and the target band, so participants learn how each force feels.  A task whose target moves (force tracking) shows
its band moving on the gauge in every session -- the target is what the participant follows -- and the force
still only in training.  A task that presents forces and asks about them (force discrimination) shows which force
is being presented (``first``, ``second``), then its question with a button per answer; the participant answers with
a button or a key (the answer's own, ``1``/``2``, or ←/→ for the first/second), sent to the engine
(:class:`study_app.engine.messages.AnswerTrial`) once per question.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from protocol.tasks.base import Task, TrialScreen
from study_app.engine import messages as m
from study_app.models import Emitter

__all__ = ["ParticipantScreen", "ParticipantScreenModel"]


@dataclass(frozen=True, slots=True)
class ParticipantScreen:
    """One frame of the participant screen.  ``gauge_force_n`` is None unless a gauge is allowed; ``show_gauge``
    with no force: the target band alone (a target that moves)."""

    headline: str
    subline: str
    show_gauge: bool
    gauge_force_n: float | None
    band_n: tuple[float, float] | None
    gauge_max_n: float = 3.0
    #: The open question's answers, (key, words): a button each ("": none open).
    answers: tuple[tuple[str, str], ...] = ()
    #: The target's course ahead (a tracking task's trace): ``(fraction of the trace's span ahead, lo, hi)`` from
    #: now (0) to ``ahead_s`` later (1), N; () -- none drawn.
    trace: tuple[tuple[float, float, float], ...] = ()
    #: How far ahead the trace reaches, s.
    ahead_s: float = 0.0


#: Points a trace ahead is drawn through (a 2 Hz sine over 2 s: 30 points a cycle).
_TRACE_POINTS = 61


def _trace(shown: TrialScreen, t_s: float) -> tuple[tuple[float, float, float], ...]:
    """The band's course from trial time ``t_s`` to ``shown.ahead_s`` later (() when the screen draws none)."""
    if shown.ahead_s <= 0.0:
        return ()
    frac = np.linspace(0.0, 1.0, _TRACE_POINTS)
    edges = shown.band_over(t_s + frac * shown.ahead_s)
    if edges is None:
        return ()
    return tuple((float(a), float(lo), float(hi)) for a, lo, hi in zip(frac, edges[0], edges[1], strict=True))


@dataclass
class ParticipantScreenModel:
    """Participant-screen state from engine events and the newest sample."""

    kind: str = ""
    live_aid: bool = False
    cue_s: float = 1.0
    task: Task | None = None  # the session's (what a trial shows is its task's)
    trial: m.TrialStarted | None = None
    phase: str = "idle"
    ended: bool = False
    force_n: float = 0.0
    t_s: float = 0.0
    screen: ParticipantScreen = field(default_factory=lambda: ParticipantScreen("", "Please wait", False, None, None))
    changed: Emitter = field(default_factory=Emitter)
    #: Sends a command to the engine (the app wires it); the answer sent to the open question (None: none yet).
    send: Callable[[object], object] | None = None
    session_id: int | None = None
    answered: str | None = None
    #: The score card shown after a block (feedback the protocol allows), until the next trial.
    card: m.ScoreCardShown | None = None

    @property
    def gauge_allowed(self) -> bool:
        """Only a training session with the live force aid may show force."""
        return self.kind == "training" and self.live_aid

    def apply(self, ev: object) -> None:
        """Update from an engine event."""
        if isinstance(ev, m.SessionStarted):
            self.kind, self.live_aid, self.cue_s, self.session_id = ev.kind, ev.live_force_aid, ev.cue_s, ev.session_id
            self.task, self.trial, self.phase, self.ended, self.card = ev.task, None, "idle", False, None
        elif isinstance(ev, m.TrialStarted):
            self.trial, self.phase, self.answered, self.card = ev, "active", None, None
        elif isinstance(ev, m.ScoreCardShown):
            self.card = ev
        elif isinstance(ev, m.PhaseEntered):
            self.phase = ev.phase
        elif isinstance(ev, m.SessionEnded):
            self.ended, self.trial, self.phase = True, None, "idle"
        else:
            return
        self._recompute()

    def answer(self, key: str) -> bool:
        """The participant pressed ``key`` (an answer's key, or ``Left``/``Right`` for the first/second answer) or
        its button: sent once per open question; False when no question is open or the key is not an answer."""
        asked = self.screen.answers
        keys = [k for k, _ in asked]
        key = {"Left": keys[0], "Right": keys[-1]}.get(key, key) if keys else key
        if self.phase != "answer" or key not in keys or self.answered is not None or self.send is None:
            return False
        if self.session_id is None:
            return False
        self.answered = key
        self.send(m.AnswerTrial(self.session_id, key))
        self._recompute()
        return True

    def update(self, t_s: float, force_n: float) -> None:
        """The newest sample time and task force (the force is used only if a gauge is allowed)."""
        self.t_s = t_s
        self.force_n = force_n if self.gauge_allowed else 0.0
        self._recompute()

    def _recompute(self) -> None:
        s = self._screen()
        if s != self.screen:
            self.screen = s
            self.changed.emit()

    def _screen(self) -> ParticipantScreen:
        if self.ended:
            return ParticipantScreen("Thank you", "The session is complete.", False, None, None)
        tr = self.trial
        if self.card is not None and self.phase not in ("active", "cued", "answer"):  # feedback after a block
            return ParticipantScreen(f"Your haptics {self.card.block.upper()} block", "\n".join(self.card.lines),
                                     False, None, None)
        if self.phase == "pause":
            return ParticipantScreen("Rest", "Let go of the tissue. The next trial starts soon.", False, None, None)
        if tr is None or self.task is None or self.phase not in ("active", "cued", "answer"):
            return ParticipantScreen("", "Please wait", False, None, None)
        shown = self.task.screen(tr)  # the task's cue word, and its band asked at this trial time
        if self.phase == "answer":  # the question: a button per answer, until one is given
            if self.answered is not None:
                said = dict(shown.answers).get(self.answered, self.answered)
                return ParticipantScreen(shown.question, f"You answered: {said}", False, None, None)
            keys = "   ·   ".join(f"{words} ({k}{' or ←' if i == 0 else ' or →'})"
                                  for i, (k, words) in enumerate(shown.answers))
            return ParticipantScreen(shown.question, keys, False, None, None, answers=shown.answers)
        if shown.spans:  # forces presented one after the other: which one is on
            word = shown.word_at(self.t_s - tr.t_s)
            cue = shown.cue_word if self.t_s - tr.t_s < self.cue_s and not word else ""
            return ParticipantScreen(word or cue, "" if word else "Hold the stylus still", False, None, None)
        band = shown.band_at(self.t_s - tr.t_s)
        if shown.follow:  # a target that moves: its band is shown all trial, moving; the force only in training
            force = self.force_n if self.gauge_allowed else None
            if not shown.show_band:  # the word only: the target is felt, not seen
                return ParticipantScreen(shown.cue_word, shown.follow, force is not None, force, None)
            word = shown.cue_word if self.gauge_allowed or self.t_s - tr.t_s < self.cue_s else ""
            return ParticipantScreen(word, shown.follow, True, force, band, trace=_trace(shown, self.t_s - tr.t_s),
                                     ahead_s=shown.ahead_s)
        if self.gauge_allowed:
            return ParticipantScreen(shown.cue_word, f"Practice · haptics {tr.haptic_mode.upper()}", True,
                                     self.force_n, band)
        if self.t_s - tr.t_s < self.cue_s:
            return ParticipantScreen(shown.cue_word, "", False, None, None)
        return ParticipantScreen("", "", False, None, None)
