"""What the experimenter may do now (the buttons and menu items enabled), and why not, in words."""

from __future__ import annotations

from study_app.models import Emitter
from study_app.models.calibration import CalibrationModel
from study_app.models.commissioning import CommissioningModel
from study_app.models.engine import EngineModel
from study_app.models.real_calibration import RealCalibrationModel
from study_app.models.session import SessionModel
from study_app.models.setup import SetupModel

__all__ = ["Actions"]


class Actions:
    """Which actions are available, from the session, the form, the calibration steps and the engine.

    Parameters
    ----------
    session, setup
        The running session and the setup form.
    calibration, real_calibration, commissioning
        The calibration window's steps (a step under way, the real rig's recorded poses, the chain on record).
    engine
        The engine: connected, dead or stalled, restartable.
    """

    def __init__(self, session: SessionModel, setup: SetupModel, calibration: CalibrationModel,
                 real_calibration: RealCalibrationModel, commissioning: CommissioningModel,
                 engine: EngineModel) -> None:
        self.session = session
        self.setup = setup
        self.calibration = calibration
        self.real_calibration = real_calibration
        self.commissioning = commissioning
        self.engine = engine
        #: Action availability changed (buttons enable/disable).
        self.changed = Emitter()
        for source in (session.changed, setup.changed, engine.changed):
            source.connect(self.changed.emit)

    @property
    def ready(self) -> bool:
        """The engine is connected and idle or running (and neither it nor its haptic loop has died)."""
        return self.session.state in ("ready", "running", "paused", "ended") and not self.engine.trouble

    def can(self, action: str) -> bool:
        """Whether an action is available: start, start_without_training, resume_session, calibrate, record_pose,
        identify, restart_engine, sim_rig_view, pause, resume, abort_trial, abort_session, note."""
        s, rig = self.session, self.engine.rig_kind
        if action == "start":
            return self.ready and not s.running and self.setup.valid
        if action == "start_without_training":
            return self.ready and not s.running and bool(self.setup.training_missing)
        if action == "resume_session":
            return self.ready and not s.running
        if action == "calibrate":
            return self.ready and not s.running and self.calibration.state != "running"
        if action == "record_pose":
            return self.ready and not s.running and rig == "real" and self.real_calibration.can_record()
        if action == "identify":
            return self.ready and not s.running and rig == "real" and not self.real_calibration.identify_refusal()
        if action == "restart_engine":
            return (bool(self.engine.trouble) or self.engine.loop_stalled) and self.engine.restarter is not None
        if action == "sim_rig_view":
            return rig == "sim"
        if action == "pause":
            return s.state == "running" and not s.paused_requested
        if action == "resume":
            return s.state == "paused" or (s.running and s.paused_requested)
        if action == "abort_trial":
            return s.running and s.phase in ("active", "cued", "answer")
        if action in ("abort_session", "note"):
            return s.running
        raise ValueError(f"unknown action {action!r}")

    def start_refusal(self) -> str:
        """Why Start is not available now, in words ("" when it is): for the button's and the menu's tooltip."""
        if self.engine.trouble:
            return "the study engine must be restarted first (Restart engine)"
        if self.session.running:
            return "a session is running"
        if not self.ready:
            return "the study engine is not ready yet"
        if self.setup.hint:
            return self.setup.hint
        return " ".join(self.setup.errors.values())

    def calibration_refusal(self) -> str:
        """Why the calibration steps may not run now ("" when they may)."""
        if self.engine.trouble and self.session.state in ("stopped", "failed"):  # (its notice is behind this window)
            return "the study engine is not running: press Restart engine in the main window"
        if self.session.running:
            return ("not during a session: a calibration step moves the robot and replaces what the force path "
                    "uses; finish or end the session first")
        return ""

    def calibration_missing(self) -> str:
        """Real rig: the first step of the chain not on record ("" when a session may start, or on the sim rig)."""
        st = self.commissioning.status
        return self.commissioning.first_missing() if st is not None and st.rig == "real" else ""
