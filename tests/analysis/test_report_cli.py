"""``haptic-study report`` and ``plot-trial`` end to end, as a researcher runs them."""

from __future__ import annotations

import csv
import json
import math
import os
import re
import shutil
import stat
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.stats
from hypothesis import given
from hypothesis import strategies as st
from studybuilder import SessionDef, build, success_trial, timeout_trial

from analysis.plots.figures import peak_downsample, significance_mark
from analysis.reading.codebook import STATS_CSV_COLUMNS
from analysis.report.measures import figure_groups
from analysis.report.report_tables import TRIALS_CSV_COLUMNS
from protocol.tasks.force_regulation import ForceRegulation
from study_app.cli.main import main

ROOT = Path(__file__).resolve().parents[2]


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
    for name in ("report.html", "trials.csv", "participants.csv", "participants_wide.csv", "stats.csv",
                 "stats_by_target.csv", "speed_accuracy.csv", "sessions.csv", "codebook.csv"):
        assert (out / name).is_file(), name
    # success_rate, tct, rmse_max_ae…: the paper's task's figures
    for stem in (*(g.file for g in figure_groups(ForceRegulation().metrics)), "paired", "speed_accuracy"):
        png = (out / "figures" / f"{stem}.png").read_bytes()
        # 300 dpi at a journal's width: one column (3.5 in, 1050 px) or the page (7.2 in)
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and int.from_bytes(png[16:20], "big") in (1050, 2160)
        svg = (out / "figures" / f"{stem}.svg").read_text()
        assert svg.lstrip().startswith("<?xml") and "<text" in svg  # real text, not glyph paths
        assert (out / "figures" / f"{stem}.pdf").read_bytes()[:5] == b"%PDF-"
    with open(out / "trials.csv") as f:
        header = next(csv.reader(f))
    assert tuple(header[: len(TRIALS_CSV_COLUMNS)]) == TRIALS_CSV_COLUMNS
    with open(out / "stats.csv") as f:
        header = next(csv.reader(f))
    assert tuple(header[: len(STATS_CSV_COLUMNS)]) == STATS_CSV_COLUMNS
    trials = pd.read_csv(out / "trials.csv")
    assert len(trials) == 42 and "aborted" not in set(trials["outcome"])  # 7 × 6 analysed, aborted left out
    # sorted by participant number, then trial (numbered from 1); the cue time is there
    keys = list(zip(trials["participant_number"], trials["participant_code"], trials["trial_number"], strict=True))
    assert keys == sorted(keys) and trials["trial_number"].min() == 1 and trials["cue_at_s"].notna().all()
    pp = pd.read_csv(out / "participants.csv")
    assert len(pp) == 14 and set(pp["haptic_mode"]) == {"on", "off"}


def test_stats_csv_equals_scipy_on_the_participant_differences(report):
    out = report
    pp = pd.read_csv(out / "participants.csv")
    stats = pd.read_csv(out / "stats.csv").set_index("metric")
    wide = pp.pivot(index="participant_code", columns="haptic_mode")
    for metric in ("rmse_N", "max_ae_N", "success_rate"):
        d = (wide[(metric, "on")] - wide[(metric, "off")]).to_numpy()
        method = stats.at[metric, "method"]
        if method == "permutation":
            continue
        ref = scipy.stats.wilcoxon(d, method=method)
        # the CSVs are rounded (means to 0.1 mN, p to 4 significant digits); the ranks are not changed by it
        assert stats.at[metric, "statistic"] == pytest.approx(float(ref.statistic), rel=1e-12)
        assert stats.at[metric, "p_value"] == pytest.approx(float(ref.pvalue), rel=5e-4)
        assert stats.at[metric, "n"] == len(d) - int((d == 0).sum())
    assert stats.at["rmse_N", "zero_method"] == "wilcox"


def test_participants_wide_has_one_row_per_participant_with_off_and_on_columns(report):
    wide = pd.read_csv(report / "participants_wide.csv")
    long = pd.read_csv(report / "participants.csv")
    assert len(wide) == 7 and wide["participant_code"].is_unique
    assert list(wide["participant_number"]) == sorted(wide["participant_number"])
    for long_name, off, on in (("rmse_N", "rmse_off_N", "rmse_on_N"),
                               ("success_rate", "success_rate_off", "success_rate_on"),
                               ("tct_s", "tct_off_s", "tct_on_s")):
        for mode, col in (("off", off), ("on", on)):
            expect = long[long["haptic_mode"] == mode].set_index("participant_code")[long_name]
            got = wide.set_index("participant_code")[col]
            pd.testing.assert_series_equal(got.sort_index(), expect.sort_index(), check_names=False)


def test_every_column_of_every_csv_is_in_the_codebook(report):
    """Generic: the columns come from the files the report wrote, so a column added later must be documented."""
    book = pd.read_csv(report / "codebook.csv", keep_default_na=False)
    assert list(book.columns) == ["file", "column", "type", "unit", "description"]
    documented = {(f, c): (t, d) for f, c, t, _, d in book.itertuples(index=False)}
    files = sorted(p.name for p in report.glob("*.csv"))
    assert "codebook.csv" in files and len(files) >= 9
    for name in files:
        for column in pd.read_csv(report / name, nrows=0).columns:
            assert (name, column) in documented, f"{name}: column {column!r} is not in codebook.csv"
            kind, description = documented[(name, column)]
            assert description and kind in ("text", "integer", "number", "boolean"), (name, column)
    # newtons are spelled _N, never _n (which reads as a count next to n_trials)
    assert not [c for _, c, *_ in book.itertuples(index=False) if c.endswith("_n")]
    assert "trial_index" in documented[("trials.csv", "trial_number")][1]  # the numbering is stated


def test_the_printed_report_keeps_every_column_of_the_test_tables(report, tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("check_report_print", ROOT / "scripts" / "check_report_print.py")
    check = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(check)
    if check.find_chromium() is None or shutil.which("pdftotext") is None:
        pytest.skip("needs Chromium and pdftotext (apt-get install chromium poppler-utils)")
    assert check.check(report, tmp_path / "report.pdf") == []


def test_html_is_self_contained_and_states_its_methods(report):
    out = report
    page = (out / "report.html").read_text()
    assert not re.search(r'(src|href)="(?!data:)', page)  # nothing to fetch: figures are embedded
    # 7 figures (the Kaplan–Meier curves of the time to success among them) + one pipeline trace per mode
    assert page.count('src="data:image/png;base64,') == 9
    assert "1 training session (1 trial) and 7 aborted trials (none re-run in its session)" in page
    assert "Simulated data" in page  # the rig the data come from, in the header
    assert "median across 7 participants, IQR" in page  # every statistic says what it is
    assert "Holm" in page and "Hodges" in page and "from the cue to the trial end" in page
    assert "a.db" in page and "b.db" in page
    # the incomplete-session rule and the deviations are stated even when there is nothing to say
    assert "Every experiment session completed (one that did not would be left out and listed" in page
    assert "No deviation from the protocol was recorded" in page


def test_an_existing_output_folder_is_kept_without_force_and_options_change_the_numbers(dbs, report, tmp_path, capsys):
    out = tmp_path / "rep"
    out.mkdir()
    (out / "mine.txt").write_text("keep me")
    code, _, err = _run(capsys, "report", "--db", str(dbs[0]), "--db", str(dbs[1]), "--out", str(out))
    assert code == 2
    assert err.count("\n") == 1 and "pass --force" in err
    assert (out / "mine.txt").read_text() == "keep me" and len(list(out.iterdir())) == 1
    # --force replaces only a folder report wrote: this one is the user's
    code, _, err = _run(capsys, "report", "--db", str(dbs[0]), "--out", str(out), "--force")
    assert code == 2 and err.count("\n") == 1 and "not a folder report wrote" in err and "nothing was deleted" in err
    assert (out / "mine.txt").read_text() == "keep me" and len(list(out.iterdir())) == 1
    # a report folder is replaced, with other options (a copy of the module's report: bytes, modes and marker)
    rep2 = tmp_path / "rep2"
    shutil.copytree(report, rep2)
    assert (rep2 / ".haptic-study-report").exists()
    code, stdout, _ = _run(capsys, "report", "--db", str(dbs[0]), "--db", str(dbs[1]), "--out", str(rep2), "--force",
                           "--tct", "successful", "--error-window", "first_contact")
    assert code == 0 and (rep2 / "report.html").exists()
    assert "7 participants, 42 trials" in stdout
    assert not list(tmp_path.glob(".rep*.*"))  # no temporary folder left behind
    # TCT over successful trials only can only shrink (a failure no longer counts at the cap), errors from first
    # contact can only shrink
    pa, pb = pd.read_csv(report / "participants.csv"), pd.read_csv(rep2 / "participants.csv")
    both = pb["tct_s"].notna()
    assert (pb["tct_s"][both] <= pa["tct_s"][both]).all() and (pb["tct_s"][both] < pa["tct_s"][both]).any()
    assert (pb["rmse_N"] <= pa["rmse_N"]).all() and (pb["rmse_N"] < pa["rmse_N"]).any()
    assert "a failed trial counting as the trial cap (4 s)" in (report / "report.html").read_text()
    # ... but not once someone put a file of their own in it
    (rep2 / "figures" / "my-annotated.png").write_bytes(b"\x89PNG mine")
    code, _, err = _run(capsys, "report", "--db", str(dbs[0]), "--out", str(rep2), "--force")
    assert code == 2 and err.count("\n") == 1
    assert "holds figures/my-annotated.png, which report did not write" in err and "nothing was deleted" in err
    assert (rep2 / "figures" / "my-annotated.png").read_bytes() == b"\x89PNG mine" and (rep2 / "report.html").exists()
    # ... nor once someone edited a file report wrote
    (rep2 / "figures" / "my-annotated.png").unlink()
    with (rep2 / "report.html").open("a") as f:
        f.write("<!-- my notes -->")
    code, _, err = _run(capsys, "report", "--db", str(dbs[0]), "--out", str(rep2), "--force")
    assert code == 2 and err.count("\n") == 1 and "report.html was changed since report wrote it" in err
    assert (rep2 / "report.html").read_text().endswith("<!-- my notes -->")


def test_force_never_replaces_a_folder_holding_the_database(tmp_path, capsys):
    """report --db d/study.db --out d --force: refused, nothing deleted (it used to delete d)."""
    d = tmp_path / "d"
    d.mkdir()
    db = d / "study.db"
    build(db, [SessionDef("P1", [success_trial("GENTLE", "on", 0), success_trial("GENTLE", "off", 1)])])
    (d / "notes.txt").write_text("lab notes")
    before = {p.name: p.read_bytes() for p in d.iterdir()}
    for out in (d, d / "sub" / ".."):
        code, _, err = _run(capsys, "report", "--db", str(db), "--out", str(out), "--force")
        assert code == 2 and err.count("\n") == 1 and "holds the input database" in err
    assert {p.name: p.read_bytes() for p in d.iterdir() if not p.name.endswith(("-wal", "-shm"))} == before


def test_a_report_crashing_half_way_leaves_the_old_report_as_it_was(dbs, report, tmp_path, capsys, monkeypatch):
    import analysis.report.report_tables

    out = tmp_path / "rep"
    shutil.copytree(report, out)  # a folder report wrote (the module's report, copied: bytes, modes and marker)
    before = {p.relative_to(out).as_posix(): p.read_bytes() for p in out.rglob("*") if p.is_file()}

    def crash(folder, tables, written_too=(), metrics=None, described=None):
        (folder / "stats.csv").write_text("half")
        raise RuntimeError("disk trouble")

    monkeypatch.setattr(analysis.report.report_tables, "write_tables", crash)
    with pytest.raises(RuntimeError, match="disk trouble"):
        main(["report", "--db", str(dbs[0]), "--out", str(out), "--force"])
    assert {p.relative_to(out).as_posix(): p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    assert [p.name for p in tmp_path.iterdir()] == ["rep"]  # no temporary folder left beside it


def test_the_report_is_as_private_as_the_database_and_keeps_a_folder_s_permissions(dbs, tmp_path, capsys):
    (tmp_path / "kept").mkdir()
    (tmp_path / "kept").chmod(0o750)
    old = os.umask(0o000)  # a permissive umask does not make the report world-readable
    try:
        assert _run(capsys, "report", "--db", str(dbs[0]), "--out", str(tmp_path / "r"))[0] == 0
        assert _run(capsys, "report", "--db", str(dbs[0]), "--out", str(tmp_path / "kept"))[0] == 0
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "r").stat().st_mode) == 0o700
    assert stat.S_IMODE((tmp_path / "kept").stat().st_mode) == 0o750  # an existing folder is written into, as it is
    for out in (tmp_path / "r", tmp_path / "kept"):
        assert stat.S_IMODE((out / "report.html").stat().st_mode) == 0o600
        assert stat.S_IMODE((out / "figures").stat().st_mode) == 0o700


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
    code, out, _ = _run(capsys, "plot-trial", "--db", str(dbs[0]), "--session", "1", "--trial", "1", "--out", str(png))
    assert code == 0 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and f"wrote {png}" in out
    code, _, _ = _run(capsys, "plot-trial", "--db", str(dbs[0]), "--session", "1", "--trial", "7",
                      "--out", str(tmp_path / "t.pdf"))
    assert code == 0 and (tmp_path / "t.pdf").read_bytes()[:5] == b"%PDF-"
    code, _, err = _run(capsys, "plot-trial", "--db", str(dbs[0]), "--session", "1", "--trial", "1",
                        "--out", str(png))
    assert code == 2 and "t.png: exists; plot-trial writes a new file only and never replaces one" in err
    png = tmp_path / "u.png"
    code, _, err = _run(capsys, "plot-trial", "--db", str(dbs[0]), "--session", "1", "--trial", "99",
                        "--out", str(png))
    assert code == 2 and "no such trial in session 1; its stored trials are 1–7" in err
    code, _, err = _run(capsys, "plot-trial", "--db", str(dbs[0]), "--session", "99", "--trial", "1",
                        "--out", str(png))
    assert code == 2 and "sessions with trials: 1, 2, 3, 4, 5" in err and "haptic-study sessions" in err
    with pytest.raises(SystemExit) as exit_:  # refused while parsing the arguments
        _run(capsys, "plot-trial", "--db", str(dbs[0]), "--session", "1", "--trial", "0", "--out", str(png))
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "--trial = '0': must be a whole number from 1" in err and "numbered from 1" in err
    code, _, err = _run(capsys, "plot-trial", "--db", str(dbs[0]), "--session", "1", "--trial", "1",
                        "--out", str(tmp_path / "t.jpg"))
    assert code == 2 and "must end in .png, .pdf or .svg" in err


def test_the_trace_axis_is_set_by_the_target_not_by_the_data():
    from protocol.study.display import task_axis_top_n

    assert task_axis_top_n(0.6, 0.7) == pytest.approx(1.5)       # band 0.54-0.66 N: 8 % of the axis
    assert task_axis_top_n(0.6, 2.0) == pytest.approx(2.1)       # a peak up to 4 F* stretches it
    assert task_axis_top_n(0.6, 2.0, snap_fraction=0.5) == pytest.approx(2.1)  # 3.5 F*: on a step already
    assert task_axis_top_n(0.6, 1.7, snap_fraction=0.5) == pytest.approx(1.8)
    assert task_axis_top_n(0.6, 18.0) == pytest.approx(2.4)      # beyond, clipped (and said in the figure)
    assert task_axis_top_n(None, 7.6) == pytest.approx(8.36)
    assert task_axis_top_n(0.6, math.nan) == pytest.approx(1.5)


def test_sessions_lists_every_session_with_its_trials(dbs, capsys):
    code, out, _ = _run(capsys, "sessions", "--db", str(dbs[0]))
    assert code == 0
    assert out.splitlines()[0].endswith("5 sessions, 4 participants")
    line = next(ln for ln in out.splitlines() if ln.split()[:2] == ["1", "A1"])
    assert line.split()[3:7] == ["experiment", "completed", "sim", "6/7"]
    code, out, _ = _run(capsys, "sessions", "--db", str(dbs[0]), "--json")
    rows = json.loads(out)
    assert rows[0]["trials_aborted"] == 1 and rows[0]["first_trial"] == 1 and rows[0]["last_trial"] == 7


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
