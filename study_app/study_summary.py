"""The one-screen summary printed after ``haptic-study run``."""

from __future__ import annotations

import math
from collections import Counter, defaultdict
from statistics import fmean, stdev

from protocol.storage import StudyReader

__all__ = ["format_study_summary"]

#: The paper's results (Sec. V-B), for the comparison column.
PAPER = {"success": (0.27, 0.54), "rmse_n": (1.35, 0.86), "max_ae_n": (2.12, 1.46)}


def _mean(xs: list[float]) -> float:
    xs = [x for x in xs if x is not None and math.isfinite(x)]
    return fmean(xs) if xs else math.nan


def _mean_sd(xs: list[float]) -> tuple[float, float]:
    xs = [x for x in xs if x is not None and math.isfinite(x)]
    if not xs:
        return math.nan, math.nan
    return fmean(xs), stdev(xs) if len(xs) > 1 else math.nan  # one participant has no spread


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def format_study_summary(db_path: str, session_ids: list[int], wall_s: float) -> str:
    """Per-mode mean ± SD across participants, each participant's trials averaged first (as ``report`` does)."""
    with StudyReader(db_path, check=False) as reader:  # the run just wrote it
        sessions = {s.session_id: s for s in reader.sessions()}
        records = reader.trial_records(session_ids)
        n_samples = reader.sample_count(session_ids)
        recorded = reader.record_count(session_ids)
    # (code, mode, target, outcome, tct, rmse, max ae, session kind, abort cause)
    rows = [(sessions[t.session_id].code, t.haptic_mode.value, t.target_label, t.outcome.value, t.tct_s, t.rmse_n,
             t.max_ae_n, sessions[t.session_id].kind, None if t.abort_cause is None else t.abort_cause.value)
            for t in records]
    exp = [r for r in rows if r[7] == "experiment" and r[3] != "aborted"]
    causes = Counter(r[8] or "cause not recorded" for r in rows if r[7] == "experiment" and r[3] == "aborted")
    aborted = sum(causes.values())
    why = (": " + ", ".join(f"{n} {c}" for c, n in sorted(causes.items()))) if causes else ""
    training = sum(1 for r in rows if r[7] == "training")
    per: dict[tuple[str, str], list[tuple]] = defaultdict(list)
    for r in exp:
        per[(r[0], r[1])].append(r)
    codes = sorted({r[0] for r in exp})
    lines = [
        f"Study database {db_path}: {_plural(len(codes), 'participant')}, {_plural(len(exp), 'experiment trial')} "
        f"({aborted} aborted and re-run{why}; {_plural(training, 'training trial')} excluded), "
        + (f"{recorded:,} records (whole sessions at 1 kHz)" if recorded else f"{n_samples:,} samples"),
        "",
        "mean ± SD across participants (each participant's trials averaged first; the report's headline figures)",
        f"{'':<32}{'haptics OFF':>16}{'haptics ON':>16}{'change':>9}   paper OFF → ON (means)",
    ]

    def metric(mode: str, fn) -> tuple[float, float]:  # type: ignore[no-untyped-def]
        return _mean_sd([fn(per[(c, mode)]) for c in codes if per[(c, mode)]])

    def cell(v: tuple[float, float]) -> str:
        if not math.isfinite(v[0]):
            return "–"
        return f"{v[0]:.3f}" + (f" ± {v[1]:.3f}" if math.isfinite(v[1]) else "")

    defs = [
        ("success rate", "success", lambda ts: sum(t[3] == "success" for t in ts) / len(ts)),
        ("TCT, successful trials (s)", None, lambda ts: _mean([t[4] for t in ts if t[3] == "success"])),
        ("RMSE (N)", "rmse_n", lambda ts: _mean([t[5] for t in ts])),
        ("Max AE (N)", "max_ae_n", lambda ts: _mean([t[6] for t in ts])),
    ]
    for name, key, fn in defs:
        off, on = metric("off", fn), metric("on", fn)
        finite = bool(off[0]) and math.isfinite(off[0]) and math.isfinite(on[0])
        change = (on[0] - off[0]) / off[0] * 100 if finite else math.nan
        paper = f"{PAPER[key][0]:g} → {PAPER[key][1]:g}" if key else "−16 %"
        change_txt = f"{change:>8.0f}%" if math.isfinite(change) else f"{'–':>9}"  # no change from nothing
        lines.append(f"  {name:<30}{cell(off):>16}{cell(on):>16}{change_txt}   {paper}")
    for label in sorted({r[2] for r in exp}):
        off = metric("off", lambda ts, lab=label: _mean([float(t[3] == 'success') for t in ts if t[2] == lab]))
        on = metric("on", lambda ts, lab=label: _mean([float(t[3] == 'success') for t in ts if t[2] == lab]))
        lines.append(f"  {'success, ' + label:<30}{cell(off):>16}{cell(on):>16}")
    lines.append("")
    where = "recordings, session_blocks" if recorded else "samples"
    lines.append(f"Wall time {wall_s:.1f} s. Every trial, record and event is in the database (tables trials, {where}, "
                 "events).")
    return "\n".join(lines)
