"""The calibration window's steps as engine commands: the arm it commissions, TCP, payload and frames (run on the
simulated rig, recorded pose by pose on the real one)."""

from __future__ import annotations

import dataclasses

from study_app.engine import messages as m
from study_app.models.actions import Actions
from study_app.models.calibration import CalibrationModel
from study_app.models.commissioning import CommissioningModel
from study_app.models.notices import Commands, Notices
from study_app.models.real_calibration import RealCalibrationModel

__all__ = ["CalibrationSteps"]


class CalibrationSteps:
    """Sends the calibration steps for the arm the calibration window commissions.

    Parameters
    ----------
    commands
        Sends the steps' commands.
    calibration, real_calibration, commissioning
        The payload step (simulated rig: a pose set; real rig: the recorded poses) and the chain (TCP, frames).
    actions
        Whether a pose may be recorded now.
    notices
        Where a step that cannot run says why.
    """

    def __init__(self, commands: Commands, calibration: CalibrationModel, real_calibration: RealCalibrationModel,
                 commissioning: CommissioningModel, actions: Actions, notices: Notices) -> None:
        self.commands = commands
        self.calibration = calibration
        self.real_calibration = real_calibration
        self.commissioning = commissioning
        self.actions = actions
        self.notices = notices

    def apply(self, ev: object) -> None:
        """A new engine: the window keeps commissioning the arm it showed."""
        if isinstance(ev, m.EngineReady) and self.commissioning.arm:
            self.real_calibration.for_arm(self.commissioning.arm)

    def select_arm(self, name: str) -> None:
        """Commission the arm called ``name`` in the calibration window (refused while a step runs)."""
        if self.commissioning.busy() or self.calibration.state == "running" or \
                self.real_calibration.state in ("recording", "identifying"):
            self.notices.notify("error", "Calibration: finish the step under way first; then choose another arm.",
                                "arm")
            self.commissioning.changed.emit()  # the selector goes back to the arm under way
            return
        if name == self.commissioning.arm:
            return
        self.commissioning.select_arm(name)
        self.calibration.state, self.calibration.result, self.calibration.done = "idle", None, 0
        self.calibration.changed.emit()
        self.real_calibration.for_arm(name)

    def _send(self, cmd: m.ArmStep) -> None:
        """A calibration step's command, for the arm the calibration window commissions."""
        self.commands(dataclasses.replace(cmd, arm=self.commissioning.arm))

    def _refused(self, why: str, what: str, command: str) -> bool:
        """Say why a step cannot run (``why`` "": it can)."""
        if why:
            self.notices.notify("error", f"Cannot {what}: {why}", command)
        return bool(why)

    def run_tcp(self) -> None:
        """TCP step: run the pose set (simulated rig) or record the orientation the instrument is in (real rig)."""
        self._send(self.commissioning.tcp_command())

    def compute_tcp(self) -> None:
        """Real rig: the pivot calibration from the recorded orientations, or say why not."""
        if not self._refused(self.commissioning.compute_refusal(), "compute the TCP", "IdentifyTcp"):
            self._send(self.commissioning.compute_command())

    def check_frames(self, axis: str = "") -> None:
        """Frames step: the whole check (simulated rig) or one axis' push (real rig)."""
        self._send(self.commissioning.frames_command(axis))

    def calibrate(self) -> None:
        """Run the chosen pose set."""
        self._send(self.calibration.command())

    def record_pose(self) -> None:
        """Real rig: measure the shown pose (the engine averages the wrench; nothing blocks here)."""
        if self.actions.can("record_pose"):
            self._send(self.real_calibration.record_command())

    def identify(self) -> None:
        """Real rig: identify from the recorded poses, or say why not."""
        if self._refused(self.real_calibration.identify_refusal(), "identify", "IdentifyPoses"):
            return
        self.calibration.state, self.calibration.result = "running", None
        self.calibration.changed.emit()
        self._send(self.real_calibration.identify_command())
