"""Qt-free models of the GUI: exact behaviour without any window."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from gui_trials import trial_record
from hypothesis import given
from hypothesis import strategies as st

from pipeline.core.tick_record import TICK_DTYPE
from pipeline.runtime.loop_messages import RECORD_FIELDS
from pipeline.runtime.ring import RingBuffer
from protocol.study.records import TrialRecord
from protocol.tasks.force_regulation import ForceRegulation
from study_app.engine import messages as m
from study_app.models.app import AppModel
from study_app.models.calibration import CalibrationModel
from study_app.models.health import HealthModel
from study_app.models.notices import Notice
from study_app.models.participant import ParticipantScreenModel
from study_app.models.plots import PlotModel, peak_downsample
from study_app.models.rig import RigViewModel
from study_app.models.session import SessionModel, TrialTable
from study_app.models.setup import SetupModel


def started(kind: str = "experiment", aid: bool = False, total: int = 2) -> m.SessionStarted:
    return m.SessionStarted(session_id=3, code="P01", kind=kind, trials_total=total, start_position=0,
                            task=ForceRegulation(), max_trial_s=12.0, pause_s=2.0, cue_s=1.0, live_force_aid=aid)


def trial(t_s: float = 5.0, position: int = 1, label: str = "FIRM", force: float = 1.2,
          mode: str = "on") -> m.TrialStarted:
    return m.TrialStarted(t_s, position - 1, position, 2, label, force, mode)


def fill_ring(ring: RingBuffer, n: int, start: int = 0, **cols: float) -> None:
    for k in range(start, start + n):
        rec: dict[str, float] = {f: 0 if TICK_DTYPE[f] == np.int64 else 0.0 for f in RECORD_FIELDS}
        rec.update(t_ns=k * 1_000_000, t_s=k * 1e-3, tick=k, period_ns=1_000_000, tip_z_m=0.1, **cols)
        ring.write([rec[f] for f in RECORD_FIELDS])


# -- setup -----------------------------------------------------------------------------------------
def test_a_database_without_write_bits_is_not_writable_even_for_root(tmp_path):
    # chmod a-w is the owner's word (an archive): the form refuses it as every command does, root included
    db = tmp_path / "archive.db"
    db.write_bytes(b"")
    db.chmod(0o444)
    s = SetupModel()
    s.update(db_path=str(db), code="P01")
    assert s.errors.get("db_path") == f"study database = {str(db)!r}: not writable"
    folder = tmp_path / "sealed"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        s.update(db_path=str(folder / "new.db"))
        assert s.errors.get("db_path") == f"study database = {str(folder / 'new.db')!r}: not writable"
    finally:
        folder.chmod(0o755)


def test_setup_validation_names_field_value_and_rule(tmp_path):
    s = SetupModel()
    s.update(db_path=str(tmp_path / "study.db"), code="P 01")
    assert set(s.errors) == {"code"}
    assert s.errors["code"] == "participant code = 'P 01': must be 1–32 characters from A–Z, a–z, 0–9, '_' and '-'"
    s.update(code="P01", db_path=str(tmp_path / "missing" / "x.db"))
    assert set(s.errors) == {"db_path"} and "does not exist" in s.errors["db_path"]
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[[targets]]\nlabel = "gentle"\nforce_n = 0.6\n', encoding="utf-8")
    s.update(db_path=str(tmp_path / "study.db"), protocol_path=str(bad))
    assert set(s.errors) == {"protocol_path"}
    assert "targets[0].label = 'gentle'" in s.errors["protocol_path"]
    s.update(protocol_path="")
    assert s.valid
    cmd = s.start_command()
    # a new participant: the form proposes the next step, training (the paper's protocol has a training block)
    assert cmd == m.StartSession(str(tmp_path / "study.db"), "P01", "training", None, 0, 1)


def known(code: str, number: int, kind: str = "experiment", status: str = "completed", sid: int = 1,
          seed: int = 0) -> dict:
    return {"session_id": sid, "code": code, "participant_number": number, "kind": kind, "status": status,
            "trials_done": 20, "trials_planned": 20, "seed": seed}


def test_setup_suggests_the_next_number_and_checks_the_entry_against_the_database(tmp_path):
    s = SetupModel()
    s.update(db_path=str(tmp_path / "study.db"))
    assert s.hint and not s.valid and not s.errors  # an empty code is a hint, not an error
    s.set_known([known("P01", 1, "training", sid=1), known("P01", 1, sid=2), known("P02", 2, sid=3)])
    assert s.values.participant_number == 3  # the next free number
    s.update(code="  P03 ")
    assert s.values.code == "P03" and s.valid and s.warnings == {}  # codes are trimmed
    s.update(code="P01")
    assert "already has a completed experiment session (session 2)" in s.errors["code"] and not s.valid
    assert s.values.participant_number == 1  # the code's own number
    s.update(kind="training")
    assert "already has a completed training session" in s.errors["code"]
    s.update(kind="experiment", code="P04")
    s.set_number(2)  # the experimenter types a number: it stays
    assert "already P02's" in s.warnings["participant_number"] and "Use 3" in s.warnings["participant_number"]
    # P04 has no training: the experiment is refused with the reason (only an override with a reason passes)
    assert set(s.errors) == {"training"} and s.training_missing.startswith("P04 has no training session")
    assert "Start without training…" in s.errors["training"] and not s.valid
    s.set_known([known("P01", 1, sid=2), known("P02", 2, sid=3), known("P05", 5, status="running", sid=4)])
    assert s.values.participant_number == 2
    s.update(code="P05", participant_number=5)
    assert "interrupted experiment session (session 4" in s.errors["code"] and "resume it" in s.errors["code"]
    # after a training session the same participant does the experiment; after an experiment, the next one
    s.session_began("P06", "training", 6)
    s.next_participant("training")
    assert (s.values.code, s.values.kind, s.values.participant_number) == ("P06", "experiment", 6)
    s.next_participant("experiment")
    assert s.values.code == "" and s.values.participant_number == 6  # the next free number (P05 has 5)


def test_setup_refuses_a_withdrawn_code_a_live_session_and_says_how_past_an_ended_training(tmp_path):
    s = SetupModel()
    s.update(db_path=str(tmp_path / "study.db"))
    live = dict(known("P05", 5, status="running", sid=4), writer="process 4242 (haptic-study gui)")
    ended = known("P02", 2, "training", status="aborted", sid=2)
    s.set_known([ended, live], [{"code": "P03", "withdrawn_at": "2026-11-29T09:00:00+00:00"}])
    s.update(code="P03")  # withdrew: refused before Start, as the engine would refuse it after
    assert s.errors["code"].startswith("P03 withdrew from the study (2026-11-29 09:00 UTC)") and not s.valid
    assert "not used again" in s.errors["code"]
    s.update(code="P05", participant_number=5)  # another window runs it now: not "interrupted, resume it"
    assert "is being run right now by process 4242 (haptic-study gui)" in s.errors["code"]
    assert "resume" not in s.errors["code"]
    # the training ended early: not "run the training first" (it cannot run twice), but the way that is left
    s.update(code="P02", participant_number=2, kind="experiment")
    why = s.errors["training"]
    assert "ended aborted, not completed" in why and "Run the training first" not in why
    assert "is not run twice" in s.errors["training"] and "Start without training…" in s.errors["training"]
    s.update(kind="training")
    assert "choose the experiment (Start without training…" in s.errors["code"]


def test_setup_refuses_a_number_field_whose_text_is_no_number(tmp_path):
    s = SetupModel()
    s.update(db_path=str(tmp_path / "study.db"), code="P01", kind="training")
    assert s.valid
    s.set_entry_problem("participant_number", "0", "must be a whole number from 1 to 9999")
    assert s.errors["participant_number"] == "participant number = '0': must be a whole number from 1 to 9999"
    assert not s.valid
    with pytest.raises(ValueError, match="participant number = '0'"):
        s.start_command()  # not with the number the field took last
    s.set_entry_problem("seed", "", "must be a whole number from 0 to 2147483647")
    s.set_entry_problem("participant_number", "4", None)
    assert list(s.errors) == ["seed"] and s.errors["seed"].startswith("seed = '': must be")
    s.set_entry_problem("seed", "7", None)
    assert s.valid


def test_a_long_word_in_a_message_gets_places_to_wrap():
    from study_app.models.setup import breakable

    code = "P" + "0123456789" * 4
    shown = breakable(f"participant code = {code!r}: must be 1–32 characters")
    assert shown.replace("\u200b", "") == f"participant code = {code!r}: must be 1–32 characters"
    assert max(len(w) for w in shown.replace("\u200b", " ").split()) <= 16
    assert breakable("short words only") == "short words only"


def test_setup_refuses_to_build_a_command_when_invalid():
    s = SetupModel()
    with pytest.raises(ValueError, match="study database: choose a file"):
        s.start_command()


# -- trial table and progress ----------------------------------------------------------------------
def test_an_ended_session_of_another_database_or_erased_is_no_longer_shown():
    s = SessionModel()
    s.apply(m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot"))
    s.apply(started())
    s.db_path = "/data/study1.db"
    s.apply(m.TrialEnded(9.0, trial_record(trial_index=0, outcome="success", tct_s=4.0), 2))
    s.apply(m.SessionEnded(3, "aborted", "the experimenter aborted it", 1, 0, 1))
    this = [known("P01", 1, status="aborted", sid=3)]
    s.listed("/data/study1.db", this)  # its own database, still stored: shown as it ended
    assert s.state == "ended" and len(s.table.rows) == 1 and s.message.startswith("session 3 aborted")
    s.listed("/data/study2.db", this)  # another database (the same session number there is another session)
    assert s.state == "ready" and s.session is None and s.table.rows == [] and s.completed == 0
    assert s.message == "study2.db open: no session running"
    s.apply(started())
    s.db_path = "/data/study1.db"
    s.apply(m.SessionEnded(3, "completed", "", 2, 0, 1))
    s.listed("/data/study1.db", [])  # the participant withdrew: the session is erased
    assert s.session is None and s.message == "session 3 is no longer stored (withdrawn): no session running"
    s.apply(started())
    s.listed("/data/study2.db", [])  # a running session is never hidden
    assert s.state == "running" and s.session is not None


def test_trial_table_cells():
    row = trial_record(trial_index=4, target_label="GENTLE", target_force_n=0.6, haptic_mode="off", outcome="success",
                       tct_s=3.456, rmse_n=0.12345, max_ae_n=0.5, abort_reason=None)
    # the task's tested measures (the paper's: TCT, RMSE, Max AE and the error impulse, none stored here)
    assert TrialTable().cells(row) == ("5", "GENTLE 0.6 N", "haptics OFF", "success", "3.46", "0.123", "0.500", "–",
                                       "")
    row = dataclasses.replace(row, outcome="aborted", metrics={**row.metrics, "tct_s": None, "rmse_n": float("nan")},
                              abort_reason="operator")
    assert TrialTable().cells(row)[3:] == ("aborted (operator)", "–", "–", "0.500", "–", "")


def test_session_progress_follows_events_and_sample_time():
    s = SessionModel()
    s.apply(m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot"))
    assert s.state == "ready" and not s.running
    s.apply(started())
    assert s.running and s.progress_text() == "Session started: the first trial is due"
    assert s.count_text() == "0 of 2 trials done · at most 30 s left"  # 2 × 12 s cap + one 2 s pause, rounded up
    s.apply(trial(t_s=5.0))
    s.set_time(7.5)
    assert s.progress_text() == "Trial 1 · FIRM · haptics ON · times out in 9.5 s"
    lo, hi = s.band([5.0, 7.5])  # asked at two moments of the trial: the paper's band holds
    assert list(lo) == pytest.approx([1.08, 1.08]) and list(hi) == pytest.approx([1.32, 1.32])
    assert s.band_for_axis() == pytest.approx((1.08, 1.32))
    s.apply(m.TrialEnded(9.0, trial_record(trial_index=0, target_label="FIRM", target_force_n=1.2, haptic_mode="on",
                                           outcome="success", tct_s=4.0, rmse_n=0.1, max_ae_n=0.2,
                                           cue_ns=5_000_000_000, end_ns=9_000_000_000), 2))
    s.apply(m.PhaseEntered(9.0, 0, "pause"))
    s.set_time(9.5)
    assert s.progress_text() == "Next trial in 1.5 s"
    assert s.count_text() == "1 of 2 trials done · about 10 s left"  # the first took 4 s: one more, no pause after
    assert s.band([9.5]) is None and s.fraction_done() == 0.5
    s.apply(m.SessionEnded(3, "completed", "", 2, 0, 1))
    assert s.state == "ended" and s.progress_text() == "session 3 completed"


def row(i: int, outcome: str = "success") -> TrialRecord:
    return trial_record(trial_index=i, target_label="FIRM", target_force_n=1.2, haptic_mode="on", outcome=outcome,
                        tct_s=4.0 if outcome == "success" else None, rmse_n=0.1, max_ae_n=0.2, abort_reason=None)


def test_a_resumed_session_restores_its_table_and_progress():
    s = SessionModel()
    s.apply(m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot"))
    stored = [row(0), row(1, "aborted"), row(2, "timeout")]
    schedule = [{"index": i, "repeat_of": None} for i in range(20)] + [{"index": 20, "repeat_of": 1}]
    s.apply(m.SessionStarted(3, "P01", "experiment", 21, 3, ForceRegulation(), 12.0, 2.0, 1.0, False, schedule=schedule,
                             participant_number=4, stored_trials=stored))
    assert len(s.table.rows) == 3 and (s.completed, s.aborted) == (2, 1)
    assert s.count.text() == "2 of 20 trials done · 1 aborted · 1 re-run left"
    assert s.fraction_done() == pytest.approx(2 / 20)
    assert s.message.endswith("(resumed)")


def test_a_pending_pause_is_shown():
    s = SessionModel()
    s.apply(m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot"))
    s.apply(started())
    s.apply(trial(t_s=5.0))
    s.set_time(6.0)
    s.paused_requested = True
    assert s.progress_text().endswith("pause requested: pausing after this trial")
    s.apply(m.PhaseEntered(9.0, 0, "pause"))
    assert s.progress_text() == "Pausing before the next trial"
    s.apply(m.Health(1000.0, 1000.0, 1000.0, 1.0, 0, 0, 100, 0, True, "autopilot", True, True))
    assert s.state == "paused" and s.progress_text() == "Paused · Resume (Space) to continue"


# -- plots -----------------------------------------------------------------------------------------
def test_peak_downsample_keeps_extremes_in_time_order():
    t = np.arange(12.0)
    y = np.array([0, 5, 1, 1, -3, 2, 0, 0, 0, 9, 0, -1], dtype=float)
    td, yd = peak_downsample(t, y, 3)
    assert td.tolist() == [0, 1, 4, 5, 9, 11]
    assert yd.tolist() == [0, 5, -3, 2, 9, -1]
    assert peak_downsample(t, y, 6)[1] is y  # short input unchanged


def test_plot_model_keeps_a_window_and_computes_magnitudes():
    ring = RingBuffer.create(TICK_DTYPE, 5000, shared=False)
    try:
        p = PlotModel(window_s=1.0, bins=100)
        p.attach(ring)
        fill_ring(ring, 1500, raw_fx=3.0, raw_fz=4.0, filt_fx=0.6, filt_fy=0.8, render_fz=-2.0, force_n=1.0)
        assert p.pull() == 1000 and p.skipped == 500  # only the window is read
        assert len(p.t) == 1000 and p.t[0] == pytest.approx(0.5) and p.latest_t_s == pytest.approx(1.499)
        assert np.all(p.data["raw_n"] == 5.0) and np.allclose(p.data["comp_n"],
                                                              1.0) and np.all(p.data["render_n"] == 2.0)
        t, _y = p.curve("raw_n")
        # constant data: each bin keeps its first sample twice
        assert len(t) == 200 and t[0] == pytest.approx(-0.999) and t[-1] == pytest.approx(-0.009)
        assert p.pull() == 0
        fill_ring(ring, 10, start=1500)
        assert p.pull() == 10 and len(p.t) == 1000 and p.data["raw_n"][-1] == 0.0
    finally:
        ring.close()


# -- participant screen ----------------------------------------------------------------------------
def test_participant_screen_experiment_cue_blank_rest_end():
    p = ParticipantScreenModel()
    p.apply(started("experiment"))
    p.apply(trial(t_s=2.0, label="GENTLE", force=0.6))
    p.update(2.5, 0.7)
    assert (p.screen.headline, p.screen.show_gauge, p.screen.gauge_force_n) == ("GENTLE", False, None)
    p.update(3.0, 0.7)  # cue_s = 1 s: the word is gone
    assert p.screen.headline == "" and not p.screen.show_gauge
    p.apply(m.PhaseEntered(6.0, 0, "pause"))
    assert p.screen.headline == "Rest"
    p.apply(m.SessionEnded(3, "completed", "", 2, 0, 0))
    assert p.screen.headline == "Thank you"


def test_participant_screen_training_shows_gauge_and_band():
    p = ParticipantScreenModel()
    p.apply(started("training", aid=True))
    p.apply(trial(t_s=1.0))
    p.update(4.0, 0.9)
    s = p.screen
    assert s.headline == "FIRM" and s.show_gauge and s.gauge_force_n == 0.9
    assert s.band_n == pytest.approx((1.08, 1.32))


_EVENTS = st.one_of(
    st.builds(lambda t, pos: trial(t_s=t, position=pos), st.floats(0, 100), st.integers(1, 2)),
    st.builds(lambda t, ph: m.PhaseEntered(t, 0, ph), st.floats(0, 100),
              st.sampled_from(["active", "pause", "idle", "cued"])),
    st.builds(lambda t, f: ("sample", t, f), st.floats(0, 100), st.floats(0, 3.0)),
)


@given(aid=st.booleans(), events=st.lists(_EVENTS, max_size=40))
def test_participant_screen_never_carries_force_in_an_experiment(aid, events):
    p = ParticipantScreenModel()
    p.apply(m.SessionStarted(1, "P01", "experiment", 2, 0, ForceRegulation(), 12.0, 2.0, 1.0, live_force_aid=aid))
    for ev in events:
        if isinstance(ev, tuple):
            p.update(ev[1], ev[2])
        else:
            p.apply(ev)
        s = p.screen
        assert not s.show_gauge and s.gauge_force_n is None and s.band_n is None
        assert p.force_n == 0.0


# -- calibration, rig, health ------------------------------------------------------------------------
def test_calibration_model_verdicts():
    c = CalibrationModel()
    with pytest.raises(ValueError, match="pose set = 'all'"):
        c.set_pose_set("all")
    assert c.command() == m.Calibrate("recommended") and c.state == "running"
    c.apply(m.CalibrationProgress(3, 24, "P03"))
    assert c.verdict() == "measuring pose 3 of 24 — keep the tool clear of the tissue"
    # the simulated rig has no hardware: its text says so, and that there is nothing to hold
    c.apply(m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot"))
    assert c.intro().startswith("Simulated rig — no hardware is attached. The simulated wrist sensor")
    assert "wrist sensor reads" not in c.intro() and "(nothing to move or hold)" in c.intro()
    c.apply(m.CalibrationProgress(4, 24, "P04"))
    assert c.verdict() == "measuring pose 4 of 24 — the simulated robot moves by itself"
    c.rig = "real"
    assert c.intro().startswith("The wrist sensor reads the instrument's weight")
    c.apply(m.CalibrationDone(False, "rank 6 of 10", "tool-down only", 6, 3e17, math.nan, math.nan, [], None))
    assert c.state == "refused"
    assert c.verdict() == "Refused — the previous calibration stays in use. Reason: rank 6 of 10"
    assert c.summary()[:2] == [("Poses", "6"), ("Condition number", "3e+17")]


def test_rig_model_geometry_and_manual_target():
    r = RigViewModel()
    r.apply(m.EngineReady("", "sim", "virtual", {}, 0.10, (0.3, 0.0, 0.115), "autopilot"))
    r.update(0.098, 0.9)
    assert r.tip_z_mm == pytest.approx(-2.0) and r.indentation_mm == pytest.approx(2.0)
    _x, z = r.surface_profile(30.0, 61)
    assert z[30] == pytest.approx(-2.0) and z[0] > -1e-3 and np.all(z <= 0)
    assert r.target_for_tip_mm(15.0) == pytest.approx(0.0)
    assert r.target_for_tip_mm(-3.0) == pytest.approx(-0.018)
    sent = []
    r.target_changed.connect(sent.append)
    r.set_manual_target(-0.1)
    r.step_manual(+2)
    assert sent == [-0.030, pytest.approx(-0.029)]


def test_health_rates_from_records():
    h = HealthModel()
    h.apply(m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot"))
    n = 1001
    rows = np.zeros(n, dtype=TICK_DTYPE)
    rows["t_s"] = np.arange(n) * 1e-3
    rows["raw_fx"] = np.arange(n)  # a new sample every tick
    rows["pose_age_ns"] = (np.arange(n) % 8) * 1_000_000  # a new pose every 8 ms
    h.update_from_rows(rows)
    assert [(d.name, d.state, round(d.rate_hz)) for d in h.devices] == [
        ("F/T sensor", "ok", 1000), ("Robot (pose)", "ok", 125), ("Haptic device", "ok", 1000)]
    h.apply(m.EngineFault(1.0, "fault", 2, "POSE_STALE"))
    assert h.devices[1].state == "FAULT: POSE_STALE" and h.devices[0].state == "ok"
    assert h.faults_text() == "POSE_STALE" and h.fault_log == ["no session, engine clock 1.000 s  fault: POSE_STALE"]


def test_loop_health_is_judged_against_its_limits():
    h = HealthModel()
    assert h.loop_figures() == [] and h.loop_text() == "loop: –"
    h.apply(m.Health(999.0, 1000.0, 1003.0, 12.0, 0, 0, 120_000, 0, True, "autopilot", True, False))
    assert [f.level for f in h.loop_figures()] == ["ok", "ok", "ok", "ok"]
    # the issue's run: 69 periods over 2 ms and 114 missed slots in 2 minutes, p99 0.3 ms
    h.apply(m.Health(990.0, 1000.0, 1300.0, 300.0, 69, 114, 120_000, 0, True, "autopilot", True, False))
    figs = {f.name: f for f in h.loop_figures()}
    assert (figs["rate"].level, figs["p99"].level, figs["over"].level, figs["missed"].level) == (
        "warn", "warn", "warn", "warn")
    assert figs["over"].text == "periods over 2 ms: 69 of 120,000 (0.06 %)" and figs["over"].limit == "≤ 0.01 %"
    h.apply(m.Health(900.0, 1100.0, 3000.0, 2000.0, 5000, 5000, 120_000, 0, True, "autopilot", True, False))
    assert {f.level for f in h.loop_figures()} == {"bad"}


def test_a_large_force_on_the_tissue_is_warned_about():
    h = HealthModel()
    seen = []
    h.changed.connect(lambda: seen.append(h.force_warning()))
    h.update_force(1.1, in_trial=True)
    assert h.force_warning() == "" and seen == []
    h.update_force(18.04, in_trial=False)
    assert h.force_warning().startswith("18.0 N on the tissue while no trial is running") and len(seen) == 1
    h.update_force(0.2, in_trial=False)
    assert h.force_warning() == "" and seen[-1] == ""


def test_without_a_payload_on_record_the_real_rig_warns_of_the_tools_weight_not_of_tissue():
    h = HealthModel()
    steps = [("TCP", False, "not on record"), ("payload", False, "not on record"), ("frames", False, "not on record")]
    h.apply(m.CalibrationStatus("real", "grasper", "/lab/calibration.json", steps, "real rig: no TCP ..."))
    h.update_force(6.4, in_trial=False)
    assert h.force_warning() == ("6.4 N task force: no payload calibration on record, so the tool's own weight "
                                 "counts as force; run the calibration wizard's payload step")
    h.update_force(4.2, in_trial=False)  # a 0.4 kg tool: below the 5 N warning, still its weight, not a contact
    assert h.force_warning().startswith("4.2 N task force: no payload calibration on record")
    h.update_force(6.4, in_trial=False)
    steps[1] = ("payload", True, "0.650 kg, RMS residual 2.9 mN")
    h.apply(m.CalibrationStatus("real", "grasper", "/lab/calibration.json", steps, ""))
    assert h.force_warning().startswith("6.4 N on the tissue while no trial is running")
    h.apply(m.CalibrationStatus("sim", "simulated instrument", "", [("payload", False, "not on record")], ""))
    assert h.force_warning().startswith("6.4 N on the tissue")  # the simulated rig compensates from its own model


def test_app_model_actions_follow_state(tmp_path):
    sent: list[object] = []
    a = AppModel(lambda c: sent.append(c) or True)
    assert not a.actions.can("start") and not a.actions.can("calibrate")
    a.apply(m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot"))
    a.setup.update(db_path=str(tmp_path / "s.db"), code="P01")
    assert a.actions.can("start") and a.actions.can("calibrate") and not a.actions.can("abort_trial")
    assert a.control.start() and sent[-1] == a.setup.start_command()
    a.apply(started())
    assert not a.actions.can("start") and a.actions.can("abort_session") and not a.actions.can("abort_trial")
    a.apply(trial())
    assert a.actions.can("abort_trial")
    a.control.abort_trial(0)
    assert sent[-1] == m.AbortTrial(trial_index=0)
    a.apply(m.CommandRefused("Pause", "no session is running"))
    assert a.notices.notice == Notice("error", "Pause refused: no session is running", "Pause")
    a.control.pause()  # a new action clears the old notice
    # pending: Resume cancels it
    assert a.notices.notice is None and not a.actions.can("pause") and a.actions.can("resume")
    a.apply(m.CommandRefused("AbortTrial", "trial 1 had already ended: nothing was aborted"))
    assert a.notices.notice.level == "info"  # a late confirmation that changed nothing is not an error


def test_a_refused_start_is_shown_until_the_form_changes(tmp_path):
    a = AppModel(lambda c: True)
    a.apply(m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot"))
    a.setup.update(db_path=str(tmp_path / "s.db"), code="P01")
    a.control.start()
    a.apply(m.CommandRefused("StartSession", "participant P01 already has an experiment session"))
    assert a.notices.notice.text.startswith("Start refused: participant P01")
    a.setup.update(code="P02")
    assert a.notices.notice is None
    a.setup.update(code="")
    assert not a.control.start() and a.notices.notice.text.startswith("Cannot start: Enter the participant's code")


def test_health_says_why_the_next_cue_waits_and_logs_every_fault_event():
    from study_app.models.health import HealthModel

    h = HealthModel()
    h.apply(m.EngineFault(1.5, "fault", 1, "SENSOR_STALE: newest F/T sample 6.0 ms old (limit 5 ms)"))
    h.apply(m.EngineFault(1.52, "fault_cleared", 1, "SENSOR_STALE: the condition is gone (latched until a reset)"))
    h.apply(m.Health(1000.0, 1000.0, 1000.0, 1.0, 0, 0, 100, 1, False, "autopilot", True, False,
                     waiting="fault latched (SENSOR_STALE): reset to continue"))
    assert h.waiting_text() == "fault latched (SENSOR_STALE): reset to continue"
    h.apply(m.EngineFault(3.0, "faults_reset", 0, "SENSOR_STALE"))
    assert [line.split("s  ", 1)[1].split(":")[0] for line in h.fault_log] == ["fault", "gone", "reset"]
    h.apply(m.Health(1000.0, 1000.0, 1000.0, 1.0, 0, 0, 100, 0, False, "autopilot", True, False, waiting="pause"))
    assert h.waiting_text() == ""  # the protocol's own pause is not worth a line


def test_a_dead_engine_or_loop_offers_a_restart_that_starts_afresh(tmp_path):
    restarts: list[int] = []
    ready = m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot")
    a = AppModel(lambda c: True)
    a.apply(ready)
    a.setup.update(db_path=str(tmp_path / "s.db"), code="P01")
    a.apply(started())
    a.apply(trial())
    assert not a.actions.can("restart_engine")  # nothing to restart while it runs
    a.apply(m.EngineStopped("the study engine exited unexpectedly", {}))
    assert a.engine.trouble == ("The study engine exited unexpectedly. Session 3 was interrupted; its stored trials "
                                "are kept.")
    assert a.engine.trouble_detail.startswith("The study engine exited unexpectedly. Without the engine the haptic")
    assert not a.actions.can("restart_engine")  # no restarter: no button that does nothing
    a.engine.restarter = lambda: restarts.append(1)
    assert a.actions.can("restart_engine") and not a.actions.can("start") and not a.actions.can("resume_session")
    a.plots.t = np.arange(3.0)
    assert a.engine.restart() and restarts == [1]
    assert a.engine.trouble == "" and len(a.plots.t) == 0 and a.session.state == "connecting"
    assert a.session.trial is None and a.session.last_trial is None and not a.session.table.rows
    a.apply(ready)
    a.apply(m.SessionsListed(str(tmp_path / "s.db"), [{"session_id": 2}, {"session_id": 3}]))
    assert a.setup.default_resume() == 3  # the interrupted one, not the first listed
    # a loop that died in a live engine: the same way out
    a.apply(m.SessionEnded(4, "interrupted", "the haptic loop died (x)", 0, 0, 0))
    a.apply(m.Health(1000.0, 1.0, 2.0, 1.0, 0, 0, 1, 0, False, "manual", False, False, loop_dead="OSError('x')"))
    assert a.engine.trouble == "The haptic loop died; the force is at zero. Session 4 was interrupted; its stored " \
        "trials are kept."
    assert a.engine.trouble_detail.startswith("The haptic loop died (OSError('x')); the haptic device's command")
    assert a.actions.can("restart_engine") and not a.actions.can("start")


def test_cue_wait_names_the_wait_its_length_and_what_ends_it():
    a = AppModel(lambda c: True)
    a.apply(m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot"))
    assert a.cue.wait is None
    a.apply(started())
    a.apply(trial(t_s=1.0))
    assert a.cue.wait is None  # a trial runs
    a.apply(m.PhaseEntered(4.0, 0, "pause"))
    a.session.set_time(4.5)
    a.apply(m.Health(1000.0, 1.0, 2.0, 1.0, 0, 0, 1, 0, False, "manual", True, False, waiting="pause"))
    assert a.cue.wait.text() == "Next cue waits: the protocol's 2 s pause between trials · 1.5 s left"
    assert a.cue.wait.action == "" and a.cue.wait.level == "info"
    # the pause is over and no cue comes, nothing latched: after a while, where to look and the way out
    a.session.set_time(11.5)
    a.apply(m.Health(1000.0, 1.0, 2.0, 1.0, 0, 0, 1, 0, False, "manual", True, False, waiting=""))
    a.session.set_time(17.0)
    a.apply(m.Health(1000.0, 1.0, 2.0, 1.0, 0, 0, 1, 0, False, "manual", True, False, waiting=""))
    assert a.cue.wait.text() == "Next cue waits: the protocol's 2 s pause between trials · 0.0 s left"
    assert a.cue.wait.help.startswith("No cue for 13 s and nothing to reset: look under Devices & health")
    a.apply(m.Health(1000.0, 1.0, 2.0, 1.0, 0, 0, 1, 1, False, "manual", True, False,
                     waiting="fault latched (SENSOR_STALE): reset to continue"))
    a.session.set_time(20.0)
    a.apply(m.Health(1000.0, 1.0, 2.0, 1.0, 0, 0, 1, 1, False, "manual", True, False,
                     waiting="fault latched (SENSOR_STALE): reset to continue"))
    w = a.cue.wait
    assert (w.level, w.action, w.text()) == ("error", "reset_faults",
                                             "Next cue waits: fault latched (SENSOR_STALE) · waiting 3 s")
    sent: list[object] = []
    a.commands.send = lambda c: sent.append(c) or True
    a.cue.end()
    assert sent == [m.ResetFaults()]


def test_a_run_of_the_same_event_is_one_log_line_counted():
    """The view coalesces repeated events (the engine stores each one; test_engine_host checks the record)."""
    h = HealthModel()
    h.apply(m.EngineFault(1.0, "fault", 1, "SENSOR_STALE: newest F/T sample 6.0 ms old (limit 5 ms)"))
    for k in range(30):
        h.apply(m.EngineFault(2.0 + k, "output_restarted", 0, f"no loop tick for {11 + k / 10:.1f} ms: the haptic "
                              "device's command watchdog (10 ms) had dropped the force to zero; feedback ramps in "
                              "again from zero", session_t_s=1.0 + k))
    h.apply(m.EngineFault(40.0, "faults_reset", 0, "SENSOR_STALE"))
    h.apply(m.EngineFault(41.0, "output_restarted", 0, "no loop tick for 10.5 ms: …", session_t_s=40.0))
    assert len(h.fault_log) == 4
    assert h.fault_log[1] == ("session clock, 1.000 s  output restarted ×30 (the last at session clock, 30.000 s): "
                              "no loop tick for 13.9 ms: the haptic device's command watchdog (10 ms) had dropped the "
                              "force to zero; feedback ramps in again from zero")
    assert h.fault_log[2].endswith("reset: SENSOR_STALE")
    assert h.fault_log[3] == "session clock, 40.000 s  output restarted: no loop tick for 10.5 ms: …"
    # a restart is a line of its own: the same event after it starts a new run; the log keeps the newest 50 lines
    h.engine_restarted()
    h.apply(m.EngineFault(1.0, "output_restarted", 0, "no loop tick for 10.7 ms: …", session_t_s=1.0))
    assert h.fault_log[-2:] == ["— engine restarted —",
                                "session clock, 1.000 s  output restarted: no loop tick for 10.7 ms: …"]
    for k in range(60):
        h.apply(m.EngineFault(2.0 + k, "fault" if k % 2 else "fault_cleared", 1, "SENSOR_STALE"))
    assert len(h.fault_log) == 50 and h.fault_log[-1].endswith("fault: SENSOR_STALE")


def test_a_starting_engine_names_the_device_it_is_opening():
    from study_app.models.session import SessionModel

    s = SessionModel()
    s.apply(m.EngineOpening("force sensor"))
    assert s.state == "connecting" and s.message == "starting the engine: opening the force sensor …"
    s.apply(m.EngineReady(ring_name="", rig="real", clock="real", calibration={}, surface_z_m=0.0,
                          tip_home_m=(0.0, 0.0, 0.0), driver="participant", rot_tip_sensor=(1.0,) * 9, devices=[]))
    s.apply(m.EngineOpening("robot"))  # late news changes nothing once ready
    assert s.state == "ready" and s.message == "engine ready (real rig, real clock)"


def test_after_a_cue_the_live_plot_judges_only_the_current_trials_samples():
    """The window still holds the last trial's force for seconds after a cue: its peak is not this trial's."""
    ring = RingBuffer.create(TICK_DTYPE, 20000, shared=False)
    try:
        p = PlotModel(window_s=10.0, bins=100)
        p.attach(ring)
        fill_ring(ring, 4000, force_n=2.7)  # the previous trial: far above a GENTLE target's axis
        fill_ring(ring, 2000, start=4000, force_n=0.6)  # the cue at 4.0 s; the current trial holds 0.6 N
        p.pull()
        s = SessionModel()
        s.apply(started())
        assert s.cue_t_s is None
        s.apply(trial(t_s=4.0, label="GENTLE", force=0.6))
        assert s.cue_t_s == 4.0
        assert p.peak(("force_n",)) == 2.7 and p.peak(("force_n",), s.cue_t_s) == 0.6
        assert p.task_axis(0.6) == pytest.approx((0.0, 2.4))  # the old peak would stretch the axis ...
        assert p.task_axis(0.6, s.cue_t_s) == pytest.approx((0.0, 1.5))  # ... the current trial's does not
        assert p.x_of(s.cue_t_s) == pytest.approx(-1.999)  # the cue's place on the time axis
        assert p.x_of(None) is None and p.x_of(-20.0) is None  # no cue; a cue scrolled out of the window
        assert p.x_of(9.0) == 0.0  # a cue announced before the ring's records of its moment: at the right edge
        s.apply(started())  # a new session: no cue of its own yet
        assert s.cue_t_s is None
        s.reset("restarting")
        assert s.cue_t_s is None
    finally:
        ring.close()


def test_the_headline_agrees_with_the_banner_when_a_fault_holds_the_next_cue():
    """A user trial: "The next trial is due" above a red "Next cue waits: fault latched (SENSOR_STALE)"."""
    from study_app.models.cue_wait import cue_wait_now, headline

    s, h = SessionModel(), HealthModel()
    s.apply(m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot"))
    s.apply(started())
    s.apply(trial(t_s=5.0))
    s.apply(m.TrialEnded(6.0, trial_record(trial_index=0, outcome="aborted", abort_reason="fault: SENSOR_STALE"), 3))
    s.apply(m.PhaseEntered(6.0, 0, "idle"))
    assert s.progress_text() == "The next trial is due"  # what the session alone knows
    held = m.Health(1000.0, 1000.0, 1000.0, 1.0, 0, 0, 100, 1, True, "autopilot", True, False,
                    waiting="fault latched (SENSOR_STALE): reset to continue")
    s.apply(held)
    h.apply(held)
    _, wait = cue_wait_now(s, h, "", None)
    assert wait is not None and wait.text() == "Next cue waits: fault latched (SENSOR_STALE)"
    assert headline(s, wait) == "Next trial waits: fault latched (SENSOR_STALE) · Reset faults"
    # the protocol's pause, a pause asked for, a running trial: the headline's own words agree already
    s.apply(dataclasses.replace(held, waiting=""))
    h.apply(dataclasses.replace(held, waiting=""))
    s.apply(m.PhaseEntered(7.0, 0, "pause"))
    s.set_time(7.5)
    _, wait = cue_wait_now(s, h, "", None)
    assert wait is not None and headline(s, wait) == "Next trial in 1.5 s"
    s.apply(trial(t_s=8.0, position=2))
    assert headline(s, cue_wait_now(s, h, "", None)[1]).startswith("Trial 2 · FIRM")


def test_abort_session_asks_what_will_actually_happen():
    """A user trial: paused, with no trial running, the question said "The running trial is stored as aborted"."""
    s = SessionModel()
    assert s.abort_session_question() == ""
    s.apply(m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot"))
    s.apply(started(total=4))
    s.apply(trial(t_s=5.0, position=1))
    q = s.abort_session_question()
    assert q == ("Abort session 3 (P01, experiment)? Trial 1 (FIRM, haptics ON) is running: it is stored as aborted "
                 "(unless it ends before you answer) and not run again. The 3 other trials not yet done are not run. "
                 "The session ends; it cannot be resumed.")
    s.apply(m.TrialEnded(9.0, row(0), 4))
    s.apply(m.PhaseEntered(9.0, 0, "pause"))
    q = s.abort_session_question()
    assert "No trial is running (between trials): none is stored as aborted." in q
    assert "If the next trial is cued before you answer, that trial is." in q
    assert "The 3 trials not yet done are not run." in q and "running: it is stored" not in q
    s.apply(m.Health(1000.0, 1000.0, 1000.0, 1.0, 0, 0, 100, 0, True, "autopilot", True, True))  # paused
    q = s.abort_session_question()
    assert s.state == "paused" and "No trial is running (the session is paused): none is stored as aborted." in q
    assert "cued before you answer" not in q  # nothing is cued while paused
