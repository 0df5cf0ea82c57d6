"""Reading what a study recorded, for the tests: a trial's samples (either store), all records, their order."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.reading.load import AnalysisError
from analysis.reading.recorded import read_trial_samples
from protocol.storage.recordings import read_segment, segments_of


def trial_samples(db: Path, trial_id: int) -> pd.DataFrame:
    """A trial's samples (``t_s`` since its cue, ``force_n``, raw and rendered force); empty when it has none."""
    try:
        return read_trial_samples(db, trial_id // 1_000_000, trial_id % 1_000_000)
    except AnalysisError:
        return pd.DataFrame({"t_s": [], "force_n": []})


def all_records(db: Path) -> dict[tuple[int, int], dict[str, np.ndarray]]:
    """Every recorded segment's columns: (session, segment) -> columns."""
    c = sqlite3.connect(db)
    try:
        sessions = [r[0] for r in c.execute("SELECT session_id FROM sessions ORDER BY session_id")]
        return {(sid, seg): read_segment(c, sid, seg).columns for sid in sessions for seg, _, _ in segments_of(c, sid)}
    finally:
        c.close()


def assert_records_unique_and_ordered(db: Path) -> None:
    """Within every segment, ticks and loop times strictly increase: no record twice, none out of order."""
    for key, cols in all_records(db).items():
        assert np.all(np.diff(cols["tick"]) > 0), f"segment {key}: ticks not strictly increasing"
        assert np.all(np.diff(cols["t_ns"]) > 0), f"segment {key}: times not strictly increasing"
