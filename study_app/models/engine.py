"""The study engine as the window sees it: which rig it runs, whether it or its haptic loop died or stalled, and
the restart that replaces it (the interrupted session then selected for resume)."""

from __future__ import annotations

from collections.abc import Callable

from pipeline.devices.interfaces import Fault
from study_app.engine import messages as m
from study_app.models import Emitter
from study_app.models.health import HealthModel
from study_app.models.notices import Commands, Notices
from study_app.models.plots import PlotModel
from study_app.models.session import SessionModel
from study_app.models.setup import SetupModel

__all__ = ["EngineModel"]


class EngineModel:
    """The engine's life: connected, dead (it exited, or its haptic loop died), stalled, restarted.

    Parameters
    ----------
    commands
        Sends a start that waited for a restart, once the new engine is ready.
    session, setup, health, plots, notices
        What a restart starts afresh (the session, its plots and health) or keeps (the form, with the interrupted
        session selected for resume).
    """

    def __init__(self, commands: Commands, session: SessionModel, setup: SetupModel, health: HealthModel,
                 plots: PlotModel, notices: Notices) -> None:
        self.commands = commands
        self.session = session
        self.setup = setup
        self.health = health
        self.plots = plots
        self.notices = notices
        #: "sim" or "real", from EngineReady ("" before the engine is connected).
        self.rig_kind = ""
        #: Why the engine must be restarted ("" while it is fine): it exited, or its haptic loop died.
        self.trouble = ""
        #: The whole story of :attr:`trouble`: the reason as the engine gave it, and what Restart does.
        self.trouble_detail = ""
        #: The engine's state changed: dead, stalled or restarted (the actions change with it).
        self.changed = Emitter()
        #: A restart was asked for (the new engine is starting).
        self.restarted = Emitter()
        #: Replaces the engine by a new one (the window's bridge; given arm names, a simulated rig with those arms in
        #: that order); None: nothing can restart it.
        self.restarter: Callable[..., None] | None = None
        #: The session the failure interrupted (selected for resume after the restart).
        self.interrupted: int | None = None
        self._pending_start: m.StartSession | m.ResumeSession | None = None  # sent when the new engine is ready
        self._restarting = False

    def watch(self, ev: object) -> None:
        """Notice an engine that exited or whose haptic loop died (before the parts forget the session)."""
        if isinstance(ev, m.EngineReady):
            self.rig_kind = ev.rig
            self._restarting = False
        s = self.session
        if isinstance(ev, m.SessionEnded) and ev.status == "interrupted":
            self.interrupted = ev.session_id
        trouble = detail = ""
        if isinstance(ev, m.EngineStopped) and not self._restarting:
            reason = ev.reason.rstrip(".")
            trouble = "The study engine exited unexpectedly." if "unexpectedly" in reason else \
                "The study engine stopped."
            detail = (reason[:1].upper() + reason[1:] + ". Without the engine the haptic device renders no force.")
            if s.running and s.session is not None:
                self.interrupted = s.session.session_id
        elif isinstance(ev, m.Health) and ev.loop_dead:
            trouble = "The haptic loop died; the force is at zero."
            detail = (f"The haptic loop died ({ev.loop_dead}); the haptic device's command watchdog dropped the "
                      "force to zero, and the engine accepts no session until it is restarted.")
        if trouble and not self.trouble:
            sid = self.interrupted
            # short: it sits in the left column of a 768-px screen; the rest is in the detail (tooltip)
            self.trouble = trouble + (f" Session {sid} was interrupted; its stored trials are kept."
                                      if sid is not None else "")
            self.trouble_detail = detail + (
                f" After Restart engine, session {sid} is selected under Interrupted sessions: press Resume selected."
                if sid is not None else " Press Restart engine to start a new one.")
            self.changed.emit()

    def stall_settled(self, was_stalled: bool) -> None:
        """After an event: say so if the loop's stall came or went with it."""
        if self.loop_stalled != was_stalled:
            self.changed.emit()

    def ready(self, ev: object) -> None:
        """After an event: the new engine is ready -- send the start it was restarted for."""
        if isinstance(ev, m.EngineReady) and self._pending_start is not None:
            cmd, self._pending_start = self._pending_start, None
            self.commands(cmd, clear=False)  # the start the rearranged engine was restarted for

    @property
    def loop_stalled(self) -> bool:
        """The engine runs but its haptic loop latched ``LOOP_STALLED`` (a tick over 50 ms late, or frozen)."""
        return (bool(self.health.faults & Fault.LOOP_STALLED) and not self.trouble
                and self.session.state not in ("connecting", "stopped", "failed"))

    def notice(self) -> tuple[str, str]:
        """(short line, the whole story) of a dead engine or haptic loop, or a stalled loop; ("", "") when fine."""
        if self.trouble:
            return self.trouble, self.trouble_detail
        if self.loop_stalled:
            s = self.session.session if self.session.running else None
            return ("The haptic loop stalled; the force is at zero. Reset faults if it runs again, else Restart "
                    "engine.",
                    "LOOP_STALLED is latched: a loop tick came over 50 ms late, or the loop is frozen (the fault log "
                    "says which). If it runs again, Reset faults clears it. If it stays frozen, Reset faults cannot "
                    "reach it: Restart engine"
                    + (f" — session {s.session_id} is then interrupted, its stored trials kept, and selected for "
                       "resume." if s is not None else "."))
        return "", ""

    def restart(self, sim_arms: tuple[str, ...] = (), then: m.StartSession | m.ResumeSession | None = None) -> bool:
        """Replace a dead engine by a new one (``sim_arms``: a simulated rig of those arms, in that order; ``then``: a
        start to send once it is ready): plots, session and health start afresh, the interrupted session selected
        for resume.  False: nothing can."""
        if self.restarter is None:
            return False
        self._pending_start = then  # a start that waited for an earlier restart is not this one's
        if self.session.running and self.session.session is not None:
            self.interrupted = self.session.session.session_id  # a live engine closes it as interrupted
        self._restarting = True
        self.plots.reset()
        self.session.reset("restarting the study engine …")
        self.health.engine_restarted()
        self.setup.preferred_resume = self.interrupted
        self.setup.running_session = None
        self.interrupted = None
        self.rig_kind = ""
        self.trouble = self.trouble_detail = ""
        self.notices.clear()
        self.changed.emit()
        self.restarter(*((sim_arms,) if sim_arms else ()))
        self.restarted.emit()
        return True
