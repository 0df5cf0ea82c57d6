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
from typing import Any

import numpy as np
import pandas as pd

from analysis.parallel import default_workers
from protocol.storage import connect_readonly

__all__ = ["format_report_bench", "run_report_bench", "synthetic_trials"]


def synthetic_trials(participants: int, seed: int = 0) -> pd.DataFrame:
    """A trial table (columns of :class:`analysis.metrics.TrialTable`) for many simulated participants.

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
    from analysis.aggregate import mode_tests, per_participant, speed_accuracy

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
        "methods": dict(zip(frame["metric"], frame["method"])),
        "rho_all": round(float(sa.set_index("haptic_mode").at["all", "rho"]), 4),
    }


def _make_study(db: str, participants: int) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "study_app.cli", "run", "--participants", str(participants),
                    "--seed", "0", "--db", db], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def run_report_bench(db: str | None = None, participants: int = 10, stats_participants: int = 10_000,
                     repeats: int = 3) -> dict[str, Any]:
    """Time the report CLI on a study database (simulated first when none is given) and the statistics at scale.

    Parameters
    ----------
    db
        An existing study database, or None to run a simulated study of ``participants`` first.
    participants
        Size of that simulated study.
    stats_participants
        Participants of the synthetic trial table for the statistics figure.
    repeats
        Report runs; the median is the figure (the first run also warms the page cache).
    """
    with tempfile.TemporaryDirectory() as tmp:
        made_s = None
        if db is None:
            db = os.path.join(tmp, "study.db")
            made_s = _make_study(db, participants)
        c = connect_readonly(db)
        try:
            samples = c.execute(
                "SELECT COALESCE(SUM(t.n_samples), 0), COUNT(*), COUNT(DISTINCT s.participant_id) FROM trials t "
                "JOIN sessions s USING (session_id) WHERE s.kind = 'experiment' AND t.outcome != 'aborted'"
            ).fetchone()
        finally:
            c.close()
        walls = []
        for k in range(repeats):
            out = os.path.join(tmp, f"report{k}")
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", "study_app.cli", "report", "--db", db, "--out", out],
                           check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            walls.append(time.perf_counter() - t0)
    stats = _stats_at_scale(stats_participants)
    return {
        "report_wall_s": round(float(np.median(walls)), 2),
        "report_runs_s": [round(w, 2) for w in walls],
        "participants": int(samples[2]),
        "trials": int(samples[1]),
        "samples": int(samples[0]),
        "study_simulated_in_s": None if made_s is None else round(made_s, 1),
        "workers": default_workers(),
        "stats_participants": stats["participants"],
        "stats_trials": stats["trials"],
        "stats_wall_s": stats["stats_wall_s"],
        "stats_methods": stats["methods"],
        "stats_rho_all": stats["rho_all"],
    }


def format_report_bench(r: dict[str, Any]) -> str:
    """Human-readable summary."""
    made = "" if r["study_simulated_in_s"] is None else f" (simulated first, in {r['study_simulated_in_s']:.0f} s)"
    return (
        f"haptic-study report, fresh process, {r['workers']} worker processes{made}:\n"
        f"  study                 {r['participants']} participants, {r['trials']} trials, {r['samples']:,} samples\n"
        f"  wall time             {r['report_wall_s']:.2f} s median of {len(r['report_runs_s'])} "
        f"({', '.join(f'{w:.2f}' for w in r['report_runs_s'])})\n"
        f"trial-level statistics, {r['stats_participants']:,} simulated participants ({r['stats_trials']:,} trials):\n"
        f"  wall time             {r['stats_wall_s']:.2f} s (aggregation, 12 Wilcoxon tests with Hodges–Lehmann CIs, "
        f"Holm, speed–accuracy)\n"
        f"  methods chosen        " + ", ".join(f"{k}: {v}" for k, v in r["stats_methods"].items())
    )
