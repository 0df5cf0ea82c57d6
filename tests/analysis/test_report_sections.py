"""The report's per-task seam (:mod:`analysis.report.task_sections`): each task's section found from its kind, given its
own sessions, on the page, in the files and on the command line -- with no task named by the report or the command.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd
import pytest
from studybuilder import SessionDef, build, success_trial, timeout_trial

from analysis.report import section_tracking
from analysis.report.task_sections import (
    SectionInput,
    SectionOutput,
    register,
    section_for,
    section_modules,
    sections_page,
    study_parts,
)
from protocol.tasks.registry import TASKS
from study_app.cli.main import main


def test_every_module_of_the_folder_is_a_section_of_a_known_kind_and_no_kind_has_two() -> None:
    seen: dict[str, str] = {}
    names = section_modules()
    assert {"analysis.report.section_tracking", "analysis.report.section_discrimination"} <= set(names)
    for name in names:
        section = importlib.import_module(name).SECTION
        assert section.kinds, name
        for kind in section.kinds:
            assert kind in TASKS, (name, kind)
            assert kind not in seen, (kind, seen.get(kind), name)
            seen[kind] = name
            assert section_for(kind) is section
    assert section_for("force_regulation") is None  # the paper's task: the core's report alone


@dataclass
class _Toy:
    """A lab's own section for the paper's task, written here alone: it says what it was given."""

    kinds: tuple[str, ...] = ("force_regulation",)
    given: list[SectionInput] = field(default_factory=list)

    def build(self, given: SectionInput, folder: Path) -> SectionOutput:
        self.given.append(given)
        (folder / "figures" / "toy.txt").write_text(f"{len(given.trials)} trials\n", encoding="utf-8")
        return SectionOutput("Toy section", f"<p>{len(given.sessions)} sessions, {len(given.trials)} trials, "
                             f"{len(given.stats)} tests</p>", files=("figures/toy.txt",),
                             lines=(f"toy: {given.kind}",))


def _participant(code: str, i: int) -> SessionDef:
    trials = [success_trial("GENTLE", "on", 100 * i), success_trial("FIRM", "off", 300 + 80 * i),
              timeout_trial("GENTLE", "off", 0.3 + 0.05 * i), success_trial("FIRM", "on", 120 * i)]
    return SessionDef(code, trials, max_trial_s=4.0)


def test_a_registered_section_is_on_the_page_in_the_files_and_on_the_command_line(tmp_path: Path, capsys) -> None:
    db = build(tmp_path / "a.db", [_participant(f"P{i}", i) for i in range(1, 4)])
    toy = _Toy()
    with register(toy):
        assert main(["report", "--db", str(db), "--out", str(tmp_path / "rep")]) == 0
    out = capsys.readouterr().out
    assert "toy: force_regulation" in out.splitlines()
    page = (tmp_path / "rep" / "report.html").read_text(encoding="utf-8")
    # in the core's page, where a task's section goes: after the per-participant tables, before the trace figures
    at = page.index("<h2>Toy section</h2>\n<p>3 sessions, 12 trials, ")
    assert page.index("Per participant") < at < page.index("<h2>Force through the pipeline</h2>")
    assert (tmp_path / "rep" / "figures" / "toy.txt").read_text(encoding="utf-8") == "12 trials\n"
    (given,) = toy.given
    assert given.kind == "force_regulation" and len(given.sessions) == 3
    assert "max_trial_s" in given.trials.columns and set(given.trials["max_trial_s"]) == {4.0}
    assert len(given.stats) > 0 and "p_value" in given.stats.columns  # the core's tests, unrounded
    assert section_for("force_regulation") is None  # registered for the block only


def test_a_kind_that_has_a_section_cannot_be_given_another() -> None:
    with pytest.raises(ValueError, match="force_tracking"), register(_Toy(kinds=("force_tracking",))):
        pass
    assert section_for("force_tracking") is section_tracking.SECTION


@dataclass
class _Task:
    kind: str


@dataclass
class _Study:
    """What :func:`study_parts` reads of a study: its sessions and each one's task."""

    sessions: pd.DataFrame
    kinds: dict[tuple[str, int], str]

    def task_of(self, database: str, session_id: int) -> _Task:
        return _Task(self.kinds[(database, int(session_id))])


def test_a_study_of_several_tasks_gives_each_its_own_analysed_experiment_sessions_in_order() -> None:
    rows = [("a.db", 1, "training", True, "force_regulation"), ("a.db", 2, "experiment", True, "force_tracking"),
            ("a.db", 3, "experiment", True, "force_regulation"), ("a.db", 4, "experiment", False, "force_regulation"),
            ("b.db", 1, "experiment", True, "force_discrimination"), ("b.db", 2, "experiment", True,
                                                                        "force_tracking")]
    sessions = pd.DataFrame([r[:4] for r in rows], columns=["database", "session_id", "kind", "analysed"])
    study = _Study(sessions, {(r[0], r[1]): r[4] for r in rows})
    parts = study_parts(study)  # type: ignore[arg-type]
    assert [k for k, _ in parts] == ["force_tracking", "force_regulation", "force_discrimination"]
    mine = {k: list(zip(s["database"], s["session_id"], strict=True)) for k, s in parts}
    assert mine == {"force_tracking": [("a.db", 2), ("b.db", 2)], "force_regulation": [("a.db", 3)],
                    "force_discrimination": [("b.db", 1)]}


def test_a_page_of_sections_alone_heads_one_with_its_title_and_several_under_the_report() -> None:
    one = SectionOutput("Force discrimination", "<p>fits</p>")
    empty = SectionOutput("Tracking a moving target", "")
    page = sections_page([one, empty])
    assert "<title>Force discrimination</title>" in page and "<h1>Force discrimination</h1>\n<p>fits</p>" in page
    assert "Tracking" not in page  # a section with nothing to say is left out
    two = sections_page([one, SectionOutput("Another task", "<p>more</p>")])
    assert two.count("<h1>") == 1 and "<h2>Force discrimination</h2>" in two and "<h2>Another task</h2>" in two
