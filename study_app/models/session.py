"""The running session as the experimenter sees it: state, progress and the trial table."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from protocol.design import HapticMode
from protocol.records import Outcome, TrialRecord
from study_app import messages as m
from study_app.models import Emitter

__all__ = ["SessionModel", "TrialTable", "TRIAL_COLUMNS"]

#: Columns of the live trial table.
TRIAL_COLUMNS = ("#", "Target", "Mode", "Outcome", "TCT (s)", "RMSE (N)", "Max AE (N)")


def _num(v: Any, fmt: str = "{:.2f}") -> str:
    return "–" if v is None or (isinstance(v, float) and not math.isfinite(v)) else fmt.format(v)


@dataclass
class TrialTable:
    """Finished trials, filled live from :class:`study_app.messages.TrialEnded` records."""

    rows: list[TrialRecord] = field(default_factory=list)
    row_added: Emitter = field(default_factory=Emitter)
    cleared: Emitter = field(default_factory=Emitter)

    def add(self, row: TrialRecord) -> None:
        """Append a finished trial."""
        self.rows.append(row)
        self.row_added.emit(len(self.rows) - 1)

    def clear(self) -> None:
        """Forget all rows (a new session)."""
        self.rows.clear()
        self.cleared.emit()

    @staticmethod
    def cells(row: TrialRecord) -> tuple[str, ...]:
        """The displayed text of a row, in :data:`TRIAL_COLUMNS` order."""
        outcome = str(row.outcome)
        if row.abort_reason:
            outcome += f" ({row.abort_reason})"
        return (
            str(row.trial_index + 1),
            f"{row.target_label} {row.target_force_n:g} N",
            "haptics ON" if row.haptic_mode is HapticMode.ON else "haptics OFF",
            outcome,
            _num(row.tct_s),
            _num(row.rmse_n, "{:.3f}"),
            _num(row.max_ae_n, "{:.3f}"),
        )


@dataclass
class SessionModel:
    """Session state from engine events, and the progress line from the newest sample time.

    ``state`` ∈ {connecting, ready, running, paused, ended, stopped, failed}.
    """

    state: str = "connecting"
    message: str = "starting the engine …"
    session: m.SessionStarted | None = None
    trial: m.TrialStarted | None = None
    phase: str = "idle"
    pause_until_s: float | None = None
    paused_requested: bool = False
    completed: int = 0
    aborted: int = 0
    latest_t_s: float = 0.0
    #: The newest trial started, kept after it ends (the live axis keeps its target's scale between trials).
    last_trial: m.TrialStarted | None = None
    table: TrialTable = field(default_factory=TrialTable)
    changed: Emitter = field(default_factory=Emitter)

    # -- events -------------------------------------------------------------------------------------
    def apply(self, ev: object) -> None:
        """Update from one engine event."""
        if isinstance(ev, m.EngineReady):
            self.state, self.message = "ready", f"engine ready ({ev.rig} rig, {ev.clock} clock)"
        elif isinstance(ev, m.EngineOpening) and self.state == "connecting":
            self.message = f"starting the engine: opening the {ev.device} …"  # a device that hangs is named
        elif isinstance(ev, m.SessionStarted):
            self.session, self.trial, self.phase = ev, None, "idle"
            resumed = " (resumed)" if ev.stored_trials else ""
            self.state, self.message = "running", f"session {ev.session_id}: {ev.code} {ev.kind}{resumed}"
            self.completed = self.aborted = 0
            self.paused_requested = False
            self.pause_until_s = None
            self.table.clear()
            for row in ev.stored_trials:  # a resumed session: its table and progress as they were
                self._count(row)
        elif isinstance(ev, m.TrialStarted):
            self.trial, self.phase, self.pause_until_s = ev, "active", None
            self.last_trial = ev
            if self.session is not None:  # an aborted trial's re-run lengthens the schedule
                self.session = _with_total(self.session, ev.trials_total)
            self.latest_t_s = max(self.latest_t_s, ev.t_s)
        elif isinstance(ev, m.PhaseEntered):
            self.phase = ev.phase
            if ev.phase == "pause" and self.session is not None:
                self.pause_until_s = ev.t_s + self.session.pause_s
        elif isinstance(ev, m.TrialEnded):
            self._count(ev.record)
            if self.session is not None:
                self.session = _with_total(self.session, ev.trials_total)
        elif isinstance(ev, m.SessionEnded):
            self.state = "ended"
            self.message = f"session {ev.session_id} {ev.status}" + (f": {ev.reason}" if ev.reason else "")
            self.trial, self.phase = None, "idle"
        elif isinstance(ev, m.Health):
            if self.state in ("running", "paused") and ev.session_running:
                # the engine reports a pause from the moment it is asked for; it holds only once the trial ends
                holding = ev.paused and self.phase not in ("active", "cued")
                self.paused_requested = ev.paused and not holding
                self.state = "paused" if holding else "running"
        elif isinstance(ev, m.EngineStopped):
            self.state, self.message = "stopped", f"engine stopped: {ev.reason}"
        elif isinstance(ev, m.CommandRefused) and ev.command == "connect":
            self.state, self.message = "failed", ev.message
        else:
            return
        self.changed.emit()

    def reset(self, message: str) -> None:
        """A new engine is starting: no session, no trial, an empty table (the old engine's clock is gone)."""
        self.state, self.message = "connecting", message
        self.session = self.trial = self.last_trial = None
        self.phase, self.pause_until_s, self.paused_requested = "idle", None, False
        self.completed = self.aborted = 0
        self.latest_t_s = 0.0
        self.table.clear()
        self.changed.emit()

    def _count(self, row: TrialRecord) -> None:
        self.table.add(row)
        if row.outcome is Outcome.ABORTED:
            self.aborted += 1
        else:
            self.completed += 1

    def set_time(self, t_s: float) -> None:
        """The newest sample time from the ring (drives the countdowns)."""
        if t_s != self.latest_t_s:
            self.latest_t_s = t_s
            self.changed.emit()

    # -- what the progress line shows --------------------------------------------------------------------
    @property
    def running(self) -> bool:
        """A session is running (possibly paused)."""
        return self.state in ("running", "paused")

    def progress_text(self) -> str:
        """``trial k of N · time left`` or the pause countdown, or the state."""
        s = self.session
        if s is None or not self.running:
            return self.message
        done = self.completed + self.aborted
        if self.state == "paused":
            return f"paused after {done} of {s.trials_total} trials · Resume (Space) to continue"
        pending = " · pause requested: pausing after this trial" if self.paused_requested else ""
        if self.phase in ("active", "cued") and self.trial is not None:
            left = max(0.0, s.max_trial_s - (self.latest_t_s - self.trial.t_s))
            return (f"trial {self.trial.position} of {s.trials_total} · {self.trial.target_label} · "
                    f"haptics {self.trial.haptic_mode.upper()} · {left:4.1f} s left{pending}")
        if self.phase == "pause" and self.pause_until_s is not None:
            left = max(0.0, self.pause_until_s - self.latest_t_s)
            nxt = "pausing before the next trial" if pending else f"next trial in {left:3.1f} s"
            return f"{done} of {s.trials_total} trials done · {nxt}"
        return f"{done} of {s.trials_total} trials done{pending}"

    def fraction_done(self) -> float:
        """Share of the schedule finished (0–1); aborted trials count (their re-runs are in the schedule too)."""
        s = self.session
        if s is None or s.trials_total == 0:
            return 0.0
        return min(1.0, (self.completed + self.aborted) / s.trials_total)

    def band_for_axis(self) -> tuple[float, float] | None:
        """The band of the current trial, or of the last one between trials (the live axis keeps its scale)."""
        tr = self.last_trial
        if tr is None or self.session is None:
            return None
        f, tol = tr.target_force_n, self.session.tolerance_fraction
        return (f * (1 - tol), f * (1 + tol))

    def band_label(self) -> str:
        """The live plot's label of the band: ``GENTLE: target 0.6 N ± 10 % (0.54–0.66 N)`` ("" without a band)."""
        band = self.band()
        if band is None or self.trial is None or self.session is None:
            return ""
        tol_pct = round(100 * self.session.tolerance_fraction, 1)
        return (f"{self.trial.target_label}: target {self.trial.target_force_n:g} N ± {tol_pct:g} % "
                f"({band[0]:.3g}–{band[1]:.3g} N)")

    def band(self) -> tuple[float, float] | None:
        """The current target band (N) while a trial is active, else None."""
        if self.trial is None or self.session is None or self.phase != "active":
            return None
        f, tol = self.trial.target_force_n, self.session.tolerance_fraction
        return (f * (1 - tol), f * (1 + tol))


def _with_total(s: m.SessionStarted, total: int) -> m.SessionStarted:
    if total == s.trials_total:
        return s
    from dataclasses import replace

    return replace(s, trials_total=total)
