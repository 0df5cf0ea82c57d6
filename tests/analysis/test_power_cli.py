"""``haptic-study power``, ``report --power`` and ``bench power`` as a researcher runs them."""

from __future__ import annotations

import html.parser
import json
import sqlite3
import subprocess
import sys
from typing import ClassVar

import pandas as pd
import pytest
from studybuilder import SessionDef, build, success_trial, timeout_trial

from analysis.planning.power import POWER_CSV_COLUMNS
from protocol.metrics import tested as which_tested  # (not `tested`: pytest would collect it)
from protocol.tasks.force_regulation import ForceRegulation
from study_app.cli.main import main
from study_app.headless.sim_trials import MODEL_VERSION

PAPER = ForceRegulation().metrics  # the paper's study's metrics (its task's)


def _participant(code: str, i: int) -> SessionDef:
    trials = [success_trial("GENTLE", "on", 100 * i), success_trial("FIRM", "on", 150 * i),
              timeout_trial("GENTLE", "on", 0.2 + 0.05 * i), success_trial("FIRM", "off", 400 + 90 * i),
              timeout_trial("GENTLE", "off", 1.0 + 0.1 * i), timeout_trial("FIRM", "off", 2.0)]
    if i % 3 == 0:  # no success with haptics OFF: TCT undefined for this participant
        trials[3] = timeout_trial("FIRM", "off", 2.5)
    return SessionDef(code, trials, max_trial_s=4.0)


@pytest.fixture(scope="module")
def pilots(tmp_path_factory):
    d = tmp_path_factory.mktemp("pilots")
    six = build(d / "pilot.db", [_participant(f"A{i}", i) for i in range(1, 7)])
    three = build(d / "tiny.db", [_participant(f"B{i}", i) for i in range(1, 4)])
    return six, three


def _html_table(page: str) -> pd.DataFrame:
    """The first table of a page: its head and body cells (text only) as a frame."""
    class Cells(html.parser.HTMLParser):
        head: ClassVar[list[str]] = []
        rows: ClassVar[list[list[str]]] = []
        cell: list[str] | None = None

        def handle_starttag(self, tag, attrs):
            if tag == "tr":
                self.rows.append([])
            elif tag in ("td", "th"):
                self.cell = []

        def handle_endtag(self, tag):
            if tag in ("td", "th") and self.cell is not None:
                (self.head if tag == "th" else self.rows[-1]).append("".join(self.cell).strip())
                self.cell = None

        def handle_data(self, data):
            if self.cell is not None:
                self.cell.append(data)

    p = Cells()
    p.head, p.rows = [], []
    p.feed(page[page.index("<table"): page.index("</table>")])
    return pd.DataFrame([r for r in p.rows if r], columns=p.head)


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_power_from_a_pilot_writes_table_words_and_figure(pilots, tmp_path, capsys):
    out = tmp_path / "plan"
    # TCT over successful trials (the paper's text), where a participant with no success in a mode has none
    code, stdout, stderr = _run(capsys, "power", "--db", pilots[0], "--out", out, "--resamples", "400",
                                "--n", "6,10,16", "--tct", "successful")
    assert code == 0, stderr
    assert "Source: the pilot study pilot.db; 6 participants with both haptic modes" in stdout
    assert "TCT (s) is undefined for 2 of 6 participants (no successful trial in a mode)" in stdout
    assert "resampled Wilcoxon tests (and Holm) in" in stderr
    for name in ("power.csv", "power.txt", "power.png", "power.pdf", "power.svg"):
        assert (out / name).stat().st_size > 500, name
    assert "Power at each n (overall; the two-sided rejection rate in brackets):" in stdout
    frame = pd.read_csv(out / "power.csv")
    assert list(frame.columns[: len(POWER_CSV_COLUMNS)]) == list(POWER_CSV_COLUMNS)
    assert sorted(set(frame["n"])) == [6, 10, 16] and set(frame["resamples"]) == {400}
    assert set(frame["scope"]) == {"overall", "GENTLE", "FIRM"}
    assert set(frame["metric"]) == {*(m.participant_exported for m in which_tested(PAPER)), "all_four_holm", "any_holm"}
    shown = frame[["power", "ci_low", "ci_high", "two_sided_ci_high"]].to_numpy().ravel()
    assert all(v != v or v == round(v, 4) for v in shown)  # rounded as the codebook says (NaN: a family row)
    assert (out / "power.txt").read_text().strip() == stdout.split("\nWritten in")[0].strip()
    marker = json.loads((out / ".haptic-study-power").read_text())
    assert sorted(marker["files"]) == ["power.csv", "power.pdf", "power.png", "power.svg", "power.txt"]
    argv = ("power", "--db", pilots[0], "--out", out, "--resamples", "400", "--n", "6,10,16", "--tct", "successful")
    # a second run needs --force; it replaces its own files and gives the same numbers for the same seed
    code, _, stderr = _run(capsys, *argv)
    assert code == 2 and "the folder exists and holds power.csv and 4 more" in stderr and "pass --force" in stderr
    assert _run(capsys, *argv, "--force")[0] == 0
    pd.testing.assert_frame_equal(pd.read_csv(out / "power.csv"), frame)
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary folder left


def test_power_force_replaces_only_its_own_unedited_files(pilots, tmp_path, capsys):
    out = tmp_path / "plan"
    argv = ("power", "--db", pilots[0], "--out", out, "--resamples", "50", "--n", "6")
    assert _run(capsys, *argv)[0] == 0
    (out / "notes.md").write_text("mine")  # someone else's file: a refusal naming it, nothing touched
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    code, stdout, stderr = _run(capsys, *argv, "--force")
    assert code == 2 and stdout == ""
    assert stderr == (f"haptic-study: error: --out {out}: holds notes.md, which power did not write; move it or "
                      "choose another folder (nothing was deleted)\n")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    (out / "notes.md").unlink()
    with (out / "power.txt").open("a") as f:  # an edited output: the same
        f.write("my reading of it\n")
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    code, _, stderr = _run(capsys, *argv, "--force")
    assert code == 2 and stderr.count("\n") == 1 and "power.txt was changed since power wrote it" in stderr
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_power_refuses_a_pilot_inside_the_output_folder(pilots, tmp_path, capsys):
    out = tmp_path / "plan"
    out.mkdir()
    db = out / "pilot.db"
    db.write_bytes(pilots[0].read_bytes())
    code, _, stderr = _run(capsys, "power", "--db", db, "--out", out, "--force", "--resamples", "50")
    assert code == 2 and stderr.count("\n") == 1 and f"--out {out}: holds the input database {db}" in stderr
    assert [p.name for p in out.iterdir()] == ["pilot.db"]


def test_power_crashing_while_writing_leaves_the_old_output(pilots, tmp_path, capsys, monkeypatch):
    import analysis.planning.power_figures

    out = tmp_path / "plan"
    argv = ("power", "--db", pilots[0], "--out", out, "--resamples", "50", "--n", "6")
    assert _run(capsys, *argv)[0] == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def broken(result):
        raise RuntimeError("the figure crashed")

    monkeypatch.setattr(analysis.planning.power_figures, "power_curves", broken)
    with pytest.raises(RuntimeError, match="the figure crashed"):
        main([str(a) for a in (*argv[:-2], "--n", "8", "--force")])
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_power_refuses_a_pilot_of_three_in_one_line(pilots, tmp_path, capsys):
    code, _, stderr = _run(capsys, "power", "--db", pilots[1], "--out", tmp_path / "o")
    assert code == 2
    lines = [ln for ln in stderr.splitlines() if ln.startswith("haptic-study:")]
    assert lines == ["haptic-study: error: the pilot study tiny.db has 3 participants with both haptic modes: at "
                     "least 4 are needed to resample planned studies from (with fewer, every resampled study "
                     "repeats the same few people)"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--n", "0"], "--n = '0': each n must be a whole number from 2 to 10000, comma-separated (e.g. 6,8,10,12)"),
        (["--n", "abc"], "--n = 'abc': each n must be a whole number from 2 to 10000"),
        (["--n", "6,,8"], "--n = '6,,8': each n must be a whole number"),
        (["--n", "4,8,4"], "--n = '4,8,4': 4 is given twice; give each n once"),
        (["--resamples", "-1"], "--resamples = '-1': must be a whole number from 1 to 1000000"),
        (["--resamples", "1.5"], "--resamples = '1.5': must be a whole number from 1 to 1000000"),
        (["--alpha", "2"], "--alpha = '2': must be a number with 0 < alpha < 1 (e.g. 0.05)"),
        (["--alpha", "nan"], "--alpha = 'nan': must be a number with 0 < alpha < 1"),
        (["--seed", "-3"], "--seed = '-3': must be a whole number from 0 to 4294967295"),
        (["--pool", "50"], "--pool = '50': only with --simulated"),
    ],
)
def test_bad_values_are_one_line_naming_the_option(pilots, tmp_path, capsys, args, message):
    code, stdout, stderr = _run(capsys, "power", "--db", pilots[0], "--out", tmp_path / "o", *args)
    assert code == 2 and stdout == ""
    assert stderr == f"haptic-study: error: {message}\n" if message.endswith(")") else message in stderr
    assert len(stderr.splitlines()) == 1
    assert not (tmp_path / "o").exists()  # nothing written, nothing simulated


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--out", "o"], "power needs a source: --db PILOT.db (a pilot study) or --simulated (simulated participants)"),
        (["--db", "x.db", "--simulated", "--out", "o"], "--db and --simulated: give one or the other"),
        (["--simulated", "--pool", "3", "--out", "o"], "--pool = '3': must be a whole number from 4 to 10000"),
        (["--simulated"], "--out: give the output folder (DIR)"),
        (["--db", "missing.db", "--out", "o"], "missing.db: no such database"),
    ],
)
def test_bad_sources_are_one_line(tmp_path, capsys, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    code, _, stderr = _run(capsys, "power", *args)
    assert code == 2
    assert message in stderr and len(stderr.splitlines()) == 1
    assert not list(tmp_path.iterdir())


def test_bad_value_in_a_fresh_process_has_no_traceback(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "study_app.cli", "power", "--simulated", "--n", "0", "--out",
                           str(tmp_path / "o")], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == ["haptic-study: error: --n = '0': each n must be a whole number from 2 to "
                                        "10000, comma-separated (e.g. 6,8,10,12)"]


@pytest.mark.slow
def test_simulated_pool_is_simulated_once_then_reused(tmp_path, capsys, monkeypatch):
    import dataclasses

    import protocol.study.config

    # the paper's protocol with one trial per cell and no training: the same runner, a sixth of the simulation
    paper = protocol.study.config.default_protocol()
    short = dataclasses.replace(paper, trials_per_cell=1, training=dataclasses.replace(paper.training, enabled=False),
                                trial=dataclasses.replace(paper.trial, pause_s=0.1))  # short pauses: fewer ticks
    monkeypatch.setattr(protocol.study.config, "default_protocol", lambda: short)
    out = tmp_path / "plan"
    argv = ("power", "--simulated", "--pool", "4", "--seed", "7", "--resamples", "200", "--n", "6,10", "--out", out)
    code, stdout, stderr = _run(capsys, *argv)
    assert code == 0, stderr
    pool = out / "pool-4-seed7.db"
    assert pool.is_file()
    assert f"simulated pool written to {pool}" in stderr and "simulating pool" in stderr  # the progress bar
    assert (f"Source: a simulated pool of 4 participants of participant model v{MODEL_VERSION} (study seed 7, "
            "pool-4-seed7.db); 4 participants") in stdout
    first = pd.read_csv(out / "power.csv")

    def sessions() -> list[tuple]:
        c = sqlite3.connect(f"file:{pool}?mode=ro", uri=True)
        try:
            return c.execute("SELECT session_id, kind, status FROM sessions ORDER BY session_id").fetchall()
        finally:
            c.close()

    before = sessions()
    assert [s[1:] for s in before].count(("experiment", "completed")) == 4
    pool_bytes = pool.read_bytes()
    assert "pool-4-seed7.db" not in json.loads((out / ".haptic-study-power").read_text())["files"]
    code, stdout2, stderr2 = _run(capsys, *argv, "--force")  # --force replaces the outputs, never the pool
    assert code == 0
    assert f"reusing the simulated pool {pool} (SHA-256 checked)" in stderr2 and "simulating pool" not in stderr2
    assert sessions() == before and pool.read_bytes() == pool_bytes
    pd.testing.assert_frame_equal(pd.read_csv(out / "power.csv"), first)
    assert stdout2 == stdout
    # a fresh folder holding only the pool (and its record) needs no --force
    only_pool = tmp_path / "only-pool"
    only_pool.mkdir()
    for p in out.glob("pool-*"):
        (only_pool / p.name).write_bytes(p.read_bytes())
    code, stdout3, stderr3 = _run(capsys, "power", "--simulated", "--pool", "4", "--seed", "7", "--resamples", "200",
                                  "--n", "6,10", "--out", only_pool)
    assert code == 0 and "reusing the simulated pool" in stderr3
    assert stdout3.split("\nWritten in")[0] == stdout.split("\nWritten in")[0]


def test_report_power_adds_the_section(pilots, tmp_path, capsys):
    out = tmp_path / "rep"
    code, _, stderr = _run(capsys, "report", "--db", pilots[0], "--out", out, "--power", "--tct", "successful")
    assert code == 0, stderr
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "<h2>What n would a study need?</h2>" in page
    assert "Resampling this study's 6 participants with both haptic modes" in page
    # a real table built from the result, not preformatted text
    assert "<pre" not in page
    section = page[page.index('<section class="power">'):]
    section = section[: section.index("</section>")]
    table = _html_table(section)
    assert list(table.columns[:7]) == ["target", "measure", "pilot shows", "n for 80 %", "n for 80 % (Holm)",
                                       "n for 90 %", "n for 90 % (Holm)"]
    assert list(table.columns[7:]) == [f"n = {n}" for n in (6, 8, 10, 12, 16, 20, 30)]
    assert len(table) == 3 * (len(which_tested(PAPER)) + 2) and set(table["target"]) == {"overall", "GENTLE", "FIRM"}
    frame = pd.read_csv(out / "power.csv")
    # the measures by the names every CSV and the codebook use (power.csv said rmse_n), numbers rounded as the
    # codebook says (ci_low was 0.01827534035513624)
    assert set(frame["metric"]) == {*(m.participant_exported for m in which_tested(PAPER)), "all_four_holm", "any_holm"}
    shown = frame[["power", "ci_low", "ci_high", "holm_ci_low"]].to_numpy().ravel()
    assert all(v != v or v == round(v, 4) for v in shown)
    rmse = frame[(frame["scope"] == "overall") & (frame["metric"] == "rmse_N")].set_index("n")
    row = table[(table["target"] == "overall") & (table["measure"] == "RMSE (N)")].iloc[0]
    assert row["n = 10"] == f"{rmse.at[10, 'power']:.0%}" and row["pilot shows"] == "ON < OFF"
    assert "undefined for 2 of 6 participants" in section  # the notes, as a list
    assert (out / "power.csv").is_file() and (out / "figures" / "power.png").stat().st_size > 1000
    assert page.index("What n would a study need?") < page.index("<h2>Methods</h2>")
    # power.csv is described in the codebook like every other CSV of the report
    book = pd.read_csv(out / "codebook.csv", keep_default_na=False)
    described = book[book["file"] == "power.csv"]
    assert list(described["column"]) == list(pd.read_csv(out / "power.csv", nrows=0).columns)
    assert (described["description"] != "").all()
    # without --power the report is as before
    code, _, _ = _run(capsys, "report", "--db", pilots[0], "--out", tmp_path / "plain")
    assert "What n would" not in (tmp_path / "plain" / "report.html").read_text(encoding="utf-8")
    assert not (tmp_path / "plain" / "power.csv").exists()


def test_report_power_of_three_participants_says_why_not(pilots, tmp_path, capsys):
    from analysis.planning.power_outputs import report_section
    from analysis.reading.load import load_study
    from analysis.reading.metrics import MetricOptions, compute_trials

    trials = compute_trials(load_study([pilots[1]]), workers=1).trials
    section = report_section(trials, MetricOptions(), "wilcox", tmp_path)
    assert section.result is None and section.png is None
    assert section.notice.startswith("Not estimated: this study has 3 participants with both haptic modes: at least 4 "
                                     "are needed")
    assert not list(tmp_path.iterdir())
    # and the report shows it, visibly, where the section would be
    code, _, stderr = _run(capsys, "report", "--db", pilots[1], "--out", tmp_path / "rep", "--power")
    assert code == 0, stderr
    page = (tmp_path / "rep" / "report.html").read_text(encoding="utf-8")
    assert ('<h2>What n would a study need?</h2><p class="warn">Not estimated: this study has 3 participants with '
            "both haptic modes") in page
    assert not (tmp_path / "rep" / "power.csv").exists()


def test_report_power_table_leaves_out_empty_columns(monkeypatch):
    import analysis.planning.power_plan
    from analysis.planning.paired_pool import pool_from_trials
    from analysis.planning.power import estimate_power
    from analysis.planning.power_outputs import ReportPower
    from analysis.planning.power_plan import plan_table
    from analysis.report.power_section import power_html as _power_html

    trials = pd.DataFrame([dict(participant_code=f"P{p}", target_label="GENTLE", target_force_n=0.6, haptic_mode=m,
                                success=True, tct_s=3.0 + p + (m == "on"), rmse_n=1.0 + p * (m == "on"),
                                max_ae_n=2.0, time_in_band_s=1.0, peak_force_n=1.0, tct_censored_s=3.0)
                           for p in range(6) for m in ("off", "on")])
    result = estimate_power(pool_from_trials(trials), (6, 10), resamples=50)
    full = _power_html(ReportPower(result, "", None), PAPER)
    assert "<th>pilot shows</th>" in full and "<th>n for 80 %</th>" in full

    def without_direction(r):
        t = plan_table(r)
        t["direction"] = ""
        return t

    monkeypatch.setattr(analysis.planning.power_plan, "plan_table", without_direction)
    page = _power_html(ReportPower(result, "", None), PAPER)
    assert "pilot shows" not in page and "<th>n for 80 %</th>" in page  # the column and the words naming it
    assert page.count("<td") == full.count("<td") - len(plan_table(result))


def test_bench_power_agrees_with_the_paired_wilcoxon_loop(capsys):
    from bench.power_bench import format_power_bench, run_power_bench

    r = run_power_bench(resamples=60, reference_resamples=6, n_values=(6, 12, 30), repeats=1)
    assert r["identical_p_values"] == r["identical_sides"] == r["sided_tests"] == r["reference_tests"] == 6 * 3 * 4
    text = format_power_bench(r)
    assert "paired_wilcoxon loop" in text and "speed-up" in text
    code, _, _ = _run(capsys, "bench", "power", "--resamples", "50", "--reference-resamples", "60")
    assert code == 2  # the reference cannot run more studies than the engine


def test_parser_default_n_is_the_analysis_default_and_needs_no_analysis_import():
    from analysis.planning.power import DEFAULT_N_VALUES
    from study_app.cli.power_cmds import DEFAULT_N_TEXT

    assert ",".join(str(n) for n in DEFAULT_N_VALUES) == DEFAULT_N_TEXT
    proc = subprocess.run([sys.executable, "-c", "import sys; from study_app.cli.main import build_parser; "
                          "build_parser(); "
                           "print(sorted(m for m in ('pandas', 'scipy', 'matplotlib', 'numba') if m in sys.modules))"],
                          capture_output=True, text=True, timeout=60)
    assert proc.stdout.strip() == "[]"



def test_a_long_request_says_its_size_and_memory_before_its_work(capsys: pytest.CaptureFixture[str]) -> None:
    from study_app.cli.power_cmds import _PowerRequest, _say_the_size

    _say_the_size(_PowerRequest((6, 8), 1_000_000, 0.05, 0, 100))
    said = capsys.readouterr().err
    assert "1,000,000 resampled studies for each of 2 sizes (14,000,000 participants drawn; at most" in said
    assert "MiB at once" in said and "how long is left" in said
    _say_the_size(_PowerRequest((6, 8), 2000, 0.05, 0, 100))  # seconds of work: nothing to say
    assert capsys.readouterr().err == ""
