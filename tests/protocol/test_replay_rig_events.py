"""Replay stays bit for bit with what the rig does to the force outside the framework's step.

A headless session on the simulated rig (virtual clock) is recorded while

* the Touch's motors warm and it derates (the loop clamps the safety stage to its falling limit:
  ``"device_limit"`` in the replay log, ``derate`` in the records);
* the loop ticks late (the device's command watchdog dropped the force: the output restarts from
  zero), stalls (``LOOP_STALLED``), is found frozen (its supervisor latches through a
  :class:`pipeline.runtime.loop.LatchFault`) and found dead (:meth:`pipeline.runtime.loop.HapticLoop.fail_safe`) --
  each a ``"zero"`` in the log;

and :func:`pipeline.force.replay.replay` of the stored recording must reproduce the rendered force, the
task force and the ramp gain bit for bit -- and must not without those log entries (the test can fail).
The faults and causes reach the database as they should: LOOP_STALLED aborts its trial with cause
``fault``, a late tick with ``gap``, derating a haptics-ON trial with ``feedback``.
"""

from __future__ import annotations

import dataclasses
import sqlite3
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from test_faults_in_the_record import rows, short_protocol
from test_recording import bits

import study_app.headless.session_run as session_run
from analysis.reading.load import load_study
from analysis.stats.loop_health import abort_counts, health_table
from pipeline.assembly.engine import Engine
from pipeline.devices.registry import haptic_model
from pipeline.devices.touch_output import HapticLimits
from pipeline.force.replay import ReplayInputs, replay
from pipeline.sim.rig import SimRigConfig
from protocol.storage.recordings import SegmentData, read_segment, segments_of
from study_app.headless import run_study

MS = 1_000_000
#: A Touch whose motors warm within a trial at the study's forces (continuous rating 0.3 N, budget 1 N²·s).
HOT_TOUCH = dataclasses.replace(haptic_model("touch").limits, continuous_force_n=0.3, thermal_budget_n2s=1.0)
#: A study seed whose participant holds a FIRM trial with feedback long enough for HOT_TOUCH to derate in it.
HOT_SEED = 2


def run_recorded(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, touch: HapticLimits | None,
                 tamper: Callable[[Engine], None] | None = None, seed: int = 3) -> tuple[Path, list[SegmentData]]:
    """One participant's session on a simulated rig built as ``run`` builds it, with this Touch; its recording."""
    if touch is not None:
        monkeypatch.setattr(session_run, "sim_rig_config", lambda seed: SimRigConfig(seed=seed, touch=touch))
    if tamper is not None:
        build = session_run._engine

        def engine(*args: object) -> Engine:
            eng = build(*args)
            tamper(eng)
            return eng

        monkeypatch.setattr(session_run, "_engine", engine)
    db = tmp_path / "study.db"
    run_study(str(db), participants=1, seed=seed, protocol=short_protocol(), jobs=1)
    c = sqlite3.connect(db)
    try:
        return db, [read_segment(c, 1, seg) for seg, _, _ in segments_of(c, 1)]
    finally:
        c.close()


def assert_bit_identical(seg: SegmentData, inputs: ReplayInputs | None = None) -> None:
    out = replay(inputs or seg.replay_inputs())
    for axis in ("fx", "fy", "fz"):
        np.testing.assert_array_equal(bits(out.column(f"render_{axis}")), bits(seg.columns[f"render_{axis}"]))
    np.testing.assert_array_equal(bits(out.force_n), bits(seg.columns["force_n"]))
    np.testing.assert_array_equal(bits(out.gain), bits(seg.columns["gain"]))


def without(seg: SegmentData, kind: str) -> ReplayInputs:
    """The segment's replay inputs with the log entries of one kind left out."""
    return dataclasses.replace(seg.replay_inputs(), events=[e for e in seg.log() if e[1] != kind])


def test_a_session_with_thermal_derating_replays_bit_for_bit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    db, (seg,) = run_recorded(tmp_path, monkeypatch, HOT_TOUCH, seed=HOT_SEED)
    assert seg.continuous
    limits = [p for _, k, p in seg.log() if k == "device_limit"]
    assert len(limits) > 100 and min(limits) < HOT_TOUCH.peak_force_n - 0.5  # it derated, and deeply
    derate = seg.columns["derate"]
    assert derate.min() < 0.99 and np.all((derate > 0) & (derate <= 1.0))  # the records say what derating cut
    assert_bit_identical(seg)
    with pytest.raises(AssertionError):
        assert_bit_identical(seg, without(seg, "device_limit"))  # the log entries are what makes it exact
    # derating is an event, and a haptics-ON trial it cut is aborted with the cause "feedback"
    assert rows(db, "SELECT COUNT(*) FROM events WHERE kind = 'derating'")[0][0] >= 1
    reasons = rows(db, "SELECT abort_reason FROM trials WHERE abort_cause = 'feedback'")
    assert reasons and all(r.startswith("feedback: the haptic device's thermal derating rendered ") for r, in reasons)
    assert all("100.00 %" not in r for r, in reasons)  # a cut is never reported as the full force


def test_a_cold_session_records_no_cut(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _, (seg,) = run_recorded(tmp_path, monkeypatch, None)
    assert np.all(seg.columns["derate"] == 1.0)
    # a log entry this version cannot apply (a newer recorder's) is refused, never skipped into a silent difference
    inputs = seg.replay_inputs()
    newer = dataclasses.replace(inputs, events=[*inputs.events, (int(seg.columns["tick"][5]), "haptic_gain_2", 0.5)])
    with pytest.raises(ValueError, match=r"'haptic_gain_2' at tick \d+: this version of replay applies only pose, "):
        replay(newer)
    peak_n = haptic_model("touch").limits.peak_force_n
    assert [p for _, k, p in seg.log() if k == "device_limit"] == [peak_n]  # once, at the start
    assert_bit_identical(seg)


def failing_loop(plan: list[tuple[int, str]], done: list[tuple[int, str]]) -> Callable[[Engine], None]:
    """Make the engine's loop fail as planned: at the first tick from each planned one at which it renders a force.

    ``late``: the next tick comes 20 ms late; ``stall``: 60 ms late; ``frozen``: its supervisor finds it
    frozen (a LatchFault for its next tick); ``dead``: the supervisor finds its thread dead (the fail-safe),
    and it ticks again anyway (a loop restarted in the same run).
    """

    def tamper(eng: Engine) -> None:
        loop, clock = eng.loop, eng.clock
        pending = list(plan)

        def run_ticks(n: int) -> None:
            for _ in range(n):
                rec = loop.last_record
                if pending and loop.tick_count >= pending[0][0] and rec is not None and rec["render_fy"] ** 2 + \
                        rec["render_fx"] ** 2 + rec["render_fz"] ** 2 > 0.2 ** 2 and rec["gain"] == 1.0:
                    _, what = pending.pop(0)
                    done.append((loop.tick_count, what))
                    if what in ("late", "stall"):
                        clock.advance((20 if what == "late" else 60) * MS)
                    else:
                        loop.fail_safe(f"test: the loop was found {what}", thread_dead=what == "dead")
                loop.tick()
                clock.advance(loop.period_ns)

        loop.run_ticks = run_ticks

    return tamper


def test_a_session_with_late_ticks_and_latched_loop_faults_replays_bit_for_bit(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    done: list[tuple[int, str]] = []
    plan = [(3_000, "late"), (13_000, "stall"), (23_000, "frozen"), (33_000, "dead")]
    db, (seg,) = run_recorded(tmp_path, monkeypatch, None, failing_loop(plan, done))
    assert [w for _, w in done] == [w for _, w in plan]
    zeros = [(t, p) for t, k, p in seg.log() if k == "zero"]
    tick_of = dict((w, t) for t, w in done)
    # the late tick and the stall zero the output on the tick that comes late; a frozen loop's latch and a
    # dead loop's fail-safe before the next tick
    assert zeros == [(tick_of["late"], "late_tick"), (tick_of["stall"], "late_tick"),
                     (tick_of["frozen"], "latch_fault"), (tick_of["dead"], "fail_safe")]
    assert_bit_identical(seg)
    with pytest.raises(AssertionError):
        assert_bit_identical(seg, without(seg, "zero"))
    # the stall, the frozen and the dead loop latched LOOP_STALLED, stored, each aborting its trial ("fault")
    stalled = rows(db, "SELECT detail FROM events WHERE kind = 'fault' AND detail LIKE 'LOOP_STALLED%'")
    assert len(stalled) == 3, stalled
    assert rows(db, "SELECT COUNT(*) FROM events WHERE kind = 'output_restarted'")[0][0] == 1
    # the late tick left a 21 ms gap in its trial's records ("gap"); the others latched the fault on that record
    aborted = rows(db, "SELECT abort_cause, abort_reason FROM trials WHERE outcome = 'aborted' ORDER BY started_at_s")
    assert aborted[0] == ("gap", "gap: no loop record for 21.0 ms (limit 5 ms)")
    assert [c for c, _ in aborted[1:]] == ["fault"] * 3
    assert all(r.startswith("fault: LOOP_STALLED") for _, r in aborted[1:])
    # the report: aborted trials by cause, and the late and stalled ticks in the loop health of the trials they ended
    study = load_study([str(db)])
    counts = dict(zip(*abort_counts(study).to_dict("list").values(), strict=True))
    assert (counts["fault"], counts["gap"], sum(counts.values())) == (3, 1, 4)
    health = health_table(study).set_index("trial_index")
    assert health.loc[0, "period_max_ms"] == pytest.approx(21.0) and health.loc[0, "within_bounds"] == False  # noqa: E712
    stall = next(i for i, (c, r) in enumerate(rows(db, "SELECT abort_cause, abort_reason FROM trials ORDER BY "
                                                      "trial_index")) if r and "61.0 ms" in r)
    assert health.loc[stall, "period_max_ms"] == pytest.approx(61.0)
    assert "longest tick period 61 > 2" in health.loc[stall, "outside_bounds"]
    assert rows(db, "SELECT status FROM sessions") == [("completed",)]
