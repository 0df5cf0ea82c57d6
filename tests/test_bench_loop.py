"""``haptic-study bench loop`` measures what it says (no timing is asserted: the figures are the bench's)."""

from __future__ import annotations

import numpy as np
import pytest

from bench.loop_bench import format_loop_bench, run_loop_bench
from bench.loop_load import LoadSpec, parse_load
from bench.loop_probe import _figures
from study_app.cli.main import main


def test_the_load_is_spelled_out_and_a_wrong_one_is_one_line() -> None:
    assert parse_load("busy=2,report,gui") == LoadSpec(2, True, True)
    assert parse_load("none") == LoadSpec(0, False, False) and parse_load("gui") == LoadSpec(0, False, True)
    assert LoadSpec(2, True, True).describe(2).startswith("4 busy processes (2 per CPU, 2 CPUs")
    with pytest.raises(ValueError, match=r"^--load: 'video' is not a load; allowed: busy=N \(per CPU\)"):
        parse_load("busy=1,video")
    with pytest.raises(ValueError, match=r"^--load busy=x: a whole number"):
        parse_load("busy=x")


@pytest.mark.parametrize(("argv", "said"), [
    (["--load", "busy=99"], "--load busy=99: a whole number of busy processes per CPU from 0 to 16"),
    (["--reference-tree", "/nonexistent"], "--reference-tree = '/nonexistent': not a haptic-study source tree"),
    (["--study-db", "/nonexistent.db"], "--study-db = '/nonexistent.db': no such file"),
])
def test_bad_input_is_refused_before_any_work(argv, said, capsys) -> None:
    assert main(["bench", "loop", *argv]) == 2
    err = capsys.readouterr().err
    assert said in err and "Traceback" not in err


class _Health:
    def __init__(self, missed: int) -> None:
        self.missed_slots, self.scheduling, self.loop_pid, self.latency = missed, "SCHED_FIFO/20", 7, None


def test_the_figures_of_a_measurement_count_periods_over_the_gap_limit() -> None:
    p_us = np.array([1000.0] * 96 + [1500.0, 2500.0, 6000.0, 12000.0])
    trials = [{"index": 0, "outcome": "success", "abort_cause": "", "abort_reason": ""},
              {"index": 1, "outcome": "aborted", "abort_cause": "gap",
               "abort_reason": "gap: no loop record for 6.0 ms"},
              {"index": 1, "outcome": "aborted", "abort_cause": "fault", "abort_reason": "SENSOR_STALE"}]
    r = _figures(p_us, 0, 1.0, _Health(3), _Health(10), trials, True)
    assert r["ticks"] == 100 and r["over_2ms"] == 3 and r["over_gap_5ms"] == 2 and r["missed_slots"] == 7
    assert r["histogram_us"]["counts"] == [96, 0, 0, 1, 1, 1, 1, 0]  # 1500 µs is in 1.5–2 ms (bins: [a, b))
    assert r["session"] == {"ended": True, "attempts": 3, "completed": 1, "aborted": {"fault": 1, "gap": 1},
                            "gap_aborts": 1, "gap_reasons": ["gap: no loop record for 6.0 ms"]}
    assert r["period_us"]["max"] == 12000.0 and r["abs_dev_p99_us"] > 5000.0


def test_a_short_quiet_run_of_our_tree_reads_every_period_and_says_where_the_loop_ran() -> None:
    r = run_loop_bench(seconds=1.0, load=LoadSpec(0, False, True), session=False)
    (run,) = r["runs"]["ours"]
    assert run["ticks"] > 500 and run["records_lost"] == 0 and run["session"] is None
    assert (run["loop_pid"] > 0 and "SCHED_FIFO" in run["scheduling"]) or "normal" in run["scheduling"]
    floor = run["floor"]  # the bare timer ran beside it, for as long, and counted its periods as the loop's are
    assert floor["periods"] > 500 and 0 <= floor["over_5ms"] <= floor["over_2ms"] < floor["periods"]
    text = format_loop_bench(r)
    assert "a GUI plotting the live ring at 30 Hz" in text and "the loop in its own process (pid" in text
    assert "p99 |period - 1 ms|" in text and "Rerun on a quiet machine" in text
    assert "the machine's floor, same CPU and time" in text and "a bare 1 ms timer (" in text
