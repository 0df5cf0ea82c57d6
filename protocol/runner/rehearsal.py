"""Fault rehearsal: a planned fault at a chosen moment of a participant's session, on the simulated rig.

``haptic-study run ... --inject-fault KIND@CODE:TRIAL[+SECONDS]`` plans one: a
fault of ``KIND`` in participant ``CODE``'s experiment session, ``SECONDS``
(default 3) after the cue of its ``TRIAL``-th trial (1-based, the order the
participant met them).  The device kinds (:data:`pipeline.sim.faults.DEVICE_FAULT_KINDS`)
drive the simulated devices' own fault switches; ``kill`` ends the whole
command with SIGKILL, as a crash or ``kill -9`` would.  The GUI's simulated
rig offers the same.  A real rig refuses them: a person's hand is on it.

:class:`RehearsalTrigger` watches a session runner's events and fires each
planned fault when its trial's cue has passed by ``SECONDS``.  **A fault planned
for trial k lands in trial k, or is said to have been moved or withdrawn**: one
the watchdog would latch only after the trial's latest end (its cap) is moved
earlier, so that it latches inside the window (a stalled sensor is seen 5 ms
late, a frozen robot 50 ms late: :func:`pipeline.sim.faults.latch_delay_s`); one
whose trial ends before it begins is withdrawn, and one whose trial ends after it
began but before the watchdog latched it is ended at once (it does not go on
into the pause or the next trial).  A ``kill`` is fired at its record exactly
(the driver hands the records up to it to the runner first, :meth:`RehearsalTrigger.due_ns`).
:attr:`RehearsalTrigger.report` says what happened to each.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Final

from protocol.storage import CODE_PATTERN
from protocol.study.records import AbortCause, Outcome, TrialRecord
from protocol.study.trial import PhaseChanged, TrialPhase

__all__ = ["FAULT_KINDS", "FaultPlan", "RehearsalTrigger", "parse_fault_plan"]

#: What ``--inject-fault`` accepts: the simulated devices' faults and the process's own death.
FAULT_KINDS: Final = ("sensor-stall", "nan-burst", "bad-status", "stale-pose", "device-error", "kill")
_SPEC = re.compile(r"^(?P<kind>[a-z-]+)@(?P<code>[^:]+):(?P<trial>[^+]+)(?:\+(?P<seconds>.+))?\Z")
_FORMAT = "KIND@CODE:TRIAL[+SECONDS], e.g. sensor-stall@P01:4+2.5"


@dataclass(frozen=True, slots=True)
class FaultPlan:
    """One planned fault.

    Attributes
    ----------
    kind
        One of :data:`FAULT_KINDS`.
    code
        The participant.
    trial
        1-based position of the trial in the participant's session.
    seconds
        Time after that trial's cue, s.
    session
        ``"experiment"`` (what the command line plans) or ``"training"``.
    """

    kind: str
    code: str
    trial: int
    seconds: float = 3.0
    session: str = "experiment"

    def __str__(self) -> str:
        where = "" if self.session == "experiment" else "training:"
        return f"{self.kind}@{self.code}:{where}{self.trial}+{self.seconds:g}"


def parse_fault_plan(text: str) -> FaultPlan:
    """Read ``KIND@CODE:TRIAL[+SECONDS]``.

    Raises
    ------
    ValueError
        One line naming what is wrong and what is allowed.
    """
    m = _SPEC.match(text.strip())
    if m is None:
        raise ValueError(f"--inject-fault = {text!r}: expected {_FORMAT}")
    kind, code, trial_text, sec_text = m["kind"], m["code"], m["trial"], m["seconds"]
    if kind not in FAULT_KINDS:
        raise ValueError(f"--inject-fault = {text!r}: kind {kind!r} is not one of {', '.join(FAULT_KINDS)}")
    if not CODE_PATTERN.match(code):
        raise ValueError(f"--inject-fault = {text!r}: participant code {code!r} must be 1–32 characters from "
                         "A–Z, a–z, 0–9, '_' and '-'")
    if not re.fullmatch(r"[0-9]{1,6}", trial_text) or int(trial_text) < 1:
        raise ValueError(f"--inject-fault = {text!r}: trial {trial_text!r} must be a whole number ≥ 1 (the trial's "
                         "1-based position in the participant's experiment session)")
    seconds = 3.0
    if sec_text is not None:
        try:
            seconds = float(sec_text)
        except ValueError:
            seconds = math.nan
        if not (math.isfinite(seconds) and 0 <= seconds <= 600):
            raise ValueError(f"--inject-fault = {text!r}: seconds {sec_text!r} must be a number from 0 to 600 "
                             "(time after the trial's cue)")
    return FaultPlan(kind, code, int(trial_text), seconds)


@dataclass
class _Pending:
    plan: FaultPlan
    at_ns: int | None = None  # loop time (the records' axis) once the trial's cue is known
    trial_index: int | None = None
    cue_ns: int = 0
    moved: str = ""  # why it fires earlier than planned ("" if it does not)


@dataclass
class RehearsalTrigger:
    """Fires the planned faults of one session as its runner reaches them.

    Parameters
    ----------
    plans
        The faults planned for this session (its participant and kind).
    inject
        ``inject(kind, at_ns)`` schedules a device fault at loop time ``at_ns`` (the records' axis).
    kill
        Ends the process (SIGKILL of the command), called from :meth:`poll`.
    cancel
        ``cancel(kind, at_ns)`` withdraws a scheduled device fault, or ends it if it has begun (its trial ended
        before it, or before the watchdog latched it).
    max_trial_s
        The trials' cap (None: not known, no fault is moved).
    latch_s
        ``latch_s(kind)``: the longest time from a fault's start to the watchdog's latch, s.
    note
        ``note(t_ns, text)`` stores a line in the session's record (a
        :data:`~protocol.runner.study_rules.FAULT_REHEARSAL_EVENT` event): each plan when its trial is cued, and what it
        did -- so a trial a rehearsal aborted is never taken for a device's failure.
    """

    plans: Sequence[FaultPlan]
    inject: Callable[[str, int], None]
    kill: Callable[[], None]
    cancel: Callable[[str, int], object] = lambda kind, at_ns: None
    max_trial_s: float | None = None
    latch_s: Callable[[str], float] = lambda kind: 0.0
    note: Callable[[int, str], object] = lambda t_ns, text: None
    report: list[str] = field(default_factory=list)
    _pending: list[_Pending] = field(default_factory=list)
    _position: int = 0  # trials cued so far in this run of the session

    def __post_init__(self) -> None:
        self._pending = [_Pending(p) for p in self.plans]

    @classmethod
    def for_session(
        cls, plans: Sequence[FaultPlan], code: str, kind: str, start_position: int,
        inject: Callable[[str, int], None], kill: Callable[[], None],
        cancel: Callable[[str, int], object] = lambda kind, at_ns: None, max_trial_s: float | None = None,
        latch_s: Callable[[str], float] = lambda kind: 0.0, note: Callable[[int, str], object] = lambda t, x: None,
    ) -> RehearsalTrigger:
        """The trigger of one session: the plans for its participant and kind, counting trials from
        ``start_position``."""
        mine = [p for p in plans if p.code == code and p.session == kind]
        trig = cls(mine, inject, kill, cancel, max_trial_s, latch_s, note)
        trig._position = start_position
        return trig

    def _place(self, p: _Pending, cue_ns: int, trial_index: int) -> None:
        """Fix a plan's time from its trial's cue: moved earlier if the watchdog would latch it after the cap."""
        p.cue_ns, p.trial_index = cue_ns, trial_index
        p.at_ns = cue_ns + round(p.plan.seconds * 1e9)
        if self.max_trial_s is None:
            return
        latch_ns = round(self.latch_s(p.plan.kind) * 1e9)
        # latched (or killed) on a record before the one that times the trial out, at the latest
        latest = cue_ns + round(self.max_trial_s * 1e9) - latch_ns - 1_000_000
        if p.at_ns > latest:
            p.at_ns = max(cue_ns, latest)
            why = f"a {p.plan.kind} is latched up to {latch_ns / 1e6:g} ms after it begins and " if latch_ns else ""
            p.moved = (f"moved to +{(p.at_ns - cue_ns) / 1e9:.3f} s: {why}trial {p.plan.trial} ends "
                       f"{self.max_trial_s:g} s after its cue at the latest")

    def on_runner_event(self, ev: object) -> None:
        """Runner listener: a trial's start fixes its planned faults' times; its end says what they did."""
        if isinstance(ev, PhaseChanged) and ev.new is TrialPhase.ACTIVE:
            self._position += 1
            for p in self._pending:
                if p.at_ns is None and p.plan.trial == self._position:
                    self._place(p, ev.t_ns, ev.trial_index)
                    assert p.at_ns is not None
                    self.note(ev.t_ns, f"{p.plan}: rehearsed on the simulated rig (not a device failure), due "
                                       f"+{(p.at_ns - p.cue_ns) * 1e-9:g} s into trial {p.plan.trial}"
                                       f"{f', {p.moved}' if p.moved else ''}")
                    if p.plan.kind != "kill":
                        assert p.at_ns is not None
                        self.inject(p.plan.kind, p.at_ns)
        elif isinstance(ev, TrialRecord):
            for p in [p for p in self._pending if p.trial_index == ev.trial_index and p.at_ns is not None]:
                self._trial_ended(p, ev)

    def _trial_ended(self, p: _Pending, ev: TrialRecord) -> None:
        """What a planned fault did to the trial that just ended (a kill still due fires from :meth:`poll`)."""
        assert p.at_ns is not None
        plan, moved = p.plan, f", {p.moved}" if p.moved else ""
        if p.at_ns > ev.end_ns:
            # the trial ended first: the fault would hit the pause or the next trial, not this one
            self._pending.remove(p)
            if plan.kind != "kill":
                self.cancel(plan.kind, p.at_ns)
            self._tell(ev.end_ns, f"{plan}: not injected: trial {plan.trial} ended ({ev.outcome}) "
                                  f"{(ev.end_ns - p.cue_ns) * 1e-9:.1f} s after its cue, before "
                                  f"+{(p.at_ns - p.cue_ns) * 1e-9:g} s{moved}")
        elif plan.kind != "kill":
            self._pending.remove(p)
            if ev.outcome is Outcome.ABORTED and ev.abort_cause is AbortCause.FAULT:
                self._tell(ev.end_ns, f"{plan}: injected during trial {plan.trial}{moved}")
            elif ev.outcome is Outcome.ABORTED:
                # aborted for another cause (the experimenter's Esc) before the watchdog latched it: not its doing
                self.cancel(plan.kind, p.at_ns)
                self._tell(ev.end_ns, f"{plan}: begun {(p.at_ns - p.cue_ns) * 1e-9:g} s into trial {plan.trial}"
                                      f"{moved}, which was aborted ({ev.abort_cause}) before the watchdog latched it: "
                                      "ended at once, not the trial's abort")
            else:
                # it began, but the trial ended before the watchdog latched it: end it now, not in the next trial
                self.cancel(plan.kind, p.at_ns)
                self._tell(
                    ev.end_ns,
                    f"{plan}: begun {(p.at_ns - p.cue_ns) * 1e-9:g} s into trial {plan.trial}{moved}, which ended "
                    f"({ev.outcome}) {(ev.end_ns - p.at_ns) * 1e-6:.0f} ms later, before the watchdog latched it: "
                    "ended at once, the trial was not aborted")

    def _tell(self, t_ns: int, line: str) -> None:
        """What a plan did: in the command's report and in the session's record."""
        self.report.append(line)
        self.note(t_ns, line)

    def due_ns(self) -> int | None:
        """When the next planned ``kill`` fires (loop time, the records' axis), or None."""
        due = [p.at_ns for p in self._pending if p.plan.kind == "kill" and p.at_ns is not None]
        return min(due) if due else None

    def poll(self, t_ns: int) -> None:
        """Called with the newest record's time: kills when a ``kill`` is due (the runner has its records up to it)."""
        for p in list(self._pending):
            if p.plan.kind != "kill" or p.at_ns is None or t_ns < p.at_ns:
                continue
            self._pending.remove(p)
            self.report.append(f"{p.plan}: injected during trial {p.plan.trial}{f', {p.moved}' if p.moved else ''}")
            self.kill()

    @property
    def unfired(self) -> list[FaultPlan]:
        """Plans whose trial was never reached in this run."""
        return [p.plan for p in self._pending]
