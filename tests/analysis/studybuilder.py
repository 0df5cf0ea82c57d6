"""Small study databases with hand-made traces, for analysis tests.

Each trial's task force is piecewise constant at 1 kHz: ``(level_n, until_ms)``
segments after the cue.  The stored summary is computed by the live definition
(``protocol.tasks.force_regulation.trial_metrics``) exactly as the session runner stores it, so
analysis must reproduce it, and tests can compute every expectation by hand.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from protocol.metrics import stored
from protocol.storage import StudyDatabase, trial_id_of
from protocol.study.config import default_protocol
from protocol.tasks.force_regulation import trial_metrics

MS = 1_000_000


@dataclass
class TrialDef:
    """One trial: its target, mode, and force segments [(level_n, until_ms), …] (last one runs to the cap)."""

    label: str
    mode: str
    segments: list[tuple[float, int]]
    outcome_override: str | None = None  # "aborted" to store an aborted trial
    with_samples: bool = True
    repeat_of: int | None = None  # the trial index of the aborted trial this one re-runs


@dataclass
class SessionDef:
    code: str
    trials: list[TrialDef]
    kind: str = "experiment"
    status: str = "completed"
    max_trial_s: float = 12.0
    extra: dict = field(default_factory=dict)
    designed: int | None = None  # the schedule's length when the session stopped before its end (default: the trials)
    end_reason: str = "test"
    software_commit: str | None = None
    software_dirty: bool | None = None
    events: list[tuple[float, str, str]] = field(default_factory=list)  # (t_s, kind, detail)


TARGETS = {"GENTLE": 0.6, "FIRM": 1.2}


def trace(segments: list[tuple[float, int]], cap_ms: int) -> tuple[np.ndarray, np.ndarray]:
    """Times (ns) and forces of a piecewise-constant trace from 0 to cap_ms inclusive."""
    k = np.arange(cap_ms + 1, dtype=np.int64)
    f = np.empty(len(k))
    start = 0
    for level, until in segments:
        f[start:until] = level
        start = until
    f[start:] = segments[-1][0]
    return k * MS, f


def build(path: Path, sessions: list[SessionDef]) -> Path:
    """Write the sessions into a new study database at ``path``."""
    db = StudyDatabase(path)
    proto = default_protocol()
    for number, s in enumerate(sessions, start=1):
        pj = proto.to_dict()
        pj["trial"]["max_trial_s"] = s.max_trial_s
        n = s.designed or len(s.trials)
        planned = [s.trials[i % len(s.trials)] for i in range(n)]
        sid = db.create_session(
            code=s.code, kind=s.kind, seed=0, participant_number=number, protocol_json=json.dumps(pj),
            schedule_json=json.dumps([{"index": i, "target_label": t.label, "target_force_n": TARGETS[t.label],
                                       "haptic_mode": t.mode, "repeat_of": None} for i, t in enumerate(planned)]),
            software_version="test", rig="sim", config={}, calibration=None,
            software_commit=s.software_commit, software_dirty=s.software_dirty,
        )
        for t_s, kind, detail in s.events:
            db.insert_event(sid, t_s, kind, detail)
        cap_ms = round(s.max_trial_s * 1000)
        for idx, tdef in enumerate(s.trials):
            target = TARGETS[tdef.label]
            t_ns, f = trace(tdef.segments, cap_ms)
            m = trial_metrics(t_ns, f, target, max_trial_s=s.max_trial_s)
            end = m.n_samples
            tid = trial_id_of(sid, idx)
            # one transaction per trial, as the session runner commits a trial: in autocommit every sample row
            # would be a transaction of its own (most of the time of building a study)
            with db.transaction():
                if tdef.with_samples:
                    z = np.zeros(end)
                    rows = np.column_stack([np.full(end, float(tid)), t_ns[:end] / 1e9, f[:end],
                                            z, z, f[:end] + 6.4, z, z, z, z, z, f[:end], z, z, -f[:end] * 0.5])
                    db.insert_samples(rows.tolist())
                outcome = tdef.outcome_override or ("success" if m.success else "timeout")
                db.insert_trial({
                    "trial_id": tid, "session_id": sid, "trial_index": idx, "target_label": tdef.label,
                    "target_force_n": target, "haptic_mode": tdef.mode, "outcome": outcome,
                    "started_at_s": 20.0 * idx, "ended_at_s": 20.0 * idx + m.end_s,
                    # every stored metric of the task's, as the runner stores it (TCT only with a success)
                    **{x.name: None if x.success_only and outcome != "success" else m[x.name]
                       for x in stored(proto.task.metrics)},
                    "n_samples": m.n_samples,
                    "abort_reason": "test abort" if outcome == "aborted" else None, "repeat_of": tdef.repeat_of,
                })
        if s.status != "running":
            db.end_session(sid, s.status, s.end_reason)
    db.close()
    return path


def success_trial(label: str, mode: str, approach_ms: int) -> TrialDef:
    """0 N for approach_ms, then exactly on target: success at approach_ms + 1000 ms."""
    return TrialDef(label, mode, [(0.0, approach_ms), (TARGETS[label], 10**9)])


def timeout_trial(label: str, mode: str, level_n: float, approach_ms: int = 500) -> TrialDef:
    """0 N, then a constant level outside the band: a timeout."""
    return TrialDef(label, mode, [(0.0, approach_ms), (level_n, 10**9)])


def rmse_of_success(target_n: float, approach_ms: int) -> float:
    """RMSE of :func:`success_trial` over the cue window (0 … approach+1000 ms inclusive)."""
    n_approach = approach_ms
    n_total = approach_ms + 1000 + 1
    return math.sqrt(n_approach * target_n**2 / n_total)
