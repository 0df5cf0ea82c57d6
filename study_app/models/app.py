"""The experimenter app's model: routes engine events to the part models and turns actions into commands."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from study_app import messages as m
from study_app.models import Emitter
from study_app.models.calibration import CalibrationModel
from study_app.models.health import HealthModel
from study_app.models.participant import ParticipantScreenModel
from study_app.models.plots import PlotModel
from study_app.models.real_calibration import RealCalibrationModel
from study_app.models.rig import RigViewModel
from study_app.models.session import SessionModel
from study_app.models.setup import SetupModel

__all__ = ["AppModel"]

#: Sample time over which device rates are measured.
_RATE_WINDOW_S = 0.5


class AppModel:
    """Everything the windows show, fed by engine events and ring pulls; actions become engine commands.

    Parameters
    ----------
    send
        Delivers a command to the engine; returns False if the engine is gone.
    window_s
        Plot window, s.
    """

    def __init__(self, send: Callable[[object], bool] | None = None, window_s: float = 10.0) -> None:
        self.send: Callable[[object], bool] = send or (lambda cmd: False)
        self.setup = SetupModel()
        self.session = SessionModel()
        self.plots = PlotModel(window_s)
        self.health = HealthModel()
        self.participant = ParticipantScreenModel()
        self.calibration = CalibrationModel()
        self.real_calibration = RealCalibrationModel()
        #: "sim" or "real", from EngineReady ("" before the engine is connected).
        self.rig_kind = ""
        self.rig = RigViewModel()
        self.rig.target_changed.connect(lambda y: self.send(m.ManualTarget(y)))
        #: A command was refused or failed: (title, message).
        self.error = Emitter()
        #: Action availability changed (buttons enable/disable).
        self.actions_changed = Emitter()
        self._rate_rows: list[np.ndarray] = []
        self._rate_span = 0.0
        self.session.changed.connect(lambda: self.actions_changed.emit())
        self.setup.changed.connect(lambda: self.actions_changed.emit())

    # -- engine → models ------------------------------------------------------------------------
    def apply(self, ev: object) -> None:
        """Route one engine event."""
        if isinstance(ev, m.EngineReady):
            self.rig_kind = ev.rig
        for part in (self.session, self.health, self.participant, self.calibration, self.real_calibration, self.rig):
            part.apply(ev)
        if isinstance(ev, m.SessionsListed):
            self.setup.set_resumable(ev.sessions)
        elif isinstance(ev, m.CommandRefused):
            self.error.emit(f"{ev.command} refused", ev.message)
        elif isinstance(ev, m.SessionEnded) and self.setup.values.db_path:
            self.list_sessions()
        elif isinstance(ev, m.EngineStopped):
            self.plots.detach()

    def attach_ring(self, ring: object) -> None:
        """Start pulling samples from the engine's ring."""
        self.plots.attach(ring)

    def tick(self) -> int:
        """Pull new samples (call at ~30 Hz) and update every sample-driven model; returns the number pulled."""
        n = self.plots.pull()
        if n == 0 or self.plots.last_row is None:
            return 0
        last = self.plots.last_row
        t = float(last["t_s"])
        self.session.set_time(t)
        self.participant.update(t, float(last["force_n"]))
        self.rig.update(float(last["tip_z_m"]), float(last["true_fz"]))
        rows = self.plots.new_rows
        self._rate_rows.append(rows)
        self._rate_span += float(rows["t_s"][-1] - rows["t_s"][0]) if len(rows) > 1 else 0.0
        if self._rate_span >= _RATE_WINDOW_S:
            self.health.update_from_rows(np.concatenate(self._rate_rows))
            self._rate_rows, self._rate_span = [], 0.0
        return n

    # -- what may be done now -------------------------------------------------------------------------
    @property
    def ready(self) -> bool:
        """The engine is connected and idle or running."""
        return self.session.state in ("ready", "running", "paused", "ended")

    def can(self, action: str) -> bool:
        """Whether an action is available: start, pause, resume, abort_trial, abort_session, calibrate, resume_session."""
        s = self.session
        if action == "start":
            return self.ready and not s.running and self.setup.valid
        if action == "resume_session":
            return self.ready and not s.running
        if action == "calibrate":
            return self.ready and not s.running and self.calibration.state != "running"
        if action == "record_pose":
            return self.ready and not s.running and self.rig_kind == "real" and self.real_calibration.can_record()
        if action == "identify":
            return self.ready and not s.running and self.rig_kind == "real" and not self.real_calibration.identify_refusal()
        if action == "sim_rig_view":
            return self.rig_kind == "sim"
        if action == "pause":
            return s.state == "running"
        if action == "resume":
            return s.state == "paused" or (s.running and s.paused_requested)
        if action == "abort_trial":
            return s.running and s.phase in ("active", "cued")
        if action == "abort_session":
            return s.running
        raise ValueError(f"unknown action {action!r}")

    # -- actions -----------------------------------------------------------------------------------------
    def _send(self, cmd: object) -> bool:
        ok = self.send(cmd)
        if not ok:
            self.error.emit("engine not running", "The study engine is not running; restart the application.")
        return ok

    def start(self) -> bool:
        """Start the session described by the setup form (False if the form is invalid or nothing may start)."""
        if not self.can("start"):
            errors = self.setup.validate()
            if errors:
                self.error.emit("cannot start", "\n".join(errors.values()))
            return False
        return self._send(self.setup.start_command())

    def pause(self) -> None:
        """Hold before the next trial."""
        self.session.paused_requested = True
        self._send(m.Pause())
        self.actions_changed.emit()

    def resume(self) -> None:
        """Continue after a pause."""
        self.session.paused_requested = False
        self._send(m.Resume())
        self.actions_changed.emit()

    def abort_trial(self) -> None:
        """Abort the running trial (stored as aborted, re-run later)."""
        self._send(m.AbortTrial())

    def abort_session(self) -> None:
        """Abort the session."""
        self._send(m.AbortSession())

    def reset_faults(self) -> None:
        """Clear faults whose condition has gone away."""
        self._send(m.ResetFaults())

    def calibrate(self) -> None:
        """Run the chosen pose set."""
        self._send(self.calibration.command())

    def record_pose(self) -> None:
        """Real rig: measure the shown pose (the engine averages the wrench; nothing blocks here)."""
        if self.can("record_pose"):
            self._send(self.real_calibration.record_command())

    def identify(self) -> None:
        """Real rig: identify from the recorded poses, or say why not."""
        why = self.real_calibration.identify_refusal()
        if why:
            self.error.emit("cannot identify", why)
            return
        self.calibration.state, self.calibration.result = "running", None
        self.calibration.changed.emit()
        self._send(self.real_calibration.identify_command())

    def set_driver(self, mode: str) -> None:
        """Autopilot (simulated participant) or manual (mouse/keyboard)."""
        self.rig.driver = mode
        self._send(m.SetDriver(mode))
        self.rig.changed.emit()

    def list_sessions(self) -> None:
        """Ask the engine for the database's resumable sessions (database work stays off the GUI thread)."""
        if self.setup.values.db_path.strip():
            import os

            self._send(m.ListSessions(os.path.abspath(self.setup.values.db_path)))

    def resume_session(self, session_id: int) -> None:
        """Continue an interrupted session."""
        import os

        self._send(m.ResumeSession(os.path.abspath(self.setup.values.db_path), int(session_id)))
