"""Why the next cue of the running session waits, for how long, and what ends the wait (the Trials tab's banner)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from study_app.models import Emitter
from study_app.models.engine import EngineModel
from study_app.models.health import HealthModel
from study_app.models.screen_guard import ScreenGuard
from study_app.models.session import SessionModel

__all__ = ["CUE_ACTIONS", "CUE_STUCK_S", "CueWait", "CueWaitModel", "cue_wait_now", "headline"]


@dataclass(frozen=True, slots=True)
class CueWait:
    """Why the next cue of the running session has not come, for how long, and what ends the wait.

    ``level`` is ``info`` (it ends by itself: the protocol's pause), ``warning`` (the experimenter ends it:
    a pause) or ``error`` (something must be put right: a latched fault, a dead engine).  ``left_s`` is the time
    until the cue when it is known, ``waited_s`` how long it has waited so far (sample time).  ``action`` names
    what ends it (``reset_faults``, ``resume``, ``restart_engine`` or ""), ``help`` what to do if that does not.
    """

    level: str
    reason: str
    left_s: float | None = None
    waited_s: float = 0.0
    action: str = ""
    help: str = ""

    def text(self) -> str:
        """One line: ``Next cue waits: <reason> · 1.2 s left`` (or ``· waiting 14 s``)."""
        when = (f" · {self.left_s:.1f} s left" if self.left_s is not None
                else f" · waiting {self.waited_s:.0f} s" if self.waited_s >= 1.0 else "")
        return f"Next cue waits: {self.reason}{when}"


#: How the runner's wait for a questionnaire begins (:mod:`protocol.runner.questionnaire_wait`).
QUESTIONNAIRE_WAIT = "questionnaire: "
#: How the banner and the progress line name that wait.
QUESTIONNAIRE_REASON = "the participant answers the questionnaire "
#: A wait with nothing named to end it, after this long (s), says where to look.
CUE_STUCK_S = 5.0
#: What ends each wait, as the button reads.
CUE_ACTIONS = {"reset_faults": "Reset faults", "resume": "Resume", "restart_engine": "Restart engine"}


def cue_wait_now(session: SessionModel, health: HealthModel, engine_trouble: str,
                 interrupted: int | None, screen_closed: str = "") -> tuple[str, CueWait | None]:
    """(kind of wait, the wait without its duration) from the session, the engine's Health and the trouble;
    ``screen_closed`` says why the session paused for the participant screen ("" when it did not)."""
    s = session
    if engine_trouble:
        if interrupted is None and not s.running:  # no session was cut short: there is no cue to wait for
            return "", None
        return "engine", CueWait("error", "no trial runs until the study engine is restarted",
                                 action="restart_engine", help="Restart engine, then Resume selected.")
    if not s.running or s.session is None or s.phase in ("active", "cued", "answer"):
        return "", None
    h = health.loop
    waiting = h.waiting if h is not None and h.session_running else ""
    if s.state == "paused":
        if screen_closed:  # the engine paused the session: no cue goes to a screen nobody sees
            return "paused-screen", CueWait("error", f"{screen_closed}; the session paused", action="resume",
                                            help="Resume (Space) opens the participant screen and continues with "
                                                 "the next trial.")
        if waiting and waiting != "pause" and "paused" in waiting:  # the runner paused itself, and says why
            return "paused-runner", CueWait("error", waiting, action="resume",
                                            help="Resume (Space) once the cause is dealt with; Devices & health "
                                                 "says whether this computer is too busy for the loop.")
        return "paused", CueWait("warning", "the session is paused", action="resume",
                                 help="Resume (Space) to continue with the next trial.")
    if waiting.startswith(QUESTIONNAIRE_WAIT):  # the participant answers on their screen: it ends by itself
        return "questionnaire", CueWait(
            "info", f"{QUESTIONNAIRE_REASON}{waiting.removeprefix(QUESTIONNAIRE_WAIT)} on their screen",
            help="The next trial comes the protocol's pause after the participant sends the answers (Submit on "
                 "their screen); the answers are stored with the session. Skip questionnaire… skips it (stored as "
                 "skipped, a deviation).")
    if waiting.startswith("fault latched") and "LOOP_STALLED" in waiting:
        return "fault", CueWait(
            "error", waiting.replace(": reset to continue", ""), action="reset_faults",
            help="The haptic loop stalled. Reset faults if it runs again; if the fault stays, the loop is frozen "
                 "and no reset reaches it: Restart engine (under Start), then Resume selected.")
    if waiting.startswith("fault latched"):
        return "fault", CueWait(
            "error", waiting.replace(": reset to continue", ""), action="reset_faults",
            help="No trial is cued while a fault is latched. Reset faults; if the fault latches again, its cause "
                 "is still there — the fault log under Devices & health names it (a stalled sensor, a device "
                 "error, the stylus pressed at the start): put it right, then reset.")
    if s.phase == "pause" and s.pause_until_s is not None:
        left = round(max(0.0, s.pause_until_s - s.latest_t_s), 1)
        return "pause", CueWait("info", f"the protocol's {s.session.pause_s:g} s pause between trials", left_s=left)
    if waiting == "pause":
        return "pause-again", CueWait("info", f"the protocol's {s.session.pause_s:g} s pause before the next cue "
                                      "(after the session began or a fault was cleared)")
    return "due", CueWait("info", "the next cue is due")


def headline(session: SessionModel, wait: CueWait | None) -> str:
    """The progress line above the plots, in agreement with the banner: while the next cue is held by something
    that must be put right (a latched fault, a dead engine), ``Next trial waits: fault latched (SENSOR_STALE) ·
    Reset faults`` -- never "The next trial is due" above a red "Next cue waits".  Otherwise
    :meth:`SessionModel.progress_text` (a pause, the experimenter's or the session's, has its own words there)."""
    if wait is not None and wait.reason.startswith(QUESTIONNAIRE_REASON):
        return f"Next trial waits: {wait.reason}"
    in_trial = session.phase in ("active", "cued", "answer")
    if wait is None or wait.level != "error" or session.state == "paused" or in_trial:
        return session.progress_text()
    action = CUE_ACTIONS.get(wait.action, "")
    return f"Next trial waits: {wait.reason}" + (f" · {action}" if action else "")


class CueWaitModel:
    """Why the next cue waits now (:attr:`wait`; None: a trial runs, or no session does), kept up to date as events
    and samples come; its button does what ends the wait.

    Parameters
    ----------
    session, health, engine
        What the wait is read from (:func:`cue_wait_now`).
    screen
        The participant screen (a session paused because it closed says so).
    actions
        What ends each wait, by its action's name (:data:`CUE_ACTIONS`).
    """

    def __init__(self, session: SessionModel, health: HealthModel, engine: EngineModel,
                 actions: Mapping[str, Callable[[], object]], screen: ScreenGuard | None = None) -> None:
        self.session = session
        self.screen = screen
        self.health = health
        self.engine = engine
        self.actions = actions
        self.wait: CueWait | None = None
        self.changed = Emitter()
        self._key = ""
        self._since_s = 0.0

    def refresh(self) -> None:
        """Read the wait afresh: its kind, how long it has lasted, and -- stuck -- where to look."""
        key, wait = cue_wait_now(self.session, self.health, self.engine.trouble, self.engine.interrupted,
                                 self.screen.closed_in_session if self.screen is not None else "")
        if key != self._key:
            s = self.session
            since = s.latest_t_s
            if key == "pause" and s.pause_until_s is not None and s.session is not None:
                since = s.pause_until_s - s.session.pause_s  # the pause began when the trial ended
            self._key, self._since_s = key, since
        if wait is not None:
            waited = max(0.0, self.session.latest_t_s - self._since_s)
            help_ = wait.help
            # a wait that should end by itself but has not: say where to look, and the way out
            expected = self.session.session.pause_s if key in ("pause", "pause-again") and self.session.session else 0.0
            if not wait.action and key != "questionnaire" and waited >= expected + CUE_STUCK_S:
                help_ = (f"No cue for {waited:.0f} s and nothing to reset: look under Devices & health (the loop's "
                         "figures, the fault log). If it stays stuck, Quit: the running trial is stored as aborted and "
                         "the session can be resumed after a restart.")
            wait = dataclasses.replace(wait, waited_s=round(waited, 1), help=help_)
        if wait != self.wait:
            self.wait = wait
            self.changed.emit()

    def end(self) -> None:
        """Do what ends the current wait (the banner's button)."""
        end = self.actions.get(self.wait.action) if self.wait is not None else None
        if end is not None:
            end()
