"""A simulated two-group study end to end: placed in turn, simulated by profile, reported and planned.

Six simulated participants of a protocol with ``[groups]`` (novices and surgeons, the surgeons experienced) are
run by the headless runner; the report writes the group files and section, their codebook entries, and the
group comparison recomputed here from the report's own participants.csv by scipy; ``power --groups`` plans from the
study.  Bad input is refused in one line, exit 2, nothing written.
"""

from __future__ import annotations

import contextlib
import io
import json
import sqlite3
from pathlib import Path

import pandas as pd
import pytest
from scipy import stats as sps

from analysis.report.report import build_report
from protocol.study.config import load_protocol
from study_app.cli.main import main
from study_app.headless import run_study

PROTOCOL = """
name = "Two groups test"
[[targets]]
label = "GENTLE"
force_n = 0.6
[[targets]]
label = "FIRM"
force_n = 1.2
[design]
trials_per_cell = 2
[trial]
max_trial_s = 6.0
pause_s = 1.0
[training]
enabled = false
[[covariates]]
name = "group"
kind = "category"
levels = ["novice", "resident", "surgeon"]
required = true
[groups]
by = "group"
simulated = ["novice", "surgeon"]
experienced = ["surgeon"]
"""


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("groups")
    proto = folder / "p.toml"
    proto.write_text(PROTOCOL, encoding="utf-8")
    db = folder / "study.db"
    run_study(str(db), participants=6, seed=2, protocol=load_protocol(proto), jobs=1)
    out = folder / "report"
    build_report([db], out, workers=1)
    return {"db": db, "out": out, "folder": folder, "proto": proto}


def _run(args: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main(args)
        except SystemExit as exc:
            rc = int(exc.code or 0)
    return rc, out.getvalue(), err.getvalue()


def test_participants_placed_in_turn_and_simulated_by_profile(study) -> None:
    c = sqlite3.connect(study["db"])
    try:
        groups = dict(c.execute("SELECT p.code, c.value FROM covariates c JOIN participants p USING (participant_id) "
                                "WHERE c.name = 'group'").fetchall())
        configs = {code: json.loads(cfg) for code, cfg in c.execute(
            "SELECT p.code, s.config_json FROM sessions s JOIN participants p USING (participant_id)")}
    finally:
        c.close()
    assert sorted(groups.values()) == ["novice"] * 3 + ["surgeon"] * 3
    for code, group in groups.items():
        assert configs[code].get("participant_profile") == ("experienced" if group == "surgeon" else None)


def test_report_writes_the_group_files(study) -> None:
    out = study["out"]
    groups = pd.read_csv(out / "groups.csv")
    assert set(groups["group"]) == {"novice", "resident", "surgeon"}
    assert groups.groupby("group")["n_participants"].first().to_dict() == {"novice": 3, "resident": 0, "surgeon": 3}
    assert groups.loc[groups["group"] == "resident", "p_value"].isna().all()
    inter = pd.read_csv(out / "group_interaction.csv")
    terms = set(inter["term"].dropna())
    assert {"haptics_on", "group_surgeon", "haptics_on_x_group_surgeon", "target_FIRM"} <= terms
    assert inter["formula"].str.contains("haptics_on × group").all()
    tests = pd.read_csv(out / "group_tests.csv")
    assert set(tests["reference"]) == {"novice"} and set(tests["group"]) == {"surgeon"}
    book = pd.read_csv(out / "codebook.csv")
    mine = book[book["file"].isin(["groups.csv", "group_interaction.csv", "group_tests.csv"])]
    assert len(mine) and mine["description"].notna().all() and (mine["description"].str.len() > 10).all()
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "Between groups: group" in page and "Mann–Whitney U" in page and "MixedLM" in page
    assert "resident</b>, n = 0: not tested" in page


def test_between_groups_recomputed_from_participants_csv(study) -> None:
    per = pd.read_csv(study["out"] / "participants.csv")
    wide = per.pivot(index="participant_code", columns="haptic_mode", values="rmse_N")
    group = per.drop_duplicates("participant_code").set_index("participant_code")["group"]
    diff = wide["on"] - wide["off"]
    sur, nov = diff[group.reindex(diff.index) == "surgeon"], diff[group.reindex(diff.index) == "novice"]
    expected = sps.mannwhitneyu(sur, nov, alternative="two-sided", method="exact")
    row = pd.read_csv(study["out"] / "group_tests.csv").set_index("metric").loc["rmse_N"]
    assert row["u_statistic"] == expected.statistic
    # participants.csv holds means rounded to 4 decimals: the p of ranks is unchanged unless two effects tie there
    assert row["p_value"] == pytest.approx(expected.pvalue, rel=1e-3)


def test_power_groups_from_the_study(study) -> None:
    out = study["folder"] / "power"
    rc, text, err = _run(["power", "--groups", "--db", str(study["db"]), "--out", str(out), "--n", "3,6",
                          "--resamples", "200"])
    assert rc == 0, err
    assert "Two-group study: surgeon against novice (group)" in text
    frame = pd.read_csv(out / "group_power.csv")
    assert set(frame["n_per_group"]) == {3, 6} and frame["power"].between(0, 1).all()
    assert (frame["pool_reference"] <= 3).all() and (frame["resamples"] == 200).all()


@pytest.mark.parametrize(("args", "line"), [
    (["--protocol", "{proto}"], "--protocol = '{proto}': only with --groups --simulated"),
    (["--groups", "--protocol", "{proto}"], "--protocol = '{proto}': only with --groups --simulated (a pilot's"),
])
def test_power_groups_refusals(study, args: list[str], line: str) -> None:
    out = study["folder"] / "refused"
    filled = [a.format(proto=study["proto"]) for a in args]
    rc, _, err = _run(["power", "--db", str(study["db"]), "--out", str(out), *filled])
    assert rc == 2 and err.count("\n") == 1 and line.format(proto=study["proto"]) in err
    assert not out.exists()


def test_power_groups_needs_groups_in_the_protocol(tmp_path: Path) -> None:
    proto = tmp_path / "g.toml"
    proto.write_text(PROTOCOL.replace("[groups]\nby = \"group\"", "[groups]\nby = \"handedness\""), encoding="utf-8")
    rc, _, err = _run(["run", "--participants", "1", "--db", str(tmp_path / "x.db"), "--protocol", str(proto)])
    assert rc == 2 and err.count("\n") == 1
    assert "groups.by = 'handedness': must name a category covariate the protocol declares" in err
    assert not (tmp_path / "x.db").exists()
    plain = tmp_path / "plain.toml"
    plain.write_text(PROTOCOL.split("[groups]")[0], encoding="utf-8")
    rc, _, err = _run(["power", "--groups", "--simulated", "--protocol", str(plain), "--out", str(tmp_path / "p")])
    assert rc == 2 and "declares no [groups]" in err and not (tmp_path / "p").exists()


def test_power_groups_on_a_pilot_without_groups(tmp_path: Path) -> None:
    plain = tmp_path / "plain.toml"
    plain.write_text(PROTOCOL.split("[groups]")[0].replace("trials_per_cell = 2", "trials_per_cell = 1"),
                     encoding="utf-8")
    db = tmp_path / "pilot.db"
    run_study(str(db), participants=1, seed=0, protocol=load_protocol(plain), jobs=1)
    rc, _, err = _run(["power", "--groups", "--db", str(db), "--out", str(tmp_path / "p")])
    assert rc == 2 and err.strip().endswith("--groups: the study's protocol declares no [groups] (which covariate "
                                            "divides the participants); see docs/groups.md")
    assert not (tmp_path / "p").exists()
