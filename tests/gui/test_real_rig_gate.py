"""The real rig's commissioning chain through the study engine, and the session gate, on the loopback fakes.

TCP (orientations recorded about a divot, then Compute), payload (poses identified), frames (a push along
each axis): each is saved for the mounted tool; only then does Start measure the force at rest for 2 s and
open the session -- or refuse it, in one line, when the tool touches something or its payload is wrong.
Hardware runs on the wall clock: the engine is stepped while waiting for conditions (bounded). A recording's
sensor stall is judged only where the fake box is made to stop streaming (see ``steady_stream``): elsewhere the
only stall is the machine's load, and a test must not fail by it.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "backends"))

from fake_netft import FakeNetFT
from fake_rtde import FakeRtde
from test_real_rig import CPF, FAKE_TOUCH, G, hardware_file, wait_for

from pipeline.commissioning import steps
from pipeline.commissioning.tcp import pivot_orientations
from pipeline.force.frames import matrix_to_rotvec
from pipeline.sim.robot import TOOL_DOWN
from study_app.engine import messages as m
from study_app.engine import ring_windows
from study_app.engine.commissioning import pose_set
from study_app.engine.host import StudyEngine
from study_app.engine.setup import HostConfig

TIP = np.array([0.0015, -0.0010, 0.2212])  # the tool's true tip in the flange frame (the pendant's TCP is zero)
PIVOT = np.array([0.30, -0.10, 0.15])
MASS, COM = 0.3, np.array([0.0, 0.0, 0.06])
BIAS = np.array([0.4, -0.3, 0.2])


def counts(rot: tuple[float, ...], extra_base_n: np.ndarray | None = None) -> tuple[int, ...]:
    r = np.asarray(rot).reshape(3, 3)
    g_s = r.T @ np.array([0.0, 0.0, -G])
    f = MASS * g_s + BIAS + (r.T @ extra_base_n if extra_base_n is not None else 0.0)
    return tuple(int(round(v * CPF)) for v in (*f, *np.cross(COM, MASS * g_s)))


def put(rtde: FakeRtde, rot: tuple[float, ...], p: np.ndarray) -> None:
    rv = matrix_to_rotvec(rot)
    rtde.send(f"pose {p[0]} {p[1]} {p[2]} {rv[0]} {rv[1]} {rv[2]}")


def at(e: StudyEngine, rot: tuple[float, ...], p: np.ndarray) -> None:
    target = np.asarray(rot).reshape(3, 3)
    wait_for(e, lambda: np.allclose(np.asarray(e.eng.rig.robot.read_pose().rot_base_tip).reshape(3, 3), target,
                                    atol=1e-9))


def answered(e: StudyEngine, events: list, kinds: tuple, n_before: int, timeout_s: float = 8.0) -> list:
    wait_for(e, lambda: any(isinstance(ev, kinds) for ev in events[n_before:]), timeout_s)
    return [ev for ev in events[n_before:] if isinstance(ev, kinds)]


def first_answer(events: list, n_before: int) -> object:
    """The engine's first answer to a start pressed after ``events[n_before - 1]``: its rest check's notice or a
    refusal (a fault the loop latched meanwhile on a busy machine, a health report, may come before it)."""
    return next(ev for ev in events[n_before:] if isinstance(ev, (m.StartChecking, m.CommandRefused)))


def start_answered(e: StudyEngine, events: list, cmd: m.StartSession) -> tuple[m.StartChecking, object]:
    """Press Start and wait for the gate's answer after its 2 s rest check: (the check's notice, the answer)."""
    n = len(events)
    e.handle(cmd)
    checking = first_answer(events, n)
    assert isinstance(checking, m.StartChecking), events[n:]
    (answer,) = answered(e, events, (m.CommandRefused, m.SessionStarted), n)
    return checking, answer


@pytest.fixture
def steady_stream(monkeypatch) -> None:
    """The fake box streams without a pause: a recording's stall can then only be the machine's load (this process's
    threads or the fake's descheduled past the 50 ms limit), and is not judged -- what these tests prove holds on
    every record a window averages, stale or not, since the counts never change during a window (each test waits for
    the loop to read new counts before it records). The stall's refusal itself is proven where the box stops
    streaming (test_a_rest_check_the_sensor_stalled_in_...), at the product's limit: a stall load can only bring
    sooner."""
    monkeypatch.setattr(ring_windows, "sensor_stalled", lambda sensor_age_ns: False)


@pytest.fixture
def engine(tmp_path):
    with FakeNetFT(rate_hz=1000, initial_records=0) as netft, FakeRtde() as rtde:
        events: list[object] = []
        e = StudyEngine(HostConfig(rig="real", hardware_path=str(hardware_file(tmp_path, netft, rtde.host)),
                                   haptic_factory=FAKE_TOUCH), events.append, shared_ring=False)
        e.start()
        try:
            yield e, events, netft, rtde
        finally:
            e.close("test over")
            e.release_ring()


@pytest.mark.usefixtures("steady_stream")
def test_the_chain_in_order_then_the_gate_measures_the_force_at_rest(engine, tmp_path, short_protocol) -> None:
    e, events, netft, rtde = engine
    # -- TCP: four orientations about the divot; the pendant's TCP is the flange (tcp_offset_m defaults to 0)
    poses = []
    for k, rot in enumerate(pivot_orientations("minimal", TOOL_DOWN)):
        r = np.asarray(rot).reshape(3, 3)
        put(rtde, rot, PIVOT - r @ TIP)
        netft.counts = counts(rot)
        at(e, rot, PIVOT - r @ TIP)
        n = len(events)
        e.handle(m.RecordPivot(f"O{k + 1}", 0.2))
        (rec,) = answered(e, events, (m.PivotRecorded, m.CommandRefused), n)
        assert isinstance(rec, m.PivotRecorded), rec
        poses.append((rec.label, rec.rot_base_flange, rec.flange_position_m))
    n = len(events)
    e.handle(m.IdentifyTcp(tuple(poses)))
    (done,) = [ev for ev in events[n:] if isinstance(ev, m.TcpCalibrationDone)]
    assert done.accepted and np.allclose(done.result["tip_in_flange_m"], TIP, atol=1e-5)
    # the robot's poses are now reported at the tip: resting in the divot, the tip is at the pivot
    wait_for(e, lambda: np.allclose(e.eng.rig.robot.read_pose().position_m, PIVOT, atol=1e-5))

    # -- payload: six well-spread poses (what Record pose would have measured there)
    rots = pose_set("quick")
    n = len(events)
    e.handle(m.IdentifyPoses(tuple((f"P{k + 1:02d}", rot, tuple(c / CPF for c in counts(rot)))
                                   for k, rot in enumerate(rots)), "quick"))
    (cal,) = [ev for ev in events[n:] if isinstance(ev, m.CalibrationDone)]
    assert cal.accepted and cal.calibration["mass_kg"] == pytest.approx(MASS, abs=1e-5)

    # -- frames: tool down, the experimenter pushes 1 N along each base axis
    put(rtde, TOOL_DOWN, PIVOT)
    at(e, TOOL_DOWN, PIVOT)
    for axis, push in (("+x", (1.0, 0, 0)), ("+y", (0, 1.0, 0)), ("+z", (0, 0, 1.0))):
        netft.counts = counts(TOOL_DOWN, np.asarray(push))
        wait_for(e, lambda: (r := e.loop.last_record) is not None and abs(r["raw_fx"] - netft.counts[0] / CPF) < 1e-9)
        n = len(events)
        e.handle(m.RecordFrameAxis(axis, 0.6))
        (res,) = answered(e, events, (m.FrameAxisChecked, m.CommandRefused), n)
        assert isinstance(res, m.FrameAxisChecked) and res.passed, res
    (fc,) = [ev for ev in events if isinstance(ev, m.FrameCheckDone)]
    assert fc.passed and fc.summary == "Frames and signs: PASS (3 of 3 axes)"
    status = [ev for ev in events if isinstance(ev, m.CalibrationStatus)][-1]
    assert status.missing == "" and all(ok for _, ok, _ in status.steps)
    saved = json.loads((tmp_path / "calibration.json").read_text(encoding="utf-8"))["tools"]["instrument"]
    assert sorted(saved) == ["frames", "payload", "tcp"] and saved["frames"]["passed"]

    # -- the gate: something leans on the tool (0.3 N): refused after the 2 s measurement, one line
    db = str(tmp_path / "real.db")
    netft.counts = counts(TOOL_DOWN, np.array([0.0, 0.3, 0.0]))
    wait_for(e, lambda: (r := e.loop.last_record) is not None and abs(r["raw_fy"] - netft.counts[1] / CPF) < 1e-9)
    checking, refused = start_answered(e, events, m.StartSession(db, "R01", "experiment", short_protocol, 1, 1))
    assert checking.seconds == 2.0
    assert isinstance(refused, m.CommandRefused) and refused.message.startswith(
        "real rig: the compensated force at rest is 0.30") and "(limit 0.1 N)" in refused.message
    assert not Path(db).exists()

    # -- the tool hangs free: the session starts
    netft.counts = counts(TOOL_DOWN)
    wait_for(e, lambda: (r := e.loop.last_record) is not None and abs(r["raw_fy"] - netft.counts[1] / CPF) < 1e-9)
    _checking, started = start_answered(e, events, m.StartSession(db, "R01", "experiment", short_protocol, 1, 1))
    assert isinstance(started, m.SessionStarted), started
    e.handle(m.AbortSession("gate checked"))
    wait_for(e, lambda: any(isinstance(ev, m.SessionEnded) for ev in events))


@pytest.mark.usefixtures("steady_stream")
def test_nothing_on_record_is_refused_in_one_line_and_an_override_does_not_waive_the_force_at_rest(
        engine, tmp_path, short_protocol) -> None:
    e, events, netft, rtde = engine
    put(rtde, TOOL_DOWN, PIVOT)
    netft.counts = counts(TOOL_DOWN)  # the tool hangs free; no payload on record: its weight is not compensated
    wait_for(e, lambda: (r := e.loop.last_record) is not None and abs(r["raw_fz"] - netft.counts[2] / CPF) < 1e-9)
    db = str(tmp_path / "real.db")
    n = len(events)
    e.handle(m.StartSession(db, "R01", "experiment", short_protocol, 1, 1))
    (refused,) = [ev for ev in events[n:] if isinstance(ev, m.CommandRefused)]
    assert refused.message == ("real rig: no TCP calibration on record for tool 'instrument': run haptic-study "
                               "calibrate tcp --rig real --hardware FILE (or the calibration wizard's TCP step)")
    assert "\n" not in refused.message and not Path(db).exists()
    # the experimenter overrides with a reason: the steps are waived, the force at rest is still measured -- and the
    # uncompensated weight of the tool (what feedback would push the hand with) refuses the start
    checking, refused = start_answered(
        e, events, m.StartSession(db, "R01", "experiment", short_protocol, 1, 1, override_reason="rehearsal"))
    weight = float(np.linalg.norm(np.asarray(counts(TOOL_DOWN)[:3]) / CPF))
    assert isinstance(refused, m.CommandRefused) and refused.message.startswith(
        f"real rig: the compensated force at rest is {weight:.3f} N over 2 s (limit 0.1 N)")
    assert refused.message.endswith("no payload calibration is on record for tool 'instrument', so the tool's own "
                                    "weight counts as force; calibrate the payload first (the calibration wizard's "
                                    "step 2, or haptic-study calibrate payload); an override does not waive this check")
    assert checking.message.startswith("starting without the calibration chain of tool 'instrument'")
    assert not Path(db).exists()


def test_a_rest_check_the_sensor_stalled_in_is_refused_and_start_may_be_pressed_again(engine, tmp_path,
                                                                                        short_protocol) -> None:
    e, events, netft, rtde = engine
    put(rtde, TOOL_DOWN, PIVOT)
    netft.counts = counts(TOOL_DOWN)
    wait_for(e, lambda: (r := e.loop.last_record) is not None and abs(r["raw_fz"] - netft.counts[2] / CPF) < 1e-9)
    start = m.StartSession(str(tmp_path / "real.db"), "R01", "experiment", short_protocol, 1, 1,
                           override_reason="rehearsal")
    n = len(events)
    e.handle(start)
    assert isinstance(first_answer(events, n), m.StartChecking), events[n:]
    netft.streaming.clear()  # the box stops streaming during the 2 s measurement
    try:
        (refused,) = answered(e, events, (m.CommandRefused, m.SessionStarted), n)
    finally:
        netft.streaming.set()
    assert refused.message == ("the force sensor stalled while measuring the force at rest (check the Devices tab) "
                               "— press Start again")
    # streaming again: a fresh sample by the product's own measure (not a load-bound 2 ms)
    wait_for(e, lambda: (r := e.loop.last_record) is not None
             and r["sensor_age_ns"] * 1e-9 < steps.POSE_MAX_SENSOR_AGE_S)
    n = len(events)
    e.handle(start)  # pressed again: measured again (it was refused with "being measured; wait for it")
    assert isinstance(first_answer(events, n), m.StartChecking), events[n:]


@pytest.mark.usefixtures("steady_stream")
def test_one_axis_pushed_again_after_a_failed_check_completes_a_new_check(engine, tmp_path) -> None:
    """The window keeps every axis's newest push and says nothing is left to do after a check: pushing the failed
    axis again must judge the three newest pushes and put that verdict on record (it was kept as the old FAIL, the
    engine waiting for two more pushes the window never asked for)."""
    e, events, netft, rtde = engine
    poses = []
    for k, rot in enumerate(pivot_orientations("minimal", TOOL_DOWN)):
        r = np.asarray(rot).reshape(3, 3)
        poses.append((f"O{k + 1}", rot, tuple(PIVOT - r @ TIP)))
    e.handle(m.IdentifyTcp(tuple(poses)))
    rots = pose_set("quick")
    e.handle(m.IdentifyPoses(tuple((f"P{k + 1:02d}", rot, tuple(c / CPF for c in counts(rot)))
                                   for k, rot in enumerate(rots)), "quick"))
    put(rtde, TOOL_DOWN, PIVOT)
    at(e, TOOL_DOWN, PIVOT)

    def push(axis: str, force: tuple[float, float, float]) -> None:
        netft.counts = counts(TOOL_DOWN, np.asarray(force))
        wait_for(e, lambda: (r := e.loop.last_record) is not None and abs(r["raw_fz"] - netft.counts[2] / CPF) < 1e-9)
        n = len(events)
        e.handle(m.RecordFrameAxis(axis, 0.6))
        (res,) = answered(e, events, (m.FrameAxisChecked, m.CommandRefused), n)
        assert isinstance(res, m.FrameAxisChecked), res

    push("+x", (1.0, 0, 0))
    push("+y", (0, 1.0, 0))
    push("+z", (0, 0, -1.0))  # pushed down, not up
    (failed,) = [ev for ev in events if isinstance(ev, m.FrameCheckDone)]
    assert not failed.passed
    push("+z", (0, 0, 1.0))  # the failed axis again, the right way
    done = [ev for ev in events if isinstance(ev, m.FrameCheckDone)]
    assert len(done) == 2 and done[-1].passed, done
    status = [ev for ev in events if isinstance(ev, m.CalibrationStatus)][-1]
    assert status.missing == "" and all(ok for _, ok, _ in status.steps)
    saved = json.loads((tmp_path / "calibration.json").read_text(encoding="utf-8"))["tools"]["instrument"]
    assert saved["frames"]["passed"]


def test_the_payload_step_refuses_at_its_first_pose_without_a_tcp_on_record(engine) -> None:
    """As `calibrate payload` does, and before the experimenter has jogged the robot through the whole pose set (the
    wizard accepted a payload without a TCP, against the documented chain)."""
    e, events, _netft, _rtde = engine
    n = len(events)
    e.handle(m.RecordPose("P01", 0.2))
    rots = pose_set("quick")
    e.handle(m.IdentifyPoses(tuple((f"P{k + 1:02d}", rot, tuple(c / CPF for c in counts(rot)))
                                   for k, rot in enumerate(rots)), "quick"))
    refused = [(ev.command, ev.message) for ev in events[n:] if isinstance(ev, m.CommandRefused)]
    why = "payload: no TCP calibration on record for tool 'instrument'; the chain runs in order: calibrate tcp first"
    assert refused == [("RecordPose", why), ("IdentifyPoses", why)]
    assert not any(isinstance(ev, (m.PoseRecorded, m.CalibrationDone)) for ev in events[n:])
