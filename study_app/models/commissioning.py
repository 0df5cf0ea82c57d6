"""The calibration wizard's commissioning steps besides the payload (Qt-free): TCP, frames, what is on record, and the
jaw.

* :class:`CommissioningModel` -- the chain's status for the mounted tool (from
  :class:`study_app.engine.messages.CalibrationStatus`), the TCP pivot step (simulated
  rig: a pose set run automatically; real rig: orientations recorded one at a
  time about the divot, then Compute) and the frame and sign check (simulated:
  automatic; real: one recording per base axis while the experimenter pushes
  the free tip), with the texts the wizard shows;
* :class:`JawModel` -- the jaw's position, fault and last command, and the
  controls' commands.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pipeline.commissioning.frame_check import AXES
from pipeline.commissioning.tcp import MIN_PIVOT_POSES, MIN_SPREAD_DEG
from study_app.engine import messages as m
from study_app.models import Emitter

__all__ = ["CommissioningModel", "JawModel"]

#: What each base axis means to the experimenter pushing the tip (the robot's base frame).
AXIS_WORDS = {"+x": "+x", "+y": "+y", "+z": "+z (up)"}


@dataclass
class CommissioningModel:
    """State of the TCP and frame steps and of what is on record (see the module docstring).

    ``tcp_state`` / ``frames_state`` ∈ {idle, running, recording, accepted, refused} / {idle, running,
    recording, passed, failed}.
    """

    rig: str = ""
    status: m.CalibrationStatus | None = None
    pivot_set: str = "recommended"
    tcp_state: str = "idle"
    tcp_message: str = ""
    tcp_result: m.TcpCalibrationDone | None = None
    pivots: list[m.PivotRecorded] = field(default_factory=list)
    frames_state: str = "idle"
    frames_lines: dict[str, str] = field(default_factory=dict)
    frames_summary: str = ""
    frames_passed: bool = False
    recording_axis: str = ""
    #: A rig of several arms: their names (the task arm first; () for one arm), the arm the window commissions, and
    #: what is on record for each (``status`` is the chosen arm's).
    arms: tuple[str, ...] = ()
    arm: str = ""
    statuses: dict[str, m.CalibrationStatus] = field(default_factory=dict)
    changed: Emitter = field(default_factory=Emitter)

    @property
    def real(self) -> bool:
        """The engine drives the real rig."""
        return self.rig == "real"

    # -- the arm -------------------------------------------------------------------------------------
    def busy(self) -> bool:
        """A TCP or frame step is under way (the arm may not change)."""
        return self.tcp_state in ("running", "recording") or self.frames_state in ("running", "recording")

    def select_arm(self, name: str) -> None:
        """Commission the arm called ``name`` from now on: its status shown, the steps' state of the arm before
        cleared (its results are on record; a half-recorded step is not carried over to another arm)."""
        if name not in self.arms:
            raise ValueError(f"arm = {name!r}: allowed values are {', '.join(self.arms) or 'none (one arm)'}")
        if name == self.arm:
            return
        self.arm, self.status = name, self.statuses.get(name)
        self.pivots, self.tcp_state, self.tcp_message, self.tcp_result = [], "idle", "", None
        self.frames_state, self.frames_lines, self.frames_summary, self.recording_axis = "idle", {}, "", ""
        self.frames_passed = False
        self.changed.emit()

    def arm_title(self) -> str:
        """Which arm the steps commission, in a few words ("" on a rig of one arm).  No arm is marked the task arm
        here: every arm needs its chain, and which one does the task is the session's protocol's to say."""
        return f"arm {self.arm}" if self.arm else ""

    def first_missing(self) -> str:
        """The first step a session still needs ("" when none): on a rig of several arms, the first arm's with one,
        named as the engine's gate names it."""
        if not self.arms:
            return self.status.missing if self.status is not None else ""
        return next((f"arm {a}: {s.missing}" for a in self.arms if (s := self.statuses.get(a)) and s.missing), "")

    def override_prompt(self) -> str:
        """What *Start without calibration…* asks: every step not on record (not only the first), and what the
        override does not waive -- a tool with no payload on record is refused for its own weight."""
        missing = self.first_missing()
        if not missing:
            return ""
        st = self.status
        # one arm: its steps (with several, the first line names the arm and its step; the picker shows each chain)
        absent = [name for name, done, _ in (st.steps if st is not None and not self.arms else []) if not done]
        text = f"{missing}."
        if len(absent) > 1:
            text += f"\n\nNot on record for {st.tool!r}: {', '.join(absent)}."  # type: ignore[union-attr]  # absent implies a status
        # short lines: the question's label does not wrap, and a long one stretched it across a laptop's screen
        text += ("\n\nStart anyway? The session stores this override and your reason.\nThe force at rest is still "
                 "measured for 2 s and must be below 0.1 N")
        if "payload" in absent:
            text += ";\nwith no payload on record the tool's own weight counts as force, and the start is refused"
        return text + ".\n\nReason:"

    def arms_overview(self) -> list[tuple[str, str]]:
        """Per arm: (name, each step on record ✔ or not ✘, e.g. ``✔ TCP ✔ payload ✘ frames``) -- a rig of several
        arms."""
        out = []
        for a in self.arms:
            st = self.statuses.get(a)
            out.append((a, "–" if st is None else " ".join(f"{'✔' if ok else '✘'} {n}" for n, ok, _ in st.steps)))
        return out

    # -- commands ----------------------------------------------------------------------------------
    def tcp_command(self) -> m.RecordPivot | m.CalibrateTcp:
        """Simulated rig: run the pose set; real rig: record the orientation the instrument is in now."""
        if self.real:
            self.tcp_state, self.tcp_message = "recording", ""
            self.changed.emit()
            return m.RecordPivot(f"O{len(self.pivots) + 1}")
        self.tcp_state, self.tcp_result, self.tcp_message = "running", None, ""
        self.changed.emit()
        return m.CalibrateTcp(self.pivot_set)

    def compute_refusal(self) -> str:
        """Why Compute is not possible now ("" if it is); real rig only."""
        if self.tcp_state == "recording":
            return "an orientation is being recorded"
        if len(self.pivots) < MIN_PIVOT_POSES:
            return f"record at least {MIN_PIVOT_POSES} orientations first ({len(self.pivots)} so far)"
        return ""

    def compute_command(self) -> m.IdentifyTcp:
        """Real rig: the pivot calibration from the recorded orientations."""
        why = self.compute_refusal()
        if why:
            raise RuntimeError(f"cannot compute: {why}")
        self.tcp_state = "running"
        self.changed.emit()
        return m.IdentifyTcp(tuple((p.label, p.rot_base_flange, p.flange_position_m) for p in self.pivots))

    def clear_pivots(self) -> None:
        """Start the orientations again."""
        self.pivots, self.tcp_state, self.tcp_message, self.tcp_result = [], "idle", "", None
        self.changed.emit()

    def frames_command(self, axis: str = "") -> m.RecordFrameAxis | m.CheckFrames:
        """Simulated rig: the whole check; real rig: record a push along ``axis``."""
        if self.real:
            if axis not in AXES:
                raise ValueError(f"axis = {axis!r}: allowed values are {', '.join(AXES)}")
            self.frames_state, self.recording_axis = "recording", axis
            self.changed.emit()
            return m.RecordFrameAxis(axis)
        self.frames_state, self.frames_lines, self.frames_summary = "running", {}, ""
        self.changed.emit()
        return m.CheckFrames()

    # -- engine events -----------------------------------------------------------------------------
    def apply(self, ev: object) -> None:
        """Update from engine events."""
        if isinstance(ev, m.EngineReady):
            self.rig = ev.rig
            self.arms = tuple(name for name, _ in ev.arm_rings)
            self.statuses = {}
            # a new engine (a restart) holds no pushes: the window must not show axes it would not count
            self.frames_lines, self.frames_summary = {}, ""
            if self.arm not in self.arms:  # a new engine (a restart): the task arm, or no arm on a one-arm rig
                self.arm = self.arms[0] if self.arms else ""
        elif isinstance(ev, m.CalibrationStatus):
            self.statuses[ev.arm] = ev
            if ev.arm == self.arm:  # another arm's is shown in the overview only
                self.status = ev
        elif isinstance(ev, m.PivotRecorded):
            self.pivots.append(ev)
            self.tcp_state, self.tcp_message = "idle", self._too_close(ev)
        elif isinstance(ev, m.TcpCalibrationDone):
            self.tcp_result = ev
            self.tcp_state = "accepted" if ev.accepted else "refused"
            self.tcp_message = ev.reason
        elif isinstance(ev, m.FrameAxisChecked):
            self.frames_lines[ev.axis] = ev.line
            self.frames_summary = ""  # a new push: an earlier verdict or refusal is no longer the news
            if self.frames_state == "recording":
                self.frames_state = "idle"
        elif isinstance(ev, m.FrameCheckDone):
            self.frames_state = "passed" if ev.passed else "failed"
            self.frames_summary, self.frames_passed = ev.summary, ev.passed
        elif isinstance(ev, m.CommandRefused) and ev.command in ("RecordPivot", "IdentifyTcp", "CalibrateTcp"):
            self.tcp_state, self.tcp_message = ("idle" if ev.command == "RecordPivot" else "refused"), ev.message
        elif isinstance(ev, m.CommandRefused) and ev.command in ("RecordFrameAxis", "CheckFrames"):
            self.frames_state, self.frames_summary = "idle", ev.message
        else:
            return
        self.changed.emit()

    def _too_close(self, ev: m.PivotRecorded) -> str:
        """A warning when an orientation repeats an earlier one (it adds nothing to the fit)."""
        r = np.asarray(ev.rot_base_flange).reshape(3, 3)
        best: tuple[float, str] | None = None
        for p in self.pivots[:-1]:
            c = (float(np.trace(np.asarray(p.rot_base_flange).reshape(3, 3).T @ r)) - 1.0) / 2.0
            ang = math.degrees(math.acos(min(1.0, max(-1.0, c))))
            if best is None or ang < best[0]:
                best = (ang, p.label)
        if best is None or best[0] >= 5.0:
            return ""
        # it stays in the fit (harmless, nothing to undo): the advice is about the next orientation
        return (f"{ev.label} is only {best[0]:.1f}° from {best[1]}: kept, but it adds little — turn the instrument "
                f"further before the next one (at least {MIN_SPREAD_DEG:g}° between orientations, in two directions)")

    # -- what the wizard shows -------------------------------------------------------------------------
    def status_lines(self) -> list[tuple[str, bool, str]]:
        """Per step: (name, on record, summary)."""
        return list(self.status.steps) if self.status is not None else []

    def gate_text(self) -> str:
        """Whether a session may start on this rig, in one line."""
        st = self.status
        if st is None:
            return ""
        where = f" ({st.file})" if st.file else ""
        if st.rig != "real":
            return (f"Simulated rig: nothing is saved and a session does not need the chain; on the real rig each "
                    f"accepted step is saved for the mounted tool and a session starts only when all three are on "
                    f"record{where}.")
        if st.missing:
            return f"A session cannot start yet: {self.arm_title() + ': ' if self.arm else ''}{st.missing}."
        other = next((a for a, s in self.statuses.items() if s.missing), None)
        if other is not None:  # the gate needs every arm's chain
            return (f"Arm {self.arm}'s chain is on record{where}; a session cannot start yet: arm {other}: "
                    f"{self.statuses[other].missing}.")
        return (f"Tool {st.tool!r}: TCP, payload and frames on record{where}; a session starts after the force at "
                "rest is checked (2 s, below 0.1 N)" + (" on every arm." if self.arms else "."))

    def tcp_instruction(self) -> str:
        """What to do in the TCP step now."""
        if not self.real:
            return ("The simulated robot rests the tip in a divot and turns the instrument through the pose set; a "
                    "least-squares fit gives the tip in the flange frame and the divot in the base frame.")
        n = len(self.pivots)
        if self.tcp_state == "recording":
            return f"Recording orientation O{n + 1} — keep the robot still."
        return (f"Rest the tip in the divot and turn the instrument through at least {MIN_PIVOT_POSES} orientations, "
                f"tilted at least {MIN_SPREAD_DEG:g}° apart in two directions; press Record orientation at each "
                f"({n} recorded), then Compute.")

    def tcp_verdict(self) -> str:
        """The last result in one line (or what went wrong)."""
        r = self.tcp_result
        if self.tcp_state == "running":
            return "computing …" if self.real else "turning the instrument about the divot …"
        if r is None or (self.tcp_message and self.tcp_state == "idle"):
            return self.tcp_message
        if not r.accepted:
            return f"Refused: {r.reason}"
        res = r.result or {}
        tip = ", ".join(f"{1e3 * v:+.2f}" for v in res.get("tip_in_flange_m", []))
        text = (f"Accepted: tip ({tip}) mm in the flange frame, RMS residual "
                f"{1e3 * res.get('rms_residual_m', math.nan):.3f} mm over {r.n_poses} orientations")
        if math.isfinite(r.error_mm):
            text += f"; {r.error_mm:.3f} mm from the simulated truth"
        if not self.real:
            return text + "."
        # as `calibrate tcp` says it: the robot's own program needs the tip on its pendant, the file for a restart
        t = res.get("tip_in_flange_m", [])
        metres = ", ".join(f"{v:.5f}" for v in t)
        return (text + f" — saved for the tool. Set the TCP on the pendant to ({tip}) mm and robot.tcp_offset_m to "
                f"[{metres}] (until then the app corrects the poses itself).")

    def frames_instruction(self) -> str:
        """What to do in the frames step now."""
        if not self.real and self.frames_state == "running":
            return ("Checking … the simulated experimenter pushes the free tip along +x, +y and +z in turn (feedback "
                    "off); the result appears below when the three pushes are done.")
        if not self.real:
            return ("The simulated experimenter pushes the free tip 1 N along each base axis with feedback off; the "
                    "compensated force in the base frame and the force the Touch would render must point the "
                    "expected way (within 30°).")
        if self.frames_state == "recording":
            return (f"Recording 3 s: push the tip gently (about 1 N) along base {AXIS_WORDS[self.recording_axis]} "
                    "and let go.")
        left = [a for a in AXES if a not in self.frames_lines]
        return ("With the tip free, press Record for each axis and push the tip gently along it within 3 s"
                + (f" (still to do: {', '.join(left)})." if left else "."))

    def frames_view(self) -> list[str]:
        """One line per axis checked so far, then the verdict."""
        lines = [self.frames_lines[a] for a in AXES if a in self.frames_lines]
        if self.frames_summary:
            lines.append(self.frames_summary)
        return lines

    def frames_display(self) -> list[str]:
        """:meth:`frames_view` for a window ~90 characters wide: each axis's verdict first, its parts below it.

        ``+x  peak 1.02 N · base force 0.7° from +x · rendered force … · PASS`` (one terminal line) becomes
        ``+x  PASS · peak 1.02 N`` with the base and the rendered force indented beneath, so no verdict is
        wrapped onto a line of its own.
        """
        out: list[str] = []
        for a in AXES:
            line = self.frames_lines.get(a)
            if line is None:
                continue
            parts = line.split(" · ")
            verdict = parts.pop() if len(parts) > 1 and parts[-1] in ("PASS", "FAIL") else ""
            head = parts[0][len(a):].strip() if parts[0].startswith(a) else parts[0]
            out.append(f"{a}  " + " · ".join(p for p in (verdict, head) if p))
            out += [" " * (len(a) + 2) + p for p in parts[1:]]
        if self.frames_summary:
            out.append(self.frames_summary)
        return out


@dataclass
class JawModel:
    """The jaw as the health panel and the controls show it."""

    state: m.JawState | None = None
    log: list[str] = field(default_factory=list)
    changed: Emitter = field(default_factory=Emitter)

    @property
    def available(self) -> bool:
        """The rig has a jaw (the engine reported one)."""
        return self.state is not None

    def apply(self, ev: object) -> None:
        """Update from :class:`study_app.engine.messages.JawState` events."""
        if isinstance(ev, m.JawState):
            self.state = ev
            if ev.last:
                self.log.append(ev.last)
                del self.log[:-50]
        elif isinstance(ev, m.EngineStopped):
            self.state = None
        else:
            return
        self.changed.emit()

    @staticmethod
    def command(action: str) -> m.JawCommand:
        """A control's command."""
        if action not in m.JAW_ACTIONS:
            raise ValueError(f"jaw action = {action!r}: allowed values are {', '.join(m.JAW_ACTIONS)}")
        return m.JawCommand(action)

    def text(self) -> str:
        """Position and fault in one line."""
        s = self.state
        if s is None:
            return "no jaw actuator"
        if s.fault:
            return f"FAULT: {s.fault}"
        return f"{s.fraction_open:.0%} open ({s.pulse_us} µs)" + (", at the limit" if s.at_limit else "")
