"""The experimenter app's model: the part models the windows show, each engine event and each pull of samples
routed to them.

Each part has one job: what the window shows (:mod:`~study_app.models.setup`, :mod:`~study_app.models.session`,
:mod:`~study_app.models.plots`, :mod:`~study_app.models.health`, ...), what the experimenter may do now
(:class:`~study_app.models.actions.Actions`) and the commands the controls send
(:class:`~study_app.models.session_control.SessionControl`,
:class:`~study_app.models.calibration_steps.CalibrationSteps`, :class:`~study_app.models.rig_control.RigControl`),
the engine's life and its restart (:class:`~study_app.models.engine.EngineModel`), why the next cue waits
(:class:`~study_app.models.cue_wait.CueWaitModel`) and the line the experimenter reads
(:class:`~study_app.models.notices.Notices`).  The windows wire their controls to the parts.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from study_app.engine import messages as m
from study_app.models.actions import Actions
from study_app.models.calibration import CalibrationModel
from study_app.models.calibration_steps import CalibrationSteps
from study_app.models.commissioning import CommissioningModel, JawModel
from study_app.models.cue_wait import CueWaitModel
from study_app.models.engine import EngineModel
from study_app.models.health import HealthModel
from study_app.models.notices import Commands, Notices
from study_app.models.participant import ParticipantScreenModel
from study_app.models.plots import PlotModel
from study_app.models.questionnaire import QuestionnaireModel
from study_app.models.real_calibration import RealCalibrationModel
from study_app.models.rig import RigViewModel
from study_app.models.rig_control import RigControl
from study_app.models.screen_guard import ScreenGuard
from study_app.models.session import SessionModel
from study_app.models.session_control import SessionControl
from study_app.models.setup import SetupModel

__all__ = ["AppModel"]


class AppModel:
    """Everything the windows show, fed by engine events and ring pulls; the controls' parts turn actions into
    engine commands.

    Parameters
    ----------
    send
        Delivers a command to the engine; returns False if the engine is gone.
    window_s
        Plot window, s.
    """

    def __init__(self, send: Callable[[object], bool] | None = None, window_s: float = 10.0) -> None:
        # what the windows show
        self.setup = SetupModel()
        self.session = SessionModel()
        self.plots = PlotModel(window_s)
        self.health = HealthModel()
        self.participant = ParticipantScreenModel()
        self.calibration = CalibrationModel()
        self.real_calibration = RealCalibrationModel()
        self.commissioning = CommissioningModel()
        self.jaw = JawModel()
        self.rig = RigViewModel()
        self.notices = Notices()
        self.commands = Commands(send or (lambda cmd: False), self.notices)
        self.questionnaire = QuestionnaireModel(send=lambda cmd: self.commands(cmd, clear=False))
        self.participant.send = lambda cmd: self.commands(cmd, clear=False)  # a trial's answer (discrimination)
        # the engine, what may be done, and the controls
        self.engine = EngineModel(self.commands, self.session, self.setup, self.health, self.plots, self.notices)
        self.actions = Actions(self.session, self.setup, self.calibration, self.real_calibration, self.commissioning,
                               self.engine)
        self.screen = ScreenGuard(self.commands, self.session, self.notices)
        self.control = SessionControl(self.commands, self.setup, self.session, self.commissioning, self.engine,
                                      self.actions, self.notices, self.screen)
        self.steps = CalibrationSteps(self.commands, self.calibration, self.real_calibration, self.commissioning,
                                      self.actions, self.notices)
        self.rig_control = RigControl(self.commands, self.rig, self.jaw, self.session, self.engine, self.notices)
        self.cue = CueWaitModel(self.session, self.health, self.engine, {
            "reset_faults": self.control.reset_faults, "resume": self.control.resume,
            "restart_engine": self.engine.restart}, screen=self.screen)
        self.screen.changed.connect(self.cue.refresh)
        self.engine.restarted.connect(self.cue.refresh)
        # the form changed: a refusal of Start was about what it said before
        self.setup.changed.connect(lambda: self.notices.clear(("StartSession",)))

    def apply(self, ev: object) -> None:
        """Route one engine event: the engine's life first (before the parts forget the session), then the parts
        that show it, then what follows from it (the notices, the form, the actions, why the next cue waits)."""
        was_stalled = self.engine.loop_stalled
        self.engine.watch(ev)
        for part in (self.session, self.health, self.participant, self.calibration, self.real_calibration, self.rig,
                     self.commissioning, self.jaw, self.screen, self.questionnaire):
            part.apply(ev)
        self.notices.apply(ev)
        self.control.apply(ev)
        self.rig_control.apply(ev)
        if isinstance(ev, m.EngineStopped):
            self.plots.detach()
        self.engine.stall_settled(was_stalled)
        self.steps.apply(ev)
        self.engine.ready(ev)
        self.cue.refresh()

    def attach_ring(self, ring: object, task_arm: str = "", arm_rings: dict[str, object] | None = None) -> None:
        """Start pulling samples from the engine's ring (and, on a rig of several arms, the other arms' rings)."""
        self.plots.attach(ring)
        self.plots.attach_arms(task_arm, dict(arm_rings or {}))

    def tick(self) -> int:
        """Pull new samples (call at ~30 Hz) and update every sample-driven model; returns the number pulled."""
        n = self.plots.pull()
        if n == 0 or self.plots.last_row is None:
            return 0
        last = self.plots.last_row
        t = float(last["t_s"])
        self.session.set_time(t)
        self.cue.refresh()
        self.participant.update(t, float(last["force_n"]))
        self.rig.update(float(last["tip_z_m"]), float(last["true_fz"]))
        rows = self.plots.new_rows
        in_trial = self.session.phase in ("active", "cued", "answer")
        self.health.update_force(float(np.nanmax(rows["force_n"])) if len(rows) else 0.0, in_trial)
        self.health.add_rows(rows)
        return n
