"""What keeps the GUI thread short: bounded per-tick work, incremental tables, still axes, and the stall detector's
attribution."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from gui_trials import trial_record

from pipeline.core.tick_record import TICK_DTYPE
from pipeline.runtime.loop_messages import RECORD_FIELDS
from pipeline.runtime.ring import RingBuffer
from study_app.gui.session_views import QtTrialTable
from study_app.gui.stall import Stall, StallRecorder, culprit
from study_app.models.plots import PlotModel, nice_range
from study_app.models.session import TrialTable

_T = RECORD_FIELDS.index("t_s")
_RAW_FZ = RECORD_FIELDS.index("raw_fz")


def _zero_row() -> list[float]:
    return [0 if TICK_DTYPE[f] == np.int64 else 0.0 for f in RECORD_FIELDS]


def _ring_with(n: int, capacity: int = 30_000) -> RingBuffer:
    ring = RingBuffer.create(TICK_DTYPE, capacity, shared=False)
    row = _zero_row()
    for i in range(n):
        row[_T] = i * 1e-3
        row[_RAW_FZ] = 0.5
        ring.write(row)
    return ring


def test_a_pull_far_behind_reads_at_most_one_window():
    ring = _ring_with(25_000)
    plots = PlotModel(window_s=10.0)  # capacity 10 000 records
    plots.ring, plots.cursor = ring, 0  # as if the GUI had stalled since the first record
    assert plots.pull() == 10_000
    assert len(plots.new_rows) == 10_000 and plots.skipped == 15_000 and plots.lost == 0
    assert plots.cursor == 25_000
    # sample times are ticks × 1 ms: up to that product's rounding
    assert float(plots.new_rows["t_s"][0]) == pytest.approx(15.0, abs=1e-9)
    assert plots.latest_t_s == pytest.approx(24.999, abs=1e-9)
    assert len(plots.t) == 10_000
    # caught up: the next pull copies only what is new
    row = _zero_row()
    row[_T] = 25.0
    ring.write(row)
    assert plots.pull() == 1 and plots.skipped == 15_000


def test_axis_range_snaps_so_the_axes_stay_still():
    assert nice_range(0.0, 1.31, floor_zero=True) == (0.0, 1.5)
    assert nice_range(0.0, 0.2, floor_zero=True) == (0.0, 1.0)  # min span
    assert nice_range(-0.26, 0.3) == (-0.5, 0.5)
    assert nice_range(float("nan"), 1.0, floor_zero=True) == (0.0, 1.0)
    plots = PlotModel(window_s=10.0)
    plots.attach(_ring_with(2_000))
    plots.pull()
    r = plots.y_range(("raw_n",), floor_zero=True)
    assert r == (0.0, 1.0)
    assert plots.y_range(("raw_n",), floor_zero=True, include=(1.08, 1.32)) == (0.0, 1.5)  # the target band is shown
    assert plots.y_range(("raw_n", "comp_n"), floor_zero=True) == r  # a series of zeros does not move it


def test_trial_table_appends_without_rebuilding(qtbot):
    table = TrialTable()
    view = QtTrialTable(table)
    qtbot.addWidget(view)
    row = trial_record(trial_index=0, target_label="FIRM", target_force_n=1.2, haptic_mode="on", outcome="success",
                       tct_s=2.5, rmse_n=0.2, max_ae_n=0.4)
    table.add(row)
    first = [view.item(0, j) for j in range(7)]
    for k in range(1, 5):
        table.add(dataclasses.replace(row, trial_index=k))
    assert view.rowCount() == 5
    assert all(view.item(0, j) is first[j] for j in range(7))  # existing cells untouched
    assert [view.item(4, 0).text(), view.item(0, 0).text()] == ["5", "1"]


def test_stall_recorder_attributes_the_gap_to_the_sampled_callback():
    rec = StallRecorder(interval_s=0.005, threshold_s=0.03)
    rec.set_phase("session", 10.0)
    rec.beat(10.005)
    assert not rec.overdue(10.02) and rec.overdue(10.045)
    plot_stack = ("pyqtgraph/functions.py:2090 arrayToQPath", "study_app/gui/widgets.py:140 refresh",
                  "study_app/gui/main_window.py:173 _on_plot_timer", "study_app/cli/main.py:166 main")
    rig_stack = ("study_app/gui/rig_view.py:51 paintEvent", "study_app/cli/main.py:166 main")
    rec.sample(plot_stack)
    rec.sample(plot_stack)
    rec.sample(rig_stack)
    rec.beat(10.205)
    assert rec.stalls == [Stall(
        "session", 195.0,
        "study_app/gui/widgets.py:140 refresh ← study_app/gui/main_window.py:173 _on_plot_timer "
        "[in pyqtgraph/functions.py:2090 arrayToQPath]", 3,
    )]
    rec.beat(10.215)  # a 5 ms gap: measured, not kept
    assert len(rec.stalls) == 1 and np.isclose(rec.worst_ms["session"], 195.0)
    rec.set_phase("calibration", 11.0)
    rec.beat(11.045)  # overdue, but nothing sampled
    assert rec.worst("calibration") == Stall("calibration", 40.0, "(not sampled: the GUI thread held the GIL)", 0)
    assert rec.worst() is rec.stalls[0]
    where = "study_app/cli/main.py:166 main"
    assert culprit((where,)) == f"event loop (Qt painting/layout) in {where}"
