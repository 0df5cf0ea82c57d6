"""The one-screen summary printed after ``haptic-study run``.

Its per-mode mean ± SD across participants is the report's (:func:`analysis.stats.aggregate.per_participant`, then
:func:`analysis.stats.aggregate.mean_sd` across participants), computed from the metrics each trial stored live: its
rows are the study's metrics the report tests (its sessions' tasks', :func:`protocol.tasks.base.metrics_of`).
"""

from __future__ import annotations

import json
import math
from collections import Counter
from typing import Any

import pandas as pd

from analysis.reading.metrics import MetricOptions
from analysis.stats.aggregate import by_mode, mean_sd, per_participant
from pipeline.force.pipeline_settings import describe, non_default_settings, stored_settings
from protocol.metrics import Metric, tested
from protocol.storage import StudyReader
from protocol.storage.database import part_key
from protocol.study.labels import plural
from protocol.study.records import Outcome, TrialRecord
from protocol.tasks.base import metrics_of
from protocol.tasks.registry import DEFAULT_KIND, stored_task

__all__ = ["format_study_summary"]

#: The paper's results (Sec. V-B), for the comparison column: OFF → ON means, or the change it quotes (TCT).
PAPER: dict[str, tuple[float, float] | str] = {"success": (0.27, 0.54), "tct_s": "−16 %", "rmse_n": (1.35, 0.86),
                                               "max_ae_n": (2.12, 1.46)}

def _value(v: float | None) -> float:
    return math.nan if v is None else float(v)


def _trials_frame(exp: list[tuple[str, TrialRecord]], metrics: tuple[Metric, ...]) -> pd.DataFrame:
    """The analysed trials as :func:`analysis.stats.aggregate.per_participant` takes them, with their stored metrics."""
    ok = [t.outcome is Outcome.SUCCESS for _, t in exp]
    return pd.DataFrame({
        "participant_code": [c for c, _ in exp], "haptic_mode": [t.haptic_mode.value for _, t in exp],
        "target_label": [t.target_label for _, t in exp],
        # every metric as stored; a success-only one (TCT) only where the trial succeeded
        **{m.name: ok if m.boolean else [_value(t.metric(m.name)) if s or not m.success_only else math.nan
                                         for (_, t), s in zip(exp, ok, strict=True)] for m in metrics},
    })


def _across(per_part: pd.DataFrame | None, metric: str, mode: str) -> tuple[float, float]:
    """Mean and SD across participants of their per-mode means (SD NaN for one participant: no spread)."""
    if per_part is None or per_part.empty:
        return math.nan, math.nan
    mean, sd, n = mean_sd(by_mode(per_part, metric)[mode])
    return mean, sd if n > 1 else math.nan


def _cell(v: tuple[float, float]) -> str:
    if not math.isfinite(v[0]):
        return "–"
    return f"{v[0]:.3f}" + (f" ± {v[1]:.3f}" if math.isfinite(v[1]) else "")


def _settings_line(config_jsons: list[str]) -> str:
    """The pipeline settings the sessions ran with (``run --set``), as far as they are not the paper's."""
    found = set()
    for cj in config_jsons:
        try:
            record = json.loads(cj or "{}").get("framework")
        except (ValueError, TypeError, AttributeError):
            record = None
        found.add(describe(non_default_settings(stored_settings(record))))
    return "Pipeline settings: " + " / ".join(sorted(found or {"the paper's"})) + (
        "" if found <= {"the paper's"} else " (the paper's for the others)")


def _mode_table(exp: list[tuple[str, TrialRecord]], sessions: list[Any], codes: list[str]) -> list[str]:
    """The rows of the per-mode table over the trials ``exp`` of ``sessions`` (whose tasks give the metrics)."""
    lines: list[str] = []
    tasks = [stored_task(json.loads(info.protocol_json), f"session {info.session_id}") for info in sessions]
    metrics = metrics_of(tasks)
    papers = all(t.kind == DEFAULT_KIND for t in tasks)  # the paper's numbers compare with the paper's task only
    frame = _trials_frame(exp, metrics) if exp else None
    # TCT as this summary labels it, over successful trials (the report's default counts a failure at the cap)
    successful = MetricOptions(tct_policy="successful")
    overall = None if frame is None else per_participant(frame, successful)
    for m in tested(metrics):  # the rows: the study's metrics the report tests, in order
        off, on = _across(overall, m.participant, "off"), _across(overall, m.participant, "on")
        finite = bool(off[0]) and math.isfinite(off[0]) and math.isfinite(on[0])
        change = (on[0] - off[0]) / off[0] * 100 if finite else math.nan
        quoted = PAPER.get(m.name, "") if papers else ""  # a metric or task the paper did not report: no comparison
        paper = quoted if isinstance(quoted, str) else f"{quoted[0]:g} → {quoted[1]:g}"
        name = m.summary_label
        change_txt = f"{change:>8.0f}%" if math.isfinite(change) else f"{'–':>9}"  # no change from nothing
        lines.append(f"  {name:<30}{_cell(off):>16}{_cell(on):>16}{change_txt}   {paper}")
    # TCT's mean is over fewer people where some never succeeded (a study of a task with a TCT)
    if overall is not None and not overall.empty and "tct_s" in overall.columns:
        tct = by_mode(overall, "tct_s")
        n_off, n_on = (int(tct[mode].notna().sum()) if mode in tct else 0 for mode in ("off", "on"))
        if min(n_off, n_on) < len(codes):
            lines.append(f"  (TCT: over {n_off} (OFF) / {n_on} (ON) of {plural(len(codes), 'participant')}: one "
                         "with no success in a mode has no TCT there)")
    targets = None if frame is None else per_participant(frame, successful, by_target=True)
    rates = overall is not None and "success_rate" in overall.columns  # (a task with a success rule)
    for label in sorted({t.target_label for _, t in exp}) if rates else ():
        part = None if targets is None else targets[targets["target_label"] == label]
        off, on = _across(part, "success_rate", "off"), _across(part, "success_rate", "on")
        lines.append(f"  {'success, ' + label:<30}{_cell(off):>16}{_cell(on):>16}")
    return lines


def format_study_summary(db_path: str, session_ids: list[int], wall_s: float) -> str:
    """Per-mode mean ± SD across participants, each participant's trials averaged first (as ``report`` does)."""
    with StudyReader(db_path, check=False) as reader:  # the run just wrote it
        sessions = {s.session_id: s for s in reader.sessions()}
        records = reader.trial_records(session_ids)
        n_samples = reader.sample_count(session_ids)
        recorded = reader.record_count(session_ids)
        other_arms = reader.arms()
    experiment = [t for t in records if sessions[t.session_id].kind == "experiment"]
    exp = [(sessions[t.session_id].code, t) for t in experiment if t.outcome is not Outcome.ABORTED]
    causes = Counter("cause not recorded" if t.abort_cause is None else t.abort_cause.value
                     for t in experiment if t.outcome is Outcome.ABORTED)
    aborted = sum(causes.values())
    why = (": " + ", ".join(f"{n} {c}" for c, n in sorted(causes.items()))) if causes else ""
    training = sum(1 for t in records if sessions[t.session_id].kind == "training")
    codes = sorted({c for c, _ in exp})
    # after a --resume or --continue the command ran only some of the study's sessions: say whose figures these are
    scope = "" if set(session_ids) >= set(sessions) else (
        f" (the {plural(len(set(session_ids)), 'session')} this command ran, of {len(sessions)} stored; "
        "haptic-study report analyses them all)")
    lines = [
        f"Study database {db_path}{scope}: {plural(len(codes), 'participant')}, {plural(len(exp), 'experiment trial')} "
        f"({aborted} aborted and re-run{why}; {plural(training, 'training trial')} excluded), "
        + (f"{recorded:,} records (whole sessions at 1 kHz)" if recorded else f"{n_samples:,} samples"),
        _settings_line([sessions[i].config_json for i in session_ids if i in sessions]),
        "",
        "mean ± SD across participants (each participant's trials averaged first; the report's headline figures)",
        f"{'':<32}{'haptics OFF':>16}{'haptics ON':>16}{'change':>9}   paper OFF → ON (means)",
    ]
    parts = sorted({(part_key(info.protocol_json), info.session_id) for info in sessions.values() if info.part},
                   key=lambda p: p[1])
    if not parts:  # a study of one task: one table
        lines.extend(_mode_table(exp, list(sessions.values()), codes))
    for name in dict.fromkeys(p for p, _ in parts):  # several parts: a table per experiment part (VISIT-PART)
        of_part = [info for info in sessions.values() if part_key(info.protocol_json) == name]
        if all(info.kind != "experiment" for info in of_part):
            continue
        ids = {info.session_id for info in of_part}
        lines.append(f"  part {name!r}:")
        table = _mode_table([(c, t) for c, t in exp if t.session_id in ids], of_part, codes)
        lines.extend(table or ["  (no measure compared between the modes: haptic-study report gives its results)"])
    lines.append("")
    where = "recordings, session_blocks" if recorded else "samples"
    if other_arms:  # a rig of several arms: the others' records beside the task arm's
        where += f", arm_recordings, arm_blocks ({', '.join(other_arms)})"
    lines.append(f"Wall time {wall_s:.1f} s. Every trial, record and event is in the database (tables trials, {where}, "
                 "events).")
    return "\n".join(lines)

