"""The study engine on the real rig, against the loopback fakes: Net F/T (UDP + HTTP), a UR controller's RTDE
server (a subprocess), and a Touch whose HDAPI is faked under the real Touch backend (no OpenHaptics here;
injected at the rig-construction seam, ``HostConfig.haptic_factory``).

Hardware runs on the wall clock, so these tests wait for conditions with timeouts, as the backend tests do.
"""

from __future__ import annotations

import json
import math
import sqlite3
import sys
import time
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "backends"))

from fake_netft import FakeNetFT
from fake_rtde import FakeRtde

from pipeline.commissioning.tcp import pivot_orientations
from pipeline.devices.interfaces import Fault
from pipeline.force.frames import matrix_to_rotvec
from pipeline.sim.robot import TOOL_DOWN
from study_app.engine import messages as m
from study_app.engine.client import EngineClient
from study_app.engine.host import StudyEngine
from study_app.engine.setup import HostConfig
from study_app.models.real_calibration import RealCalibrationModel

FAKE_TOUCH = "fake_touch:open_fake_touch"
G = 9.80665
#: The payload the fakes present: mass, centre of mass in the sensor frame, force and torque bias.
MASS_KG, COM_M = 0.25, np.array([0.0, 0.01, 0.05])
F_BIAS_N, T_BIAS_NM = np.array([0.3, -0.2, 0.5]), np.array([0.01, 0.02, -0.01])
CPF = 1_000_000  # the fake box's counts per N and per N·m


#: The rotations a real rig's file must give (no default sets a force's direction).
FRAMES = "rot_tip_sensor = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\nrot_haptic_base = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]\n"


def hardware_file(tmp_path: Path, netft: FakeNetFT, rtde_host: str, extra: str = "") -> Path:
    p = tmp_path / "hardware.toml"
    p.write_text(
        f'[sensor]\nhost = "127.0.0.1"\nport = {netft.udp_port}\nhttp_port = {netft.http_port}\n'
        f'[robot]\nhost = "{rtde_host}"\nconnect_timeout_s = 1.0\n[haptic]\ndevice_name = "Fake Touch"\n'
        f"[frames]\n{FRAMES}[framework]\nf_max_n = 2.5\nf_scale_n = 6.0\nfilter_window = 8\n{extra}",
        encoding="utf-8",
    )
    return p


def payload_counts(rot_base_sensor: tuple[float, ...]) -> tuple[int, ...]:
    """What the sensor reads at this orientation (gravity on the payload plus bias), in counts."""
    g_s = np.asarray(rot_base_sensor).reshape(3, 3).T @ np.array([0.0, 0.0, -G])
    f = MASS_KG * g_s + F_BIAS_N
    t = np.cross(COM_M, MASS_KG * g_s) + T_BIAS_NM
    return tuple(int(round(x * CPF)) for x in (*f, *t))


def wait_for(e: StudyEngine, pred, timeout_s: float = 5.0) -> None:
    end = time.monotonic() + timeout_s
    while not pred():
        if time.monotonic() > end:
            raise AssertionError(f"condition not reached (faults {e.loop.faults}, {list(e.loop.events)[-3:]}, "
                                 f"waiting {e.health().waiting!r})")
        e.step()
        time.sleep(0.002)


#: How often a test records again when the fake sensor's thread stalled past 50 ms on a busy machine (as the
#: experimenter would: the refusal says "record it again"); a stall on every try is a real failure.
STALL_RETRIES = 5


def stalled_refusal(events: list[object]) -> bool:
    """Whether these events hold a recording's refusal because the sensor stalled (the machine was busy)."""
    return any(isinstance(ev, m.CommandRefused) and "the force sensor stalled while recording" in ev.message
               for ev in events)


def tcp_on_record(e: StudyEngine, events: list[object], arm: str = "") -> None:
    """The chain in order: a TCP on record first (from four orientations about a divot, the tool 200 mm long; the
    payload step refuses without it), and the robot's poses reported at that tip before anything is recorded."""
    n_before = len(events)
    e.handle(m.IdentifyTcp(tuple(
        (f"O{k + 1}", rot, tuple(np.array([0.3, -0.1, 0.15]) - np.asarray(rot).reshape(3, 3) @ [0.0, 0.0, 0.2]))
        for k, rot in enumerate(pivot_orientations("minimal", TOOL_DOWN))), arm=arm))
    assert [ev.accepted for ev in events[n_before:] if isinstance(ev, m.TcpCalibrationDone)] == [True]
    ticks = e.loop.tick_count
    end = time.monotonic() + 5.0
    while e.loop.tick_count < ticks + 100 and time.monotonic() < end:  # 100 ms: poses at the new tip (125 Hz)
        e.step()
        time.sleep(0.002)


@pytest.fixture
def rig(tmp_path):
    with FakeNetFT(rate_hz=1000, initial_records=0) as netft, FakeRtde() as rtde:
        yield netft, rtde, hardware_file(tmp_path, netft, rtde.host)


def test_real_rig_calibration_wizard_and_a_session(rig, tmp_path, short_protocol):
    netft, rtde, hw_path = rig
    events: list[object] = []
    e = StudyEngine(HostConfig(rig="real", hardware_path=str(hw_path), haptic_factory=FAKE_TOUCH), events.append,
                    shared_ring=False)
    try:
        e.start()
        ready = next(ev for ev in events if isinstance(ev, m.EngineReady))  # (a busy machine: a fault may come first)
        assert isinstance(ready, m.EngineReady) and ready.rig == "real" and ready.driver == "participant"
        assert math.isnan(ready.surface_z_m)
        assert ready.devices == [f"F/T sensor: Net F/T at 127.0.0.1:{netft.udp_port}",
                                 f"robot: UR over RTDE at {rtde.host} (observe)", "haptic device: Fake Touch"]
        # no simulated participant, no automatic calibration on hardware
        for cmd in (m.SetDriver("manual"), m.Calibrate("recommended")):
            e.handle(cmd)
        refused = [ev.message for ev in events if isinstance(ev, m.CommandRefused)]
        assert refused == [
            "real rig: a person holds the stylus; the simulated participant and manual driving exist on the "
            "simulated rig only",
            "real rig: the poses are recorded one at a time in the calibration wizard (move the robot, then Record "
            "pose)",
        ]

        tcp_on_record(e, events)
        wiz = RealCalibrationModel(seconds=0.2)
        wiz.apply(ready)
        wiz.begin("quick")
        assert wiz.identify_refusal() == "record at least 6 poses first (0 so far)"
        while wiz.current is not None and wiz.current.recorded is None:
            step = wiz.current
            # the experimenter moves the robot to the target (here: the fake controller reports it) ...
            rv = matrix_to_rotvec(step.target_rot_base_sensor)  # rot_tip_sensor is the identity
            rtde.send(f"pose 0.3 -0.1 0.2 {rv[0]} {rv[1]} {rv[2]}")
            netft.counts = payload_counts(step.target_rot_base_sensor)
            target = np.asarray(step.target_rot_base_sensor).reshape(3, 3)
            wait_for(e, lambda target=target: np.allclose(
                np.asarray(e.eng.rig.robot.read_pose().rot_base_tip).reshape(3, 3), target, atol=1e-9))
            wait_for(e, lambda: (r := e.loop.last_record) is not None
                     and abs(r["raw_fx"] - netft.counts[0] / CPF) < 1e-9)
            # ... and presses Record pose: the engine averages 0.2 s of wrench off the GUI thread
            for _attempt in range(STALL_RETRIES):
                n_before = len(events)
                e.handle(wiz.record_command())
                assert wiz.state == "recording"
                wait_for(e, lambda n_before=n_before: any(isinstance(ev, (m.PoseRecorded, m.CommandRefused))
                                                          for ev in events[n_before:]))
                for ev in events[n_before:]:
                    wiz.apply(ev)
                if not stalled_refusal(events[n_before:]):
                    break
            rec = step.recorded
            assert rec is not None and rec.samples == 200 and rec.off_target_deg < 1e-3 and rec.force_std_n < 1e-9
            assert np.allclose(rec.wrench, np.asarray(netft.counts) / CPF, atol=1e-9)
            if len(wiz.recorded) == len(wiz.steps):
                break
        assert wiz.progress() == (6, 6) and wiz.instruction().startswith("All 6 poses are recorded: press Identify")
        assert wiz.message == ""  # said once, in the instruction

        n_before = len(events)
        e.handle(wiz.identify_command())
        done = [ev for ev in events[n_before:] if isinstance(ev, m.CalibrationDone)]
        assert len(done) == 1 and done[0].accepted and done[0].n_poses == 6 and done[0].rms_force_residual_n < 1e-5
        wiz.apply(done[0])
        assert wiz.state == "accepted"
        assert e.calibration.mass_kg == pytest.approx(MASS_KG, abs=1e-5)

        # a session: no simulated participant; the hardware-agnostic config record and the calibration are stored
        db = str(tmp_path / "real.db")
        # no trial is cued while a fault is latched (here the operator's stop; the sensor's first packets may
        # also have come after the loop started, a stale start latched until the reset)
        e.handle(m.OperatorStop())
        wait_for(e, lambda: e.loop.faults & Fault.OPERATOR_STOP)
        # the TCP and the payload are on record (the wizard saved them) but no frame check: the gate refuses, one line
        e.handle(m.StartSession(db, "R01", "experiment", short_protocol, 1, 1))
        refusal = [ev for ev in events if isinstance(ev, m.CommandRefused)][-1]
        assert refusal.command == "StartSession" and refusal.message == (
            "real rig: no frame and sign check on record for tool 'instrument': run haptic-study calibrate frames "
            "--rig real --hardware FILE (or the wizard's Frames step)")
        assert not Path(db).exists()  # nothing was created
        status = [ev for ev in events if isinstance(ev, m.CalibrationStatus)][-1]
        assert [(n, ok) for n, ok, _ in status.steps] == [("TCP", True), ("payload", True), ("frames", False)]
        # the experimenter overrides, with a reason: the session starts and the reason is stored with it
        start = m.StartSession(db, "R01", "experiment", short_protocol, 1, 1,
                               override_reason="rehearsal of the session flow, nobody holds the stylus")
        e.handle(start)
        stalled: list[object] = []

        def waiting_for_reset() -> bool:
            # on a busy machine the fake sensor's thread may stall during the 2 s rest check: the start is refused
            # in one line and the experimenter presses Start again
            refused = [ev for ev in events if isinstance(ev, m.CommandRefused) and ev.command == "StartSession"
                       and ev.message.startswith("the force sensor stalled while measuring the force at rest")]
            if len(refused) > len(stalled):
                stalled.append(refused[-1])
                e.handle(start)
            return "OPERATOR_STOP" in e.health().waiting

        wait_for(e, waiting_for_reset, timeout_s=30.0)
        assert e.health().waiting.startswith("fault latched (")
        assert not any(isinstance(ev, m.TrialStarted) for ev in events)
        e.handle(m.ResetFaults())

        def started() -> bool:
            # on a busy machine the fake sensor's thread may stall past the watchdog's 5 ms again: the
            # experimenter then presses Reset once more
            if e.loop.faults and not e.loop.faults & Fault.OPERATOR_STOP:
                e.handle(m.ResetFaults())
            return any(isinstance(ev, m.TrialStarted) for ev in events)

        wait_for(e, started, timeout_s=30.0)
        e.handle(m.AbortSession("rehearsal over"))
        wait_for(e, lambda: any(isinstance(ev, m.SessionEnded) for ev in events))
        ended = next(ev for ev in events if isinstance(ev, m.SessionEnded))
        assert ended.status == "aborted" and ended.aborted >= 1  # (more if a stalled fake sensor aborted one)
        # fault rehearsal exists on the simulated rig only: a person's hand is on this one
        e.handle(m.InjectFault("sensor-stall"))
        refused = [ev for ev in events if isinstance(ev, m.CommandRefused) and ev.command == "InjectFault"]
        assert len(refused) == 1 and "refused on the real rig" in refused[0].message
    finally:
        e.close("test over")
        e.release_ring()
    con = sqlite3.connect(db)
    try:
        rig_kind, config_json, cal_json = con.execute(
            "SELECT rig, config_json, calibration_json FROM sessions").fetchone()
    finally:
        con.close()
    config, cal = json.loads(config_json), json.loads(cal_json)
    assert rig_kind == "real" and config["rig"] == "real" and config["participant"] == "person"
    assert config["hardware_toml"] == hw_path.read_text(encoding="utf-8")
    assert config["hardware"]["sensor"]["port"] == netft.udp_port and config["hardware"]["robot"]["host"] == rtde.host
    assert config["framework"]["f_max_n"] == 2.5 and config["framework"]["filter_window"] == 8
    assert config["framework"]["rot_tip_sensor"] == [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    assert "sim" not in config and "rig_seed" not in config
    assert cal["mass_kg"] == pytest.approx(MASS_KG, abs=1e-5)
    # the calibration chain's provenance: the tool, the file, what was on record, the override and its reason
    rc = config["rig_calibration"]
    assert rc["tool"] == "instrument" and rc["file"] == str(tmp_path / "calibration.json")
    assert rc["payload"]["mass_kg"] == pytest.approx(MASS_KG, abs=1e-5) and "tcp" in rc and "frames" not in rc
    assert config["calibration_override"]["reason"] == "rehearsal of the session flow, nobody holds the stylus"
    assert config["calibration_override"]["missing"].startswith("no frame and sign check on record for tool "
                                                                "'instrument'")
    assert config["calibration_override"]["rest_force_n"] < 0.1  # the override waived the steps, not the force at rest
    con = sqlite3.connect(db)
    try:
        (detail,) = con.execute("SELECT detail FROM events WHERE kind = 'calibration_override'").fetchone()
    finally:
        con.close()
    assert detail.startswith("started by the experimenter's override: no frame and sign check on record for tool") and \
        "; the compensated force at rest was 0.0" in detail and \
        detail.endswith("N (limit 0.1 N). Reason: rehearsal of the session flow, nobody holds the stylus")
    # and the wizard's accepted payload is in the calibration file, for the tool, dated
    saved = json.loads((tmp_path / "calibration.json").read_text(encoding="utf-8"))
    assert saved["tools"]["instrument"]["payload"]["mass_kg"] == pytest.approx(MASS_KG, abs=1e-5)
    assert saved["tools"]["instrument"]["payload"]["date"]


def test_a_pose_recorded_while_the_robot_moves_is_refused(rig):
    _netft, rtde, hw_path = rig
    events: list[object] = []
    e = StudyEngine(HostConfig(rig="real", hardware_path=str(hw_path), haptic_factory=FAKE_TOUCH), events.append,
                    shared_ring=False)
    try:
        e.start()
        tcp_on_record(e, events)  # (poses are then reported 200 mm further along the tool axis)
        for _attempt in range(STALL_RETRIES):
            rtde.send("pose 0.3 -0.1 0.2 0 0 0")
            wait_for(e, lambda: e.eng.rig.robot.read_pose().position_m[2] == pytest.approx(0.4))
            n_before = len(events)
            e.handle(m.RecordPose("P01", 0.3))
            rtde.send("pose 0.3 -0.1 0.25 0 0 0")  # 50 mm up during the recording
            end = time.monotonic() + 5.0  # the engine's driver is not stepped until the robot reports the move
            while e.eng.rig.robot.read_pose().position_m[2] != pytest.approx(0.45) and time.monotonic() < end:
                time.sleep(0.002)
            wait_for(e, lambda n_before=n_before: any(isinstance(ev, (m.CommandRefused, m.PoseRecorded))
                                                      for ev in events[n_before:]))
            if not stalled_refusal(events[n_before:]):
                break
            del events[n_before:]  # the experimenter records it again
        (ev,) = [ev for ev in events if isinstance(ev, m.CommandRefused)]
        assert ev.command == "RecordPose" and ev.message.startswith("pose P01: the robot moved while recording (")
        assert not any(isinstance(ev, m.PoseRecorded) for ev in events)
    finally:
        e.close("test over")
        e.release_ring()


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ("[robot.bogus]\n", "real rig: {path}: robot.bogus = {{}}: unknown field"),
        ("", "real rig: {path}: no such hardware file"),
    ],
)
def test_a_bad_hardware_file_is_one_line(tmp_path, extra, message):
    p = tmp_path / "hardware.toml"
    if extra:
        p.write_text('[sensor]\nhost = "127.0.0.1"\n[robot]\nhost = "127.0.0.1"\n[haptic]\n' + extra, encoding="utf-8")
    with pytest.raises(RuntimeError) as info:
        StudyEngine(HostConfig(rig="real", hardware_path=str(p)), lambda ev: None, shared_ring=False)
    assert message.format(path=p) in str(info.value) and "\n" not in str(info.value)


def test_a_device_that_cannot_be_opened_is_named_and_the_engine_process_exits(rig):
    """No Touch on this machine: the engine process reports the haptic device in one line and exits (no hang)."""
    _netft, _rtde, hw_path = rig
    client = EngineClient(HostConfig(rig="real", hardware_path=str(hw_path)))
    client.start()
    try:
        got: list[object] = []
        end = time.monotonic() + 20.0
        while not any(isinstance(ev, m.EngineStopped) for ev in got) and time.monotonic() < end:
            ev = client.get(0.1)
            if ev is not None:
                got.append(ev)
        assert client.join(5.0)
        refused = [ev for ev in got if isinstance(ev, m.CommandRefused)]
        assert len(refused) == 1 and refused[0].command == "connect"
        assert refused[0].message.startswith("real rig: haptic device: the 3D Systems Touch needs OpenHaptics")
        assert not any(isinstance(ev, m.EngineReady) for ev in got)
    finally:
        client.kill()


def test_real_rig_window_disables_the_sim_views_and_walks_the_poses(qtbot, tmp_path):
    """The window's real-rig wiring; the engine fails to connect (no such file), then an EngineReady of a real rig is
    fed in."""
    from PySide6.QtCore import QSettings

    from study_app.gui.main_window import ExperimenterWindow

    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    w = ExperimenterWindow(HostConfig(rig="real", hardware_path=str(tmp_path / "none.toml")), settings, None)
    qtbot.addWidget(w)
    qtbot.waitUntil(lambda: w.model.session.state == "stopped", timeout=20_000)  # refused, then the engine exits
    assert w.model.session.message == (f"engine stopped: real rig: {tmp_path / 'none.toml'}: no such hardware file "
                                       "(copy hardware.example.toml and edit it)")
    w._on_engine_event(m.EngineReady("", "real", "real", {}, math.nan, (math.nan,) * 3, "participant"))
    assert not w.rig_button.isEnabled() and not w.view_actions["Simulated rig"].isEnabled()
    assert w.rig_button.toolTip().startswith("real rig: a person holds the stylus")
    wiz = w.calibration_wizard
    panel = wiz.real_panel
    assert panel is not None and not panel.isHidden() and wiz.sim_controls.isHidden()
    panel.pose_set.setCurrentText("quick")
    panel.start_button.click()
    assert panel.instruction.text().startswith("Pose 1 (1 of 6): move the TCP to rotation vector (")
    assert panel.record_button.isEnabled() and not panel.identify_button.isEnabled()
    assert panel.identify_button.toolTip() == "record at least 6 poses first (0 so far)"
    cal = w.model.real_calibration
    for step in list(cal.steps):
        w._on_engine_event(m.PoseRecorded(step.label, 1000, (0.0, 0.0, 2.0, 0.0, 0.0, 0.0),
                                          step.target_rot_base_sensor, (0.3, -0.1, 0.2), 20.0, 0.001))
    assert panel.poses.rowCount() == 6 and panel.poses.item(0, 1).text() == "20.0"
    assert panel.poses.item(5, 2).text() == "2.000" and panel.identify_button.isEnabled()
    assert panel.message.text().startswith("Pose 6 is 20° from its target — kept")
