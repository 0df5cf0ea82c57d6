"""``haptic-study sweep`` and ``run --set``: pairing, the cache, the tables, the caveat, settings stored and refused.

Cheap: a two-trial protocol (one GENTLE trial per mode, 2 s cap), one or two participants, one process.
"""

from __future__ import annotations

import json
import math
import sqlite3
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st

from analysis.planning.setting_labels import value_format
from analysis.planning.sim_study import TrialRow, sim_metrics
from analysis.planning.sweep import (
    CACHE_FILE,
    FILTER_NOTE,
    METRICS,
    cell_key,
    read_cache,
    summary_frame,
    sweep_frame,
    t_interval,
)
from pipeline.force.pipeline_settings import framework_with, paper_settings, settings_of
from protocol.metrics import TRADE_PHASES
from protocol.study.config import protocol_from_dict
from protocol.tasks.force_regulation import ForceRegulation
from study_app.cli.main import main
from study_app.headless import sweep_run
from study_app.headless.sim_trials import MODEL_VERSION
from study_app.headless.sweep_run import run_sweep

#: The paper's study's measures: its task's the report tests (what a sweep of the paper's protocol reports).
PAPER = sim_metrics(ForceRegulation())

SHORT = """name = "short"
[[targets]]
label = "GENTLE"
force_n = 0.6
[design]
modes = ["on", "off"]
trials_per_cell = 1
[trial]
max_trial_s = 2.0
pause_s = 0.05
[training]
enabled = false
"""


@pytest.fixture(scope="module")
def short_protocol():
    import tomllib

    return protocol_from_dict(tomllib.loads(SHORT), "short.toml")


def _grid(*windows: int) -> list[dict[str, float]]:
    return [{**paper_settings(), "filter_window": w} for w in windows]


def test_every_setting_meets_the_same_participants(tmp_path: Path, short_protocol, monkeypatch) -> None:
    calls: list[tuple[int, int, int]] = []
    real = sweep_run.run_participant

    def spy(study, participant, protocol, framework):
        calls.append((framework.filter_window, study, participant))
        return real(study, participant, protocol, framework)

    monkeypatch.setattr(sweep_run, "run_participant", spy)
    cells = run_sweep(_grid(1, 50), studies=2, participants=2, seed=3, cache=tmp_path / CACHE_FILE,
                      protocol=short_protocol)
    by_window = {w: sorted((s, p) for ww, s, p in calls if ww == w) for w in (1, 50)}
    assert by_window[1] == by_window[50] == [(3000, 1), (3000, 2), (3001, 1), (3001, 2)]
    # the same schedule (targets and modes in order) for both settings: the comparison is paired
    for k in range(2):
        a = [(r.participant, r.index, r.target, r.mode) for r in cells[k].rows]
        b = [(r.participant, r.index, r.target, r.mode) for r in cells[2 + k].rows]
        assert a == b and len(a) == 4
    # the filter changes what the participants did
    assert [r.values["rmse_n"] for r in cells[0].rows] != [r.values["rmse_n"] for r in cells[2].rows]


def test_a_second_run_computes_nothing_and_a_cut_line_is_run_again(tmp_path: Path, short_protocol,
                                                                     monkeypatch) -> None:
    cache = tmp_path / CACHE_FILE
    first = run_sweep(_grid(10), studies=2, participants=1, seed=0, cache=cache, protocol=short_protocol)

    def refuse(*_args, **_kw):
        raise AssertionError("a cached cell was run again")

    monkeypatch.setattr(sweep_run, "run_participant", refuse)
    again = run_sweep(_grid(10), studies=2, participants=1, seed=0, cache=cache, protocol=short_protocol)
    assert [c.rows for c in again] == [c.rows for c in first]
    # a killed run's last line, cut short: skipped, its cell run again and appended on a line of its own
    lines = cache.read_text().splitlines()
    cache.write_text(lines[0] + "\n" + lines[1][: len(lines[1]) // 2])
    monkeypatch.undo()
    third = run_sweep(_grid(10), studies=2, participants=1, seed=0, cache=cache, protocol=short_protocol)
    assert [c.rows for c in third] == [c.rows for c in first]
    assert len(read_cache(cache, sim_metrics(short_protocol.task))) == 2


def test_the_cache_key_names_what_decides_the_rows() -> None:
    base = cell_key(paper_settings(), 0, 10, 0, MODEL_VERSION, "p", "run")
    assert base == cell_key(dict(reversed(list(paper_settings().items()))), 0, 10, 0, MODEL_VERSION, "p", "run")
    for other in (cell_key({**paper_settings(), "f_scale_n": 3.0}, 0, 10, 0, MODEL_VERSION, "p", "run"),
                  cell_key(paper_settings(), 1, 10, 0, MODEL_VERSION, "p", "run"),
                  cell_key(paper_settings(), 0, 9, 0, MODEL_VERSION, "p", "run"),
                  cell_key(paper_settings(), 0, 10, 1, MODEL_VERSION, "p", "run"),
                  cell_key(paper_settings(), 0, 10, 0, MODEL_VERSION + "x", "p", "run"),
                  cell_key(paper_settings(), 0, 10, 0, MODEL_VERSION, "q", "run"),
                  cell_key(paper_settings(), 0, 10, 0, MODEL_VERSION, "p", "bench-v2")):
        assert other != base


def test_the_t_interval_over_study_means() -> None:
    mean, lo, hi = t_interval([1.0, 2.0, 3.0])
    assert mean == 2.0 and hi - mean == pytest.approx(4.302653 * 1.0 / math.sqrt(3), rel=1e-6) and lo < mean
    assert math.isnan(t_interval([1.0])[1]) and math.isnan(t_interval([])[0])
    # two studies of a rate: the t-interval (t 12.7) passes 0 and 1; its ends are clipped to what a rate can be
    assert t_interval([0.0, 0.36]) == pytest.approx((0.18, -2.1073, 2.4673), abs=1e-3)
    assert t_interval([0.0, 0.36], bounds=(0.0, 1.0)) == pytest.approx((0.18, 0.0, 1.0))


def _row(study: int, p: int, mode: str, ok: bool, rmse: float) -> TrialRow:
    return TrialRow(study, p, 0, "GENTLE", mode,
                    {"success": ok, "tct_s": 1.5 if ok else None, "rmse_n": rmse, "max_ae_n": 2 * rmse})


def test_the_tables_per_study_and_per_setting(tmp_path: Path) -> None:
    from analysis.planning.sweep import SweepCell

    cells = [SweepCell({**paper_settings(), "filter_window": w}, k,
                       [_row(k, 1, "off", False, 1.0 + k), _row(k, 1, "on", True, 0.5 * w / 10)])
             for w in (10, 20) for k in range(2)]
    tidy = sweep_frame(cells, ["filter_window"], 12.0)
    assert list(tidy.columns) == ["filter_window", "study", "metric", "off", "on", "change", "n_trials_off",
                                  "n_trials_on"]
    assert len(tidy) == 4 * 5  # 2 settings × 2 studies, a row per measure the trials carry (their task's)
    assert set(tidy["metric"]) == {"success", "tct_s", "tct_cens_s", "rmse_n", "max_ae_n"} <= set(METRICS)
    # TCT in both readings: over successful trials (n: the successes, none OFF here) and with failures at the cap
    tct = tidy[(tidy["metric"] == "tct_s") & (tidy["filter_window"] == 10)].iloc[0]
    cens = tidy[(tidy["metric"] == "tct_cens_s") & (tidy["filter_window"] == 10)].iloc[0]
    assert (tct["n_trials_off"], tct["n_trials_on"], math.isnan(tct["off"]), tct["on"]) == (0, 1, True, 1.5)
    assert (cens["n_trials_off"], cens["off"], cens["on"]) == (1, 12.0, 1.5)
    rm = tidy[(tidy["metric"] == "rmse_n") & (tidy["filter_window"] == 20)]
    assert rm["on"].tolist() == [1.0, 1.0] and rm["off"].tolist() == [1.0, 2.0]
    summary = summary_frame(tidy, ["filter_window"], paper_settings())
    paper_rows = summary[summary["paper"]]
    assert set(paper_rows["filter_window"]) == {10}
    s = summary[(summary["metric"] == "success") & (summary["filter_window"] == 10)].iloc[0]
    assert (s["off"], s["on"], s["n_studies"]) == (0.0, 1.0, 2)
    r = summary[(summary["metric"] == "rmse_n") & (summary["filter_window"] == 10)].iloc[0]
    assert r["off_ci_low"] == 0.0 < r["off_ci_high"]  # 1.0 and 2.0 over two studies: the t-interval passes 0
    assert (summary["change_ci_low"].dropna() >= -1.0).all()


def test_sweep_command_writes_its_outputs_with_the_caveat(tmp_path: Path, capsys) -> None:
    (tmp_path / "short.toml").write_text(SHORT)
    out = tmp_path / "out"
    args = ["sweep", "--set", "filter_window=5,10", "--participants", "1", "--studies", "2", "--jobs", "1",
            "--protocol", str(tmp_path / "short.toml"), "--out", str(out)]
    assert main(args) == 0
    said = capsys.readouterr().out
    assert said.startswith(f"These results are a prediction of simulated participant model v{MODEL_VERSION} (")
    assert "| 10 (paper) | RMSE (N) |" in said
    assert FILTER_NOTE in said and FILTER_NOTE in (out / "sweep.md").read_text(encoding="utf-8")
    for name in ("sweep.csv", "sweep_summary.csv", "sweep.png", "sweep_front.png", "sweep.md", CACHE_FILE):
        assert (out / name).is_file(), name
    assert "a prediction of simulated participant model" in (out / "sweep.md").read_text().splitlines()[2]
    for name in ("sweep.csv", "sweep_summary.csv"):  # the report's names (they said success, rmse_n, max_ae_n)
        # the tested measures, TCT also censored at the cap, and the trade's phases (the front)
        expected = {m.participant_exported for m in PAPER} | {"tct_censored_s"}
        assert {m.name for m in TRADE_PHASES} <= {m.name for m in PAPER}
        assert set(pd.read_csv(out / name)["metric"]) == expected, name
    # the same command again: refused (the outputs are there) unless --force, which computes nothing new
    assert main(args) == 2
    before = (out / CACHE_FILE).read_bytes()
    assert main([*args, "--force"]) == 0
    assert (out / CACHE_FILE).read_bytes() == before


def test_run_set_is_stored_and_continue_with_other_settings_is_refused(tmp_path: Path, capsys) -> None:
    (tmp_path / "short.toml").write_text(SHORT)
    db = tmp_path / "s.db"
    base = ["run", "--participants", "1", "--jobs", "1", "--protocol", str(tmp_path / "short.toml"), "--db", str(db)]
    assert main([*base, "--set", "filter_window=20", "--set", "slew=30"]) == 0
    assert "Pipeline settings: filter_window=20, slew_n_per_s=30" in capsys.readouterr().out
    with sqlite3.connect(db) as conn:
        (config_json,) = conn.execute("SELECT config_json FROM sessions").fetchone()
    config = json.loads(config_json)
    assert config["framework"]["filter_window"] == 20 and config["framework"]["safety"]["slew_n_per_s"] == 30
    assert config["pipeline_settings"] == {"filter_window": 20, "slew_n_per_s": 30.0}
    assert settings_of(framework_with({"filter_window": 20, "slew": 30})) == {
        **paper_settings(), "filter_window": 20, "slew_n_per_s": 30.0}
    before = db.read_bytes()
    assert main([*base[:2], "2", *base[3:], "--continue", "--set", "filter_window=20"]) == 2
    assert "ran with the pipeline settings: filter_window=20, slew_n_per_s=30; this command's: filter_window=20" \
        in capsys.readouterr().err
    assert db.read_bytes() == before
    assert main(["sessions", "--db", str(db)]) == 0
    assert "pipeline settings not the paper's (run --set): filter_window=20, slew_n_per_s=30 (session 1)" \
        in capsys.readouterr().out


@given(st.lists(st.floats(min_value=1e-6, max_value=1e6), min_size=1, max_size=8))
def test_labels_tell_apart_every_setting_and_keep_g_where_it_does(values: list[float]) -> None:
    fmt = value_format(values)
    assert len({fmt(v) for v in values}) == len(set(values))
    if len({f"{v:g}" for v in values}) == len(set(values)):
        assert [fmt(v) for v in values] == [f"{v:g}" for v in values]


@pytest.mark.parametrize(("grid", "shown"), [("f_scale=7,7.0000001", ("| 7 (paper) |", "| 7.0000001 |")),
                                             ("slew=123456,123456.5", ("| 123456 |", "| 123456.5 |"))])
def test_settings_below_the_printed_precision_or_far_from_the_paper(tmp_path: Path, capsys, grid: str,
                                                                    shown: tuple[str, str]) -> None:
    # 7.0000001 read '7' beside 7 in every table; a slew near 123456 N/s put the figure's 'paper' label (50 N/s)
    # millions of pixels away, and the renderer failed after the cells were run
    (tmp_path / "short.toml").write_text(SHORT)
    out = tmp_path / "out"
    assert main(["sweep", "--set", grid, "--participants", "1", "--studies", "1", "--jobs", "1",
                 "--protocol", str(tmp_path / "short.toml"), "--out", str(out)]) == 0
    said = capsys.readouterr().out
    for cell in shown:
        assert cell in said and cell in (out / "sweep.md").read_text(encoding="utf-8")
    assert (out / "sweep.png").is_file() and (out / "sweep_front.png").is_file()
