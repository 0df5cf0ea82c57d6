"""What the participant's screen shows -- and, in experiment sessions, what it must never show.

Experiment sessions: the target word at the start of each trial (for the
protocol's ``cue_s``), a neutral screen for the rest of the trial, a rest
screen between trials.  Never any live force: the participant's only cues
are the camera (haptics OFF) and the haptic device (ON), as in the paper.
Training sessions with the live force aid: the word stays, with a force gauge
and the target band, so participants learn how each force feels.  A task whose target moves (force tracking) shows
its band moving on the gauge in every session -- the target is what the participant follows -- and the force
still only in training.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from protocol.tasks.base import Task
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

    @property
    def gauge_allowed(self) -> bool:
        """Only a training session with the live force aid may show force."""
        return self.kind == "training" and self.live_aid

    def apply(self, ev: object) -> None:
        """Update from an engine event."""
        if isinstance(ev, m.SessionStarted):
            self.kind, self.live_aid, self.cue_s = ev.kind, ev.live_force_aid, ev.cue_s
            self.task, self.trial, self.phase, self.ended = ev.task, None, "idle", False
        elif isinstance(ev, m.TrialStarted):
            self.trial, self.phase = ev, "active"
        elif isinstance(ev, m.PhaseEntered):
            self.phase = ev.phase
        elif isinstance(ev, m.SessionEnded):
            self.ended, self.trial, self.phase = True, None, "idle"
        else:
            return
        self._recompute()

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
        if self.phase == "pause":
            return ParticipantScreen("Rest", "Let go of the tissue. The next trial starts soon.", False, None, None)
        if tr is None or self.task is None or self.phase not in ("active", "cued"):
            return ParticipantScreen("", "Please wait", False, None, None)
        shown = self.task.screen(tr)  # the task's cue word, and its band asked at this trial time
        band = shown.band_at(self.t_s - tr.t_s)
        if shown.follow:  # a target that moves: its band is shown all trial, moving; the force only in training
            word = shown.cue_word if self.gauge_allowed or self.t_s - tr.t_s < self.cue_s else ""
            force = self.force_n if self.gauge_allowed else None
            return ParticipantScreen(word, shown.follow, True, force, band)
        if self.gauge_allowed:
            return ParticipantScreen(shown.cue_word, f"Practice · haptics {tr.haptic_mode.upper()}", True,
                                     self.force_n, band)
        if self.t_s - tr.t_s < self.cue_s:
            return ParticipantScreen(shown.cue_word, "", False, None, None)
        return ParticipantScreen("", "", False, None, None)
