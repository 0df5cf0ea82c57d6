"""Two sites pooled on the fly (issue 41): ``report --db A.db --site A --db B.db --site B``.

Two databases that each numbered their participants from 1 (both hold a P01): named by site they are re-coded
``A:P01`` and ``B:P01`` as they are read (the files untouched), every model has a site term, the page has a table
per site whose tests equal SciPy's on participants.csv, a Kruskal–Wallis test of whether the effect differs
between the sites equal to SciPy's, and the methods say the sites were pooled.  A participant number held at both
sites stays a warning.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats as sps
from studybuilder import SessionDef, build, success_trial, timeout_trial

from study_app.cli.main import main


def _session(code: str, i: int, slow_ms: int) -> SessionDef:
    return SessionDef(code, [success_trial("GENTLE", "on", 100 + 30 * i), timeout_trial("GENTLE", "off", 0.2),
                             success_trial("FIRM", "off", slow_ms + 70 * i), success_trial("FIRM", "on", 200 + 9 * i),
                             success_trial("GENTLE", "off", slow_ms + 40 * i), timeout_trial("FIRM", "on", 2.0)],
                      max_trial_s=4.0)


@pytest.fixture(scope="module")
def pooled(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path, dict[Path, str]]:
    d = tmp_path_factory.mktemp("sites")
    a = build(d / "a.db", [_session(f"P0{i}", i, 600) for i in range(1, 5)])
    b = build(d / "b.db", [_session(f"P0{i}", i, 1200) for i in range(1, 5)])
    digests = {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in (a, b)}
    out = d / "rep"
    assert main(["report", "--db", str(a), "--site", "A", "--db", str(b), "--site", "B", "--out", str(out)]) == 0
    return a, b, out, digests


def test_codes_clash_without_sites_and_are_recoded_with_them(pooled, tmp_path: Path) -> None:
    a, b, out, digests = pooled
    assert main(["report", "--db", str(a), "--db", str(b), "--out", str(tmp_path / "x")]) == 2  # P01 twice
    per = pd.read_csv(out / "participants.csv")
    assert sorted(per["participant_code"].unique()) == [f"{s}:P0{i}" for s in "AB" for i in range(1, 5)]
    sessions = pd.read_csv(out / "sessions.csv")
    assert set(zip(sessions["site"], sessions["participant_code"].str[0], strict=True)) == {("A", "A"), ("B", "B")}
    assert {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in (a, b)} == digests  # read, never written


def test_per_site_tests_equal_scipy_on_participants_csv(pooled) -> None:
    _, _, out, _ = pooled
    per = pd.read_csv(out / "participants.csv")
    by_site = pd.read_csv(out / "stats_by_site.csv")
    wide = per.assign(site=per["participant_code"].str[0]).pivot_table(
        index=["site", "participant_code"], columns="haptic_mode", values="rmse_N")
    for site in "AB":
        mine = wide.loc[site]
        d = np.round(mine["on"] - mine["off"], 10)
        ref = sps.wilcoxon(d)
        row = by_site[(by_site["site"] == site) & (by_site["metric"] == "rmse_N")].iloc[0]
        assert int(row["n"]) == len(d)
        assert row["p_value"] == pytest.approx(ref.pvalue, rel=5e-4)  # stats CSVs carry p to 4 significant digits
    diffs = pd.read_csv(out / "site_differences.csv").set_index("metric")
    groups = [(wide.loc[s]["on"] - wide.loc[s]["off"]).to_numpy() for s in "AB"]
    ref = sps.kruskal(*groups)
    assert diffs.loc["rmse_N", "h_statistic"] == pytest.approx(ref.statistic, rel=5e-4)
    assert diffs.loc["rmse_N", "p_value"] == pytest.approx(ref.pvalue, rel=5e-4)


def test_models_have_a_site_term_and_the_page_says_sites_were_pooled(pooled) -> None:
    _, _, out, _ = pooled
    learning = pd.read_csv(out / "learning_models.csv")
    fitted = learning[learning["term"].notna()]
    assert "site_B" in set(fitted["term"]), sorted(set(fitted["term"]))
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "<b>Sites.</b> 2 sites pooled" in page and "<h2>Sites</h2>" in page
    assert "Participant numbers repeat across the analysed sessions" in page  # still a warning
