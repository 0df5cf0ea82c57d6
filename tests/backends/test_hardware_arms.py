"""hardware.toml with [[arm]] tables: both arms of the rig as data; every refusal names the arm, field and value."""

from __future__ import annotations

import copy
import tomllib
from pathlib import Path
from typing import Any

import pytest

from pipeline.settings.hardware import SINGLE_ARM_NAME, HardwareConfig, HardwareError, hardware_from_dict, load_hardware

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "hardware.example.toml"
MARK = "# The lines below, uncommented"


def _force() -> dict[str, Any]:
    return {"frames": {"rot_tip_sensor": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
                       "rot_haptic_base": [[1, 0, 0], [0, 0, 1], [0, -1, 0]]},
            "framework": {"f_max_n": 3.0, "f_scale_n": 7.0}}


def two_arms() -> dict[str, Any]:
    return {"arm": [
        {"name": "right", "sensor": {"host": "10.0.0.1"}, "robot": {"host": "10.0.0.2"},
         "haptic": {"device_name": "Right Touch"}, **_force()},
        {"name": "left", "sensor": {"host": "10.0.0.3"}, "robot": {"host": "10.0.0.4"},
         "haptic": {"device_name": "Left Touch"}, **_force()},
    ]}


def example_two_arm_text() -> str:
    """The example file's commented two-arm file, uncommented."""
    lines = EXAMPLE.read_text(encoding="utf-8").splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(MARK)) + 1
    return "\n".join(line[2:] if line.startswith("# ") else line[1:] for line in lines[start:]) + "\n"


def test_the_examples_two_arm_file_loads(tmp_path: Path) -> None:
    p = tmp_path / "hw.toml"
    p.write_text(example_two_arm_text(), encoding="utf-8")
    hw = load_hardware(p)
    assert [a.name for a in hw.arms] == ["right", "left"] and hw.fault_policy == "both"
    right, left = hw.arms
    assert (right.sensor.host, left.sensor.host, left.robot.host) == ("192.168.1.1", "192.168.1.3", "192.168.1.4")
    assert (right.haptic.device_name, left.haptic.device_name) == ("Right Touch", "Left Touch")
    # each arm its own calibration file next to the hardware file; the one-arm fields are the first arm's
    assert left.calibration_file == str(tmp_path / "calibration-left.json")
    assert hw.sensor is right.sensor and hw.calibration_file == right.calibration_file
    assert hw.arm("left") is left
    with pytest.raises(KeyError, match="right, left"):
        hw.arm("middle")


def test_a_one_arm_file_is_one_arm_named_right() -> None:
    hw = load_hardware(EXAMPLE)  # the one-arm example, unchanged
    assert len(hw.arms) == 1 and hw.arms[0].name == SINGLE_ARM_NAME == "right"
    assert hw.arms[0].sensor is hw.sensor and hw.arms[0].calibration_file == hw.calibration_file
    assert hw.fault_policy == "both"
    # built in code from the one-arm fields, too
    built = HardwareConfig(hw.sensor, hw.robot, hw.haptic, None)
    assert [a.name for a in built.arms] == ["right"] and built.arms[0].robot is hw.robot


def test_independent_policy() -> None:
    d = two_arms()
    d["rig"] = {"fault_policy": "independent"}
    assert hardware_from_dict(d).fault_policy == "independent"


def _refused(d: dict[str, Any], *parts: str) -> str:
    with pytest.raises(HardwareError) as e:
        hardware_from_dict(d, "hw.toml")
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith("hw.toml: ")
    for part in parts:
        assert part in msg, msg
    return msg


def _edit(path: tuple[Any, ...], value: Any) -> dict[str, Any]:
    d = copy.deepcopy(two_arms())
    t: Any = d
    for k in path[:-1]:
        t = t[k]
    t[path[-1]] = value
    return d


@pytest.mark.parametrize(("path", "value", "parts"), [
    (("arm", 1, "sensor", "host"), "10.0.0.1", ("arm 'left': sensor.host = '10.0.0.1'", "arm 'right' has it already")),
    (("arm", 1, "robot", "host"), "10.0.0.2", ("arm 'left': robot.host = '10.0.0.2'", "arm 'right' has it already")),
    (("arm", 1, "haptic", "device_name"), "Right Touch",
     ("arm 'left': haptic.device_name = 'Right Touch'", "one Touch")),
    (("arm", 1, "name"), "right", ("arm[1].name = 'right'", "its own name")),
    (("arm", 1, "name"), "two words", ("arm[1].name = 'two words'", "letters, digits")),
    (("arm", 1, "name"), 7, ("arm[1].name = 7",)),
    (("arm", 1, "sensor", "port"), 0, ("arm 'left': sensor.port = 0", "from 1 to 65535")),
    (("arm", 0, "haptic", "command_timeout_s"), 0.5, ("arm 'right': haptic.command_timeout_s = 0.5",)),
    (("arm", 1, "frames", "rot_tip_sensor"), [[1, 0, 0]], ("arm 'left': frames.rot_tip_sensor",)),
    (("arm", 1, "wheels"), {}, ("arm 'left': wheels = {}", "unknown field")),
    (("arm", 0, "calibration"), {"file": "cal.json"}, ()),
    (("rig",), {"fault_policy": "one"}, ("rig.fault_policy = 'one'", "'both'", "'independent'")),
    (("sensor",), {"host": "10.0.0.9"}, ("sensor = ", "move [sensor] into an [[arm]] table")),
    (("arm",), [], ("arm = []", "one or more [[arm]] tables")),
    (("arm",), {"name": "x"}, ("arm = ", "one or more [[arm]] tables")),
])
def test_each_refusal_names_the_arm_the_field_and_the_value(path: tuple[Any, ...], value: Any,
                                                            parts: tuple[str, ...]) -> None:
    d = _edit(path, value)
    if path == ("arm", 0, "calibration"):  # a file of its own: fine; the same file and tool on both: refused
        hardware_from_dict(d)
        d["arm"][1]["calibration"] = {"file": "./cal.json"}
        parts = ("arm 'left': calibration.tool = 'instrument'", "overwrite each other")
    _refused(d, *parts)


def test_missing_name_and_jaw_port_and_too_many_arms() -> None:
    d = two_arms()
    del d["arm"][0]["name"]
    _refused(d, "arm[0].name = None", "required")
    d = two_arms()
    for a in d["arm"]:
        a["jaw"] = {"port": "/dev/ttyACM0"}
    _refused(d, "arm 'left': jaw.port = '/dev/ttyACM0'", "arm 'right' has it already")
    d = two_arms()
    d["arm"] = [dict(d["arm"][0], name=f"a{i}", sensor={"host": f"10.0.1.{i}"}, robot={"host": f"10.0.2.{i}"},
                     haptic={"device_name": f"T{i}"}) for i in range(5)]
    _refused(d, "at most 4 arms")


def test_refusals_are_one_line_from_the_file(tmp_path: Path) -> None:
    text = example_two_arm_text().replace('host = "192.168.1.3"', 'host = "192.168.1.1"')
    p = tmp_path / "hw.toml"
    p.write_text(text, encoding="utf-8")
    with pytest.raises(HardwareError, match=r"arm 'left': sensor.host = '192.168.1.1': arm 'right' has it already"):
        load_hardware(p)
    assert tomllib.loads(text)["arm"][1]["name"] == "left"


def test_replacing_a_one_arm_field_replaces_the_first_arms() -> None:
    import dataclasses

    hw = hardware_from_dict(two_arms())
    moved = dataclasses.replace(hw, sensor=dataclasses.replace(hw.sensor, host="10.0.0.9"))
    assert moved.arms[0].sensor.host == "10.0.0.9" and moved.arms[0].name == "right"
    assert moved.arms[1] is hw.arms[1]
