"""The progress bar says how long is left once the rate means something."""

from __future__ import annotations

import io

from study_app.cli.progress import ProgressBar


def _bar_at(elapsed_s: float, done: float, total: float = 100.0) -> str:
    now = [0.0]
    out = io.StringIO()  # not a terminal: a line every 10 %
    bar = ProgressBar(total, "work", "items", stream=out, decimals=0, clock=lambda: now[0])
    now[0] = elapsed_s
    bar.update(done)
    return out.getvalue()


def test_time_left_from_the_mean_rate() -> None:
    assert "(10.0 s, about 30 s left)" in _bar_at(10.0, 25)
    assert "about 15 min left" in _bar_at(300.0, 25)
    assert "about 2.5 h left" in _bar_at(3600.0, 28.5714)  # 1 h for 2/7 of it: 2.5 h to go


def test_no_time_left_before_it_means_something_or_at_the_end() -> None:
    assert _bar_at(1.0, 50).rstrip().endswith("(1.0 s)")  # under 2 s: the start-up's rate
    assert _bar_at(30.0, 0.5).rstrip().endswith("(30.0 s)")  # under 1 % done
    assert _bar_at(30.0, 100).rstrip().endswith("(30.0 s)")  # done
    assert _bar_at(30.0, 0).rstrip().endswith("(30.0 s)")  # nothing done: no rate (no division by zero)
