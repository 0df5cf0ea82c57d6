"""Trial records as the engine hands them to the GUI (:class:`study_app.engine.messages.TrialEnded`), for the GUI
tests."""

from __future__ import annotations

from typing import Any

from protocol.metrics import names
from protocol.study.clock import SessionClock
from protocol.study.records import TrialRecord


def trial_record(**fields: Any) -> TrialRecord:
    """A finished trial with the fields a test names (a metric by its name: ``rmse_n=0.2``); the rest a successful
    FIRM haptics-ON trial of session 1."""
    base: dict[str, Any] = dict(session_id=1, trial_index=0, target_label="FIRM", target_force_n=1.2, haptic_mode="on",
                                outcome="success", clock=SessionClock(0.0, 0), cue_ns=0, end_ns=0)
    metrics = {k: fields.pop(k) for k in list(fields) if k in names()}
    return TrialRecord(**{**base, **fields, "metrics": metrics})
