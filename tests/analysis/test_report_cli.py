"""``haptic-study report`` and ``plot-trial`` end to end, as a researcher runs them."""

from __future__ import annotations

import csv
import re

import numpy as np
import pandas as pd
import pytest
import scipy.stats
from hypothesis import given
from hypothesis import strategies as st
from studybuilder import SessionDef, build, success_trial, timeout_trial

from analysis.figures import peak_downsample, significance_mark
from analysis.report import STATS_CSV_COLUMNS, TRIALS_CSV_COLUMNS
from study_app.cli import main


def _participant(code: str, i: int) -> SessionDef:
    aborted = success_trial("FIRM", "on", 0)
    aborted.outcome_override = "aborted"
    trials = [success_trial("GENTLE", "on", 100 * i), success_trial("FIRM", "on", 150 * i),
              timeout_trial("GENTLE", "on", 0.2 + 0.05 * i), success_trial("FIRM", "off", 400 + 90 * i),
              timeout_trial("GENTLE", "off", 1.0 + 0.1 * i), timeout_trial("FIRM", "off", 2.0), aborted]
    return SessionDef(code, trials, max_trial_s=4.0)  # 4 s trials: a quarter of the samples to write


@pytest.fixture(scope="module")
def dbs(tmp_path_factory):
    d = tmp_path_factory.mktemp("report")
    a = build(d / "a.db", [_participant(f"A{i}", i) for i in range(1, 5)]
              + [SessionDef("A1", [success_trial("GENTLE", "on", 0)], kind="training", max_trial_s=4.0)])
    b = build(d / "b.db", [_participant(f"B{i}", i + 4) for i in range(1, 4)])
    return a, b


@pytest.fixture(scope="module")
def report(dbs, tmp_path_factory):
    """The report of both databases, run once through the CLI for the tests that only read it."""
    out = tmp_path_factory.mktemp("out") / "rep"
    code = main(["report", "--db", str(dbs[0]), "--db", str(dbs[1]), "--out", str(out)])
    assert code == 0
    return out


def _run(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_report_writes_every_file_with_the_promised_columns(report):
    out = report
    for name in ("report.html", "trials.csv", "participants.csv", "stats.csv", "stats_by_target.csv",
                 "speed_accuracy.csv", "sessions.csv"):
        assert (out / name).is_file(), name
    for stem in ("success_rate", "tct", "rmse_max_ae", "paired", "speed_accuracy"):
        assert (out / "figures" / f"{stem}.png").stat().st_size > 1000
        assert (out / "figures" / f"{stem}.svg").read_text().lstrip().startswith("<?xml")
    with open(out / "trials.csv") as f:
        header = next(csv.reader(f))
    assert tuple(header[: len(TRIALS_CSV_COLUMNS)]) == TRIALS_CSV_COLUMNS
    with open(out / "stats.csv") as f:
        header = next(csv.reader(f))
    assert tuple(header[: len(STATS_CSV_COLUMNS)]) == STATS_CSV_COLUMNS
    trials = pd.read_csv(out / "trials.csv")
    assert len(trials) == 42 and "aborted" not in set(trials["outcome"])  # 7 × 6 analysed, aborted left out
    pp = pd.read_csv(out / "participants.csv")
    assert len(pp) == 14 and set(pp["haptic_mode"]) == {"on", "off"}


def test_stats_csv_equals_scipy_on_the_participant_differences(report):
    out = report
    pp = pd.read_csv(out / "participants.csv")
    stats = pd.read_csv(out / "stats.csv").set_index("metric")
    wide = pp.pivot(index="participant_code", columns="haptic_mode")
    for metric in ("rmse_n", "max_ae_n", "success_rate"):
        d = (wide[(metric, "on")] - wide[(metric, "off")]).to_numpy()
        method = stats.at[metric, "method"]
        if method == "permutation":
            continue
        ref = scipy.stats.wilcoxon(d, method=method)
        assert stats.at[metric, "statistic"] == pytest.approx(float(ref.statistic), rel=1e-15)
        assert stats.at[metric, "p_value"] == pytest.approx(float(ref.pvalue), rel=1e-12)
        assert stats.at[metric, "n"] == len(d) - int((d == 0).sum())
    assert stats.at["rmse_n", "zero_method"] == "wilcox"


def test_html_is_self_contained_and_states_its_methods(report):
    out = report
    page = (out / "report.html").read_text()
    assert not re.search(r'(src|href)="(?!data:)', page)  # nothing to fetch: figures are embedded
    assert page.count('src="data:image/png;base64,') == 7  # 5 figures + one pipeline trace per mode
    assert "1 training sessions (1 trials) and 7 aborted trials" in page
    assert "Holm" in page and "Hodges" in page and "from the cue to the trial end" in page
    assert "a.db" in page and "b.db" in page


def test_an_existing_output_folder_is_kept_without_force_and_options_change_the_numbers(dbs, report, tmp_path, capsys):
    out = tmp_path / "rep"
    out.mkdir()
    (out / "mine.txt").write_text("keep me")
    code, _, err = _run(capsys, "report", "--db", str(dbs[0]), "--db", str(dbs[1]), "--out", str(out))
    assert code == 2
    assert err.count("\n") == 1 and "pass --force" in err
    assert (out / "mine.txt").read_text() == "keep me" and len(list(out.iterdir())) == 1
    code, stdout, _ = _run(capsys, "report", "--db", str(dbs[0]), "--db", str(dbs[1]), "--out", str(out), "--force",
                           "--tct", "censored", "--error-window", "first_contact")
    assert code == 0 and not (out / "mine.txt").exists() and (out / "report.html").exists()
    assert "7 participants, 42 trials" in stdout
    assert not list(tmp_path.glob(".rep.*"))  # no temporary folder left behind
    # censored TCT can only grow, errors from first contact can only shrink
    pa, pb = pd.read_csv(report / "participants.csv"), pd.read_csv(out / "participants.csv")
    assert (pb["tct_s"] >= pa["tct_s"]).all() and (pb["tct_s"] > pa["tct_s"]).any()
    assert (pb["rmse_n"] <= pa["rmse_n"]).all() and (pb["rmse_n"] < pa["rmse_n"]).any()
    assert "a failed trial counting as the trial cap (4 s)" in (out / "report.html").read_text()


@pytest.mark.parametrize(
    ("setup", "message"),
    [
        (lambda p: p.write_text("not sqlite"), "not a haptic-study database"),
        (lambda p: build(p, []), "empty study database"),
        (lambda p: build(p, [SessionDef("T1", [success_trial("GENTLE", "on", 0)], kind="training")]),
         "only training sessions"),
    ],
)
def test_bad_databases_give_one_line_and_exit_2(tmp_path, capsys, setup, message):
    db = tmp_path / "bad.db"
    setup(db)
    code, stdout, err = _run(capsys, "report", "--db", str(db), "--out", str(tmp_path / "rep"))
    assert code == 2 and stdout == ""
    assert err.startswith("haptic-study: error: ") and err.count("\n") == 1 and message in err
    assert not (tmp_path / "rep").exists()


def test_plot_trial(dbs, tmp_path, capsys):
    png = tmp_path / "t.png"
    code, _, _ = _run(capsys, "plot-trial", "--db", str(dbs[0]), "--session", "1", "--trial", "0", "--out", str(png))
    assert code == 0 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    code, _, err = _run(capsys, "plot-trial", "--db", str(dbs[0]), "--session", "1", "--trial", "99",
                        "--out", str(png))
    assert code == 2 and "no such trial" in err
    code, _, err = _run(capsys, "plot-trial", "--db", str(dbs[0]), "--session", "1", "--trial", "0",
                        "--out", str(tmp_path / "t.pdf"))
    assert code == 2 and "must end in .png or .svg" in err


# -- figure helpers ------------------------------------------------------------------------------
@given(st.lists(st.floats(-1e6, 1e6), min_size=1, max_size=5000), st.integers(1, 300))
def test_peak_downsampling_keeps_every_extreme(values, buckets):
    y = np.asarray(values)
    t = np.arange(len(y), dtype=float)
    tk, yk = peak_downsample(t, y, buckets)
    assert yk.max() == y.max() and yk.min() == y.min()
    assert np.all(np.diff(tk) >= 0) and len(yk) <= max(len(y), 2 * buckets)
    assert np.array_equal(y[tk.astype(int)], yk)


def test_significance_marks():
    class R:
        computable = True
        p_value = 0.2

    r = R()
    assert [significance_mark(r, p_holm=p) for p in (0.0004, 0.001, 0.009, 0.049, 0.05, float("nan"))] == [
        "***", "**", "**", "*", "n.s.", "n/c"]
    r.computable = False
    assert significance_mark(r, p_holm=0.001) == "n/c" and significance_mark(None) == "n/c"
