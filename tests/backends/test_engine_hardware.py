"""The engine process on the real rig: built from a hardware file, against the loopback fakes (real clock, short)."""

from __future__ import annotations

from pathlib import Path

import pytest

from fake_jaw import PtyJaw
from fake_netft import FakeNetFT
from fake_rtde import FakeRtde
from pipeline.engine import EngineConfig, EngineProcess, EngineStartError
from test_hardware_config import write_rig_file

FAKE_OPENHAPTICS = Path(__file__).resolve().parent / "fake_openhaptics"


def test_engine_process_runs_the_real_rig_from_a_hardware_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # the child finds the pure-Python pyOpenHaptics stand-in (spawn passes sys.path on); the Touch backend,
    # its PyOpenHapticsApi adapter, the Net F/T client, ur_rtde and the jaw's serial port are all the real ones
    monkeypatch.syspath_prepend(str(FAKE_OPENHAPTICS))
    with FakeNetFT(rate_hz=1000.0) as netft, FakeRtde() as rtde, PtyJaw() as jaw:
        path = write_rig_file(tmp_path, netft, rtde, jaw)
        proc = EngineProcess(EngineConfig(hardware_file=str(path), ring_seconds=1.0), max_ticks=300)
        try:
            proc.start(timeout_s=10.0)
            assert proc.opening == "jaw actuator" and proc.calibration is not None
            proc.wait(timeout_s=5.0)
            assert proc.final_ticks == 300
            assert proc.ring is not None
            rows = proc.ring.latest(300)
            assert len(rows) == 300
            raw_fx = proc.ring.column(rows, "raw_fx")
            tip_z = proc.ring.column(rows, "tip_z_m")
            stylus_y = proc.ring.column(rows, "stylus_y_m")
            assert set(raw_fx.tolist()) == {1.5} and set(tip_z.tolist()) == {0.2}  # the fakes' values, in N and m
            assert set(stylus_y.tolist()) == {0.01}  # the stand-in Touch reports 10 mm
        finally:
            proc.stop()
        assert not proc.alive


def test_a_device_that_fails_to_open_is_one_clear_start_error(tmp_path: Path) -> None:
    # no OpenHaptics here: the Touch fails after the sensor and robot opened (and are closed again)
    with FakeNetFT() as netft, FakeRtde() as rtde:
        path = write_rig_file(tmp_path, netft, rtde, None)
        proc = EngineProcess(EngineConfig(hardware_file=str(path)))
        with pytest.raises(EngineStartError, match=r"^engine could not start: haptic device: the 3D Systems Touch needs OpenHaptics"):
            proc.start(timeout_s=10.0)
        assert not proc.alive and proc.opening == "haptic device"
        assert [r[1] for r in netft.requests] == [2, 0]  # START, then STOP when the rig was unwound
    bad = tmp_path / "bad.toml"
    bad.write_text('[sensor]\nhost = "1.2.3.4"\n[robot]\nhost = "1.2.3.5"\nmode = "teleop"\n[haptic]\n', encoding="utf-8")
    proc = EngineProcess(EngineConfig(hardware_file=str(bad)))
    with pytest.raises(EngineStartError, match=r"bad.toml: teleop = None: robot.mode = 'teleop' needs a \[teleop\] table"):
        proc.start(timeout_s=10.0)


def test_a_device_that_hangs_times_out_naming_it(tmp_path: Path) -> None:
    # the Net F/T answers HTTP but never streams: the sensor waits its own 3 s; the parent gives up first
    with FakeNetFT(initial_records=0) as netft, FakeRtde() as rtde:
        path = write_rig_file(tmp_path, netft, rtde, None)
        path.write_text(path.read_text(encoding="utf-8").replace("connect_timeout_s = 1.0", "connect_timeout_s = 3.0", 1),
                        encoding="utf-8")
        proc = EngineProcess(EngineConfig(hardware_file=str(path)))
        with pytest.raises(EngineStartError, match=r"^engine did not become ready within 1.5 s \(still opening the force sensor\)$"):
            proc.start(timeout_s=1.5)
        assert not proc.alive
