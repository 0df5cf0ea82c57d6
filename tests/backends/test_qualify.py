"""``haptic-study qualify`` against the loopback fake Touch (tests/backends/fake_openhaptics), whose device state
outlives its process (``FAKE_TOUCH_STATE``): a correct device zeroes its force once its process dies, a misbehaving
one (``FAKE_TOUCH_KEEPS_FORCE=1``) keeps it.  The checks run as a user runs them: the command in a subprocess, the
holding child in a subprocess of that."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline.commissioning.qualification import record_path
from pipeline.devices.registry import haptic_model
from pipeline.devices.touch_output import HapticLimits
from pipeline.settings.hardware import load_hardware
from study_app.cli.qualify_checks import run_thermal
from study_app.cli.qualify_cmds import describe_record
from study_app.engine.session_config import qualification_record

ROOT = Path(__file__).resolve().parents[2]
FAKE_OPENHAPTICS = Path(__file__).resolve().parent / "fake_openhaptics"

HARDWARE = """version = 1
[sensor]
host = "127.0.0.1"
[robot]
host = "127.0.0.1"
[haptic]
[frames]
rot_tip_sensor = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
rot_haptic_base = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]
[framework]
f_max_n = 3.0
f_scale_n = 7.0
"""


def qualify(tmp_path: Path, *args: str, keeps_force: bool = False,
            fake: bool = True) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("HAPTIC_STUDY", "FAKE_TOUCH"))}
    if fake:
        env["PYTHONPATH"] = os.pathsep.join([str(FAKE_OPENHAPTICS), str(ROOT)])
        env["FAKE_TOUCH_STATE"] = str(tmp_path / "touch.state")
    if keeps_force:
        env["FAKE_TOUCH_KEEPS_FORCE"] = "1"
    return subprocess.run([sys.executable, "-m", "study_app.cli", "qualify", *args], capture_output=True, text=True,
                          timeout=60, cwd=tmp_path, env=env)


@pytest.fixture
def hardware(tmp_path: Path) -> Path:
    p = tmp_path / "hardware.toml"
    p.write_text(HARDWARE, encoding="utf-8")
    return p


def test_a_correct_device_passes_and_the_record_is_kept_beside_the_calibration(tmp_path: Path,
                                                                              hardware: Path) -> None:
    proc = qualify(tmp_path, "--hardware", str(hardware), "--json")
    assert proc.returncode == 0, proc.stderr
    record = json.loads(proc.stdout)
    checks = {c["name"]: c for c in record["checks"]}
    assert checks["process-death"]["verdict"] == "PASS", json.dumps(checks["process-death"])
    assert "0.440 N held" in checks["process-death"]["measured"]  # half the fake's 0.88 N continuous rating
    assert checks["thermal-budget"]["verdict"] == "PASS", checks["thermal-budget"]
    assert checks["latency"]["verdict"] == "NOT CHECKED" and checks["latency"]["why"]
    assert record["verdict"] == "PARTIAL" and record["software_version"] and record["date"]
    path = record_path(str(tmp_path / "calibration.json"))
    assert path == tmp_path / "calibration.qualification.json"
    assert json.loads(path.read_text(encoding="utf-8")) == record
    shown = describe_record(str(tmp_path / "calibration.json"))
    assert shown is not None and shown.startswith("PARTIAL on ") and "process-death PASS" in shown
    # a real-rig session stores it with its config_json, for the report's methods
    assert qualification_record(load_hardware(str(hardware))) == {"qualification": {"right": record}}


def test_a_device_that_keeps_its_force_after_its_process_died_fails_naming_the_check(tmp_path: Path,
                                                                                    hardware: Path) -> None:
    proc = qualify(tmp_path, "--hardware", str(hardware), "--checks", "process-death", keeps_force=True)
    assert proc.returncode == 1, proc.stderr
    line = next(s for s in proc.stdout.splitlines() if "process-death" in s)
    assert "FAIL" in line and "0.4400 N at" in line and "kept its force after its process died" in line
    assert proc.stdout.splitlines()[-2] == "verdict: FAIL"
    assert json.loads(record_path(str(tmp_path / "calibration.json")).read_text())["verdict"] == "FAIL"


def test_a_device_that_cannot_be_opened_is_not_checked_never_passed(tmp_path: Path, hardware: Path) -> None:
    proc = qualify(tmp_path, "--hardware", str(hardware), "--checks", "process-death,thermal-budget", fake=False)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout.splitlines()
    assert all("NOT CHECKED" in s and "OpenHaptics" in s for s in out[1:3]), out
    assert out[3] == "verdict: PARTIAL"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--hardware", "/nonexistent/hw.toml"], "/nonexistent/hw.toml: no such hardware file"),
        (["--arm", "left"], "hardware.toml has no such arm; its arms: right"),
        (["--checks", "process-death,warp"], "--checks = 'process-death,warp': must name one or more of "
                                             "process-death, thermal-budget, latency, "
                                             "loop-under-load"),
        (["--seconds", "0.5"], "--seconds = '0.5': must be a number of seconds from 1 to 3600"),
        (["--seconds", "nan"], "--seconds = 'nan': must be a number of seconds from 1 to 3600"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_nothing_written(tmp_path: Path, hardware: Path, args: list[str],
                                                          message: str) -> None:
    proc = qualify(tmp_path, *(["--hardware", str(hardware)] if args[0] != "--hardware" else []), *args)
    assert proc.returncode == 2 and message in proc.stderr and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert not record_path(str(tmp_path / "calibration.json")).exists()


def test_the_thermal_check_fails_a_device_whose_budget_is_never_derated() -> None:
    touch = haptic_model("touch").limits
    assert run_thermal(touch, 0.010).verdict == "PASS"
    # derating from the budget itself: the heat passes it before the limit comes down (HD_WARM_MOTORS)
    late = HapticLimits(touch.peak_force_n, touch.continuous_force_n, touch.thermal_budget_n2s, 0.999999)
    result = run_thermal(late, 0.010)
    assert result.verdict == "FAIL" and "HD_WARM_MOTORS" in result.measured
