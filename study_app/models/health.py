"""Device and loop health: each device's state, update rate and sample age; faults; the loop's timing."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from pipeline.devices.interfaces import Fault
from protocol.study.records import AbortCause, TrialRecord
from study_app.engine import messages as m
from study_app.guide_paths import guide
from study_app.models import Emitter

__all__ = ["HIGH_FORCE_N", "LOOP_LIMITS", "RATE_WINDOW_S", "DeviceStatus", "HealthModel", "LoopFigure",
           "lost_to_the_machine"]

#: Sample time over which device rates are measured, s.
RATE_WINDOW_S = 0.5
#: Task force above which the window warns: well above every target of the paper's protocol (≤ 1.2 N) and above
#: what the Touch can render (3.3 N peak), so no trial needs it; it only presses the tissue (and the hand) harder.
HIGH_FORCE_N = 5.0
#: Real rig without a payload on record: a task force above this is the tool's weight, and said so (N; the
#: session gate's limit for the force at rest).
UNCOMPENSATED_NOTE_N = 0.1

#: The loop's figures against their limits: (within limits, still acceptable).  Above the second: red.
#: Rate in Hz off the nominal 1000; p99 |period - 1 ms| in µs (the lab PC reaches ~10 µs, README);
#: periods over 2 ms and missed slots as a share of ticks (the target is none in a 60 s run).
LOOP_LIMITS = {
    "rate_off_hz": (5.0, 20.0),
    "p99_us": (100.0, 500.0),
    "over_2ms_fraction": (1e-4, 1e-3),
    "missed_fraction": (1e-4, 1e-3),
}


@dataclass(frozen=True, slots=True)
class LoopFigure:
    """One loop-health figure as shown: its text, ``level`` ok/warn/bad/unknown, and the limit it is judged by."""

    name: str
    text: str
    level: str
    limit: str


def _level(value: float, limits: tuple[float, float]) -> str:
    if not math.isfinite(value):
        return "unknown"
    return "ok" if value <= limits[0] else "warn" if value <= limits[1] else "bad"

def lost_to_the_machine(record: TrialRecord) -> bool:
    """A trial aborted because the 1 kHz loop fell behind: records missing for longer than the watchdog allows
    (``gap``), or the loop stalled (``LOOP_STALLED``) -- what a computer too busy for the loop causes."""
    cause, reason = record.abort_cause, record.abort_reason or ""
    return cause is AbortCause.GAP or (cause is AbortCause.FAULT and "LOOP_STALLED" in reason)


#: What helps a computer too busy for the loop (the health panel's notice, docs/gui.md "Machine health").
BUSY_HELP = ("What helps: close other programs (web browsers, video calls, software updates, other studies), keep a "
             "laptop on mains power, and use this computer for nothing else during a session.")


#: How the fault log names each kind of loop event.
_VERBS = {"fault": "fault", "fault_cleared": "gone", "faults_reset": "reset", "derating": "derating",
          "derating_ended": "derating ended", "output_restarted": "output restarted"}

#: Numbers in an event's detail (a run of "no loop tick for 11.2 ms", "… 12.9 ms" is one kind of event).
_NUMBER = re.compile(r"\d+(?:\.\d+)?")


@dataclass(slots=True)
class _LogRun:
    """Events of one kind in a row (numbers in their details aside), shown as one line of the fault log."""

    key: tuple[str, str]
    first: str  # when the first happened ("" for a line that is no event: "engine restarted")
    last: str
    detail: str  # the newest one's
    count: int = 1

    def line(self) -> str:
        """The first, and for more than one, ×N and the newest's time and detail."""
        verb = self.key[0]
        if not self.first:
            return verb
        if self.count == 1:
            return f"{self.first}  {verb}: {self.detail}"
        return f"{self.first}  {verb} ×{self.count} (the last at {' '.join(self.last.split())}): {self.detail}"


#: Lines the fault log keeps.
_LOG_LINES = 50


#: Fault bits that belong to each device row.
_DEVICE_FAULTS = {
    "F/T sensor": Fault.SENSOR_STALE | Fault.SENSOR_STATUS | Fault.SENSOR_SATURATION | Fault.NON_FINITE,
    "Robot (pose)": Fault.POSE_STALE,
    "Haptic device": Fault.HAPTIC_DEVICE | Fault.LOOP_STALLED,
}


@dataclass(frozen=True, slots=True)
class DeviceStatus:
    """One row of the device table."""

    name: str
    state: str
    rate_hz: float
    age_ms: float


@dataclass
class HealthModel:
    """Health from :class:`study_app.engine.messages.Health` events, fault events and the ring's records.

    Device rates are measured in sample time from the records: a new F/T
    sample changes the raw wrench, a new robot pose resets the pose age.
    """

    connected: bool = False
    faults: int = 0
    loop: m.Health | None = None
    devices: list[DeviceStatus] = field(default_factory=list)
    #: Largest task force in the newest records, N, and whether a trial was running then.
    force_n: float = 0.0
    in_trial: bool = False
    #: The real rig has no payload calibration on record: the task force carries the tool's own weight.
    uncompensated: bool = False
    #: The jaw (None: the rig has none, or it has not reported yet).
    jaw: m.JawState | None = None
    changed: Emitter = field(default_factory=Emitter)
    #: Trials of the running session lost to the machine (:func:`lost_to_the_machine`), and their numbers.
    busy_trials: list[int] = field(default_factory=list)
    #: The runs behind :attr:`fault_log`, oldest first.
    _log_runs: list[_LogRun] = field(default_factory=list, repr=False)
    #: The newest records not yet measured for the device rates, and the sample time they span, s.
    _rate_rows: list[np.ndarray] = field(default_factory=list, repr=False)
    _rate_span_s: float = 0.0
    #: The running session's id (None between sessions): the fault log names it.
    _session: int | None = field(default=None, repr=False)

    @property
    def fault_log(self) -> list[str]:
        """The newest events, one line each; a run of the same event is one line counted ``×N``."""
        return [run.line() for run in self._log_runs]

    def apply(self, ev: object) -> None:
        """Update from an engine event."""
        if isinstance(ev, m.EngineReady):
            self.connected = True
        elif isinstance(ev, m.Health):
            self.loop = ev
            self.faults = ev.faults
        elif isinstance(ev, m.EngineFault):
            self.faults = ev.faults
            self._log_event(ev)
        elif isinstance(ev, m.JawState):
            self.jaw = ev
        elif isinstance(ev, m.CalibrationStatus):
            self.uncompensated = ev.rig == "real" and not any(done for name, done, _ in ev.steps if name == "payload")
        elif isinstance(ev, m.EngineStopped):
            self._session = None
            # what the dead engine measured and latched goes with it: no 1000 Hz, no 0.0 ms sample age, no "next cue
            # waits … Resume" beside "disconnected" (the fault log keeps what happened)
            self.connected, self.loop, self.faults = False, None, 0
        elif isinstance(ev, m.SessionStarted):
            self.busy_trials = [r.trial_index + 1 for r in ev.stored_trials if lost_to_the_machine(r)]
            self._session = ev.session_id  # the log's lines name it: earlier sessions' lines stay told apart
            began = "resumed" if ev.stored_trials else "started"
            self._log_line(f"— session {ev.session_id} ({ev.code} {ev.kind}) {began} —")
        elif isinstance(ev, m.SessionEnded):
            self._session = None
            return
        elif isinstance(ev, m.TrialEnded):
            if not lost_to_the_machine(ev.record):
                return
            self.busy_trials.append(ev.record.trial_index + 1)
        else:
            return
        self._refresh_states()
        self.changed.emit()

    def machine_notice(self) -> str:
        """When the loop falling behind cost trials: that the computer is too busy, how many trials it cost, what
        helps, and whether the loop got the real-time priority it asked for ("" while no trial was lost so)."""
        n = len(self.busy_trials)
        if not n:
            return ""
        which = ("…, " if n > 5 else "") + ", ".join(str(k) for k in self.busy_trials[-5:])  # the newest five
        text = (f"This computer is too busy for the 1 kHz haptic loop: {n} trial{'s' if n > 1 else ''} of this "
                f"session (trial{'s' if n > 1 else ''} {which}) {'were' if n > 1 else 'was'} aborted because the "
                "loop fell behind; each is run again, so the session takes longer. " + BUSY_HELP)
        sched = self.loop.scheduling if self.loop is not None else ""
        if sched.startswith("SCHED_FIFO"):
            text += f" The loop asked for real-time priority and got it ({sched})."
        elif sched.startswith("normal"):
            why = sched[len("normal"):].strip(" ()")
            text += (f" The loop asked for real-time priority and did not get it ({why}): it runs at normal priority, "
                     f"so any busy program can delay it; allow real-time scheduling for this user ({guide('gui.md')}, "
                     "Machine health).")
        return text

    def _log_event(self, ev: m.EngineFault) -> None:
        """One line per event; a run of the same event (numbers aside) is one line counted ``×N``.

        Only the view coalesces: the engine stores every event in the database.
        """
        verb = _VERBS.get(ev.kind, ev.kind)
        # one way of saying when: in a session, which one and its clock (the time the database stores the event at);
        # else the engine's clock, said to be that
        if math.isfinite(ev.session_t_s):
            which = f"session {self._session}" if self._session is not None else "session clock"
            when = f"{which}, {ev.session_t_s:.3f} s"
        else:
            when = f"no session, engine clock {ev.t_s:.3f} s"
        # an aborted trial's reason names its cause already ("gap: no loop record …"): say it once
        detail = ev.detail.removeprefix(f"{verb}: ")
        key = (verb, _NUMBER.sub("#", detail))
        last = self._log_runs[-1] if self._log_runs else None
        if last is not None and last.key == key:
            last.last, last.detail, last.count = when, detail, last.count + 1
            return
        self._log_runs.append(_LogRun(key, when, when, detail))
        del self._log_runs[:-_LOG_LINES]

    def engine_restarted(self) -> None:
        """A new engine replaces the old one: its figures and faults are gone (the log keeps what happened)."""
        self.connected, self.loop, self.faults, self.devices = False, None, 0, []
        self.busy_trials = []
        self._rate_rows, self._rate_span_s = [], 0.0
        self._session = None
        self._log_line("— engine restarted —")
        self.changed.emit()

    def _log_line(self, text: str) -> None:
        """A line of the fault log that is no event (a session began, the engine restarted)."""
        self._log_runs.append(_LogRun((text, ""), "", "", ""))
        del self._log_runs[:-_LOG_LINES]

    def add_rows(self, rows: np.ndarray) -> None:
        """The newest records: the device rates are measured over every ``RATE_WINDOW_S`` of them."""
        self._rate_rows.append(rows)
        self._rate_span_s += float(rows["t_s"][-1] - rows["t_s"][0]) if len(rows) > 1 else 0.0
        if self._rate_span_s >= RATE_WINDOW_S:
            self.update_from_rows(np.concatenate(self._rate_rows))
            self._rate_rows, self._rate_span_s = [], 0.0

    def update_from_rows(self, rows: np.ndarray) -> None:
        """Measure device rates and ages over a block of records (≥ ~0.2 s gives stable rates)."""
        if len(rows) < 2:
            return
        span = float(rows["t_s"][-1] - rows["t_s"][0])
        if span <= 0:
            return
        raw = np.stack([rows["raw_fx"], rows["raw_fy"], rows["raw_fz"]], axis=1)
        sensor_new = int(np.count_nonzero(np.any(np.diff(raw, axis=0) != 0, axis=1)))
        pose_new = int(np.count_nonzero(np.diff(rows["pose_age_ns"]) < 0))
        last = rows[-1]
        ticks = len(rows) - 1
        self.devices = [
            DeviceStatus("F/T sensor", "", sensor_new / span, float(last["sensor_age_ns"]) * 1e-6),
            DeviceStatus("Robot (pose)", "", pose_new / span, float(last["pose_age_ns"]) * 1e-6),
            DeviceStatus("Haptic device", "", ticks / span, 0.0),
        ]
        self._refresh_states()
        self.changed.emit()

    def _refresh_states(self) -> None:
        out = []
        for d in self.devices:
            if d.name == "Jaw actuator":
                continue
            bits = Fault(self.faults & _DEVICE_FAULTS.get(d.name, 0))
            if not self.connected:  # no figures of a device nobody reads
                out.append(DeviceStatus(d.name, "disconnected", math.nan, math.nan))
                continue
            state = "FAULT: " + bits.describe() if bits else "ok"
            if state == "ok" and d.name == "Haptic device" and self.derating():
                state = f"ok, derating: at most {self.loop.haptic_force_limit_n:.2f} N"  # type: ignore[union-attr]  # derating() is True only with a loop
            out.append(DeviceStatus(d.name, state, d.rate_hz, d.age_ms))
        j = self.jaw
        if j is not None:
            state = "disconnected" if not self.connected else (
                f"FAULT: {j.fault}" if j.fault else f"ok, {j.fraction_open:.0%} open ({j.pulse_us} µs)"
                + (" at the limit" if j.at_limit else ""))
            out.append(DeviceStatus("Jaw actuator", state, math.nan, math.nan))
        self.devices = out

    def derating(self) -> bool:
        """The haptic device lowered its force limit below its peak (its motors are warm)."""
        h = self.loop
        if h is None or not math.isfinite(h.haptic_force_limit_n):
            return False
        if math.isfinite(h.haptic_peak_force_n):
            return h.haptic_force_limit_n < h.haptic_peak_force_n
        return h.haptic_heat_fraction > 0.5  # an engine that does not say its peak: the default onset

    def thermal_figure(self) -> LoopFigure | None:
        """The Touch's motor heat against its budget (None before the first Health event)."""
        h = self.loop
        if h is None:
            return None
        frac = h.haptic_heat_fraction
        text = f"Touch motors at {100 * frac:.0f} % of their heat budget"
        derating = self.derating()
        if derating:
            peak, cont = h.haptic_peak_force_n, h.haptic_continuous_force_n
            text += f": derating — it may render at most {h.haptic_force_limit_n:.2f} N now"
            if math.isfinite(peak) and math.isfinite(cont):
                text += (f" (its {peak:g} N peak, lowered toward its {cont:g} N continuous rating as the motors "
                         "heat; back to the peak when they cool)")
        level = "bad" if frac > 0.9 else "warn" if derating or frac > 0.5 else "ok"
        return LoopFigure("thermal", text, level, "derating above 50 %")

    def faults_text(self) -> str:
        """Latched faults, or 'none'."""
        return Fault(self.faults).describe()

    def arms_text(self) -> str:
        """A rig of several arms: one line per arm (the task arm first, marked), its force now and its latched
        faults ("" on a rig of one arm)."""
        arms = self.loop.arms if self.loop is not None else ()
        return "\n".join(
            f"{name}{' (task)' if k == 0 else ''}: {force:.2f} N, faults: {Fault(faults).describe()}"
            if math.isfinite(force) else f"{name}{' (task)' if k == 0 else ''}: no record yet"
            for k, (name, force, faults) in enumerate(arms))

    def waiting_text(self) -> str:
        """Why the session's next cue is held back ('' when it is not, or between pauses)."""
        h = self.loop
        return "" if h is None or h.waiting in ("", "pause") else h.waiting

    def loop_text(self) -> str:
        """Loop rate, p99 |period − 1 ms| and overruns, in one line."""
        figures = self.loop_figures()
        if not figures:
            return "loop: –"
        return " · ".join(f.text for f in figures)

    def loop_figures(self) -> list[LoopFigure]:
        """The loop's figures, each judged against :data:`LOOP_LIMITS` (empty before the first Health event)."""
        h = self.loop
        if h is None:
            return []
        ticks = max(1, h.ticks)
        over, missed = h.periods_over_2ms / ticks, h.missed_slots / ticks
        p99 = "–" if math.isnan(h.abs_dev_p99_us) else f"{h.abs_dev_p99_us:.0f} µs"
        lim = LOOP_LIMITS
        return [
            LoopFigure("rate", f"loop {h.loop_rate_hz:.0f} Hz",
                       _level(abs(h.loop_rate_hz - 1000.0), lim["rate_off_hz"]),
                       f"1000 ± {lim['rate_off_hz'][0]:g} Hz"),
            LoopFigure("p99", f"p99 |period − 1 ms| {p99}", _level(h.abs_dev_p99_us, lim["p99_us"]),
                       f"≤ {lim['p99_us'][0]:g} µs"),
            LoopFigure("over", f"periods over 2 ms: {h.periods_over_2ms} of {h.ticks:,} ({100 * over:.2f} %)",
                       _level(over, lim["over_2ms_fraction"]), f"≤ {100 * lim['over_2ms_fraction'][0]:g} %"),
            LoopFigure("missed", f"missed slots: {h.missed_slots} ({100 * missed:.2f} %)",
                       _level(missed, lim["missed_fraction"]), f"≤ {100 * lim['missed_fraction'][0]:g} %"),
        ]

    def placement_text(self) -> str:
        """Where the 1 kHz loop runs and how it is scheduled: its own process and CPU, or why not ("" before the
        first Health event)."""
        h = self.loop
        if h is None or not h.scheduling:
            return ""
        if h.scheduling == "virtual clock":
            return "The 1 kHz loop: on the virtual clock (simulated time), in the engine's process"
        where = (f"alone in its own process (pid {h.loop_pid})" if h.loop_pid
                 else "a thread of the engine's process")
        return f"The 1 kHz loop: {where}, {h.scheduling}"

    def latency_text(self) -> str:
        """The end-to-end latency a participant feels, in one line ("" when the engine does not say: virtual clock)."""
        lat = self.loop.latency if self.loop is not None else None
        if not lat:
            return ""

        def ms(key: str) -> str:
            v = lat.get(key)
            return "not measured" if v is None else f"{v:.1f} ms"

        return (f"End-to-end latency: tip → hand {ms('force_ms')} · hand → tip {ms('motion_ms')} · "
                f"round trip {ms('total_ms')} (a {lat.get('step_n', 1.0):g} N step of tip force)")

    def latency_stages(self) -> list[str]:
        """The latency's stages, one line each (empty when the engine does not say)."""
        lat = self.loop.latency if self.loop is not None else None
        out = []
        for s in (lat or {}).get("stages", []):
            ms = "–" if s["ms"] is None else f"{s['ms']:.1f} ms"
            out.append(f"{'tip → hand' if s['path'] == 'force' else 'hand → tip'}: {ms}  {s['name']} ({s['source']})")
        return out

    def update_force(self, max_force_n: float, in_trial: bool) -> None:
        """The largest task force of the newest records, and whether a trial was running."""
        f = max_force_n if math.isfinite(max_force_n) else 0.0
        was = self.force_warning()
        self.force_n, self.in_trial = f, in_trial
        if self.force_warning() != was:
            self.changed.emit()

    def force_warning(self) -> str:
        """A warning when the task force is above :data:`HIGH_FORCE_N`, else ''; on the real rig without a payload
        on record, whenever there is a task force at all (a tool lighter than 0.5 kg weighs less than the limit,
        and its weight would read as a contact)."""
        if self.uncompensated and self.force_n > UNCOMPENSATED_NOTE_N:
            # not a force on the tissue: the tool's weight, nothing subtracts it
            return (f"{self.force_n:.1f} N task force: no payload calibration on record, so the tool's own weight "
                    "counts as force; run the calibration wizard's payload step")
        if self.force_n <= HIGH_FORCE_N:
            return ""
        where = "" if self.in_trial else " while no trial is running"
        return (f"{self.force_n:.1f} N on the tissue{where} (warning above {HIGH_FORCE_N:g} N): "
                "lift the instrument")
