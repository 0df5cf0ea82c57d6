"""``haptic-study bench study``: wall time of a complete simulated study on the virtual clock."""

from __future__ import annotations

import os
import sqlite3
import tempfile
import time
from typing import Any

from protocol.config import load_protocol
from protocol.study import default_jobs, run_study

__all__ = ["run_study_bench", "format_study_bench"]


def run_study_bench(participants: int = 10, seed: int = 0, protocol_path: str | None = None) -> dict[str, Any]:
    """Run the study into a temporary database and measure it (participants in parallel, as ``run`` does by default)."""
    protocol = load_protocol(protocol_path)
    with tempfile.TemporaryDirectory() as tmp:
        db = os.path.join(tmp, "bench.db")
        t0 = time.perf_counter()
        progress = run_study(db, participants=participants, seed=seed, protocol=protocol)
        wall = time.perf_counter() - t0
        c = sqlite3.connect(db)
        try:
            trials = c.execute("SELECT COUNT(*) FROM trials t JOIN sessions s USING (session_id) WHERE s.kind = 'experiment'").fetchone()[0]
            samples = c.execute("SELECT COUNT(*) FROM samples").fetchone()[0]
        finally:
            c.close()
        size = sum(os.path.getsize(os.path.join(tmp, f)) for f in os.listdir(tmp))
    ticks = progress.study_time_s * 1000.0
    return {
        "participants": participants,
        "jobs": default_jobs(participants),
        "wall_s": round(wall, 2),
        "study_time_min": round(progress.study_time_s / 60.0, 2),
        "speed_x_real_time": round(progress.study_time_s / wall, 1),
        "us_per_tick": round(wall / ticks * 1e6, 2) if ticks else None,
        "experiment_trials": trials,
        "samples_stored": samples,
        "database_mb": round(size / 1e6, 1),
    }


def format_study_bench(r: dict[str, Any]) -> str:
    """Human-readable summary."""
    return (
        f"{r['participants']} simulated participants (training + experiment), virtual clock, "
        f"{r['jobs']} worker process{'es' if r['jobs'] != 1 else ''}:\n"
        f"  wall time             {r['wall_s']:.1f} s\n"
        f"  study time            {r['study_time_min']:.1f} min ({r['speed_x_real_time']:.0f}x real time)\n"
        f"  wall time per tick    {r['us_per_tick']:.1f} µs (all workers together; rig + pipeline + participant + runner + storage)\n"
        f"  stored                {r['experiment_trials']} experiment trials, {r['samples_stored']:,} samples, "
        f"{r['database_mb']:.0f} MB"
    )
