"""Fault rehearsal: a planned fault at a chosen moment of a participant's session, on the simulated rig.

``haptic-study run ... --inject-fault KIND@CODE:TRIAL[+SECONDS]`` plans one: a
fault of ``KIND`` in participant ``CODE``'s experiment session, ``SECONDS``
(default 3) after the cue of its ``TRIAL``-th trial (1-based, the order the
participant met them).  The device kinds (:data:`pipeline.sim.faults.DEVICE_FAULT_KINDS`)
drive the simulated devices' own fault switches; ``kill`` ends the whole
command with SIGKILL, as a crash or ``kill -9`` would.  The GUI's simulated
rig offers the same.  A real rig refuses them: a person's hand is on it.

:class:`RehearsalTrigger` watches a session runner's events and fires each
planned fault when its trial's cue has passed by ``SECONDS``; a fault whose
trial ends before that is withdrawn (it would hit the next trial instead).
:attr:`RehearsalTrigger.report` says what happened to each.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Final

from protocol.storage import CODE_PATTERN
from protocol.records import TrialRecord
from protocol.trial import PhaseChanged, TrialPhase

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
        ``cancel(kind, at_ns)`` withdraws a scheduled device fault (its trial ended before it).
    """

    plans: Sequence[FaultPlan]
    inject: Callable[[str, int], None]
    kill: Callable[[], None]
    cancel: Callable[[str, int], object] = lambda kind, at_ns: None
    report: list[str] = field(default_factory=list)
    _pending: list[_Pending] = field(default_factory=list)
    _position: int = 0  # trials cued so far in this run of the session

    def __post_init__(self) -> None:
        self._pending = [_Pending(p) for p in self.plans]

    @classmethod
    def for_session(
        cls, plans: Sequence[FaultPlan], code: str, kind: str, start_position: int,
        inject: Callable[[str, int], None], kill: Callable[[], None],
        cancel: Callable[[str, int], object] = lambda kind, at_ns: None,
    ) -> RehearsalTrigger:
        """The trigger of one session: the plans for its participant and kind, counting trials from ``start_position``."""
        mine = [p for p in plans if p.code == code and p.session == kind]
        trig = cls(mine, inject, kill, cancel)
        trig._position = start_position
        return trig

    def on_runner_event(self, ev: object) -> None:
        """Runner listener: a trial's start fixes its planned faults' times; its end is noted for the report."""
        if isinstance(ev, PhaseChanged) and ev.new is TrialPhase.ACTIVE:
            self._position += 1
            for p in self._pending:
                if p.at_ns is None and p.plan.trial == self._position:
                    p.at_ns = ev.t_ns + round(p.plan.seconds * 1e9)
                    p.trial_index = ev.trial_index
                    if p.plan.kind != "kill":
                        self.inject(p.plan.kind, p.at_ns)
        elif isinstance(ev, TrialRecord):
            for p in list(self._pending):
                if p.trial_index == ev.trial_index and p.at_ns is not None and p.at_ns > ev.end_ns:
                    # the trial ended first: the fault would hit the pause or the next trial, not this one
                    self._pending.remove(p)
                    if p.plan.kind != "kill":
                        self.cancel(p.plan.kind, p.at_ns)
                    after = (ev.end_ns - (p.at_ns - round(p.plan.seconds * 1e9))) * 1e-9
                    self.report.append(f"{p.plan}: not injected: trial {p.plan.trial} ended ({ev.outcome}) "
                                       f"{after:.1f} s after its cue, before +{p.plan.seconds:g} s")

    def poll(self, t_ns: int) -> None:
        """Called with the newest record's time: reports injected faults; kills when a ``kill`` is due."""
        for p in list(self._pending):
            if p.at_ns is None or t_ns < p.at_ns:
                continue
            self._pending.remove(p)
            self.report.append(f"{p.plan}: injected during trial {p.plan.trial}")
            if p.plan.kind == "kill":
                self.kill()

    @property
    def unfired(self) -> list[FaultPlan]:
        """Plans whose trial was never reached in this run."""
        return [p.plan for p in self._pending]
