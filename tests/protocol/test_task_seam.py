"""The task seam's proof: a new task written in this one file, registered at run time, runs a simulated study end to
end -- the protocol file names it, the session runner cues and judges its trials, the simulated participant aims at
what it says, the recorder stores its cue words and its metrics, the report reads its rule and its parameters back.

Nothing of the product is edited for it: a task in the product is this module under ``protocol/tasks/`` and its
line in :data:`protocol.tasks.registry.TASKS` (docs/architecture.md, "A task", counts the files a real one touches).

The toy task, *press*: push to at least ``floor_fraction`` of the target force and stay there for ``dwell_s`` -- a
rule with a floor and no ceiling, its two parameters in the file's ``[task]`` table, none in ``[trial]``, and no band
to draw.
"""

from __future__ import annotations

import json
import sqlite3
import tomllib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt
import pandas as pd
import pytest

from pipeline.core.aim import TrialAim
from pipeline.settings.tomlfields import Fields
from protocol.study.config import ProtocolError, protocol_from_dict
from protocol.tasks import registry
from protocol.tasks.base import Parameter, Task, TaskTables, Timing, TrialCondition, TrialScreen, listed
from protocol.tasks.window import TrialMetrics, capped, judged
from study_app.cli.main import main
from study_app.headless import run_study

CAP_S = 4.0


class _Dwell:
    """The streaming rule: the first sample at which the force has been at or above the floor for ``dwell_ns``."""

    def __init__(self, floor_n: float, dwell_ns: int) -> None:
        self.floor_n, self.dwell_ns = floor_n, dwell_ns
        self.since_ns: int | None = None
        self.done = False

    def feed(self, t_ns: int, force_n: float) -> bool:
        if self.done:
            return False
        if force_n >= self.floor_n:  # NaN compares False: below the floor
            self.since_ns = t_ns if self.since_ns is None else self.since_ns
            self.done = t_ns - self.since_ns >= self.dwell_ns
            return self.done
        self.since_ns = None
        return False


@dataclass(frozen=True, slots=True)
class Press(Task):
    """Push to at least ``floor_fraction``·F* and stay there ``dwell_s``."""

    floor_fraction: float = 0.8
    dwell_s: float = 0.2

    kind: ClassVar[str] = "toy_press"
    title: ClassVar[str] = "press"
    metric_names: ClassVar[tuple[str, ...]] = ("success", "tct_s", "rmse_n", "max_ae_n", "peak_force_n")
    task_fields: ClassVar[frozenset[str]] = frozenset({"floor_fraction", "dwell_s"})
    described: ClassVar[tuple[Parameter, ...]] = (
        Parameter("floor_fraction", "the least force of a press as a fraction of F*", "fraction (0–1)", "floor", 4),
        Parameter("dwell_s", "time the force must stay at or above the floor for success", "s", "dwell (s)", 3),
    )

    @classmethod
    def from_tables(cls, f: Fields, task: Mapping[str, Any], trial: Mapping[str, Any]) -> Press:
        return cls(floor_fraction=f.number("task.floor_fraction", task.get("floor_fraction", 0.8), lo=0.0, hi=1.0),
                   dwell_s=f.number("task.dwell_s", task.get("dwell_s", 0.2), lo=0.0, hi=10.0))

    def tables(self) -> TaskTables:
        return {"floor_fraction": self.floor_fraction, "dwell_s": self.dwell_s}, {}

    def check_timing(self, f: Fields, timing: Timing) -> None:
        if self.dwell_s >= timing.max_trial_s:
            raise f.fail("task.dwell_s", self.dwell_s,
                         f"must be shorter than trial.max_trial_s = {timing.max_trial_s:g}")

    def target_n(self, trial: TrialCondition, t_s: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return np.full(len(t_s), float(trial.target_force_n))

    def rule(self, trial: TrialCondition) -> _Dwell:
        return _Dwell(self.floor_fraction * trial.target_force_n, int(round(self.dwell_s * 1e9)))

    def judge(self, t_ns: npt.ArrayLike, force_n: npt.ArrayLike, trial: TrialCondition, *, max_trial_s: float,
              window: str = "cue", sample_period_s: float = 0.001) -> TrialMetrics:
        t, f = capped(t_ns, force_n, max_trial_s, window)
        rule = self.rule(trial)  # the offline form walks the streaming rule: one definition, at the toy's scale
        done = next((i for i, (ti, fi) in enumerate(zip(t.tolist(), f.tolist(), strict=True)) if rule.feed(ti, fi)),
                    None)
        floor, target = self.floor_fraction * trial.target_force_n, float(trial.target_force_n)
        return judged(t, f, done, target_n=lambda times: np.full(len(times), target),
                      on_target=lambda force: force >= floor, max_trial_s=max_trial_s, window=window,
                      sample_period_s=sample_period_s, metrics=self.metrics)

    def cue_text(self, trial: TrialCondition) -> str:
        return f"press {trial.target_label} ≥ {self.floor_fraction * trial.target_force_n:g} N"

    def screen(self, trial: TrialCondition) -> TrialScreen:
        return TrialScreen(cue_word=f"PRESS {trial.target_label}", band=None, band_label="", band_legend="")

    def aim(self, trial: TrialCondition, aid: bool) -> TrialAim:
        return TrialAim.constant(trial.target_force_n, trial.haptic_mode == "on", gauge=aid, practice=aid)

    def rule_words(self) -> str:
        return f"press ≥ {self.floor_fraction:.0%} for {self.dwell_s:g} s"

    @classmethod
    def methods(cls, tasks: Sequence[Task], caps: Sequence[float]) -> str:
        mine = [t for t in tasks if isinstance(t, Press)]
        floors = listed([t.floor_fraction for t in mine], "")
        return (f"A press trial succeeds when the force stays at or above {floors} of F* for "
                f"{listed([t.dwell_s for t in mine], ' s')} within {listed(caps, ' s')} of the cue.")


def _protocol_text(task: str) -> str:
    return f"""name = "toy press"
[[targets]]
label = "GENTLE"
force_n = 0.6
[[targets]]
label = "FIRM"
force_n = 1.2
[design]
modes = ["on", "off"]
trials_per_cell = 1
{task}
[trial]
max_trial_s = {CAP_S}
pause_s = 0.3
[training]
enabled = false
"""


TOY = '[task]\nkind = "toy_press"\nfloor_fraction = 0.75\ndwell_s = 0.25'


@pytest.fixture(scope="module")
def press() -> Iterator[type[Press]]:
    with registry.register(Press) as cls:
        yield cls


@pytest.fixture(scope="module")
def study(press, tmp_path_factory) -> tuple[Path, Path]:
    """Two simulated participants of the toy task (4 trials each), in one process (its registration is this
    process's), and their report."""
    d = tmp_path_factory.mktemp("press")
    db = d / "press.db"
    protocol = protocol_from_dict(tomllib.loads(_protocol_text(TOY)), "press.toml")
    assert protocol.task == Press(floor_fraction=0.75, dwell_s=0.25)
    run_study(str(db), participants=2, seed=5, protocol=protocol, jobs=1)
    assert main(["report", "--db", str(db), "--out", str(d / "rep")]) == 0
    return db, d / "rep"


def _rows(db: Path, sql: str) -> list[tuple]:
    c = sqlite3.connect(db)
    try:
        return c.execute(sql).fetchall()
    finally:
        c.close()


def test_the_protocol_file_names_the_task_and_its_parameters_are_validated_in_one_line(press) -> None:
    with pytest.raises(ProtocolError, match=r"^p\.toml: task\.floor_fraction = 1\.5: must be a number"):
        protocol_from_dict(tomllib.loads(_protocol_text(TOY.replace("0.75", "1.5"))), "p.toml")
    # the paper's parameters are not the toy's: its [trial] refuses them, naming the fields it allows
    with pytest.raises(ProtocolError, match=r"trial\.hold_s = 1\.0: unknown field; allowed: cue_s, max_trial_s"):
        protocol_from_dict(tomllib.loads(_protocol_text(TOY).replace("pause_s = 0.3", "pause_s = 0.3\nhold_s = 1.0")),
                           "p.toml")
    with pytest.raises(ProtocolError, match=r"task\.dwell_s = 5\.0: must be shorter than trial\.max_trial_s = 4"):
        protocol_from_dict(tomllib.loads(_protocol_text(TOY.replace("0.25", "5"))), "p.toml")
    kinds = "force_regulation, force_tracking, force_discrimination, toy_press"
    with pytest.raises(ProtocolError, match=rf"task\.kind = 'toy_pull'.*{kinds}"):
        protocol_from_dict(tomllib.loads(_protocol_text(TOY.replace("toy_press", "toy_pull"))), "p.toml")
    # without a [task] table a file is the paper's task, as every file written before the tasks
    assert protocol_from_dict(tomllib.loads(_protocol_text("")), "p.toml").task.kind == "force_regulation"


def test_a_simulated_study_runs_the_task_cues_its_words_and_stores_its_verdicts(study) -> None:
    db, _ = study
    (proto,) = {p for (p,) in _rows(db, "SELECT protocol_json FROM sessions")}
    stored = json.loads(proto)
    assert stored["task"] == {"kind": "toy_press", "floor_fraction": 0.75, "dwell_s": 0.25}
    assert set(stored["trial"]) == {"max_trial_s", "pause_s", "cue_s"}  # none of the paper's band and hold
    cues = [d for (d,) in _rows(db, "SELECT detail FROM events WHERE kind = 'cue'")]
    assert len(cues) == 8 and all(("press GENTLE ≥ 0.45 N" in c) or ("press FIRM ≥ 0.9 N" in c) for c in cues)
    trials = _rows(db, "SELECT outcome, tct_s, peak_force_n, time_in_band_s, target_force_n FROM trials")
    assert len(trials) == 8 and {t[0] for t in trials} <= {"success", "timeout"}
    assert any(t[0] == "success" for t in trials)  # the participant, aiming at F*, gets past 75 % of it
    # a metric the task does not produce is not stored: empty in the schema's own columns (the paper's, from before
    # the tasks), and no column at all for a later one (the error impulse, force tracking's lag and gain)
    columns = {r[1] for r in _rows(db, "PRAGMA table_info(trials)")}
    assert not {"abs_impulse_n_s", "lag_s", "gain"} & columns
    for outcome, tct, peak, in_band, target in trials:
        assert in_band is None
        if outcome == "success":  # the rule's verdict: the peak passed the floor, a dwell after the cue at least
            assert peak >= 0.75 * target and 0.25 <= tct <= CAP_S


def test_the_report_reads_the_task_back_its_rule_its_parameters_and_agrees_with_the_live_verdicts(study) -> None:
    _, rep = study
    assert len(pd.read_csv(rep / "trials.csv")) == 8
    sessions = pd.read_csv(rep / "sessions.csv")  # each session's task parameters, the task's columns
    assert set(sessions["floor_fraction"]) == {0.75} and set(sessions["dwell_s"]) == {0.25}
    assert "tolerance_fraction" not in sessions.columns
    book = pd.read_csv(rep / "codebook.csv").set_index(["file", "column"])  # the task describes its parameters
    assert book.loc[("sessions.csv", "dwell_s"), "description"].startswith("time the force must stay at or above")
    page = (rep / "report.html").read_text(encoding="utf-8")
    assert "A press trial succeeds when the force stays at or above 0.75 of F* for 0.25 s within 4 s" in page
    assert "A sample is in the band" not in page  # the paper's task's words are its own
    # the offline form, recomputed from the recorded samples, agrees with every live verdict
    assert "and agree with the values stored live" in page and "disagree" not in page
