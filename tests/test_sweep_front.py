"""The sweep's front figure follows the protocol's task: force regulation's speed–accuracy front, force tracking's
lag against its tracking error (``haptic-study sweep`` on a tracking protocol), each point a setting with haptics ON.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from analysis.planning.sweep_figures import FRONTS, front_figure, front_of, metrics_figure
from protocol.metrics import METRICS
from study_app.cli.main import main

TRACKING = """name = "short tracking"
[[targets]]
label = "SINE"
force_n = 0.8
[design]
modes = ["on", "off"]
trials_per_cell = 1
[task]
kind = "force_tracking"
profile = "sine"
offset_n = 0.8
amplitude_n = 0.4
frequency_hz = 0.5
duration_s = 2.0
lead_in_s = 1.0
band_n = 0.1
[trial]
max_trial_s = 3.5
pause_s = 0.05
[training]
enabled = false
"""


def _summary(folder: Path) -> pd.DataFrame:
    """sweep_summary.csv with the registry's names back (the file has the report's: rmse_N)."""
    back = {m.participant_exported: m.name for m in METRICS}
    frame = pd.read_csv(folder / "sweep_summary.csv")
    return frame.assign(metric=frame["metric"].map(lambda v: back.get(v, v)))


def test_a_tracking_sweep_draws_the_lag_against_the_error_of_each_setting(tmp_path: Path, capsys) -> None:
    (tmp_path / "tracking.toml").write_text(TRACKING, encoding="utf-8")
    out = tmp_path / "out"
    assert main(["sweep", "--set", "filter_window=5,40", "--participants", "1", "--studies", "1", "--jobs", "1",
                 "--protocol", str(tmp_path / "tracking.toml"), "--out", str(out)]) == 0
    capsys.readouterr()
    md = (out / "sweep.md").read_text(encoding="utf-8")
    assert "sweep_front.png (the lag–error front: lag against RMSE, haptics ON, each setting's gain beside it)" in md
    summary = _summary(out)
    assert front_of(summary) is FRONTS[1]  # tracking's measures: no rise time, so not the speed–accuracy front
    fig = front_figure(summary, ["filter_window"], "a note")
    (ax,) = [a for a in fig.axes if a.get_visible()]
    assert ax.get_title() == "Lag–error front across filter_window (lower left is better)"
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("RMSE (N), haptics ON", "lag (s), haptics ON")
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert len(labels) == 2 and labels[0].startswith("5, gain ") and labels[1].startswith("40, gain ")
    # each point is its setting's ON means: the lag on y, the RMSE on x
    on = summary.set_index(["filter_window", "metric"])["on"]
    points = [c.lines[0] for c in ax.containers]  # each errorbar's data line
    drawn = sorted((round(float(p.get_xdata()[0]), 9), round(float(p.get_ydata()[0]), 9)) for p in points)
    expected = sorted((round(float(on[(w, "rmse_n")]), 9), round(float(on[(w, "lag_s")]), 9)) for w in (5, 40))
    assert drawn == expected
    # a longer filter delays the force: the simulated hand's lag grows with the window (40 ms more of group delay)
    assert on[(40, "lag_s")] > on[(5, "lag_s")]


def test_the_paper_s_task_keeps_its_speed_accuracy_front() -> None:
    rows = [{"metric": m, "filter_window": 10, "on": 0.5} for m in ("success", "rise_time_s", "reach_rmse_n",
                                                                    "rmse_n")]
    assert front_of(pd.DataFrame(rows)) is FRONTS[0]
    assert front_of(pd.DataFrame([{"metric": "rmse_n", "on": 0.5}])) is None


def test_the_success_counts_stand_apart_from_each_other() -> None:
    """Each TCT-over-successes point's count (n=) sits on the side away from the other mode's point at the same
    setting -- the higher one's above, the lower one's below, a tie ON above -- so close points' labels do not
    overlap (they did at filter_window 1 of the README's sweep: OFF's below its point, ON's above its own)."""
    tct = next(m.name for m in METRICS if m.success_only)
    rows = [(1, 8.27, 7.97), (10, 6.70, 8.35), (50, 7.0, 7.0)]  # OFF above, OFF below, a tie
    summary = pd.DataFrame([{"filter_window": w, "metric": tct, "n_studies": 3, "n_trials_off": 13,
                             "n_trials_on": 17, "off": off, "off_ci_low": off - 0.5, "off_ci_high": off + 0.5,
                             "on": on, "on_ci_low": on - 0.5, "on_ci_high": on + 0.5} for w, off, on in rows])
    fig = metrics_figure(summary, ["filter_window"], {"filter_window": 10.0}, "a note")
    ax = fig.axes[0]
    near = [w for w, _, _ in rows]  # (the modes' points are drawn a little apart on a log axis)
    up = {(min(near, key=lambda w: abs(w - t.xy[0])), t.get_text()): t.xyann[1] > 0
          for t in ax.texts if t.get_text().startswith("n=")}
    assert up == {(1, "n=13"): True, (1, "n=17"): False, (10, "n=13"): False, (10, "n=17"): True,
                  (50, "n=13"): False, (50, "n=17"): True}
