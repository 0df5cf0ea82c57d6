"""The study engine (the GUI's) on a real rig of two arms, against the loopback fakes: each commissioning step
reads the named arm's own devices and ring and saves to that arm's calibration file only.

Two Net F/T boxes (127.0.0.2 reads 1 N along z for the right arm, 127.0.0.3 reads 2 N for the left), two fake UR
controllers and two faked Touch devices in one servo scheduler (the fakes of :mod:`tests.backends.test_real_rig_arms`,
the boxes streaming at 1 kHz).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from arm_fakes import arm_fakes
from fake_multi_hd import FakeMultiHD, FakeTouch
from fake_netft import FakeNetFT
from fake_rtde import FakeRtde
from waits import until

from pipeline.commissioning.payload_identification import recommended_pose_set
from pipeline.commissioning.tcp import pivot_orientations
from pipeline.sim.robot import TOOL_DOWN
from study_app.engine import messages as m
from study_app.engine.host import StudyEngine
from study_app.engine.setup import HostConfig

G = 9.80665
MASS_KG, COM_M = 0.3, np.array([0.0, 0.01, 0.06])


@pytest.fixture
def fakes() -> Iterator[dict[str, tuple[FakeNetFT, FakeRtde]]]:
    """Two boxes streaming at 1 kHz (the right arm's first) and two UR controllers."""
    with arm_fakes(rate_hz=1000, initial_records=0) as out:
        yield out


@pytest.fixture
def two_touches(monkeypatch: pytest.MonkeyPatch) -> FakeMultiHD:
    hd = FakeMultiHD(FakeTouch("Right Touch"), FakeTouch("Left Touch"))
    monkeypatch.setattr("pipeline.backends.touch.PyOpenHapticsApi", lambda dll_dir=None: hd)
    return hd


def _hardware(tmp_path: Path, fakes: dict[str, Any]) -> Path:
    frames = ("rot_tip_sensor = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n"
              "rot_haptic_base = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]\n")
    text = ""
    for arm, (box, ur) in fakes.items():
        text += (f'[[arm]]\nname = "{arm}"\n[arm.sensor]\nhost = "{box.host}"\nport = {box.udp_port}\n'
                 f'http_port = {box.http_port}\nconnect_timeout_s = 1.0\n[arm.robot]\nhost = "{ur.host}"\n'
                 f'connect_timeout_s = 1.0\n[arm.haptic]\ndevice_name = "{arm.title()} Touch"\n[arm.frames]\n{frames}'
                 "[arm.framework]\nf_max_n = 3.0\nf_scale_n = 7.0\n"
                 f'[arm.calibration]\nfile = "{tmp_path / f"cal-{arm}.json"}"\ntool = "grasper"\n')
    p = tmp_path / "hardware.toml"
    p.write_text(text, encoding="utf-8")
    return p


def _wait(e: StudyEngine, pred: Any, timeout_s: float = 5.0) -> None:
    """Step the engine until ``pred`` holds (its devices' fakes stream in real time)."""
    assert until(lambda: pred() or e.step(), timeout_s), "condition not reached"


def test_each_arm_of_the_real_rig_is_commissioned_from_its_own_devices_into_its_own_file(
        fakes: Any, two_touches: FakeMultiHD, tmp_path: Path) -> None:
    events: list[object] = []
    e = StudyEngine(HostConfig(rig="real", hardware_path=str(_hardware(tmp_path, fakes))), events.append,
                    shared_ring=False)
    try:
        e.start()
        ready = next(ev for ev in events if isinstance(ev, m.EngineReady))
        assert [a for a, _ in ready.arm_rings] == ["right", "left"] == [a for a, _ in ready.arm_mounts]
        statuses = {ev.arm: ev for ev in events if isinstance(ev, m.CalibrationStatus)}
        assert set(statuses) == {"right", "left"} and statuses["left"].file == str(tmp_path / "cal-left.json")
        # a pose recorded on the left arm averages the left box (2 N along z), not the right one (1 N)
        _wait(e, lambda: e.loop.tick_count > 50)
        # the chain in order: the left arm's TCP first (the payload step refuses without it)
        e.handle(m.IdentifyTcp(tuple(
            (f"O{k + 1}", rot, tuple(np.array([0.3, -0.1, 0.15]) - np.asarray(rot).reshape(3, 3) @ [0.0, 0.0, 0.2]))
            for k, rot in enumerate(pivot_orientations("minimal", TOOL_DOWN))), arm="left"))
        assert [ev.accepted for ev in events if isinstance(ev, m.TcpCalibrationDone)] == [True]
        ticks = e.loop.tick_count
        _wait(e, lambda: e.loop.tick_count > ticks + 100)  # the left arm's poses reported at the new tip first
        e.handle(m.RecordPose("P01", seconds=0.2, arm="left"))
        _wait(e, lambda: any(isinstance(ev, (m.PoseRecorded, m.CommandRefused)) for ev in events))
        rec = next(ev for ev in events if isinstance(ev, (m.PoseRecorded, m.CommandRefused)))
        assert isinstance(rec, m.PoseRecorded), rec
        assert rec.samples == 200 and rec.wrench[2] == pytest.approx(2.0, abs=1e-6)
        # the left arm's payload from its poses: installed in its force path, saved in its file only
        poses = []
        for k, rot in enumerate(recommended_pose_set(6)):
            g_s = np.asarray(rot).reshape(3, 3).T @ np.array([0.0, 0.0, -G])
            f = MASS_KG * g_s
            poses.append((f"P{k + 1:02d}", tuple(float(v) for v in np.asarray(rot).ravel()),
                          (*map(float, f), *map(float, np.cross(COM_M, f)))))
        e.handle(m.IdentifyPoses(tuple(poses), "quick", arm="left"))
        done = [ev for ev in events if isinstance(ev, m.CalibrationDone)][-1]
        assert done.accepted, done.reason
        assert e.eng.calibrations["left"].mass_kg == pytest.approx(MASS_KG, rel=1e-6)
        assert e.calibration.mass_kg != pytest.approx(MASS_KG, rel=1e-3)  # the right arm's (the task arm's) is kept
        _wait(e, lambda: e.loop.arm("left").framework.calibration.mass_kg == pytest.approx(MASS_KG, rel=1e-6))
        saved = json.loads((tmp_path / "cal-left.json").read_text(encoding="utf-8"))
        assert "payload" in json.dumps(saved) and not (tmp_path / "cal-right.json").exists()
        left = [ev for ev in events if isinstance(ev, m.CalibrationStatus) and ev.arm == "left"][-1]
        assert dict((n, ok) for n, ok, _ in left.steps)["payload"]
    finally:
        e.close("test over")
        e.release_ring()
