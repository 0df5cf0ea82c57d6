"""The metric registry (protocol.metrics): each metric defined once, and what every consumer reads of it.

The paper's primary family is exactly its four outcomes; the live trial machine and the offline recompute give every
metric the same value; a file from before a metric existed reads it as None and gets its column only from a writer.
"""

from __future__ import annotations

import hashlib
import math
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from protocol.metrics import METRICS, Role, exported_name, family_word, get, names, primary, select, split_unit, stored
from protocol.metrics import tested as which_tested  # (not `tested`: pytest would collect it)
from protocol.storage import StudyDatabase, StudyReader, trial_id_of
from protocol.study.clock import SessionClock
from protocol.study.config import TrialTiming
from protocol.study.design import TrialSpec
from protocol.study.records import Outcome, TrialRecord
from protocol.study.trial import TrialFinished, TrialMachine
from protocol.tasks.force_regulation import ForceRegulation, trial_metrics

MS = 1_000_000  # ns


PAPER = ForceRegulation().metrics  # the paper's study's metrics: its task's


def test_the_primary_family_is_the_papers_four_outcomes() -> None:
    # Holm's correction runs across exactly these: a metric or a task added later must not change the paper's numbers
    assert [m.participant for m in primary(PAPER)] == ["success_rate", "tct_s", "rmse_n", "max_ae_n"]
    assert family_word(PAPER) == "four"
    assert [m.name for m in which_tested(PAPER)][:4] == ["success", "tct_s", "rmse_n", "max_ae_n"]
    assert all(m.role is not Role.PRIMARY for m in which_tested(PAPER)[4:])
    # the registry holds every task's metrics; a study lists its tasks' (force tracking's lag and gain are not the
    # paper's), so the paper's study is the paper's four and its five others (the trade's phases last), in order
    assert [m.name for m in PAPER] == ["success", "tct_s", "rmse_n", "max_ae_n", "time_in_band_s", "peak_force_n",
                                       "abs_impulse_n_s", "rise_time_s", "reach_rmse_n"]
    assert {"lag_s", "gain"} <= set(names()) and not {"lag_s", "gain"} & set(names(PAPER))


def test_a_study_lists_its_tasks_metrics() -> None:
    from protocol.tasks.base import metrics_of
    from protocol.tasks.force_tracking import ForceTracking

    tracking = ForceTracking().metrics
    assert [m.name for m in tracking] == ["rmse_n", "max_ae_n", "time_in_band_s", "lag_s", "gain"]
    assert [m.name for m in primary(tracking)] == ["rmse_n", "max_ae_n"] and family_word(tracking) == "two"
    assert [m.name for m in which_tested(tracking)] == ["rmse_n", "max_ae_n", "lag_s", "gain"]
    # a study of both: the union, in the registry's order
    assert metrics_of([ForceTracking(), ForceRegulation()]) == METRICS


@pytest.mark.parametrize("metric", METRICS, ids=lambda m: m.name)
def test_each_metric_is_defined_whole(metric) -> None:
    stem, units = split_unit(metric.name)
    assert stem and metric.name == "_".join((stem, *units))
    # the unit is in the name: a newton's name ends in _n, a second's in _s (N·s: _n_s), a yes/no has none
    expected = {"": (), "s": ("s",), "N": ("n",), "N·s": ("n", "s")}
    assert units == expected[metric.unit], metric.name
    assert metric.label and metric.description and metric.better in ("higher", "lower", "one")
    assert metric.decimals >= 3 and metric.exported == exported_name(metric.name)
    assert get(metric.name) is metric and metric.name in names()
    assert not (metric.boolean and metric.stored)


def test_select_gives_a_tasks_metrics_in_the_registrys_order_and_refuses_an_unknown_one() -> None:
    assert [m.name for m in select(["rmse_n", "success"])] == ["success", "rmse_n"]
    with pytest.raises(KeyError, match="no metric 'rmse_N'"):
        get("rmse_N")
    with pytest.raises(KeyError, match="no metric nonesuch"):
        select(["nonesuch", "tct_s"])


def test_the_live_trial_machine_and_the_offline_recompute_give_every_metric_the_same_value() -> None:
    rng = np.random.default_rng(3)
    force = np.clip(np.linspace(0.0, 0.9, 12001) + rng.normal(0.0, 0.003, 12001), 0.0, None)  # a ramp through F*
    force[700] = math.nan  # a sample the sensor did not give: left out of the errors, out of band
    timing = TrialTiming(max_trial_s=12.0, pause_s=2.0)
    machine = TrialMachine(timing, ForceRegulation(tolerance_fraction=0.10, hold_s=1.0))
    spec = TrialSpec(index=0, target_label="GENTLE", target_force_n=0.6, haptic_mode="on")
    cue = 5_000 * MS
    machine.start(spec, cue - MS)
    done = [e for e in machine.feed((cue + k * MS, float(f), 0) for k, f in enumerate(force))
            if isinstance(e, TrialFinished)]
    assert len(done) == 1 and done[0].outcome is Outcome.SUCCESS
    n = done[0].metrics.n_samples
    offline = trial_metrics(np.arange(len(force)) * MS, force, 0.6)
    assert tuple(done[0].metrics.values) == names(PAPER) == tuple(offline.values)
    for name in names(PAPER):
        live, again = done[0].metrics[name], offline[name]
        assert (live is None and again is None) or live == again or (math.isnan(live) and math.isnan(again)), name
    assert n == offline.n_samples


def _one_trial(path: Path, index: int = 0) -> None:
    from test_storage import _session_args

    db = StudyDatabase(path)
    sid = db.create_session(**_session_args()) if index == 0 else 1
    spec = TrialSpec(index=index, target_label="GENTLE", target_force_n=0.6, haptic_mode="on")
    m = trial_metrics(np.arange(3001) * MS, np.full(3001, 0.6), 0.6)
    rec = TrialRecord.finished(session_id=sid, spec=spec, outcome=Outcome.SUCCESS, clock=SessionClock(1.0, 0),
                               cue_ns=0, end_ns=3000 * MS, metrics=m)
    db.insert_trial(rec.to_row())
    db.close()


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_a_file_from_before_a_metric_reads_it_as_none_and_only_a_writer_adds_its_column(tmp_path: Path) -> None:
    path = tmp_path / "study.db"
    _one_trial(path)
    later = stored(PAPER)[-1].name  # the paper's metric defined last: a file written before it had no column for it
    with sqlite3.connect(path) as c:
        c.execute(f"ALTER TABLE trials DROP COLUMN {later}")
    c.close()
    before = _sha(path)
    with StudyReader(path) as reader:  # reading (report, check, export) never alters the file
        (record,) = reader.trial_records()
    assert record.metric(later) is None and record.metric("rmse_n") == 0.0 and _sha(path) == before
    db = StudyDatabase(path)  # a writer: opening the file adds nothing (its columns are its sessions' tasks')
    db.close()
    with sqlite3.connect(path) as c:
        assert later not in [r[1] for r in c.execute("PRAGMA table_info(trials)")]
    c.close()
    _one_trial(path, 1)  # the session of the task writes a trial: the column is back, empty in the earlier row
    with sqlite3.connect(path) as c:
        columns = [r[1] for r in c.execute("PRAGMA table_info(trials)")]
        value = c.execute(f"SELECT {later}, rmse_n FROM trials WHERE trial_id = ?", (trial_id_of(1, 0),)).fetchone()
    c.close()
    assert columns[-1] == later and value == (None, 0.0)
    assert [m.name for m in stored(PAPER) if m.name not in columns] == []
    assert not {"lag_s", "gain"} & set(columns)  # another task's columns: not in a file of the paper's task
