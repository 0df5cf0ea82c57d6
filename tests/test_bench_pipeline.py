"""``haptic-study bench pipeline`` measures what it says (no timing is asserted: the figures are the bench's)."""

from __future__ import annotations

import itertools
import math

import pytest

from bench.pipeline_bench import format_pipeline_bench, run_pipeline_bench
from bench.pipeline_cost import measure_pipeline_cost, record_samples
from pipeline.force.config import FrameworkConfig


@pytest.fixture(scope="module")
def samples() -> dict:
    return record_samples(2000)


def test_recorded_poses_update_at_the_robots_125_hz(samples) -> None:
    t = samples["pose_t_ns"]
    changes = [i for i in range(1, len(t)) if t[i] != t[i - 1]]
    assert {b - a for a, b in itertools.pairwise(changes)} == {8}  # every 8th 1 ms tick


def test_cost_drives_the_framework_as_the_loop_does_and_agrees_with_numpy(samples) -> None:
    r = measure_pipeline_cost(samples, FrameworkConfig(), batch=500)
    assert r["ticks_timed"] == 2000
    assert abs(r["pose_updates_per_tick"] - 0.125) <= 0.001  # 1 in 8, give or take the ends
    assert r["ours_vs_naive_max_abs_diff_n"] <= 1e-12
    for key in ("ours_us_per_tick", "ours_pose_every_tick_us", "naive_numpy_us_per_tick", "harness_overhead_us"):
        assert math.isfinite(r[key]) and r[key] > 0, key
    # the ratio of the unrounded medians, rounded to 0.1; the medians themselves are reported to 0.001 µs
    naive, ours = r["naive_numpy_us_per_tick"], r["ours_us_per_tick"]
    ratio = naive / ours
    assert abs(r["speedup"] - ratio) <= 0.05 + 1.01 * ratio * (0.0005 / ours + 0.0005 / naive)


def test_the_whole_bench_without_the_loop_has_the_issues_fields() -> None:
    r = run_pipeline_bench(loop_seconds=0, ticks=2000)
    for key in ("ours_us_per_tick", "naive_numpy_us_per_tick", "speedup", "loop_period_p50_us",
                "loop_period_p99_us", "loop_periods_over_2ms", "filter_trade"):
        assert key in r, key
    assert r["loop_period_p50_us"] is None and r["bare_loop"] is None  # the loop was skipped: null in the JSON
    assert [row["window"] for row in r["filter_trade"]] == [1, 2, 5, 10, 20, 50, 100]
    assert [row["group_delay_ms"] for row in r["filter_trade"]] == [(w - 1) / 2 for w in (1, 2, 5, 10, 20, 50, 100)]
    noise = [row["noise_rms_n"] for row in r["filter_trade"]]
    assert noise == sorted(noise, reverse=True)  # a longer window is quieter ...
    text = format_pipeline_bench(r)
    assert "NumPy transcription" in text and "Moving-average window" in text
    assert "1 kHz loop: not run (--loop-seconds 0)" in text


def test_the_empty_reference_loop_reports_the_loops_statistics() -> None:
    from bench.machine import bare_loop_stats

    r = bare_loop_stats(0.05)  # 50 periods of real time: what is reported, not how fast
    assert r["ticks"] == 50.0
    assert set(r) >= {"period_p50_us", "period_p99_us", "period_max_us", "abs_dev_p99_us", "periods_over_2ms"}
    assert r["scheduling"].startswith(("SCHED_FIFO/", "normal ("))


def test_the_reference_tree_runs_its_own_code_in_turn_with_ours(tmp_path) -> None:
    """``--reference-tree``: the other tree's bench really runs (a stand-in tree reports its own figures), ours runs
    ours, and the medians and ratios are of each side's rounds."""
    from bench.pipeline_reference import format_reference, run_reference

    tree = tmp_path / "ref"
    (tree / "study_app").mkdir(parents=True)
    (tree / "study_app" / "__init__.py").write_text("")
    (tree / "study_app" / "cli.py").write_text(
        "import json\nprint(json.dumps({'ours_us_per_tick': 99.0, 'arms_tick_one_us': 99.0, "
        "'arms_tick_two_us': 198.0, 'loop_abs_dev_p99_us': None}))\n")
    r = run_reference(str(tree), rounds=2, ticks=2000)
    f = r["figures"]
    assert set(f) == {"ours_us_per_tick", "arms_tick_one_us", "arms_tick_two_us"}  # no loop: no loop figure
    assert f["arms_tick_two_us"]["reference_rounds"] == [198.0, 198.0] and f["arms_tick_two_us"]["reference"] == 198.0
    ours = f["ours_us_per_tick"]
    assert len(ours["ours_rounds"]) == 2 and 0 < ours["ours"] < 99.0 and ours["ratio"] == round(ours["ours"] / 99.0, 3)
    assert "ours against" in format_reference(r).lower()


def test_bench_study_times_the_reference_trees_own_study_in_turn_with_ours(tmp_path) -> None:
    """``bench study --reference-tree``: a stand-in tree's "study" runs its own code (it reports its own wall
    time), ours runs a real one-participant study, and the ratio is of the two sides' medians."""
    from bench.study_reference import format_study_reference, run_study_reference

    tree = tmp_path / "ref"
    for pkg in ("protocol", "protocol/study", "study_app", "study_app/headless"):
        (tree / pkg).mkdir(parents=True)
        (tree / pkg / "__init__.py").write_text("")
    (tree / "protocol" / "study" / "config.py").write_text("def default_protocol():\n    return None\n")
    (tree / "study_app" / "headless" / "__init__.py").write_text(
        "import time\nclass P:\n    study_time_s = 1.0\n"
        "def run_study(db, participants, seed, protocol):\n    return P()\n")
    r = run_study_reference(str(tree), participants=1, rounds=1)
    assert r["reference_wall_s"][0] < 0.01  # the stand-in's own nothing, not our study
    assert r["ours_wall_s"][0] > r["reference_wall_s"][0] and r["study_time_s"]["ours"] > 60.0
    assert r["ratio"] > 10.0  # of the unrounded medians: a real study against the stand-in's nothing
    assert "DIFFERENT" in format_study_reference(r)  # 1 s of stand-in study against ours
