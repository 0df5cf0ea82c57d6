"""The line the experimenter reads under the Start button (a refusal, news, a question that became moot), and the
way the window's commands reach the engine, which replaces it."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from study_app.engine import messages as m
from study_app.models import Emitter

__all__ = ["CALIBRATION_COMMANDS", "Commands", "Notice", "Notices"]


@dataclass(frozen=True, slots=True)
class Notice:
    """A message for the experimenter where they are looking (under the Start button).

    ``level`` is ``error`` (a command was refused), ``warning`` or ``info``; ``source`` the command it
    answers (a refusal of StartSession clears when the form changes).
    """

    level: str
    text: str
    source: str = ""


#: The commands of the calibration window: their notices go when it closes, or when a session starts or ends.
CALIBRATION_COMMANDS = ("Calibrate", "CalibrateTcp", "RecordPivot", "IdentifyTcp", "CheckFrames", "RecordFrameAxis",
                        "RecordPose", "IdentifyPoses")

#: Commands as the experimenter knows them, for refusal messages.
_COMMAND_NAMES = {
    "StartSession": "Start", "ResumeSession": "Resume session", "Pause": "Pause", "Resume": "Resume",
    "AbortTrial": "Abort trial", "AbortSession": "Abort session", "Calibrate": "Calibration",
    "ListSessions": "Reading the database", "ResetFaults": "Reset faults", "SetDriver": "Driver",
    "CalibrateTcp": "TCP calibration", "RecordPivot": "Record orientation", "IdentifyTcp": "TCP calibration",
    "CheckFrames": "Frame check", "RecordFrameAxis": "Frame check", "JawCommand": "Jaw",
    "InjectFault": "Fault rehearsal", "RecordPose": "Record pose", "IdentifyPoses": "Identify",
}


class Notices:
    """What the experimenter should read now (:attr:`notice`, None: nothing), replaced by the next one."""

    def __init__(self) -> None:
        self.notice: Notice | None = None
        self.changed = Emitter()

    def notify(self, level: str, text: str, source: str = "") -> None:
        """Show a notice (replacing the previous one)."""
        self.notice = Notice(level, text, source)
        self.changed.emit()

    def clear(self, sources: tuple[str, ...] | None = None) -> None:
        """The notice was read or its cause resolved (``sources``: only a notice answering one of these commands)."""
        if self.notice is not None and (sources is None or self.notice.source in sources):
            self.notice = None
            self.changed.emit()

    def apply(self, ev: object) -> None:
        """The engine's refusals and news; a notice an event made stale goes."""
        if isinstance(ev, m.StartChecking):
            self.notify("info", ev.message, "StartSession")
        elif isinstance(ev, m.CommandRefused):
            # a late confirmation the engine refused changed nothing: say so, not as an error
            moot = ev.command in ("AbortTrial", "AbortSession") and "had already ended" in ev.message
            self.notify("info" if moot else "error",
                        ev.message if moot else f"{_COMMAND_NAMES.get(ev.command, ev.command)} refused: {ev.message}",
                        ev.command)
        elif isinstance(ev, m.TrialEnded) and self.notice is not None and self.notice.level == "info":
            self.clear()  # news about an earlier trial: stale once the next one has ended
        elif isinstance(ev, m.SessionStarted):
            self.clear()
        elif isinstance(ev, m.SessionEnded):
            self.clear(CALIBRATION_COMMANDS)  # "not during a session": its cause has gone


class Commands:
    """Delivers the window's commands to the engine: a new action clears the last notice (it was about an earlier
    one), and a command the engine cannot take says so.

    Parameters
    ----------
    send
        Delivers a command to the engine; returns False if the engine is gone.
    notices
        Where the experimenter reads what became of it.
    """

    def __init__(self, send: Callable[[object], bool], notices: Notices) -> None:
        self.send = send
        self.notices = notices

    def __call__(self, cmd: object, *, clear: bool = True) -> bool:
        """Send ``cmd``; False (and a notice saying so) if the engine is not running."""
        if clear:
            self.notices.clear()
        ok = self.send(cmd)
        if not ok:
            self.notices.notify("error", "The study engine is not running: press Restart engine.")
        return ok
