"""The study engine process on the real rig: built from a hardware file, against the loopback fakes (real clock,
short)."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from fake_jaw import PtyJaw
from fake_netft import FakeNetFT
from fake_rtde import FakeRtde
from test_hardware_config import write_rig_file

from study_app.engine import messages as m
from study_app.engine.client import EngineClient, EngineStartError
from study_app.engine.setup import HostConfig

FAKE_OPENHAPTICS = Path(__file__).resolve().parent / "fake_openhaptics"


def test_engine_process_runs_the_real_rig_from_a_hardware_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # the child finds the pure-Python pyOpenHaptics stand-in (spawn passes sys.path on); the Touch backend,
    # its PyOpenHapticsApi adapter, the Net F/T client, ur_rtde and the jaw's serial port are all the real ones
    monkeypatch.syspath_prepend(str(FAKE_OPENHAPTICS))
    with FakeNetFT(rate_hz=1000.0) as netft, FakeRtde() as rtde, PtyJaw() as jaw:
        path = write_rig_file(tmp_path, netft, rtde, jaw)
        client = EngineClient(HostConfig(rig="real", hardware_path=str(path)))
        try:
            ready, before = client.wait_ready(10.0)
            opened = [ev.device for ev in before if isinstance(ev, m.EngineOpening)]
            assert opened == ["force sensor", "robot", "haptic device", "jaw actuator"]
            assert client.opening == "jaw actuator"
            assert ready.rig == "real" and ready.calibration is not None
            ring = client.ring
            assert ring is not None
            end = time.monotonic() + 5.0
            while ring.write_count < 300:
                assert time.monotonic() < end, "the real rig's loop did not run"
                client.get(0.01)
            rows = ring.latest(300)
            assert len(rows) == 300
            raw_fx = ring.column(rows, "raw_fx")
            tip_z = ring.column(rows, "tip_z_m")
            stylus_y = ring.column(rows, "stylus_y_m")
            assert set(raw_fx.tolist()) == {1.5} and set(tip_z.tolist()) == {0.2}  # the fakes' values, in N and m
            assert set(stylus_y.tolist()) == {0.01}  # the stand-in Touch reports 10 mm
            client.shutdown()
            assert client.stopped is not None and client.stopped.stats["ticks"] >= 299
        finally:
            client.kill()
        assert not client.alive


def test_a_device_that_fails_to_open_is_one_clear_start_error(tmp_path: Path) -> None:
    # no OpenHaptics here: the Touch fails after the sensor and robot opened (and are closed again)
    with FakeNetFT() as netft, FakeRtde() as rtde:
        path = write_rig_file(tmp_path, netft, rtde, None)
        client = EngineClient(HostConfig(rig="real", hardware_path=str(path)))
        with pytest.raises(EngineStartError,
                           match=r"^engine could not start: real rig: haptic device: the 3D Systems Touch needs "
                                 r"OpenHaptics"):
            client.wait_ready(10.0)
        assert not client.alive and client.opening == "haptic device"
        assert [r[1] for r in netft.requests] == [2, 0]  # START, then STOP when the rig was unwound
    bad = tmp_path / "bad.toml"
    bad.write_text('[sensor]\nhost = "1.2.3.4"\n[robot]\nhost = "1.2.3.5"\nmode = "teleop"\n[haptic]\n',
                   encoding="utf-8")
    client = EngineClient(HostConfig(rig="real", hardware_path=str(bad)))
    with pytest.raises(EngineStartError,
                       match=r"bad.toml: teleop = None: robot.mode = 'teleop' needs a \[teleop\] table"):
        client.wait_ready(10.0)
    assert not client.alive


def test_a_device_that_hangs_times_out_naming_it(tmp_path: Path) -> None:
    # the Net F/T answers HTTP but never streams: the sensor waits its own 10 s; the parent gives up first (the
    # engine's process starts, then the loop's own, before the sensor is opened: a few seconds on a busy machine)
    with FakeNetFT(initial_records=0) as netft, FakeRtde() as rtde:
        path = write_rig_file(tmp_path, netft, rtde, None)
        path.write_text(path.read_text(encoding="utf-8").replace("connect_timeout_s = 1.0",
                                                                 "connect_timeout_s = 10.0", 1),
                        encoding="utf-8")
        client = EngineClient(HostConfig(rig="real", hardware_path=str(path)))
        with pytest.raises(EngineStartError,
                           match=r"^engine did not become ready within 5 s \(still opening the force sensor\)$"):
            client.wait_ready(5.0)
        assert not client.alive
