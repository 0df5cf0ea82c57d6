"""hardware.toml: validation with errors naming field, value and what is allowed; the real rig and engine."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pytest

from fake_jaw import PtyJaw
from fake_netft import FakeNetFT
from fake_rtde import FakeRtde
from pipeline.backends.jaw import SerialJawActuator
from pipeline.backends.netft import NetFTForceSensor
from pipeline.backends.touch import TouchHapticDevice
from pipeline.backends.ur import UrRtdeRobot
from pipeline.clock import VirtualClock
from pipeline.compensation import NO_PAYLOAD
from pipeline.devices import DeviceError, HapticState
from pipeline.engine import build_hardware_engine
from pipeline.framework import DEFAULT_ROT_HAPTIC_BASE
from pipeline.hardware import HardwareError, RealRig, build_real_rig, hardware_from_dict, load_hardware

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "hardware.example.toml"


def base() -> dict:
    return {"sensor": {"host": "10.0.0.1"}, "robot": {"host": "10.0.0.2"}, "haptic": {}}


def test_example_file_is_valid_and_documents_the_defaults() -> None:
    hw = load_hardware(EXAMPLE)
    assert hw.sensor.host == "192.168.1.1" and hw.sensor.port == 49152 and hw.sensor.counts_per_force is None
    assert hw.robot.frequency_hz == 125.0 and hw.robot.mode == "observe" and hw.robot.tcp_offset_m == (0.0, 0.0, 0.25)
    assert hw.jaw is not None and hw.jaw.port == "/dev/ttyACM0" and hw.jaw.baud == 115200
    assert hw.framework.f_max_n == 3.0 and hw.framework.f_scale_n == 7.0 and hw.framework.filter_window == 10
    assert hw.framework.rot_haptic_base == DEFAULT_ROT_HAPTIC_BASE
    assert hw.calibration_file is None


def test_minimal_file_takes_defaults() -> None:
    hw = hardware_from_dict(base())
    assert hw.jaw is None and hw.haptic.device_name == "Default Device" and hw.sensor.http_port == 80


@pytest.mark.parametrize(
    ("patch", "message"),
    [
        ({"sensor": {"host": "10.0.0.1", "port": 70000}}, "sensor.port = 70000: must be a whole port number from 1 to 65535"),
        ({"sensor": {"host": "10.0.0.1", "counts_per_force": 1e6}}, "sensor.counts_per_torque = None: give counts_per_force and counts_per_torque together"),
        ({"sensor": {"host": "10.0.0.1", "force_unit": "stone"}}, "sensor.force_unit = 'stone': allowed: N, lbf"),
        ({"sensor": {"host": "10 0 0 1"}}, "sensor.host = '10 0 0 1': must be an IPv4 address (e.g. 192.168.1.1) or a host name"),
        ({"sensor": {"hots": "10.0.0.1"}}, "sensor.hots = '10.0.0.1': unknown field; allowed: buffered, connect_timeout_s"),
        ({"sensor": {}}, "sensor.host = None: required: the Net F/T box's IP address"),
        ({"robot": {"host": "10.0.0.2", "mode": "drive"}}, "robot.mode = 'drive': allowed values: observe, teleop"),
        ({"robot": {"host": "10.0.0.2", "mode": "teleop"}}, "teleop = None: robot.mode = 'teleop' needs a [teleop] table with at least workspace_min_m"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.0]}}, "teleop.workspace_max_m = None: required: the corner of the box"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2], "workspace_max_m": [0.4, 0.2, 0.3]}}, "teleop.workspace_min_m = [0.1, -0.2]: must be 3 numbers in metres"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.3], "workspace_max_m": [0.4, 0.2, 0.3]}}, "teleop.workspace_max_m = [0.4, 0.2, 0.3]: each coordinate must be above workspace_min_m's (z: 0.3 ≤ 0.3)"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.0], "workspace_max_m": [0.4, 0.2, 1.5]}}, "teleop.workspace_max_m = [0.4, 0.2, 1.5]: must be 3 numbers in metres (x, y, z in the robot base frame), each within ±1 m"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.0], "workspace_max_m": [0.4, 0.2, 0.3], "max_speed_m_s": 0.5}}, "teleop.max_speed_m_s = 0.5: must be a number > 0 and ≤ 0.25"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.0], "workspace_max_m": [0.4, 0.2, 0.3], "max_speed_m_s": float("nan")}}, "teleop.max_speed_m_s = nan: must be a number > 0 and ≤ 0.25"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.0], "workspace_max_m": [0.4, 0.2, 0.3], "clutch_button": 1}}, "teleop.clutch_button = 1: must differ from teleop.deadman_button"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.0], "workspace_max_m": [0.4, 0.2, 0.3], "deadman_button": 4}}, "teleop.deadman_button = 4: allowed values: 1 (the Touch's front, dark-grey button), 2 (rear, light-grey)"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.0], "workspace_max_m": [0.4, 0.2, 0.3], "gain": 50}}, "teleop.gain = 50: must be a number from 100 to 2000"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.0], "workspace_max_m": [0.4, 0.2, 0.3], "speed": 1}}, "teleop.speed = 1: unknown field; allowed: clutch_button"),
        ({"robot": {"host": "10.0.0.2", "frequency_hz": 1000}}, "robot.frequency_hz = 1000: must be a number > 0 and ≤ 500"),
        ({"robot": {"host": "10.0.0.2", "tcp_offset_m": [0, 0]}}, "robot.tcp_offset_m = [0, 0]: must be 3 numbers in metres"),
        ({"jaw": {"port": "/dev/ttyACM0", "baud": 1234}}, "jaw.baud = 1234: allowed values: 9600"),
        ({"jaw": {}}, "jaw.port = None: required: the Arduino's serial port"),
        ({"frames": {"rot_tip_sensor": [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}}, "frames.rot_tip_sensor = [[1, 0, 0], [0, 1, 0], [0, 0, -1]] is a reflection"),
        ({"frames": {"rot_haptic_base": [[1, 0.1, 0], [0, 1, 0], [0, 0, 1]]}}, "frames.rot_haptic_base = [[1, 0.1, 0], [0, 1, 0], [0, 0, 1]] is not a rotation"),
        ({"framework": {"f_max_n": -3}}, "framework.f_max_n = -3: must be a number > 0 and ≤ 3.3 (N; the 3D Systems Touch's peak force)"),
        ({"framework": {"filter_window": 0}}, "framework.filter_window = 0: must be a whole number of samples from 1 to 1000"),
        ({"version": 2}, "version = 2: this software reads hardware file version 1"),
        ({"haptic": None}, "haptic = None: must be a table"),
    ],
)
def test_bad_fields_name_field_value_and_what_is_allowed(patch: dict, message: str) -> None:
    d = base()
    d.update(patch)
    if patch.get("haptic", {}) is None:
        d["haptic"] = None
    with pytest.raises(HardwareError) as info:
        hardware_from_dict(d, "lab.toml")
    assert str(info.value).startswith("lab.toml: ") and message in str(info.value)


def test_missing_unreadable_and_invalid_toml(tmp_path: Path) -> None:
    with pytest.raises(HardwareError, match=r"no such hardware file \(copy hardware.example.toml"):
        load_hardware(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[sensor\nhost=1", encoding="utf-8")
    with pytest.raises(HardwareError, match=r"bad.toml: not valid TOML"):
        load_hardware(bad)
    missing = tmp_path / "m.toml"
    missing.write_text('[sensor]\nhost = "1.2.3.4"\n[haptic]\n', encoding="utf-8")
    with pytest.raises(HardwareError, match=r"robot = None: the \[robot\] table is required"):
        load_hardware(missing)


def write_rig_file(tmp_path: Path, netft: FakeNetFT, rtde: FakeRtde, jaw: PtyJaw | None, cal: bool = False) -> Path:
    text = EXAMPLE.read_text(encoding="utf-8")
    d = tomllib.loads(text)
    lines = [
        "version = 1",
        f'[sensor]\nhost = "127.0.0.1"\nport = {netft.udp_port}\nhttp_port = {netft.http_port}\nconnect_timeout_s = 1.0',
        f'[robot]\nhost = "{rtde.host}"\nconnect_timeout_s = 1.0',
        "[haptic]",
    ]
    if jaw is not None:
        lines.append(f'[jaw]\nport = "{jaw.path}"\nready_timeout_s = 1.0')
    lines.append(f"[frames]\nrot_tip_sensor = {d['frames']['rot_tip_sensor']}")
    if cal:
        (tmp_path / "payload.json").write_text(json.dumps(NO_PAYLOAD.to_dict()), encoding="utf-8")
        lines.append('[calibration]\nfile = "payload.json"')
    p = tmp_path / "hardware.toml"
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return p


class _FakeTouch:
    """Stands in for the Touch (no OpenHaptics here); the Touch itself is tested in test_touch.py."""

    peak_force_n = 3.3
    continuous_force_n = 0.88

    def __init__(self, *a: object, **k: object) -> None:
        self.closed = False

    def command_force(self, fx: float, fy: float, fz: float) -> None:
        self.cmd = (fx, fy, fz)

    def read_state(self) -> HapticState:
        return HapticState(0, (0.0, 0.0, 0.0), 0, 0)

    def rearm(self) -> bool:
        return True

    def close(self) -> None:
        self.closed = True


def test_build_real_rig_opens_every_device_and_closes_them(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("pipeline.hardware.open_haptic", lambda cfg, clock: _FakeTouch())
    with FakeNetFT() as netft, FakeRtde() as rtde, PtyJaw() as jaw:
        hw = load_hardware(write_rig_file(tmp_path, netft, rtde, jaw, cal=True))
        assert hw.calibration_file == str(tmp_path / "payload.json")
        eng = build_hardware_engine(hw, clock=VirtualClock())
        rig = eng.rig
        try:
            assert isinstance(rig, RealRig) and all(hasattr(rig, a) for a in ("sensor", "robot", "haptic", "advance", "true_contact_force", "close"))
            assert isinstance(rig.sensor, NetFTForceSensor) and isinstance(rig.robot, UrRtdeRobot)
            assert isinstance(rig.jaw, SerialJawActuator) and rig.true_contact_force() is None
            assert eng.calibration == NO_PAYLOAD and eng.framework.safety.config.f_max_n == 3.0
            eng.loop.run_ticks(3)
            rec = eng.loop.last_record
            assert rec is not None and rec["raw_fx"] == 1.5 and rec["tip_z_m"] == 0.2
        finally:
            rig.close()
        assert rig.haptic.closed and rig.robot.state == "closed"


def test_a_failing_device_closes_the_ones_already_open(tmp_path: Path) -> None:
    with FakeNetFT() as netft, FakeRtde() as rtde:
        hw = load_hardware(write_rig_file(tmp_path, netft, rtde, None))
        with pytest.raises(DeviceError, match=r"^haptic device: .*pip install 'haptic-study\[touch\]'"):
            build_real_rig(hw, VirtualClock())
        # the sensor was opened and closed again: it sent START and then STOP
        assert [r[1] for r in netft.requests] == [2, 0]
        assert rtde.wait_for("DISCONNECTED")
