"""No trial is cued to a participant screen nobody sees: whether it is open, told to the engine, and opened before
every start and resume.

The window says whether the participant screen is open where the participant sees it (shown, not minimised, its
middle on a monitor); this model tells the engine each change
(:class:`study_app.engine.messages.ParticipantScreenState`), again to a new engine, and before a session starts or
resumes it has the window open it (where it was, brought onto a monitor) -- or refuses the start, saying why.  The
engine does the rest: a screen that closes during a session aborts the running trial (cause ``participant_screen``,
stored) and pauses the session; this model keeps why, for the banner over the trial table, until the experimenter
resumes.
"""

from __future__ import annotations

from collections.abc import Callable

from study_app.engine import messages as m
from study_app.models import Emitter
from study_app.models.notices import Commands, Notices
from study_app.models.session import SessionModel

__all__ = ["ScreenGuard"]


class ScreenGuard:
    """The participant screen's state as the engine must know it, and the check before a cue can come.

    Parameters
    ----------
    commands
        Sends the screen's state to the engine.
    session
        The running session (a screen closed during one pauses it).
    notices
        Where a start refused for want of the screen says why.
    """

    def __init__(self, commands: Commands, session: SessionModel, notices: Notices) -> None:
        self.commands = commands
        self.session = session
        self.notices = notices
        #: Set by the window: opens the participant screen (where it was, on a monitor) and returns why the
        #: participant cannot see it ("" when they can).  None: no window (a script): nothing to open.
        self.opener: Callable[[], str] | None = None
        #: Whether the participant sees the screen (None: the window has not said yet), and if not, how it is hidden.
        self.open: bool | None = None
        self.detail = ""
        #: Why the running session paused for the screen ("" when it did not, or the experimenter resumed since).
        self.closed_in_session = ""
        self.changed = Emitter()

    def shown(self, is_open: bool, detail: str = "") -> None:
        """The window: the participant screen is open where it is seen, or not (``detail``: closed, minimised, off
        every monitor)."""
        if (is_open, detail) == (self.open, self.detail):
            return
        self.open, self.detail = is_open, detail
        s = self.session
        if not is_open and s.running:
            tr = s.trial if s.phase in ("active", "cued", "answer") else None
            cut = f": trial {tr.trial_index + 1} is stored as aborted and run again later" if tr is not None else ""
            self.closed_in_session = f"the participant screen was {detail or 'closed'}{cut}"
        self.commands(m.ParticipantScreenState(is_open, detail), clear=False)
        self.changed.emit()

    def apply(self, ev: object) -> None:
        """A new engine learns the screen's state; a session that starts or ends forgets the last pause's reason."""
        if isinstance(ev, m.EngineReady) and self.open is not None:
            self.commands(m.ParticipantScreenState(self.open, self.detail), clear=False)
        elif isinstance(ev, (m.SessionStarted, m.SessionEnded)) and self.closed_in_session:
            self.closed_in_session = ""
            self.changed.emit()

    def ready(self, what: str, source: str) -> bool:
        """Before ``what`` (a start or a resume; ``source`` its command) may cue a trial: the participant screen is
        opened; False, with a notice saying why, when it still cannot be seen."""
        if self.opener is None:
            return True
        why = self.opener()
        if why:
            self.notices.notify("error", f"{what} refused: the participant screen is {why}, so the participant would "
                                "not see the cue; open it on a monitor (View → Participant screen, Ctrl+P)", source)
            return False
        if self.closed_in_session:
            self.closed_in_session = ""
            self.changed.emit()
        return True
