"""hardware.toml: validation with errors naming field, value and what is allowed; the real rig and engine."""

from __future__ import annotations

import json
import time
import tomllib
from pathlib import Path

import pytest
from fake_jaw import PtyJaw
from fake_netft import FakeNetFT
from fake_rtde import FakeRtde
from hypothesis import given, settings
from tomlvalues import TOML_VALUES, replaced

from pipeline.assembly.engine import build_hardware_engine
from pipeline.assembly.real_rig import RealRig, build_real_rig
from pipeline.backends.jaw import SerialJawActuator
from pipeline.backends.netft import NetFTForceSensor
from pipeline.backends.ur_process import UrPoseProcess
from pipeline.core.clock import VirtualClock
from pipeline.devices.interfaces import DeviceError, HapticState
from pipeline.devices.registry import haptic_model
from pipeline.force.framework import DEFAULT_ROT_HAPTIC_BASE
from pipeline.force.payload_compensator import NO_PAYLOAD
from pipeline.settings.hardware import HardwareConfig, HardwareError, hardware_from_dict, load_hardware
from pipeline.settings.tomlfields import host_problem

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "hardware.example.toml"


#: What sets a rendered force's direction and size: a real rig's file must say it (no default is taken).
FORCE_TOML = ("[frames]\nrot_tip_sensor = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n"
              "rot_haptic_base = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]\n[framework]\nf_max_n = 3.0\nf_scale_n = 7.0\n")


def base() -> dict:
    return {"sensor": {"host": "10.0.0.1"}, "robot": {"host": "10.0.0.2"}, "haptic": {}, **tomllib.loads(FORCE_TOML)}


def test_example_file_is_valid_and_documents_the_defaults() -> None:
    hw = load_hardware(EXAMPLE)
    assert hw.sensor.host == "192.168.1.1" and hw.sensor.port == 49152 and hw.sensor.counts_per_force is None
    assert hw.robot.frequency_hz == 125.0 and hw.robot.mode == "observe" and hw.robot.tcp_offset_m == (0.0, 0.0, 0.25)
    assert hw.jaw is not None and hw.jaw.port == "/dev/ttyACM0" and hw.jaw.baud == 115200
    assert hw.framework.f_max_n == 3.0 and hw.framework.f_scale_n == 7.0 and hw.framework.filter_window == 10
    assert hw.framework.rot_haptic_base == DEFAULT_ROT_HAPTIC_BASE
    # the calibration file is next to the hardware file unless named; the tool and watchdog have defaults
    assert hw.calibration_file == str(EXAMPLE.parent / "calibration.json") and hw.calibration_tool == "grasper"
    assert hw.haptic.command_timeout_s == 0.010
    assert (hw.jaw.close_button, hw.jaw.open_button) == (1, 2)


def test_minimal_file_takes_defaults() -> None:
    hw = hardware_from_dict(base())
    assert hw.jaw is None and hw.haptic.device_name == "Default Device" and hw.sensor.http_port == 80


@pytest.mark.parametrize(("table", "key"), [("frames", "rot_tip_sensor"), ("frames", "rot_haptic_base"),
                                            ("framework", "f_max_n"), ("framework", "f_scale_n")])
def test_what_sets_a_force_s_direction_or_size_has_no_default(table: str, key: str) -> None:
    d = base()
    del d[table][key]
    with pytest.raises(HardwareError) as info:
        hardware_from_dict(d, "lab.toml")
    what = "direction" if table == "frames" else "size"
    assert str(info.value).startswith(f"lab.toml: {table}.{key} = None: required on a real rig: ")
    assert f"it sets the {what} of every rendered force" in str(info.value)


@pytest.mark.parametrize(("patch", "message"), [
    ({"sensor": {"host": "10.0.0.1", "counts_per_force": 1e6, "counts_per_torque": 1e6}},
     "sensor.force_unit = None: required with sensor.counts_per_force: the unit the box's counts are per"),
    ({"sensor": {"host": "10.0.0.1", "counts_per_force": 1e6, "counts_per_torque": 1e6, "force_unit": "lbf"}},
     "sensor.torque_unit = None: required with sensor.counts_per_torque"),
    ({"robot": {"host": "10.0.0.2", "frequency_hz": 10}},
     "robot.frequency_hz = 10: must be above 20 Hz: the watchdog faults when the robot pose is older than 50 ms "
     "(watchdog.pose_max_age_s), and at 10 Hz each pose is 100 ms old when the next arrives"),
    ({"robot": {"host": "10.0.0.2", "frequency_hz": 25, "mode": "teleop"},
      "teleop": {"workspace_min_m": [0.1, -0.2, 0.0], "workspace_max_m": [0.4, 0.2, 0.3], "pose_max_age_s": 0.03}},
     "teleop.pose_max_age_s = 0.03: must be longer than the robot's pose period, 1 / robot.frequency_hz = 40 ms"),
])
def test_values_valid_alone_but_not_together_name_both_fields(patch: dict, message: str) -> None:
    d = base()
    d.update(patch)
    with pytest.raises(HardwareError) as info:
        hardware_from_dict(d, "lab.toml")
    assert str(info.value).startswith("lab.toml: ") and message in str(info.value)


@pytest.mark.parametrize(
    ("patch", "message"),
    [
        ({"sensor": {"host": "10.0.0.1", "port": 70000}},
         "sensor.port = 70000: must be a whole port number from 1 to 65535"),
        ({"sensor": {"host": "10.0.0.1", "counts_per_force": 1e6}},
         "sensor.counts_per_torque = None: give counts_per_force and counts_per_torque together"),
        ({"sensor": {"host": "10.0.0.1", "force_unit": "stone"}}, "sensor.force_unit = 'stone': allowed: N, lbf"),
        ({"sensor": {"host": "10 0 0 1"}},
         "sensor.host = '10 0 0 1': must be an IPv4 address (e.g. 192.168.1.1) or a host name"),
        ({"sensor": {"hots": "10.0.0.1"}},
         "sensor.hots = '10.0.0.1': unknown field; allowed: buffered, connect_timeout_s"),
        ({"sensor": {}}, "sensor.host = None: required: the Net F/T box's IP address"),
        ({"haptic": {"command_timeout_s": 0.2}},
         "haptic.command_timeout_s = 0.2: must be a number from 0.002 to 0.05 s (a force command this old renders as "
         "zero)"),
        ({"haptic": {"command_timeout_s": True}}, "haptic.command_timeout_s = true: must be a number"),
        ({"calibration": {"tool": ""}}, "calibration.tool = '': must be a non-empty name of the mounted instrument"),
        ({"jaw": {"port": "/dev/ttyACM0", "open_button": 1}}, "jaw.open_button = 1: must differ from jaw.close_button"),
        ({"jaw": {"port": "/dev/ttyACM0", "close_button": 3}},
         "jaw.close_button = 3: allowed values: 1 (the Touch's front"),
        ({"robot": {"host": "10.0.0.2", "mode": "drive"}}, "robot.mode = 'drive': allowed values: observe, teleop"),
        ({"robot": {"host": "10.0.0.2", "mode": "teleop"}},
         "teleop = None: robot.mode = 'teleop' needs a [teleop] table with at least workspace_min_m"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.0]}},
         "teleop.workspace_max_m = None: required: the corner of the box"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2], "workspace_max_m": [0.4, 0.2, 0.3]}},
         "teleop.workspace_min_m = [0.1, -0.2]: must be 3 numbers in metres"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.3], "workspace_max_m": [0.4, 0.2, 0.3]}},
         "teleop.workspace_max_m = [0.4, 0.2, 0.3]: each coordinate must be above workspace_min_m's (z: 0.3 ≤ 0.3)"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.0], "workspace_max_m": [0.4, 0.2, 1.5]}},
         "teleop.workspace_max_m = [0.4, 0.2, 1.5]: must be 3 numbers in metres (x, y, z in the robot base frame), "
         "each within ±1 m"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.0], "workspace_max_m": [0.4, 0.2, 0.3], "max_speed_m_s": 0.5}},
         "teleop.max_speed_m_s = 0.5: must be a number > 0 and ≤ 0.25"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.0], "workspace_max_m": [0.4, 0.2, 0.3],
                     "max_speed_m_s": float("nan")}}, "teleop.max_speed_m_s = nan: must be a number > 0 and ≤ 0.25"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.0], "workspace_max_m": [0.4, 0.2, 0.3], "clutch_button": 1}},
         "teleop.clutch_button = 1: must differ from teleop.deadman_button"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.0], "workspace_max_m": [0.4, 0.2, 0.3], "deadman_button": 4}},
         "teleop.deadman_button = 4: allowed values: 1 (the Touch's front, dark-grey button), 2 (rear, light-grey)"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.0], "workspace_max_m": [0.4, 0.2, 0.3], "gain": 50}},
         "teleop.gain = 50: must be a number from 100 to 2000"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.0], "workspace_max_m": [0.4, 0.2, 0.3], "speed": 1}},
         "teleop.speed = 1: unknown field; allowed: clutch_button"),
        ({"robot": {"host": "10.0.0.2", "frequency_hz": 1000}},
         "robot.frequency_hz = 1000: must be a number > 0 and ≤ 500"),
        ({"robot": {"host": "10.0.0.2", "tcp_offset_m": [0, 0]}},
         "robot.tcp_offset_m = [0, 0]: must be 3 numbers in metres"),
        ({"jaw": {"port": "/dev/ttyACM0", "baud": 1234}}, "jaw.baud = 1234: allowed values: 9600"),
        ({"jaw": {}}, "jaw.port = None: required: the Arduino's serial port"),
        ({"frames": {"rot_tip_sensor": [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}},
         "frames.rot_tip_sensor = [[1, 0, 0], [0, 1, 0], [0, 0, -1]] is a reflection"),
        ({"frames": {"rot_haptic_base": [[1, 0.1, 0], [0, 1, 0], [0, 0, 1]]}},
         "frames.rot_haptic_base = [[1, 0.1, 0], [0, 1, 0], [0, 0, 1]] is not a rotation"),
        ({"framework": {"f_max_n": -3}},
         "framework.f_max_n = -3: must be a number from 1e-06 to 3.3 (N; the 3D Systems Touch's peak force)"),
        ({"framework": {"filter_window": 0}},
         "framework.filter_window = 0: must be a whole number of samples from 1 to 1000"),
        ({"version": 2}, "version = 2: this software reads hardware file version 1"),
        ({"haptic": None}, "haptic = None: must be a table"),
        # types: in Python True is an int (True == 1) and 1.0 == 1, so both are refused explicitly
        ({"version": True}, "version = true: this software reads hardware file version 1"),
        ({"sensor": {"host": "10.0.0.1", "port": True}},
         "sensor.port = true: must be a whole port number from 1 to 65535"),
        ({"sensor": {"host": "10.0.0.1", "http_port": 80.0}},
         "sensor.http_port = 80.0: must be a whole port number from 1 to 65535"),
        ({"sensor": {"host": "10.0.0.1", "buffered": 1}}, "sensor.buffered = 1: must be true or false"),
        ({"jaw": {"port": "/dev/ttyACM0", "baud": 115200.0}}, "jaw.baud = 115200.0: allowed values: 9600"),
        ({"jaw": {"port": "/dev/tty ACM0"}}, "jaw.port = '/dev/tty ACM0': must be a non-empty string without spaces"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, 0.0], "workspace_max_m": [0.4, 0.2, 0.3], "deadman_button": True}},
         "teleop.deadman_button = true: allowed values: 1 (the Touch's front"),
        ({"teleop": {"workspace_min_m": [0.1, -0.2, True], "workspace_max_m": [0.4, 0.2, 0.3]}},
         "teleop.workspace_min_m = [0.1, -0.2, True]: must be 3 numbers in metres"),
        ({"framework": {"filter_window": True}},
         "framework.filter_window = true: must be a whole number of samples from 1 to 1000"),
        ({"robot": {"host": "10.0.0.2", "frequency_hz": "125"}},
         "robot.frequency_hz = '125': must be a number > 0 and ≤ 500 (Hz), or -1 to let ur_rtde choose"),
        # hosts: an IP address or an RFC 1123 host name; the Net F/T speaks IPv4 only
        ({"robot": {"host": "robot one"}},
         "robot.host = 'robot one': must be an IP address (e.g. 192.168.1.1 or fe80::1) or a host name"),
        ({"robot": {"host": "10.0.0.256"}}, "robot.host = '10.0.0.256': must be an IP address"),
        ({"robot": {"host": 10}}, "robot.host = 10: must be an IP address"),
        ({"sensor": {"host": "fe80::1"}},
         "sensor.host = 'fe80::1': must be an IPv4 address (e.g. 192.168.1.1) or a host name "
         "(letters, digits, '-', separated by '.'); this device speaks IPv4 only"),
        # rotations: 3 rows of 3 real numbers
        ({"frames": {"rot_tip_sensor": [["1", "0", "0"], ["0", "1", "0"], ["0", "0", "1"]]}},
         "frames.rot_tip_sensor = [['1', '0', '0'], ['0', '1', '0'], ['0', '0', '1']]: must be a rotation matrix: 3 "
         "rows of 3 numbers"),
        ({"frames": {"rot_tip_sensor": [[True, False, False], [False, True, False], [False, False, True]]}},
         "frames.rot_tip_sensor = [[True, False, False], [False, True, False], [False, False, True]]: must be a "
         "rotation matrix"),
        ({"frames": {"rot_tip_sensor": "identity"}}, "frames.rot_tip_sensor = 'identity': must be a rotation matrix"),
        ({"frames": {"rot_tip_sensor": [1, 0, 0, 0, 1, 0, 0, 0, 1]}},
         "frames.rot_tip_sensor = [1, 0, 0, 0, 1, 0, 0, 0, 1]: must be a rotation matrix: 3 rows"),
        ({"frames": {"rot_tip_sensor": [[10**400, 0, 0], [0, 1, 0], [0, 0, 1]]}},
         "frames.rot_tip_sensor = [[100000000000000000...0000000000000000000, 0, 0], [0, 1, 0], [0, 0, 1]]: is not a "
         "rotation: every entry of a rotation matrix lies within ±1"),
        ({"frames": {"rot_haptic_base": [[1, 0, 0], [0, float("nan"), 0], [0, 0, 1]]}},
         "frames.rot_haptic_base = [[1, 0, 0], [0, nan, 0], [0, 0, 1]]: must be a rotation matrix"),
        # f_max: never above the Touch's peak force
        ({"framework": {"f_max_n": 5.0}},
         "framework.f_max_n = 5.0: must be a number from 1e-06 to 3.3 (N; the 3D Systems Touch's peak force)"),
        ({"framework": {"f_max_n": 3.31}}, "framework.f_max_n = 3.31: must be a number from 1e-06 to 3.3"),
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
        f'[sensor]\nhost = "127.0.0.1"\nport = {netft.udp_port}\nhttp_port = {netft.http_port}\n'
        'connect_timeout_s = 1.0',
        f'[robot]\nhost = "{rtde.host}"\nconnect_timeout_s = 1.0',
        "[haptic]",
    ]
    if jaw is not None:
        lines.append(f'[jaw]\nport = "{jaw.path}"\nready_timeout_s = 1.0')
    lines.append(f"[frames]\nrot_tip_sensor = {d['frames']['rot_tip_sensor']}\n"
                 f"rot_haptic_base = {d['frames']['rot_haptic_base']}\n[framework]\nf_max_n = 3.0\nf_scale_n = 7.0")
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

    def command_force(self, fx: float, fy: float, fz: float, t_ns: int | None = None) -> None:
        self.cmd = (fx, fy, fz)

    def read_state(self) -> HapticState:
        return HapticState(0, (0.0, 0.0, 0.0), 0, 0)

    def rearm(self) -> bool:
        return True

    def close(self) -> None:
        self.closed = True


def test_build_real_rig_opens_every_device_and_closes_them(tmp_path: Path) -> None:
    with FakeNetFT() as netft, FakeRtde() as rtde, PtyJaw() as jaw:
        hw = load_hardware(write_rig_file(tmp_path, netft, rtde, jaw, cal=True))
        assert hw.calibration_file == str(tmp_path / "payload.json")
        eng = build_hardware_engine(hw, clock=VirtualClock(), open_haptic=lambda cfg, clock: _FakeTouch())
        rig = eng.rig
        try:
            assert isinstance(rig,
                              RealRig) and all(hasattr(rig, a) for a in ("sensor", "robot", "haptic", "advance",
                                                                         "true_contact_force", "close"))
            assert isinstance(rig.sensor, NetFTForceSensor) and isinstance(rig.robot, UrPoseProcess)
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
        # the sensor was opened and closed again: it sent START and then STOP (the fake reads UDP in its own
        # thread: wait, bounded, for the STOP datagram to arrive)
        deadline = time.monotonic() + 2.0
        while [r[1] for r in netft.requests] != [2, 0] and time.monotonic() < deadline:
            time.sleep(0.002)
        assert [r[1] for r in netft.requests] == [2, 0]
        assert rtde.wait_for("DISCONNECTED")


def test_f_max_may_equal_the_touchs_peak_force() -> None:
    d = base()
    d["framework"]["f_max_n"] = haptic_model("touch").limits.peak_force_n
    assert hardware_from_dict(d).framework.f_max_n == haptic_model("touch").limits.peak_force_n


def test_an_integer_too_long_for_python_is_refused_as_toml(tmp_path: Path) -> None:
    p = tmp_path / "long.toml"
    p.write_text(EXAMPLE.read_text(encoding="utf-8").replace("port = 49152", "port = " + "9" * 5000), encoding="utf-8")
    with pytest.raises(HardwareError, match=r"long.toml: not valid TOML \(Exceeds the limit \(4300 digits\)"):
        load_hardware(p)


@pytest.mark.parametrize(
    "host", ["192.168.1.1", "10.0.0.2", "localhost", "ur3.lab", "ur3-left.lab.example.org", "ur3.lab.", "3com.com",
             "a" * 63 + ".lab", "::1", "fe80::1", "fe80::1%eth0", "2001:db8::7"],
)
def test_hosts_that_are_ip_addresses_or_host_names_are_accepted(host: str) -> None:
    assert host_problem(host) is None
    assert (host_problem(host, ipv6=False) is None) == (":" not in host)


@pytest.mark.parametrize(
    "host", ["", " ", "10.0.0.1 ", "10 0 0 1", "10.0.0.256", "10.0.0", "999.1.1.1", "-ur3.lab", "ur3-.lab", "ur3..lab",
             "ur3_lab", "a" * 64 + ".lab", "a." * 127 + "b", "[::1]", "http://10.0.0.1", "10.0.0.1:30004", "ü.lab",
             "fe80::1::2", None, 10, True, ["10.0.0.1"]],
)
def test_hosts_that_are_neither_are_refused(host: object) -> None:
    assert host_problem(host) is not None and host_problem(host, ipv6=False) is not None


# -- any value of any type in any field -----------------------------------------------------------
_TELEOP = {"workspace_min_m": [0.2, -0.1, 0.05], "workspace_max_m": [0.4, 0.1, 0.25], "max_speed_m_s": 0.1,
           "motion_scale": 0.5, "deadman_button": 1, "clutch_button": 2, "stylus_max_age_s": 0.02,
           "pose_max_age_s": 0.05, "max_tracking_error_m": 0.05, "lookahead_s": 0.1, "gain": 300,
           "control_timeout_s": 5.0}
_FULL = {**tomllib.loads(EXAMPLE.read_text(encoding="utf-8")), "calibration": {"file": "payload.json"},
         "teleop": _TELEOP}
_FULL["robot"] = {**_FULL["robot"], "mode": "teleop"}
_FULL["sensor"] = {**_FULL["sensor"], "counts_per_force": 1e6, "counts_per_torque": 1e6, "force_unit": "N",
                   "torque_unit": "Nm"}
FIELDS = [(k,) for k in _FULL] + [(k, f) for k, v in _FULL.items() if isinstance(v, dict) for f in v] + [
    ("frames", "rot_tip_sensor", 1), ("frames", "rot_tip_sensor", 1, 1), ("teleop", "workspace_min_m", 2),
]


def _assert_well_typed(hw: HardwareConfig) -> None:
    for settings_ in (hw.sensor, hw.robot, hw.jaw, hw.teleop, hw.framework):
        for name in type(settings_).__dataclass_fields__:
            v = getattr(settings_, name)
            default = type(settings_).__dataclass_fields__[name].type
            assert not (isinstance(v, bool) and "bool" not in str(default)), (name, v)
            if isinstance(v, tuple):
                assert all(type(x) is float for x in v), (name, v)
    assert type(hw.sensor.port) is int and type(hw.jaw.baud) is int and type(hw.framework.filter_window) is int
    assert 0 < hw.framework.f_max_n <= haptic_model("touch").limits.peak_force_n
    assert host_problem(hw.sensor.host, ipv6=False) is None and host_problem(hw.robot.host) is None


@pytest.mark.parametrize("path", FIELDS, ids=[".".join(map(str, f)) for f in FIELDS])
@settings(max_examples=40)
@given(value=TOML_VALUES)
def test_any_toml_value_in_any_field_is_a_one_line_error_or_a_well_typed_config(path: tuple, value: object) -> None:
    assert hardware_from_dict(_FULL).teleop is not None  # the file under test is valid before the change
    try:
        hw = hardware_from_dict(replaced(_FULL, path, value), "any.toml")
    except HardwareError as exc:  # never another exception
        msg = str(exc)
        assert msg.startswith("any.toml: ") and "\n" not in msg and str(path[0]) in msg
        return
    _assert_well_typed(hw)
