"""The experimenter app's model: routes engine events to the part models and turns actions into commands."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.devices.interfaces import Fault
from study_app.engine import messages as m
from study_app.models import Emitter
from study_app.models.arms import stored_arm_order, task_arm_first
from study_app.models.calibration import CalibrationModel
from study_app.models.commissioning import CommissioningModel, JawModel
from study_app.models.cue_wait import CUE_ACTIONS, CUE_STUCK_S, CueWait, cue_wait_now
from study_app.models.health import HealthModel
from study_app.models.participant import ParticipantScreenModel
from study_app.models.plots import PlotModel
from study_app.models.real_calibration import RealCalibrationModel
from study_app.models.rig import RigViewModel
from study_app.models.session import SessionModel
from study_app.models.setup import SetupModel

#: The faults an experimenter can rehearse on the simulated rig, as the GUI names them.
REHEARSAL_KINDS: dict[str, str] = {
    "sensor-stall": "F/T sensor stalls (20 ms)", "nan-burst": "F/T sensor sends NaN (5 ms)",
    "bad-status": "F/T sensor reports an error (5 ms)", "stale-pose": "robot pose stops (100 ms)",
    "device-error": "Touch device error (until Reset)", "kill": "engine crashes (kill -9)",
}

__all__ = ["CUE_ACTIONS", "REHEARSAL_KINDS", "AppModel", "CueWait", "Notice"]

#: Sample time over which device rates are measured.
_RATE_WINDOW_S = 0.5


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
        self.commissioning = CommissioningModel()
        self.jaw = JawModel()
        #: "sim" or "real", from EngineReady ("" before the engine is connected).
        self.rig_kind = ""
        self.rig = RigViewModel()
        self.rig.target_changed.connect(lambda y: self.send(m.ManualTarget(y)))
        #: What the experimenter should read now (a refusal, a question that became moot), or None.
        self.notice: Notice | None = None
        self.notice_changed = Emitter()
        #: Action availability changed (buttons enable/disable).
        self.actions_changed = Emitter()
        #: Why the engine must be restarted ("" while it is fine): it exited, or its haptic loop died.
        self.engine_trouble = ""
        #: The whole story of :attr:`engine_trouble`: the reason as the engine gave it, and what Restart does.
        self.engine_trouble_detail = ""
        self.engine_changed = Emitter()
        #: Replaces the engine by a new one (the window's bridge; given arm names, a simulated rig with those arms in
        #: that order); None: nothing can restart it.
        self.restarter: Callable[..., None] | None = None
        self._pending_start: m.StartSession | m.ResumeSession | None = None  # sent when the new engine is ready
        self._restarting = False
        #: The session the failure interrupted (selected for resume after the restart).
        self._interrupted: int | None = None
        self._rate_rows: list[np.ndarray] = []
        self._rate_span = 0.0
        #: Why the next cue waits (None: a trial runs, or no session does); see :class:`CueWait`.
        self.cue_wait: CueWait | None = None
        self._planned: tuple[int, float] | None = None  # the last fault rehearsal planned at a trial
        self.cue_wait_changed = Emitter()
        self._wait_key = ""
        self._wait_since_s = 0.0
        #: The reason of a start without training, until the session it was given for has started.
        self._training_override = ""
        self.session.changed.connect(lambda: self.actions_changed.emit())
        self.setup.changed.connect(lambda: self.actions_changed.emit())
        self.setup.changed.connect(self._on_setup_changed)

    # -- engine → models ------------------------------------------------------------------------
    def apply(self, ev: object) -> None:
        """Route one engine event."""
        if isinstance(ev, m.EngineReady):
            self.rig_kind = ev.rig
            self._restarting = False
        was_stalled = self.loop_stalled
        self._watch_engine(ev)
        for part in (self.session, self.health, self.participant, self.calibration, self.real_calibration, self.rig,
                     self.commissioning, self.jaw):
            part.apply(ev)
        if isinstance(ev, m.StartChecking):
            self.notify("info", ev.message, "StartSession")
        if isinstance(ev, m.SessionsListed):
            self.setup.set_resumable(ev.sessions)
            self.setup.set_known(ev.known, ev.withdrawn)
            self.session.listed(ev.db_path, ev.known)
        elif isinstance(ev, m.CommandRefused):
            # a late confirmation the engine refused changed nothing: say so, not as an error
            moot = ev.command in ("AbortTrial", "AbortSession") and "had already ended" in ev.message
            self.notify("info" if moot else "error",
                        ev.message if moot else f"{_COMMAND_NAMES.get(ev.command, ev.command)} refused: {ev.message}",
                        ev.command)
        elif isinstance(ev, m.TrialEnded) and self.notice is not None and self.notice.level == "info":
            self.clear_notice()  # news about an earlier trial: stale once the next one has ended
        elif isinstance(ev, m.SessionStarted):
            self.clear_notice()
            self.session.db_path = os.path.abspath(self.setup.values.db_path)
            if any(s["session_id"] == ev.session_id for s in self.setup.resumable):  # it runs now: not to resume
                self.setup.set_resumable([s for s in self.setup.resumable if s["session_id"] != ev.session_id])
            if ev.kind == "experiment" and self._training_override:
                self.notify("warning", f"{ev.code}: started without training, stored as a deviation with your "
                            "reason.", "TrainingOverride")
            self._training_override = ""
            self.setup.session_began(ev.code, ev.kind, ev.participant_number or self.setup.values.participant_number,
                                     ev.session_id, seed=ev.seed)
        elif isinstance(ev, m.SessionEnded):
            self.clear_notice(CALIBRATION_COMMANDS)  # "not during a session": its cause has gone
            if self.session.session is not None:
                self.setup.session_ended(self.session.session.kind, ev.status)
            if self.setup.values.db_path:
                self.list_sessions()
        elif isinstance(ev, m.EngineStopped):
            self.plots.detach()
        elif isinstance(ev, m.FaultInjected):
            self.notify("info", self.rehearsal_notice(ev), "InjectFault")
        if self.loop_stalled != was_stalled:
            self.engine_changed.emit()
            self.actions_changed.emit()
        if isinstance(ev, m.EngineReady) and self.commissioning.arm:
            self.real_calibration.for_arm(self.commissioning.arm)
        if isinstance(ev, m.EngineReady) and self._pending_start is not None:
            cmd, self._pending_start = self._pending_start, None
            self._send(cmd, clear=False)  # the start the rearranged engine was restarted for
        self._refresh_cue_wait()

    # -- why the next cue waits ----------------------------------------------------------------------
    def _cue_wait_now(self) -> tuple[str, CueWait | None]:
        """(kind of wait, the wait without its duration): see :func:`study_app.models.cue_wait.cue_wait_now`."""
        return cue_wait_now(self.session, self.health, self.engine_trouble, self._interrupted)

    def _refresh_cue_wait(self) -> None:
        key, wait = self._cue_wait_now()
        if key != self._wait_key:
            s = self.session
            since = s.latest_t_s
            if key == "pause" and s.pause_until_s is not None and s.session is not None:
                since = s.pause_until_s - s.session.pause_s  # the pause began when the trial ended
            self._wait_key, self._wait_since_s = key, since
        if wait is not None:
            waited = max(0.0, self.session.latest_t_s - self._wait_since_s)
            help_ = wait.help
            # a wait that should end by itself but has not: say where to look, and the way out
            expected = self.session.session.pause_s if key in ("pause", "pause-again") and self.session.session else 0.0
            if not wait.action and waited >= expected + CUE_STUCK_S:
                help_ = (f"No cue for {waited:.0f} s and nothing to reset: look under Devices & health (the loop's "
                         "figures, the fault log). If it stays stuck, Quit: the running trial is stored as aborted and "
                         "the session can be resumed after a restart.")
            wait = dataclasses.replace(wait, waited_s=round(waited, 1), help=help_)
        if wait != self.cue_wait:
            self.cue_wait = wait
            self.cue_wait_changed.emit()

    def end_cue_wait(self) -> None:
        """Do what ends the current wait (the banner's button)."""
        action = self.cue_wait.action if self.cue_wait is not None else ""
        if action == "reset_faults":
            self.reset_faults()
        elif action == "resume":
            self.resume()
        elif action == "restart_engine":
            self.restart_engine()

    # -- a dead engine or loop, and the restart ---------------------------------------------------------
    def _watch_engine(self, ev: object) -> None:
        """Notice an engine that exited or whose haptic loop died (before the parts forget the session)."""
        s = self.session
        if isinstance(ev, m.SessionEnded) and ev.status == "interrupted":
            self._interrupted = ev.session_id
        trouble = detail = ""
        if isinstance(ev, m.EngineStopped) and not self._restarting:
            reason = ev.reason.rstrip(".")
            trouble = "The study engine exited unexpectedly." if "unexpectedly" in reason else \
                "The study engine stopped."
            detail = (reason[:1].upper() + reason[1:] + ". Without the engine the haptic device renders no force.")
            if s.running and s.session is not None:
                self._interrupted = s.session.session_id
        elif isinstance(ev, m.Health) and ev.loop_dead:
            trouble = "The haptic loop died; the force is at zero."
            detail = (f"The haptic loop died ({ev.loop_dead}); the haptic device's command watchdog dropped the "
                      "force to zero, and the engine accepts no session until it is restarted.")
        if trouble and not self.engine_trouble:
            sid = self._interrupted
            # short: it sits in the left column of a 768-px screen; the rest is in the detail (tooltip)
            self.engine_trouble = trouble + (f" Session {sid} was interrupted; its stored trials are kept."
                                             if sid is not None else "")
            self.engine_trouble_detail = detail + (
                f" After Restart engine, session {sid} is selected under Interrupted sessions: press Resume selected."
                if sid is not None else " Press Restart engine to start a new one.")
            self.engine_changed.emit()
            self.actions_changed.emit()

    @property
    def loop_stalled(self) -> bool:
        """The engine runs but its haptic loop latched ``LOOP_STALLED`` (a tick over 50 ms late, or frozen)."""
        return (bool(self.health.faults & Fault.LOOP_STALLED) and not self.engine_trouble
                and self.session.state not in ("connecting", "stopped", "failed"))

    def engine_notice(self) -> tuple[str, str]:
        """(short line, the whole story) of a dead engine or haptic loop, or a stalled loop; ("", "") when fine."""
        if self.engine_trouble:
            return self.engine_trouble, self.engine_trouble_detail
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

    def restart_engine(self, sim_arms: tuple[str, ...] = ()) -> bool:
        """Replace a dead engine by a new one (``sim_arms``: a simulated rig of those arms, in that order): plots,
        session and health start afresh, the interrupted session selected for resume.  False: nothing can."""
        if self.restarter is None:
            return False
        self._pending_start = None  # a start that waited for an earlier restart is not this one's
        if self.session.running and self.session.session is not None:
            self._interrupted = self.session.session.session_id  # a live engine closes it as interrupted
        self._restarting = True
        self.plots.reset()
        self._rate_rows, self._rate_span = [], 0.0
        self.session.reset("restarting the study engine …")
        self.health.engine_restarted()
        self.setup.preferred_resume = self._interrupted
        self.setup.running_session = None
        self._interrupted = None
        self.rig_kind = ""
        self.engine_trouble = self.engine_trouble_detail = ""
        self.clear_notice()
        self.engine_changed.emit()
        self.actions_changed.emit()
        self.restarter(*((sim_arms,) if sim_arms else ()))
        self._refresh_cue_wait()
        return True

    # -- notices -------------------------------------------------------------------------------------
    def notify(self, level: str, text: str, source: str = "") -> None:
        """Show a notice (replacing the previous one)."""
        self.notice = Notice(level, text, source)
        self.notice_changed.emit()

    def clear_notice(self, sources: tuple[str, ...] | None = None) -> None:
        """The notice was read or its cause resolved (``sources``: only a notice answering one of these commands)."""
        if self.notice is not None and (sources is None or self.notice.source in sources):
            self.notice = None
            self.notice_changed.emit()

    def _on_setup_changed(self) -> None:
        if self.notice is not None and self.notice.source == "StartSession":
            self.clear_notice()  # the form changed: the refusal was about what it said before

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
        self._refresh_cue_wait()
        self.participant.update(t, float(last["force_n"]))
        self.rig.update(float(last["tip_z_m"]), float(last["true_fz"]))
        rows = self.plots.new_rows
        in_trial = self.session.phase in ("active", "cued")
        self.health.update_force(float(np.nanmax(rows["force_n"])) if len(rows) else 0.0, in_trial)
        self._rate_rows.append(rows)
        self._rate_span += float(rows["t_s"][-1] - rows["t_s"][0]) if len(rows) > 1 else 0.0
        if self._rate_span >= _RATE_WINDOW_S:
            self.health.update_from_rows(np.concatenate(self._rate_rows))
            self._rate_rows, self._rate_span = [], 0.0
        return n

    # -- what may be done now -------------------------------------------------------------------------
    @property
    def ready(self) -> bool:
        """The engine is connected and idle or running (and neither it nor its haptic loop has died)."""
        return self.session.state in ("ready", "running", "paused", "ended") and not self.engine_trouble

    def can(self, action: str) -> bool:
        """Whether an action is available: start, pause, resume, abort_trial, abort_session, calibrate,
        resume_session."""
        s = self.session
        if action == "start":
            return self.ready and not s.running and self.setup.valid
        if action == "start_without_training":
            return self.ready and not s.running and bool(self.setup.training_missing)
        if action == "resume_session":
            return self.ready and not s.running
        if action == "calibrate":
            return self.ready and not s.running and self.calibration.state != "running"
        if action == "record_pose":
            return self.ready and not s.running and self.rig_kind == "real" and self.real_calibration.can_record()
        if action == "identify":
            return (self.ready and not s.running and self.rig_kind == "real"
                    and not self.real_calibration.identify_refusal())
        if action == "restart_engine":
            return (bool(self.engine_trouble) or self.loop_stalled) and self.restarter is not None
        if action == "sim_rig_view":
            return self.rig_kind == "sim"
        if action == "pause":
            return s.state == "running" and not s.paused_requested
        if action == "resume":
            return s.state == "paused" or (s.running and s.paused_requested)
        if action == "abort_trial":
            return s.running and s.phase in ("active", "cued")
        if action == "abort_session":
            return s.running
        raise ValueError(f"unknown action {action!r}")

    # -- actions -----------------------------------------------------------------------------------------
    def _send(self, cmd: object, *, clear: bool = True) -> bool:
        if clear:
            self.clear_notice()  # a new action: the last notice was about an earlier one
        ok = self.send(cmd)
        if not ok:
            self.notify("error", "The study engine is not running: press Restart engine.")
        return ok

    def start(self, override_reason: str = "", training_override: str = "") -> bool:
        """Start the session described by the setup form (False if the form is invalid or nothing may start).

        ``override_reason``: start on the real rig although the calibration chain is not complete (stored).
        ``training_override``: start an experiment without the completed training the protocol requires; the
        engine stores the reason as a ``deviation`` event (:mod:`protocol.runner.study_rules`).
        """
        skip_training = bool(training_override.strip()) and self.can("start_without_training")
        if not (self.can("start") or skip_training):
            errors = self.setup.validate()
            if errors or self.setup.hint:
                self.notify("error", "Cannot start: " + " ".join(list(errors.values()) or [self.setup.hint]),
                            "StartSession")
            return False
        cmd = self.setup.start_command(training_override if skip_training else "")
        if override_reason.strip():
            cmd = dataclasses.replace(cmd, override_reason=override_reason.strip())
        self._training_override = cmd.training_override
        # the protocol's task arm first, as run --sim-arms arranges it
        return self._send_on_arms(cmd, task_arm_first(self.commissioning.arms, self.rig_kind, cmd.protocol_path or ""))

    def _send_on_arms(self, cmd: m.StartSession | m.ResumeSession, order: tuple[str, ...]) -> bool:
        """Send a start or resume; with an ``order`` of the simulated rig's arms, restart the rig so first."""
        if not order or self.restarter is None:
            return self._send(cmd)
        self.restart_engine(order)
        self._pending_start = cmd
        self.notify("info", f"The session's task arm is {order[0]}: restarting the simulated rig with arm {order[0]} "
                            f"first (--sim-arms {','.join(order)}); the session starts when it is ready …",
                    type(cmd).__name__)
        return True

    def start_refusal(self) -> str:
        """Why Start is not available now, in words ("" when it is): for the button's and the menu's tooltip."""
        s = self.session
        if self.engine_trouble:
            return "the study engine must be restarted first (Restart engine)"
        if s.running:
            return "a session is running"
        if not self.ready:
            return "the study engine is not ready yet"
        if self.setup.hint:
            return self.setup.hint
        return " ".join(self.setup.errors.values())

    def calibration_refusal(self) -> str:
        """Why the calibration steps may not run now ("" when they may)."""
        if self.engine_trouble and self.session.state in ("stopped", "failed"):  # (its notice is behind this window)
            return "the study engine is not running: press Restart engine in the main window"
        if self.session.running:
            return ("not during a session: a calibration step moves the robot and replaces what the force path "
                    "uses; finish or end the session first")
        return ""

    def calibration_missing(self) -> str:
        """Real rig: the first step of the chain not on record ("" when a session may start, or on the sim rig)."""
        st = self.commissioning.status
        return self.commissioning.first_missing() if st is not None and st.rig == "real" else ""

    def select_calibration_arm(self, name: str) -> None:
        """Commission the arm called ``name`` in the calibration window (refused while a step runs)."""
        if self.commissioning.busy() or self.calibration.state == "running" or \
                self.real_calibration.state in ("recording", "identifying"):
            self.notify("error", "Calibration: finish the step under way first; then choose another arm.", "arm")
            self.commissioning.changed.emit()  # the selector goes back to the arm under way
            return
        if name == self.commissioning.arm:
            return
        self.commissioning.select_arm(name)
        self.calibration.state, self.calibration.result, self.calibration.done = "idle", None, 0
        self.calibration.changed.emit()
        self.real_calibration.for_arm(name)

    def _send_step(self, cmd: Any) -> None:
        """A calibration step's command, for the arm the calibration window commissions."""
        self._send(dataclasses.replace(cmd, arm=self.commissioning.arm))

    def run_tcp(self) -> None:
        """TCP step: run the pose set (simulated rig) or record the orientation the instrument is in (real rig)."""
        self._send_step(self.commissioning.tcp_command())

    def compute_tcp(self) -> None:
        """Real rig: the pivot calibration from the recorded orientations, or say why not."""
        why = self.commissioning.compute_refusal()
        if why:
            self.notify("error", f"Cannot compute the TCP: {why}", "IdentifyTcp")
            return
        self._send_step(self.commissioning.compute_command())

    def check_frames(self, axis: str = "") -> None:
        """Frames step: the whole check (simulated rig) or one axis' push (real rig)."""
        self._send_step(self.commissioning.frames_command(axis))

    def jaw_action(self, action: str) -> None:
        """A jaw control: open, close, step_open, step_close."""
        self._send(self.jaw.command(action))

    def pause(self) -> None:
        """Hold before the next trial (shown as pending until the running trial ends)."""
        self.session.paused_requested = True
        self._send(m.Pause())
        self.session.changed.emit()

    def resume(self) -> None:
        """Continue after a pause, or cancel a pending one."""
        self.session.paused_requested = False
        self._send(m.Resume())
        self.session.changed.emit()

    def abort_trial(self, trial_index: int | None = None) -> None:
        """Abort the running trial (stored as aborted, re-run later); the engine refuses if ``trial_index`` has
        ended."""
        self._send(m.AbortTrial(trial_index=trial_index))

    def abort_session(self, session_id: int | None = None) -> None:
        """Abort the session (refused by the engine if ``session_id`` is no longer the running one)."""
        self._send(m.AbortSession(session_id=session_id))

    def reset_faults(self) -> None:
        """Clear faults whose condition has gone away."""
        self._send(m.ResetFaults())

    def rehearsal_trials(self) -> range:
        """The trials a fault can still be planned for: the running session's trials not yet begun, numbered
        from 1 in the order the participant meets them (empty when no session runs)."""
        s = self.session
        if not s.running or s.session is None:
            return range(0)
        begun = s.trial.position if s.phase in ("active", "cued") and s.trial is not None else s.completed + s.aborted
        return range(begun + 1, s.session.trials_total + 1)

    def rehearsal_refusal(self, trial: int | None) -> str:
        """Why a fault cannot be rehearsed now or at ``trial`` ("" when it can)."""
        if self.rig_kind == "real":
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
                    + ("the session is left interrupted — its stored trials are kept, the trial under way is not "
                       "stored and runs again on resume. " if running else "")
                    + "The window then offers Restart engine" + (", then Resume selected." if running else "."))
        if planned is not None:
            k = planned[0]
            return (f"Rehearsal planned: {what}, {when} (if trial {k} ends sooner, nothing is injected). It is a real "
                    f"fault of the simulated rig in this session, stored with it like any fault — nothing in the "
                    f"record marks it as rehearsed: trial {k} is stored as aborted (cause: fault), does not count, "
                    "and is run again later. The fault latches: the next cue waits for Reset faults.")
        stored = ("It is stored with the running session like any fault — nothing in the record marks it as "
                  "rehearsed; a trial it hits is stored as aborted (cause: fault), does not count, and is run again "
                  "later. " if running else "No session is running: nothing is stored. ")
        return (f"Rehearsal: {what}, now: a real fault of the simulated rig. {stored}The fault latches"
                + (": the next cue waits for Reset faults." if running else " until Reset faults."))

    def inject_fault(self, kind: str, trial: int | None, seconds: float) -> None:
        """Rehearse a fault on the simulated rig: now (``trial`` None) or ``seconds`` after a trial's cue."""
        why = self.rehearsal_refusal(trial)
        if why:
            self.notify("error", f"Fault rehearsal refused: {why}.", "InjectFault")
            return
        self._planned = None if trial is None else (trial, seconds)
        self._send(m.InjectFault(kind, trial, seconds))

    def calibrate(self) -> None:
        """Run the chosen pose set."""
        self._send_step(self.calibration.command())

    def record_pose(self) -> None:
        """Real rig: measure the shown pose (the engine averages the wrench; nothing blocks here)."""
        if self.can("record_pose"):
            self._send_step(self.real_calibration.record_command())

    def identify(self) -> None:
        """Real rig: identify from the recorded poses, or say why not."""
        why = self.real_calibration.identify_refusal()
        if why:
            self.notify("error", f"Cannot identify: {why}", "IdentifyPoses")
            return
        self.calibration.state, self.calibration.result = "running", None
        self.calibration.changed.emit()
        self._send_step(self.real_calibration.identify_command())

    def set_driver(self, mode: str) -> None:
        """Autopilot (simulated participant) or manual (mouse/keyboard)."""
        self.rig.driver = mode
        self._send(m.SetDriver(mode))
        self.rig.changed.emit()

    def list_sessions(self) -> None:
        """Ask the engine for the database's resumable sessions (database work stays off the GUI thread)."""
        if self.setup.values.db_path.strip():
            self._send(m.ListSessions(os.path.abspath(self.setup.values.db_path)), clear=False)

    def resume_session(self, session_id: int) -> None:
        """Continue an interrupted session."""
        stored = next((r.get("arms", []) for r in self.setup.resumable if r["session_id"] == session_id), [])
        self._send_on_arms(m.ResumeSession(os.path.abspath(self.setup.values.db_path), int(session_id)),
                           stored_arm_order(self.commissioning.arms, self.rig_kind, stored))
