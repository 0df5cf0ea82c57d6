"""Force discrimination through the product's normal path (issue 43): the loop renders a commanded force through
its safety stage and replay reproduces it, the trial machine takes an answer (a key outside the task's refused in
one line), each trial's Δ is chosen from the stored answers (a resumed block continues its procedure), ``run`` then
``report`` give each participant's JND and Weber fraction, and a simulated 6-participant study through ``run``
recovers the true Weber fractions."""

from __future__ import annotations

import math
import sqlite3
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipeline.core.force_program import ForceProgram
from pipeline.force.config import SafetyConfig
from pipeline.force.framework import FrameworkConfig, HapticFramework
from pipeline.sim.participant import SimulatedParticipant
from protocol.runner.session_setup import participant_seeds
from protocol.storage.schema import connect_readonly
from protocol.storage.trial_answers import trial_answers
from protocol.study.config import TrialTiming
from protocol.study.design import TrialSpec
from protocol.study.trial import TrialFinished, TrialMachine, TrialMachineError, TrialPhase
from protocol.tasks.base import Answered
from protocol.tasks.force_discrimination import ForceDiscrimination
from study_app.cli.main import main

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "discrimination.toml"
MS = 1_000_000
SPEC = TrialSpec(0, "GENTLE", 0.6, "on")


def _small(tmp_path: Path, trials: int) -> Path:
    p = tmp_path / "small.toml"
    p.write_text(EXAMPLE.read_text(encoding="utf-8").replace("trials = 60", f"trials = {trials}"), encoding="utf-8")
    return p


def _retimed(text: str, **seconds: str) -> str:
    """A protocol file's text with the named fields (each on a line of its own: ``name = value``) given new values."""
    lines = text.splitlines()
    for name, value in seconds.items():
        at = [i for i, line in enumerate(lines) if line.split("=")[0].strip() == name]
        assert len(at) == 1, name
        lines[at[0]] = f"{name} = {value}"
    return "\n".join(lines) + "\n"


def test_a_program_is_linear_between_knots_and_refused_when_malformed() -> None:
    prog = ForceProgram(((0.0, 0.0), (0.5, 0.0), (0.7, 0.3), (1.7, 0.3), (1.9, 0.0)))
    assert prog.force_n(0) == 0.0 and prog.force_n(600 * MS) == pytest.approx(0.15, abs=1e-12)  # half-way up
    assert prog.force_n(1200 * MS) == 0.3 and prog.force_n(10_000 * MS) == 0.0
    assert ForceProgram.from_json(prog.to_json()) == prog
    with pytest.raises(ValueError, match="must start at 0 s and increase"):
        ForceProgram(((0.1, 0.0), (0.2, 1.0)))
    with pytest.raises(ValueError, match="must be finite"):
        ForceProgram(((0.0, math.inf),))


def test_the_commanded_force_passes_the_safety_stage() -> None:
    """A command above f_max is clamped, a step is slew-limited, and without feedback enabled nothing is rendered;
    the stages up to the scaled force are the sensor's, as the plain step computes them."""
    cfg = FrameworkConfig()
    fw, plain = HapticFramework(cfg, device_peak_n=3.3), HapticFramework(cfg, device_peak_n=3.3)
    out = [fw.step_commanded(0.1, 0.2, -1.0, 10.0, True, 0.001) for _ in range(3000)]
    ref = [plain.step(0.1, 0.2, -1.0, True, 0.001) for _ in range(3000)]
    assert all(a[:-3] == b[:-3] for a, b in zip(out, ref, strict=True))  # the sensor's stages, exactly
    z = np.array([o[-1] for o in out])
    slew = SafetyConfig().slew_n_per_s * 0.001
    assert np.all(np.diff(z) <= slew + 1e-12)  # slew-limited
    assert z.max() <= cfg.f_max_n and z[-1] == pytest.approx(cfg.f_max_n, rel=1e-9)  # clamped to f_max (3 N)
    off = HapticFramework(cfg, device_peak_n=3.3)
    assert all(off.step_commanded(0.0, 0.0, 0.0, 1.0, False, 0.001)[-3:] == (0.0, 0.0, 0.0) for _ in range(10))


def _asking() -> tuple[TrialMachine, list]:
    task = ForceDiscrimination()
    m = TrialMachine(TrialTiming(max_trial_s=12.0, pause_s=1.0), task)
    m.start(SPEC, 0)
    ask_ms = int(task.answer_at_s() * 1000)
    events = m.feed((k * MS, 0.0, 0) for k in range(ask_ms + 5))
    return m, events


def test_the_machine_asks_when_the_stimulus_ends_and_takes_the_answer() -> None:
    m, events = _asking()
    assert m.phase is TrialPhase.ANSWER and not any(isinstance(e, TrialFinished) for e in events)
    with pytest.raises(ValueError, match=r"^answer = '3': the force discrimination task's answers are 1, 2$"):
        m.answer(5_000 * MS, "3")
    assert m.phase is TrialPhase.ANSWER  # a refused key changes nothing
    done = next(e for e in m.answer(5_000 * MS, "2") if isinstance(e, TrialFinished))
    assert done.answer == "2" and done.end_ns == 5_000 * MS and m.phase is TrialPhase.PAUSE
    with pytest.raises(TrialMachineError, match="no question is open"):
        m.answer(5_001 * MS, "1")


def test_no_answer_within_the_window_ends_the_trial_without_one() -> None:
    m, _ = _asking()
    by_ms = int(ForceDiscrimination().trial_s() * 1000)
    events = m.feed((k * MS, 0.0, 0) for k in range(4300, by_ms + 3))
    done = next(e for e in events if isinstance(e, TrialFinished))
    assert done.answer is None and done.end_ns == by_ms * MS


def test_the_procedure_rebuilt_from_the_history_chooses_as_the_running_one() -> None:
    """QUEST+'s posterior is a function of the answers only: a procedure rebuilt from a stored history gives the
    next Δ the one that lived through it gives."""
    task = ForceDiscrimination()
    live = task.stimulus_procedure(0, 1, ())
    history: list[Answered] = []
    t_s = np.arange(0, 9000) / 1000.0
    for k in range(8):
        spec = TrialSpec(k, "GENTLE", 0.6, "on")
        stim = live.next(spec, k)
        rendered = task.stimulus_n(*(p[1] for p in stim.program.knots[2:8:4]), t_s)
        values = live.answered(spec, stim, "1" if k % 3 else "2", t_s, rendered)
        history.append(Answered("GENTLE", values, "1" if k % 3 else "2"))
    again = task.stimulus_procedure(0, 1, tuple(history))
    spec = TrialSpec(8, "GENTLE", 0.6, "on")
    assert again.next(spec, 8).values == live.next(spec, 8).values


def test_run_then_report_then_check_and_replay(tmp_path: Path, capsys) -> None:
    db, out = tmp_path / "d.db", tmp_path / "rep"
    assert main(["run", "--protocol", str(_small(tmp_path, 12)), "--participants", "2", "--seed", "0",
                 "--db", str(db)]) == 0
    conn = connect_readonly(db)
    try:
        answers = trial_answers(conn)
        trials = pd.read_sql_query("SELECT * FROM trials", conn)
    finally:
        conn.close()
    assert len(answers) == len(trials) == 2 * 2 * 12 and all(a.answer in ("1", "2") for a in answers)
    for a in answers:  # the felt forces are the commanded ones: reference and reference + Δ, through the loop
        ref, delta = a.values["reference_n"], a.values["delta_n"]
        first = a.values["comparison_first"] == 1.0
        felt = (a.values["felt_first_n"], a.values["felt_second_n"])
        assert felt == pytest.approx((ref + delta, ref) if first else (ref, ref + delta), abs=1e-9)  # the plateau
        assert a.values["correct"] == float((a.answer == "1") == first)
    capsys.readouterr()
    assert main(["check", "--db", str(db)]) == 0
    assert main(["replay", "--db", str(db), "--session", "1"]) == 0
    assert "bit-identical" in capsys.readouterr().out
    assert main(["report", "--db", str(db), "--out", str(out)]) == 0
    fits = pd.read_csv(out / "discrimination_fits.csv")
    assert len(fits) == 4 and list(fits["target_label"]) == ["GENTLE", "FIRM", "GENTLE", "FIRM"]
    assert (out / "report.html").read_text(encoding="utf-8").count("<tr>") == 5
    assert sorted(p.name for p in (out / "figures").iterdir()) == ["psychometric_P01.png", "psychometric_P02.png"]


def test_a_bad_reference_is_refused_in_one_line_before_any_work(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(EXAMPLE.read_text(encoding="utf-8").replace("force_n = 1.2", "force_n = 15.0"), encoding="utf-8")
    assert main(["run", "--protocol", str(bad), "--db", str(tmp_path / "d.db")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "task.max_delta_fraction" in err and "safety.f_max_n" in err
    assert not (tmp_path / "d.db").exists()


@pytest.mark.slow
def test_a_simulated_study_through_run_recovers_the_weber_fractions(tmp_path: Path, capsys) -> None:
    """The test that can fail, on the product's path: 6 simulated participants, 40 trials per reference, through
    ``run``; each one's true Weber fraction (its observer's, drawn from its seed) within its fitted 95 % interval
    in at least 5 of 6 at each reference (with intervals that cover, P(≥ 5 of 6) ≈ 0.97; with a fit whose
    intervals cover 60 %, 0.23).  40 trials, not the example's 60: the intervals are wider, their coverage the
    same.  The issue's 10-participant study (≥ 9 of 10) is the discrimination command's test
    (tests/protocol/test_force_discrimination.py, with the checks that the intervals are not merely wide) and the
    closing notes' run; 6 here, not 10: the suite's time (this was its slowest test)."""
    db, out = tmp_path / "d.db", tmp_path / "rep"
    # the example's block with shorter plateaus, ramps, lead-in, gap and pauses: each trial about 2.9 s of the
    # virtual clock instead of 6.2 s, the task, the observer and the fit as they are (the ramp still longer than the
    # largest force over the slew limit, 0.76 / 50 = 0.015 s; the lead-in the safety stage's ramp-in, 0.5 s)
    fast = tmp_path / "fast.toml"
    fast.write_text(_retimed(EXAMPLE.read_text(encoding="utf-8"), stimulus_s="0.4", gap_s="0.4", pause_s="0.3",
                             cue_s="0.3", ramp_s="0.1", lead_in_s="0.5", trials="40"), encoding="utf-8")
    assert main(["run", "--protocol", str(fast), "--participants", "6", "--seed", "0", "--db", str(db)]) == 0
    assert main(["report", "--db", str(db), "--out", str(out)]) == 0
    fits = pd.read_csv(out / "discrimination_fits.csv")
    true = {p: SimulatedParticipant(seed=participant_seeds(0, p)[1]).observer.weber for p in range(1, 7)}
    for label in ("GENTLE", "FIRM"):
        mine = fits[fits["target_label"] == label]
        inside = sum(lo <= true[p] <= hi for p, lo, hi in zip(mine["participant"], mine["weber_lo"], mine["weber_hi"],
                                                                strict=True))
        assert len(mine) == 6 and inside >= 5, (label, inside)
    with sqlite3.connect(db) as conn:
        assert conn.execute("SELECT count(*) FROM trial_answers WHERE answer IS NULL").fetchone()[0] == 0
