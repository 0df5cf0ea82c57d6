"""The UR pose stream in a process of its own, against the fake controller: poses, reconnects, a controller that
cannot be reached -- and the 1 kHz loop that no longer stalls while the stream reconnects.

ur_rtde holds the interpreter lock for the whole of a connect (40 ms against this fake, half a second on the
second and later connects): run in the loop's process, every reconnect of the pose stream froze the loop past its
50 ms limit and latched ``LOOP_STALLED`` -- the wrong cause, for a network hiccup.  Real processes, real clock:
bounded polls only.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from fake_netft import FakeNetFT
from fake_rtde import FakeRtde

from pipeline.backends.ur import RtdeLink
from pipeline.backends.ur_process import UrPoseProcess
from pipeline.core.clock import MonotonicClock, VirtualClock
from pipeline.devices.interfaces import DeviceError, Fault, Robot
from pipeline.force.frames import rotvec_to_matrix
from study_app.engine import messages as m
from study_app.engine.host import StudyEngine
from study_app.engine.setup import HostConfig

WAIT_S = 10.0
FAKE_TOUCH = "fake_touch:open_fake_touch"


def _until(done, timeout_s: float = WAIT_S, what: str = "") -> None:
    end = time.monotonic() + timeout_s
    while not done():
        assert time.monotonic() < end, f"timed out: {what}"
        time.sleep(0.01)


def _open(fake: FakeRtde, clock=None) -> UrPoseProcess:
    return UrPoseProcess(RtdeLink(fake.host, clock=clock or MonotonicClock(), connect_timeout_s=2.0),
                         min_backoff_s=0.05, max_backoff_s=0.2)


def test_the_pose_process_streams_poses_at_the_calibrated_tip_and_reconnects() -> None:
    with FakeRtde() as fake:
        fake.send("pose 0.31 -0.12 0.205 0.0 0.0 0.0")
        robot = _open(fake)
        try:
            assert isinstance(robot, Robot) and robot.pid != os.getpid()
            _until(lambda: robot.read_pose().position_m == (0.31, -0.12, 0.205), what="the first pose")
            pose = robot.read_pose()
            assert pose.rot_base_tip == rotvec_to_matrix(0.0, 0.0, 0.0) and pose.controller_time_s > 1000.0
            assert 0 <= MonotonicClock().now_ns() - pose.t_ns < 5e9  # stamped on the loop's (monotonic) clock
            robot.tcp_correction_m = (0.0, 0.0, 0.2)  # the tool 200 mm along the TCP's z (rotation: identity)
            _until(lambda: robot.read_pose().position_m[2] == pytest.approx(0.405), what="the corrected tip")
            fake.send("refuse")
            fake.send("drop")
            _until(lambda: robot.state in ("reconnecting", "disconnected"), what="the link's loss")
            n = robot.samples
            fake.send("listen")
            _until(lambda: robot.reconnects == 1 and robot.samples > n + 5, what="poses after the reconnect")
            assert robot.state == "connected"
        finally:
            robot.close()
        assert robot.state == "closed"


def test_a_pose_on_another_clock_is_stamped_when_the_reader_sees_it() -> None:
    with FakeRtde() as fake:
        clock = VirtualClock(123_000_000_000)
        robot = _open(fake, clock)
        try:
            _until(lambda: robot.samples > 0, what="a pose")
            assert robot.read_pose().t_ns == 123_000_000_000
        finally:
            robot.close()


def test_a_controller_that_cannot_be_reached_is_one_line() -> None:
    # nothing listens on this loopback address: the pose process's probe says so, in one line, and it ends
    with pytest.raises(DeviceError, match=r"^cannot reach the UR controller at 127\.251\.7\.3:30004 \("):
        UrPoseProcess(RtdeLink("127.251.7.3", clock=MonotonicClock(), connect_timeout_s=0.5))


def _hardware(tmp_path: Path, netft: FakeNetFT, rtde: FakeRtde) -> Path:
    p = tmp_path / "hardware.toml"
    p.write_text(
        f'[sensor]\nhost = "127.0.0.1"\nport = {netft.udp_port}\nhttp_port = {netft.http_port}\n'
        f'[robot]\nhost = "{rtde.host}"\nconnect_timeout_s = 1.0\n[haptic]\ndevice_name = "Fake Touch"\n'
        "[frames]\nrot_tip_sensor = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n"
        "rot_haptic_base = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]\n"
        "[framework]\nf_max_n = 2.5\nf_scale_n = 6.0\nfilter_window = 8\n", encoding="utf-8")
    return p


def test_a_robot_reconnect_no_longer_latches_loop_stalled(tmp_path: Path) -> None:
    """The real rig on the fakes, the loop in its own process, the pose stream in its own: the controller's link
    drops and comes back twice.  The robot's silence latches POSE_STALE (its own fault, the right cause) and the
    stream reconnects -- in the pose process, whose connects hold only its own interpreter lock: the loop ticks on
    and never latches LOOP_STALLED."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "gui"))  # the fake Touch's module
    with FakeNetFT(rate_hz=1000) as netft, FakeRtde() as rtde:
        events: list[object] = []
        e = StudyEngine(HostConfig(rig="real", hardware_path=str(_hardware(tmp_path, netft, rtde)),
                                   haptic_factory=FAKE_TOUCH), events.append)
        try:
            assert e.remote is not None
            link = e.remote.loop.link
            e.start()
            pose_pid = link.call("", "robot.pid")
            assert pose_pid not in (os.getpid(), e.remote.loop.pid)  # ur_rtde is in neither interpreter
            for k in range(2):
                rtde.send("refuse")
                rtde.send("drop")
                end = time.monotonic() + WAIT_S
                while not e.loop.faults & Fault.POSE_STALE:
                    assert time.monotonic() < end, "the robot's silence was not seen"
                    e.step()
                    time.sleep(0.002)
                rtde.send("listen")
                end = time.monotonic() + WAIT_S
                while link.call("", "robot.reconnects") < k + 1 or link.call("", "robot.state") != "connected":
                    assert time.monotonic() < end, "the pose stream did not reconnect"
                    e.step()
                    time.sleep(0.01)
                ticks = e.loop.tick_count
                end = time.monotonic() + WAIT_S
                while e.loop.tick_count < ticks + 100:  # the loop runs on, poses fresh again
                    assert time.monotonic() < end
                    e.step()
                    time.sleep(0.002)
            stalled = [ev for ev in events if isinstance(ev, m.EngineFault) and "LOOP_STALLED" in ev.detail]
            assert not stalled, [ev.detail for ev in stalled]
            assert not e.loop.faults & Fault.LOOP_STALLED
            assert any(isinstance(ev, m.EngineFault) and ev.detail.startswith("POSE_STALE") for ev in events)
        finally:
            e.close("test over")
            e.release_ring()
