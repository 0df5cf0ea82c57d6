"""What the experimenter does to the rig besides running the session: who drives the simulated stylus (and where a
person puts it), the jaw, and a rehearsed fault."""

from __future__ import annotations

from study_app.engine import messages as m
from study_app.models.commissioning import JawModel
from study_app.models.engine import EngineModel
from study_app.models.notices import Commands, Notices
from study_app.models.rig import RigViewModel
from study_app.models.session import SessionModel

__all__ = ["REHEARSAL_KINDS", "RigControl"]

#: The faults an experimenter can rehearse on the simulated rig, as the GUI names them.
REHEARSAL_KINDS: dict[str, str] = {
    "sensor-stall": "F/T sensor stalls (20 ms)", "nan-burst": "F/T sensor sends NaN (5 ms)",
    "bad-status": "F/T sensor reports an error (5 ms)", "stale-pose": "robot pose stops (100 ms)",
    "device-error": "Touch device error (until Reset)", "kill": "engine crashes (kill -9)",
}


class RigControl:
    """Turns the rig view's, the jaw box's and the fault rehearsal's controls into engine commands.

    Parameters
    ----------
    commands
        Sends the commands.
    rig, jaw
        The simulated rig view (its driver, a person's manual target) and the jaw.
    session
        The running session: the trials a fault can still be planned for.
    engine
        Which rig runs (faults are rehearsed on the simulated one only).
    notices
        What a rehearsed fault does, or why it is refused.
    """

    def __init__(self, commands: Commands, rig: RigViewModel, jaw: JawModel, session: SessionModel,
                 engine: EngineModel, notices: Notices) -> None:
        self.commands = commands
        self.rig = rig
        self.jaw = jaw
        self.session = session
        self.engine = engine
        self.notices = notices
        self._planned: tuple[int, float] | None = None  # the last fault rehearsal planned at a trial
        rig.target_changed.connect(lambda y: commands.send(m.ManualTarget(y)))

    def apply(self, ev: object) -> None:
        """A rehearsed fault was planned or fired: say what it does."""
        if isinstance(ev, m.FaultInjected):
            self.notices.notify("info", self.rehearsal_notice(ev), "InjectFault")

    def set_driver(self, mode: str) -> None:
        """Autopilot (simulated participant) or manual (mouse/keyboard)."""
        self.rig.driver = mode
        self.commands(m.SetDriver(mode))
        self.rig.changed.emit()

    def jaw_action(self, action: str) -> None:
        """A jaw control: open, close, step_open, step_close."""
        self.commands(self.jaw.command(action))

    # -- fault rehearsal ------------------------------------------------------------------------------
    def rehearsal_trials(self) -> range:
        """The trials a fault can still be planned for: the running session's trials not yet begun, numbered
        from 1 in the order the participant meets them (empty when no session runs)."""
        s = self.session
        if not s.running or s.session is None:
            return range(0)
        in_trial = s.phase in ("active", "cued", "answer") and s.trial is not None
        begun = s.trial.position if in_trial and s.trial is not None else s.completed + s.aborted
        return range(begun + 1, s.session.trials_total + 1)

    def rehearsal_refusal(self, trial: int | None) -> str:
        """Why a fault cannot be rehearsed now or at ``trial`` ("" when it can)."""
        if self.engine.rig_kind == "real":
            return "fault rehearsal is for the simulated rig only (a person's hand is on the real one)"
        if trial is None:
            return ""
        if not self.session.running or self.session.session is None:
            return f"a fault at trial {trial} needs a running session: start or resume one, or inject it now"
        future = self.rehearsal_trials()
        if trial in future:
            return ""
        total = self.session.session.trials_total
        if not future:
            return f"trial {trial}: every trial of this session has begun (all {total}); inject it now instead"
        later = (f"the trials still to come are {future[0]} to {total}" if len(future) > 1
                 else f"the one still to come is trial {total}")
        if trial > total:
            return f"trial {trial}: the session has {total} trials; {later}"
        return f"trial {trial} has already begun; {later}"

    def rehearsal_notice(self, ev: m.FaultInjected) -> str:
        """What a rehearsed fault does, as the engine runs it (:mod:`protocol.runner.rehearsal`, the session runner)."""
        what = REHEARSAL_KINDS.get(ev.kind, ev.kind)
        planned = self._planned if ev.when != "now" else None
        when = (f"{planned[1]:g} s after the cue of trial {planned[0]}" if planned is not None
                else ev.when if ev.when != "now" else "now")
        running = self.session.running
        if ev.kind == "kill":
            return (f"Rehearsal: {what}, {when}. The engine process is killed as a crash would kill it: "
                    + ("the session is left interrupted — its stored trials are kept, the trial under way is stored "
                       "as aborted (interrupted) on resume and runs again; the record says the kill was rehearsed. "
                       if running else "")
                    + "The window then offers Restart engine" + (", then Resume selected." if running else "."))
        if planned is not None:
            k = planned[0]
            return (f"Rehearsal planned: {what}, {when} (if trial {k} ends sooner, nothing is injected). It is a real "
                    f"fault of the simulated rig in this session, stored with it like any fault, and the record says "
                    f"it was rehearsed (a fault_rehearsal event, listed among the report's deviations): trial {k} is "
                    "stored as aborted (cause: fault), does not count, and is run again later. The fault latches: "
                    "the next cue waits for Reset faults.")
        stored = ("It is stored with the running session like any fault, and the record says it was rehearsed (a "
                  "fault_rehearsal event, listed among the report's deviations); a trial it hits is stored as aborted "
                  "(cause: fault), does not count, and is run again later. " if running else
                  "No session is running: nothing is stored. ")
        return (f"Rehearsal: {what}, now: a real fault of the simulated rig. {stored}The fault latches"
                + (": the next cue waits for Reset faults." if running else " until Reset faults."))

    def inject_fault(self, kind: str, trial: int | None, seconds: float) -> None:
        """Rehearse a fault on the simulated rig: now (``trial`` None) or ``seconds`` after a trial's cue."""
        why = self.rehearsal_refusal(trial)
        if why:
            self.notices.notify("error", f"Fault rehearsal refused: {why}.", "InjectFault")
            return
        self._planned = None if trial is None else (trial, seconds)
        self.commands(m.InjectFault(kind, trial, seconds))
