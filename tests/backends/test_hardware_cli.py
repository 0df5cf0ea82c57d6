"""``haptic-study probe netft`` and ``check-hardware`` against the loopback fakes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from fake_jaw import PtyJaw
from fake_netft import FakeNetFT
from fake_rtde import FakeRtde

from study_app.cli.main import main

ROOT = Path(__file__).resolve().parents[2]


def test_probe_netft_json(capsys: pytest.CaptureFixture[str]) -> None:
    with FakeNetFT(rate_hz=2000, initial_records=0, drop_every=25) as fake:
        rc = main(["probe", "netft", "--host", "127.0.0.1", "--port", str(fake.udp_port),
                   "--http-port", str(fake.http_port), "--samples", "200", "--json"])
    assert rc == 0
    r = json.loads(capsys.readouterr().out)
    assert r["samples"] == 200 and r["requested"] == 200
    assert r["mean_force_n"] == [1.5, -2.0, 3.25] and r["mean_torque_nm"] == [0.1, -0.05, 0.025]
    assert r["lost"] >= 7 and r["reordered"] == 0 and r["corrupt"] == 0 and r["rate_hz"] > 0
    assert r["calibration"]["source"].endswith("/netftapi2.xml")


def test_probe_netft_text(capsys: pytest.CaptureFixture[str]) -> None:
    with FakeNetFT(rate_hz=2000, initial_records=0) as fake:
        assert main(["probe", "netft", "--host", "127.0.0.1", "--port", str(fake.udp_port),
                     "--http-port", str(fake.http_port), "--samples", "20"]) == 0
    out = capsys.readouterr().out
    assert "20 samples" in out and "mean force     +1.5000   -2.0000   +3.2500 N" in out
    assert "lost 0, reordered 0, duplicate 0, corrupt 0, stalled 0, bad status 0" in out


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "study_app.cli", *args], capture_output=True, text=True,
                          timeout=30,
                          cwd=ROOT)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["probe", "netft", "--host", "127.0.0.1", "--http-port", "1"], "cannot read the Net F/T calibration from http://127.0.0.1:1/netftapi2.xml"),
        (["probe", "netft", "--host", "127.0.0.1", "--port", "0"],
         "--port = '0': must be a whole number from 1 to 65535"),
        (["probe", "netft", "--host", "127.0.0.1", "--samples", "0"],
         "--samples = '0': must be a whole number from 1 to 1000000"),
        (["check-hardware", "--hardware", "/nonexistent/hw.toml"], "/nonexistent/hw.toml: no such hardware file"),
    ],
)
def test_bad_input_and_unreachable_devices_are_one_line(args: list[str], message: str) -> None:
    proc = run_cli(*args)
    assert proc.returncode == 2
    assert message in proc.stderr and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 or proc.stderr.startswith("usage:")


def test_check_hardware_reports_each_device(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with FakeNetFT(rate_hz=1000, initial_records=0) as netft, FakeRtde() as rtde, PtyJaw() as jaw:
        p = tmp_path / "hardware.toml"
        p.write_text(
            f'[sensor]\nhost = "127.0.0.1"\nport = {netft.udp_port}\nhttp_port = {netft.http_port}\n'
            f'[robot]\nhost = "{rtde.host}"\n[haptic]\n[jaw]\nport = "{jaw.path}"\nready_timeout_s = 1.0\n'
            '[frames]\nrot_tip_sensor = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\nrot_haptic_base = [[1, 0, 0], [0, 0, 1], '
            '[0, -1, 0]]\n[framework]\nf_max_n = 3.0\nf_scale_n = 7.0\n',
            encoding="utf-8",
        )
        rc = main(["check-hardware", "--hardware", str(p)])
    out = capsys.readouterr().out.splitlines()
    assert rc == 1  # the Touch cannot be opened on this machine
    assert out[0].startswith("force sensor   OK   127.0.0.1: streaming, F = (+1.500, -2.000, +3.250) N, status "
                             "0x00000000")
    assert out[1].startswith(f"robot          OK   {rtde.host}: connected, TCP (+0.3000, -0.1000, +0.2000) m")
    assert out[2].startswith("haptic device  FAIL the 3D Systems Touch needs OpenHaptics")
    assert out[3] == f"jaw actuator   OK   {jaw.path}: READY, limits 1100-1900 µs, at 1100 µs (0% open)"
    assert out[4] == "qualification  OK   never qualified (haptic-study qualify)"
