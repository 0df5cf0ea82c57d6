"""The session's controls: start (from the setup form), resume, pause, abort, reset faults -- and what the form
learns as sessions start and end."""

from __future__ import annotations

import dataclasses
import os

from study_app.engine import messages as m
from study_app.models.actions import Actions
from study_app.models.arms import stored_arm_order, task_arm_first
from study_app.models.commissioning import CommissioningModel
from study_app.models.engine import EngineModel
from study_app.models.notices import Commands, Notices
from study_app.models.screen_guard import ScreenGuard
from study_app.models.session import SessionModel
from study_app.models.setup import SetupModel

__all__ = ["REASON_MIN_CHARS", "SessionControl", "reason_refusal"]

#: The shortest reason a start that deviates from the protocol (without training, without calibration) is given:
#: a few words -- "x" tells whoever reads the report nothing.
REASON_MIN_CHARS = 8


def reason_refusal(reason: str) -> str:
    """Why a deviation's reason is refused ("" when it is taken): it must say why in a few words."""
    text = reason.strip()
    if len(text) >= REASON_MIN_CHARS:
        return ""
    return (f"reason = {text!r}: say why in a few words (at least {REASON_MIN_CHARS} characters): it is stored with "
            "the session and the study report lists it")


class SessionControl:
    """Turns the session's controls into engine commands, and keeps the setup form in step with the sessions.

    Parameters
    ----------
    commands
        Sends the commands.
    setup, session
        The setup form (what a start sends) and the running session.
    commissioning
        The rig's arms (a simulated rig is restarted with the protocol's task arm first).
    engine
        The engine (its rig, its restart).
    actions
        What may be done now.
    notices
        Where a start that cannot be sent says why.
    screen
        The participant screen: opened before every start and resume, which are refused while it cannot be seen.
    """

    def __init__(self, commands: Commands, setup: SetupModel, session: SessionModel,
                 commissioning: CommissioningModel, engine: EngineModel, actions: Actions, notices: Notices,
                 screen: ScreenGuard) -> None:
        self.commands = commands
        self.setup = setup
        self.session = session
        self.commissioning = commissioning
        self.engine = engine
        self.actions = actions
        self.notices = notices
        self.screen = screen
        #: The reason of a start without training, until the session it was given for has started.
        self._training_override = ""

    def apply(self, ev: object) -> None:
        """The database's sessions as the engine lists them; a session that started or ended."""
        if isinstance(ev, m.SessionsListed):
            self.setup.set_resumable(ev.sessions)
            self.setup.set_known(ev.known, ev.withdrawn, ev.covariates)
            self.session.listed(ev.db_path, ev.known)
        elif isinstance(ev, m.SessionStarted):
            self.session.db_path = os.path.abspath(self.setup.values.db_path)
            if any(s["session_id"] == ev.session_id for s in self.setup.resumable):  # it runs now: not to resume
                self.setup.set_resumable([s for s in self.setup.resumable if s["session_id"] != ev.session_id])
            if ev.kind == "experiment" and self._training_override:
                self.notices.notify("warning", f"{ev.code}: started without training, stored as a deviation with "
                                    "your reason.", "TrainingOverride")
            self._training_override = ""
            self.setup.session_began(ev.code, ev.kind, ev.participant_number or self.setup.values.participant_number,
                                     ev.session_id, seed=ev.seed)
        elif isinstance(ev, m.SessionEnded):
            if self.session.session is not None:
                self.setup.session_ended(self.session.session.kind, ev.status)
            if self.setup.values.db_path:
                self.list_sessions()

    def start(self, override_reason: str = "", training_override: str = "", visit_reason: str = "") -> bool:
        """Start the session described by the setup form (False if the form is invalid or nothing may start).

        ``override_reason``: start on the real rig although the calibration chain is not complete (stored).
        ``training_override``: start an experiment without the completed training the protocol requires; the
        engine stores the reason as a ``deviation`` event (:mod:`protocol.runner.study_rules`).
        ``visit_reason``: start a visit's part out of order or outside its window (the form's schedule says why it
        needs one), stored as a ``deviation`` event as ``run --visit --deviation`` stores it.
        """
        can = self.actions.can
        refusal = self.setup.schedule.refusal
        if refusal and not visit_reason.strip() and can("start"):
            self.notices.notify("error", f"Nothing was started: {refusal}; start it with your reason (stored as a "
                                "deviation).", "StartSession")
            return False
        for given in (training_override, override_reason, visit_reason if refusal else ""):
            why = reason_refusal(given) if given.strip() else ""
            if why:
                self.notices.notify("error", f"Nothing was started: {why}.", "StartSession")
                return False
        skip_training = bool(training_override.strip()) and can("start_without_training")
        if not (can("start") or skip_training):
            errors = self.setup.validate()
            if errors or self.setup.hint:
                self.notices.notify("error", "Cannot start: " + " ".join(list(errors.values()) or [self.setup.hint]),
                                    "StartSession")
            return False
        if not self.screen.ready("Start", "StartSession"):  # no cue to a screen nobody sees
            return False
        cmd = self.setup.start_command(training_override if skip_training else "", visit_reason if refusal else "")
        if override_reason.strip():
            cmd = dataclasses.replace(cmd, override_reason=override_reason.strip())
        self._training_override = cmd.training_override
        # the protocol's task arm first, as run --sim-arms arranges it
        return self._send_on_arms(cmd, task_arm_first(self.commissioning.arms, self.engine.rig_kind,
                                                      cmd.protocol_path or ""))

    def resume_session(self, session_id: int) -> None:
        """Continue an interrupted session (the participant screen opened first)."""
        if not self.screen.ready("Resume", "ResumeSession"):
            return
        stored = next((r.get("arms", []) for r in self.setup.resumable if r["session_id"] == session_id), [])
        self._send_on_arms(m.ResumeSession(os.path.abspath(self.setup.values.db_path), int(session_id)),
                           stored_arm_order(self.commissioning.arms, self.engine.rig_kind, stored))

    def _send_on_arms(self, cmd: m.StartSession | m.ResumeSession, order: tuple[str, ...]) -> bool:
        """Send a start or resume; with an ``order`` of the simulated rig's arms, restart the rig so first."""
        if not order or self.engine.restarter is None:
            return self.commands(cmd)
        self.engine.restart(order, then=cmd)
        self.notices.notify("info", f"The session's task arm is {order[0]}: restarting the simulated rig with arm "
                            f"{order[0]} first (--sim-arms {','.join(order)}); the session starts when it is ready …",
                            type(cmd).__name__)
        return True

    def pause(self) -> None:
        """Hold before the next trial (shown as pending until the running trial ends)."""
        self.session.paused_requested = True
        self.commands(m.Pause())
        self.session.changed.emit()

    def resume(self) -> None:
        """Continue after a pause (the participant screen opened first), or cancel a pending one."""
        if not self.screen.ready("Resume", "Resume"):
            return
        self.session.paused_requested = False
        self.commands(m.Resume())
        self.session.changed.emit()

    def abort_trial(self, trial_index: int | None = None, reason: str = "") -> None:
        """Abort the running trial (stored as aborted, re-run later); the engine refuses if ``trial_index`` has
        ended.  ``reason``: the experimenter's words, if any, stored with the trial and as a note on it."""
        why = " ".join(reason.split())
        self.commands(m.AbortTrial(f"aborted by the experimenter: {why}" if why else "aborted by the experimenter",
                                   trial_index=trial_index, note=why))

    def note(self, text: str, trial_index: int | None, deviation: bool) -> bool:
        """The experimenter's note on the running session (``trial_index`` None) or one of its trials (False: not
        sent, and the line under Start says why)."""
        words = " ".join(text.split())
        if not words:
            self.notices.notify("info", "Nothing was noted: a note needs its words.", "Note")
            return False
        return self.commands(m.Note(words, trial_index, deviation))

    def abort_session(self, session_id: int | None = None) -> None:
        """Abort the session (refused by the engine if ``session_id`` is no longer the running one)."""
        self.commands(m.AbortSession(session_id=session_id))

    def reset_faults(self) -> None:
        """Clear faults whose condition has gone away."""
        self.commands(m.ResetFaults())

    def list_sessions(self) -> None:
        """Ask the engine for the database's resumable sessions (database work stays off the GUI thread)."""
        if self.setup.values.db_path.strip():
            self.commands(m.ListSessions(os.path.abspath(self.setup.values.db_path)), clear=False)
