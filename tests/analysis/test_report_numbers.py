"""The numbers the report shows: one value per number, no spread of one participant, counts in good English.

* one participant: the headline shows each mean without "± 0.000" (there is no SD of one value), as ``run``'s
  summary does;
* a number the page shows in two tables (the Hodges–Lehmann bound in the test table and in the sensitivity
  table) is rounded once, from its unrounded value, in both: a bound of -0.02154 is -0.022 on the page
  (stats.csv keeps it to 4 decimals, -0.0215, which rounded again would read -0.021);
* counts read "1 participant", "1 aborted trial", "1 experiment session did not complete and is left out".
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import pandas as pd
import pytest
from studybuilder import SessionDef, TrialDef, build, success_trial, timeout_trial

from analysis.report import report as report_module
from analysis.report.report import build_report
from analysis.stats import sensitivity as sensitivity_module
from analysis.stats.aggregate import mean_sd
from study_app.cli.main import main


def _aborted(label: str, mode: str) -> TrialDef:
    t = success_trial(label, mode, 0)
    t.outcome_override = "aborted"
    return t


def _session(code: str, i: int) -> SessionDef:
    return SessionDef(code, [success_trial("GENTLE", "on", 100 * i), timeout_trial("GENTLE", "off", 0.2 + 0.05 * i),
                             success_trial("FIRM", "off", 300 + 80 * i), timeout_trial("FIRM", "on", 2.0 + 0.1 * i),
                             success_trial("GENTLE", "off", 500 + 60 * i), success_trial("FIRM", "on", 150 * i)],
                      max_trial_s=4.0)


def _headline(page: str) -> str:
    return page.split('<div class="key">')[1].split("<h2>")[0]


@pytest.fixture(scope="module")
def one_participant(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """P01 complete with one aborted trial; P02's session ended by the experimenter (left out)."""
    d = tmp_path_factory.mktemp("one")
    p01 = _session("P01", 1)
    p01.trials.insert(2, _aborted("FIRM", "on"))
    p02 = SessionDef("P02", [success_trial("GENTLE", "on", 200)], max_trial_s=4.0, status="aborted",
                     end_reason="test", designed=6)
    db = build(d / "one.db", [p01, p02])
    return db, str(d / "rep")


def test_one_participant_has_no_sd(one_participant: tuple[Path, str], capsys: pytest.CaptureFixture[str]) -> None:
    db, out = one_participant
    assert main(["report", "--db", str(db), "--out", out]) == 0
    printed = capsys.readouterr().out
    page = Path(out, "report.html").read_text(encoding="utf-8")
    head = _headline(page)
    assert "±" not in head and "0.000 ±" not in head, head
    assert "OFF → ON, 1 participant: one value per mode, no spread;" in head
    mean, sd, n = mean_sd(pd.Series([0.4]))
    assert (mean, n) == (0.4, 1) and math.isnan(sd)
    # -- and the counts read as English
    assert re.search(r": 1 participant, \d+ trials, [\d,]+ samples \(excluded: 0 training trials, 1 aborted trial\)",
                     printed), printed
    assert "1 experiment session did not complete and is left out; see What was delivered." in page
    assert "1 participants" not in page and "1 aborted trials" not in page


@pytest.fixture(scope="module")
def three(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build(tmp_path_factory.mktemp("three") / "three.db", [_session(f"P0{i}", i) for i in range(1, 4)])


def test_a_number_shown_twice_is_rounded_once_from_its_unrounded_value(
        three: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    real = report_module.mode_tests

    def bound(per: pd.DataFrame, *args: object, **kwargs: object) -> tuple[object, pd.DataFrame]:
        """The tests as computed, with RMSE's Hodges–Lehmann interval set to one whose upper bound is -0.02154."""
        results, frame = real(per, *args, **kwargs)  # type: ignore[arg-type]
        rmse = frame["metric"] == "rmse_n"
        frame.loc[rmse, ["hl_estimate", "hl_ci_low", "hl_ci_high"]] = (-0.3, -0.5, -0.02154)
        return results, frame

    monkeypatch.setattr(report_module, "mode_tests", bound)
    monkeypatch.setattr(sensitivity_module, "mode_tests", bound)
    build_report([three], tmp_path / "rep", workers=1)
    stats = pd.read_csv(tmp_path / "rep" / "stats.csv").set_index("metric")
    assert stats.at["rmse_N", "hl_ci_high"] == -0.0215  # the file: 4 decimals
    page = (tmp_path / "rep" / "report.html").read_text(encoding="utf-8")
    test_table = page.split('<table class="stats">')[1].split("</table>")[0]
    rmse_row = next(r for r in test_table.split("<tbody>")[1].split("<tr") if "RMSE" in r)
    assert "-0.300 [-0.500, -0.022]" in rmse_row, rmse_row
    sens = page.split('<table class="within sens">')[1].split("</table>")[0]
    sens_row = next(r for r in sens.split("<tbody>")[1].split("<tr") if "RMSE" in r)
    assert "-0.300 [-0.500, -0.022]" in sens_row, sens_row
    assert "-0.021]" not in page


def test_a_p_value_reads_the_same_on_the_page_in_the_csv_and_on_the_terminal(
        three: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """An exact p of 1/32 is 0.03125 in stats.csv and on the terminal; the page showed 0.0312 in its test table
    and 0.031 in its headline (three renderings of one number), and the headline did not say how many pairs the
    test ranked.  The terminal rounded stats.csv's rounded numbers again (a median of 2.49651: 2.4965 in the file,
    2.496 on the terminal, 2.497 on the page) and did not say why a test ranked fewer pairs than participants."""
    real = report_module.mode_tests

    def exact(per: pd.DataFrame, *args: object, **kwargs: object) -> tuple[object, pd.DataFrame]:
        results, frame = real(per, *args, **kwargs)  # type: ignore[arg-type]
        frame.loc[frame["metric"] == "rmse_n", ["p_value", "p_holm", "median_off"]] = (0.03125, 0.03125, 2.49651)
        return results, frame

    monkeypatch.setattr(report_module, "mode_tests", exact)
    out = tmp_path / "rep"
    assert main(["report", "--db", str(three), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    # the choices that change the numbers, as the page's header names them (TCT: the figure's reading by default)
    assert "Holm-adjusted; error window: cue, TCT: censored, zero differences: wilcox):" in printed, printed
    rmse_line = next(line for line in printed.splitlines() if line.strip().startswith("rmse_N"))
    assert rmse_line.split()[4:6] == ["0.03125", "0.03125"], rmse_line
    stats = pd.read_csv(out / "stats.csv").set_index("metric")
    assert stats.at["rmse_N", "p_value"] == stats.at["rmse_N", "p_holm"] == 0.03125
    assert stats.at["rmse_N", "median_off"] == 2.4965  # rounded once: the terminal does not make it 2.496
    for metric in stats.index:  # the terminal prints stats.csv's numbers as the file has them, not rounded again
        line = next(row for row in printed.splitlines() if row.strip().startswith(metric + " "))
        shown = [float(v) for v in line.split()[1:6]]
        assert shown == pytest.approx(list(stats.loc[metric, ["n", "median_off", "median_on", "p_value", "p_holm"]]),
                                      rel=0, abs=0, nan_ok=True), line
    for metric in stats.index[stats["n"] < 3]:  # why a test ranked fewer pairs than there are participants
        assert f"  {metric}: {int(stats.at[metric, 'n_pairs'])} complete pair" in printed, printed
    page = (out / "report.html").read_text(encoding="utf-8")
    test_table = page.split('<table class="stats">')[1].split("</table>")[0]
    rmse_row = next(r for r in test_table.split("<tbody>")[1].split("<tr") if "RMSE" in r)
    assert rmse_row.count("<td>0.03125</td>") == 2, rmse_row
    card = next(c for c in _headline(page).split("<div>") if c.startswith("RMSE"))
    assert f"Wilcoxon n = {int(stats.at['rmse_N', 'n'])}, p (Holm) = 0.03125," in card, card
    assert "0.0312<" not in page and "= 0.031," not in page


def test_databases_of_two_trial_caps_merged_are_named_at_the_top_and_on_the_terminal(
        three: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``report --db a --db b`` where b's sessions ran another protocol (a 6 s cap, not 4 s: success and TCT mean
    something else) pooled them into one test; only the methods said "4 s / 6 s"."""
    other = _session("P04", 4)
    other.max_trial_s = 6.0
    six = build(tmp_path / "six.db", [other])
    out = tmp_path / "rep"
    assert main(["report", "--db", str(three), "--db", str(six), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    said = ("The analysed sessions ran under different trial rules (band ±10%, hold 1 s, cap 4 s: 3 sessions "
            "(three.db); band ±10%, hold 1 s, cap 6 s: 1 session (six.db))")
    assert f"haptic-study: warning: {said}" in err, err
    page = (out / "report.html").read_text(encoding="utf-8")
    top = page.split("<h2>")[0]
    assert f'<p class="warn">{said}' in top, top[-2000:]
    assert "different targets" not in page and "different pipeline settings" not in page
    # six.db numbered its participant from 1, as three.db did: two participants hold number 1
    numbers = "Participant numbers repeat across the analysed sessions (1: P01 (three.db), P04 (six.db)): "
    assert f"haptic-study: warning: {numbers}" in err and f'<p class="warn">{numbers}' in top, err
    # one protocol: no such warning
    assert main(["report", "--db", str(three), "--out", str(tmp_path / "one")]) == 0
    assert "ran under different" not in capsys.readouterr().err  # nor numbers that repeat
    assert "Participant numbers repeat" not in (tmp_path / "one" / "report.html").read_text(encoding="utf-8")
    assert "ran under different" not in (tmp_path / "one" / "report.html").read_text(encoding="utf-8")


def test_every_interval_is_headed_with_the_level_it_was_computed_at(three: Path, tmp_path: Path) -> None:
    """``--confidence 0.9``: the intervals of r_rm, the models and the sensitivity table are 90 % intervals, but
    their headings said "95 % CI"; and ``--tct censored`` read "Over the all trials, failures at the trial cap"."""
    out = tmp_path / "rep"
    assert main(["report", "--db", str(three), "--out", str(out), "--confidence", "0.9", "--tct", "censored"]) == 0
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "95 % CI" not in page and "95%" not in page, re.findall(r".{60}95 ?%.{20}", page)
    assert "<th>90 % CI</th>" in page and "r_rm [90 % CI]" in page and "shift ON − OFF [90 % CI]" in page
    assert "Over the all trials" not in page and "every trial, a failed trial counted at the trial cap" in page
