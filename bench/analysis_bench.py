"""``haptic-study bench report``: the full report of a study, and trial-level statistics at scale.

Two figures the analysis issue asks for:

* the whole ``haptic-study report`` of a 10-participant study (about 2 M
  samples), timed as a researcher runs it: a fresh process, imports included;
* trial-level statistics (per-participant aggregation, the ON-vs-OFF tests
  overall and per target, the speed–accuracy correlation, Holm) for 10 000
  simulated participants.  Running 10 000 participants through the rig would
  take hours, so their trial table is drawn from a simple generative model
  with the simulated study's magnitudes (per-participant skill, haptics
  doubling success, TCT on a 1 ms grid so ties occur as in real data).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pandas as pd

from bench.source_trees import check_tree, source_env
from foundation.parallel import default_workers
from protocol.storage import connect_readonly

__all__ = ["format_report_bench", "run_report_bench", "synthetic_trials"]


def synthetic_trials(participants: int, seed: int = 0) -> pd.DataFrame:
    """A trial table (columns of :class:`analysis.reading.metrics.TrialTable`) for many simulated participants.

    Parameters
    ----------
    participants
        Number of participants; each has 5 trials per target × mode (20).
    seed
        Random seed.
    """
    rng = np.random.default_rng(seed)
    n = participants * 20
    pid = np.repeat(np.arange(participants), 20)
    cell = np.tile(np.repeat(np.arange(4), 5), participants)  # (target, mode) cells, 5 trials each
    target = np.where(cell % 2 == 0, 0.6, 1.2)
    mode = np.where(cell < 2, "off", "on")
    skill = rng.normal(0.0, 0.5, participants)[pid]
    p_success = 1.0 / (1.0 + np.exp(-(skill + np.where(mode == "on", 0.2, -1.2))))
    success = rng.random(n) < p_success
    tct = np.round(rng.uniform(1.5, 11.5, n) - 0.6 * (mode == "on"), 3)  # ms grid: ties
    rmse = np.exp(rng.normal(np.log(np.where(mode == "on", 0.59, 0.72)), 0.35, n)) * (1 + 0.3 * (target > 1))
    return pd.DataFrame(
        {
            "participant_code": np.char.add("S", pid.astype(str)),
            "session_id": pid + 1,
            "trial_index": np.tile(np.arange(20), participants),
            "target_label": np.where(target < 1, "GENTLE", "FIRM"),
            "target_force_n": target,
            "haptic_mode": mode,
            "outcome": np.where(success, "success", "timeout"),
            "success": success,
            "tct_s": np.where(success, tct, np.nan),
            "rmse_n": rmse,
            "max_ae_n": rmse * rng.uniform(2.0, 3.0, n),
            "time_in_band_s": rng.uniform(0, 3, n),
            "peak_force_n": target * rng.uniform(1.0, 3.0, n),
            "first_contact_s": rng.uniform(0.3, 2.0, n),
            "tct_censored_s": np.where(success, tct, 12.0),
            "database": "synthetic",
        }
    )


def _stats_at_scale(participants: int) -> dict[str, Any]:
    from analysis.stats.aggregate import mode_tests, per_participant
    from analysis.stats.trade import speed_accuracy

    trials = synthetic_trials(participants)
    t0 = time.perf_counter()
    overall = per_participant(trials)
    by_target = per_participant(trials, by_target=True)
    _, frame = mode_tests(overall)
    for label in ("GENTLE", "FIRM"):
        mode_tests(by_target[by_target["target_label"] == label])
    sa = speed_accuracy(trials)
    wall = time.perf_counter() - t0
    return {
        "participants": participants,
        "trials": len(trials),
        "stats_wall_s": round(wall, 3),
        "methods": dict(zip(frame["metric"], frame["method"], strict=True)),
        "r_rm_all": round(float(sa.set_index("haptic_mode").at["all", "r_rm"]), 4),
    }


def _make_study(db: str, participants: int) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "study_app.cli", "run", "--participants", str(participants),
                    "--seed", "0", "--db", db], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def _read_all_samples(db: str) -> tuple[float, int]:
    """Read every analysed trial's task force as the report does, in this process: (seconds, samples)."""
    from analysis.reading.load import load_study, recorded_where
    from analysis.reading.recorded import read_task_force

    inc = load_study([db]).included
    t0 = time.perf_counter()
    conn = connect_readonly(db)
    n = 0
    try:
        for tid, sid, seg, first, last in zip(inc["trial_id"], inc["session_id"], inc["segment"], inc["first_tick"],
                                              inc["last_tick"], strict=True):
            n += len(read_task_force(conn, int(tid), recorded_where(sid, seg, first, last))[0])
    finally:
        conn.close()
    return time.perf_counter() - t0, n


def _report_wall(db: str, out: str, source: str | None = None) -> float:
    """One ``haptic-study report`` in a fresh process: ours, or the source tree ``source``'s (its code first on
    the import path, this interpreter and its installed libraries).  It runs in the output's folder: ``python -m``
    puts the working directory before PYTHONPATH, so run from our checkout the "reference" would be our code."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "study_app.cli", "report", "--db", os.path.abspath(db), "--out", out],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=source_env(source),
                   cwd=os.path.dirname(os.path.abspath(out)))
    return time.perf_counter() - t0


def _report_walls(db: str, tmp: str, tag: str, repeats: int) -> list[float]:
    return [_report_wall(db, os.path.join(tmp, f"report-{tag}{k}")) for k in range(repeats)]


def _reference_walls(db: str, tmp: str, source: str, repeats: int) -> tuple[list[float], list[float]]:
    """Our report and the reference tree's on the same database, run in turn (ours, theirs, ours, …) so a busy
    spell of the machine falls on both alike: (ours, theirs)."""
    check_tree(source, tmp, "--reference")
    ours, theirs = [], []
    for k in range(repeats):
        ours.append(_report_wall(db, os.path.join(tmp, f"report-ours{k}")))
        theirs.append(_report_wall(db, os.path.join(tmp, f"report-ref{k}"), source))
    return ours, theirs


def _study_facts(db: str) -> tuple[tuple[int, int, int], bool]:
    """(samples, trials, participants) of the analysed experiment trials, and whether the study is recorded
    (schema version 3's blocks) rather than in rows."""
    c = connect_readonly(db)
    try:
        samples = c.execute(
            "SELECT COALESCE(SUM(t.n_samples), 0), COUNT(*), COUNT(DISTINCT s.participant_id) FROM trials t "
            "JOIN sessions s USING (session_id) WHERE s.kind = 'experiment' AND t.outcome != 'aborted'"
        ).fetchone()
        recorded = c.execute("PRAGMA user_version").fetchone()[0] >= 3 and \
            c.execute("SELECT COUNT(*) FROM recordings").fetchone()[0] > 0
    finally:
        c.close()
    return samples, bool(recorded)


def run_report_bench(db: str | None = None, participants: int = 10, stats_participants: int = 10_000,
                     repeats: int = 3, log: Callable[[str], None] | None = None,
                     reference: str | None = None) -> dict[str, Any]:
    """Time the report CLI on a study database (simulated first when none is given) and the statistics at scale.

    Side by side in the same run: the same study in the row format of versions 1 and 2
    (:func:`bench.row_format.row_format_copy`), read by the same code.

    Parameters
    ----------
    db
        An existing recorded study database, or None to run a simulated study of ``participants`` first.
    participants
        Size of that simulated study.
    stats_participants
        Participants of the synthetic trial table for the statistics figure.
    repeats
        Runs of each timing; the median is the figure (the first run also warms the page cache).
    log
        Called with a line before each long step.
    reference
        A source tree of another version (e.g. a worktree of main): its ``report`` is timed in turn with ours
        on the same database, in the same run.
    """
    from bench.row_format import row_format_copy

    say = log or (lambda _: None)
    with tempfile.TemporaryDirectory() as tmp:
        made_s = None
        if db is None:
            say(f"simulating a {participants}-participant study ...")
            db = os.path.join(tmp, "study.db")
            made_s = _make_study(db, participants)
        samples, recorded = _study_facts(db)
        rows_db = None
        if recorded:
            say("writing the same study in the row format of versions 1 and 2 (replaying every session) ...")
            rows_db = row_format_copy(db, os.path.join(tmp, "rows.db"))
        say("timing the sample reading and the report ...")
        formats = {"recording": db, **({"rows": rows_db.path} if rows_db is not None else {})}
        reading = {k: [_read_all_samples(p)[0] for _ in range(repeats)] for k, p in formats.items()}
        walls = {k: _report_walls(p, tmp, k, repeats) for k, p in formats.items()}
        ref = None
        if reference is not None:
            say(f"timing our report and {reference}'s in turn ...")
            ref = _reference_walls(db, tmp, reference, repeats)
        sizes = {k: sum(os.path.getsize(f) for f in (p, p + "-wal") if os.path.exists(f)) for k, p in formats.items()}
    say("timing the statistics at scale ...")
    stats = _stats_at_scale(stats_participants)
    med = {k: round(float(np.median(v)), 3) for k, v in walls.items()}
    read = {k: round(float(np.median(v)), 3) for k, v in reading.items()}
    return {
        "report_wall_s": med["recording"],
        "report_runs_s": [round(w, 2) for w in walls["recording"]],
        "formats": {k: {"report_wall_s": med[k], "read_samples_s": read[k], "database_mb": round(sizes[k] / 1e6, 1)}
                    for k in formats},
        "report_speedup": round(med["rows"] / med["recording"], 2) if "rows" in med else None,
        "read_speedup": round(read["rows"] / read["recording"], 2) if "rows" in read else None,
        "participants": int(samples[2]),
        "trials": int(samples[1]),
        "samples": int(samples[0]),
        "study_simulated_in_s": None if made_s is None else round(made_s, 1),
        "workers": default_workers(),
        "stats_participants": stats["participants"],
        "stats_trials": stats["trials"],
        "stats_wall_s": stats["stats_wall_s"],
        "stats_methods": stats["methods"],
        "stats_r_rm_all": stats["r_rm_all"],
        "reference": None if ref is None else _reference_result(reference, *ref),
    }


def _reference_result(source: str | None, ours: list[float], theirs: list[float]) -> dict[str, Any]:
    """Our report's and the reference's runs, medians and their ratio."""
    return {"source": source, "ours_runs_s": [round(w, 2) for w in ours],
            "reference_runs_s": [round(w, 2) for w in theirs], "ours_s": round(float(np.median(ours)), 3),
            "reference_s": round(float(np.median(theirs)), 3),
            "ratio": round(float(np.median(ours) / np.median(theirs)), 2)}


def format_report_bench(r: dict[str, Any]) -> str:
    """Human-readable summary."""
    made = "" if r["study_simulated_in_s"] is None else f" (simulated first, in {r['study_simulated_in_s']:.0f} s)"
    lines = [
        f"haptic-study report, fresh process, {r['workers']} worker processes{made}:",
        f"  study                 {r['participants']} participants, {r['trials']} trials, {r['samples']:,} samples",
        (f"  wall time             {r['report_wall_s']:.2f} s median of {len(r['report_runs_s'])} "
         f"({', '.join(f'{w:.2f}' for w in r['report_runs_s'])})"),
    ]
    f = r["formats"]
    if "rows" in f:
        names = {"recording": "whole sessions, blocks (v3)", "rows": "trial windows, rows (v1/v2)"}
        lines += [
            "the same study in both formats, same code, same run (medians):",
            f"  {'format':30s} {'database':>10s} {'read every trial':>17s} {'report':>8s}",
            *(f"  {names[k]:30s} {v['database_mb']:8.1f} MB {v['read_samples_s']:15.2f} s {v['report_wall_s']:6.2f} s"
              for k, v in f.items()),
            (f"  the recording reads the samples {r['read_speedup']:.1f}x faster; the whole report runs "
             f"{r['report_speedup']:.1f}x faster (figures and statistics cost the same in both)"),
        ]
    ref = r.get("reference")
    if ref:
        lines += [
            f"against the reference {ref['source']}, same database, run in turn (medians):",
            f"  ours        {ref['ours_s']:6.2f} s ({', '.join(f'{w:.2f}' for w in ref['ours_runs_s'])})",
            f"  reference   {ref['reference_s']:6.2f} s ({', '.join(f'{w:.2f}' for w in ref['reference_runs_s'])})",
            f"  ours / reference {ref['ratio']:.2f}",
        ]
    lines += [
        f"trial-level statistics, {r['stats_participants']:,} simulated participants ({r['stats_trials']:,} trials):",
        (f"  wall time             {r['stats_wall_s']:.2f} s (aggregation, 12 Wilcoxon tests with Hodges–Lehmann CIs, "
         f"Holm, speed–accuracy within participants)"),
        "  methods chosen        " + ", ".join(f"{k}: {v}" for k, v in r["stats_methods"].items()),
    ]
    return "\n".join(lines)
