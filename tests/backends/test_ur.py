"""UR3 over RTDE: the real ``ur_rtde`` RTDEReceiveInterface against a fake controller on loopback."""

from __future__ import annotations

import math
import random
import time

import pytest
from fake_rtde import FakeRtde

from pipeline.backends.ur import RtdeLink, UrRtdeRobot, ur3_flange_pose, ur3_tcp_pose
from pipeline.core.clock import MonotonicClock
from pipeline.devices.interfaces import DeviceError, Robot
from pipeline.force.frames import matrix_to_rotvec, rotvec_to_matrix

WAIT_S = 3.0


def test_ur3_forward_kinematics_matches_the_dh_reference_vectors() -> None:
    p, rot = ur3_flange_pose((0.0,) * 6)
    assert p == pytest.approx((-0.4569, -0.19425, 0.06655), abs=1e-12)
    assert matrix_to_rotvec(rot) == pytest.approx((math.pi / 2, 0.0, 0.0), abs=1e-12)
    p, rot = ur3_flange_pose((0.0, -math.pi / 2, 0.0, -math.pi / 2, 0.0, 0.0))
    assert p == pytest.approx((0.0, -0.19425, 0.69415), abs=1e-12)
    assert matrix_to_rotvec(rot) == pytest.approx((0.0, 2.22144, -2.22144), abs=1e-5)
    # a TCP 0.2 m along the flange z axis
    p0, rot0 = ur3_flange_pose((0.1, -1.0, 1.2, -0.3, 0.5, 0.7))
    p1, rot1 = ur3_tcp_pose((0.1, -1.0, 1.2, -0.3, 0.5, 0.7), (0.0, 0.0, 0.2))
    assert p1 == pytest.approx(tuple(p0[i] + 0.2 * rot0[3 * i + 2] for i in range(3)), abs=1e-15)
    assert rot1 == rot0
    with pytest.raises(ValueError, match="a UR3 has 6 joints"):
        ur3_flange_pose((0.0,) * 5)


def open_robot(fake: FakeRtde, **kw: object) -> UrRtdeRobot:
    kw.setdefault("min_backoff_s", 0.05)
    kw.setdefault("max_backoff_s", 0.2)
    return UrRtdeRobot(RtdeLink(fake.host, clock=MonotonicClock(), connect_timeout_s=2.0), **kw)  # type: ignore[arg-type]


def test_reads_pose_rotation_joints_and_controller_time() -> None:
    with FakeRtde() as fake:
        fake.send("pose 0.31 -0.12 0.205 0.1 -2.0 0.3")
        fake.send("q 0.1 -1.0 1.2 -0.3 0.5 0.7")
        robot = open_robot(fake)
        try:
            assert isinstance(robot, Robot)
            assert fake.wait_for("SETUP 125.0")  # CB3 rate requested
            names = next(x for x in fake.lines if x.startswith("SETUP")).split()[-1].split(",")
            assert {"timestamp", "actual_TCP_pose", "actual_q"} <= set(names)
            pose = robot.read_pose()
            assert pose.position_m == (0.31, -0.12, 0.205)
            assert pose.rot_base_tip == rotvec_to_matrix(0.1, -2.0, 0.3)
            assert pose.controller_time_s > 1000.0
            assert robot.q_rad == (0.1, -1.0, 1.2, -0.3, 0.5, 0.7)
            assert robot.state == "connected"
            assert 0 <= MonotonicClock().now_ns() - pose.t_ns < 1e9
            fake.send("pose 0.25 0.0 0.3 3.14159 0 0")
            deadline = time.monotonic() + WAIT_S
            while robot.read_pose().position_m != (0.25, 0.0, 0.3) and time.monotonic() < deadline:
                robot.wait_for_samples(robot.samples + 1, WAIT_S)
            assert robot.read_pose().position_m == (0.25, 0.0, 0.3)
        finally:
            robot.close()
        assert robot.state == "closed"


def test_stalled_controller_goes_stale_then_recovers() -> None:
    with FakeRtde() as fake:
        robot = open_robot(fake, reconnect_after_s=30.0)
        try:
            fake.send("stall")
            assert robot.wait_for_state("stale", WAIT_S)
            t_last = robot.read_pose().t_ns
            assert "controller time stuck" in robot.last_error
            # no fresh pose: the loop's watchdog sees its age grow past 50 ms
            assert MonotonicClock().now_ns() - t_last > 50e6
            fake.send("resume")
            assert robot.wait_for_state("connected", WAIT_S)
            assert robot.read_pose().t_ns > t_last and robot.reconnects == 0
        finally:
            robot.close()


def test_a_controller_silent_past_the_reconnect_time_is_dialled_afresh_and_its_poses_come_back() -> None:
    """The link stays up but the controller sends nothing for longer than ``reconnect_after_s`` (a busy machine, a
    network hiccup): the backend must get poses again once it speaks. ur_rtde's own ``reconnect()`` on such a live
    link hung for good (no pose ever again: POSE_STALE for the rest of the day) or crashed the engine process in
    rtde_receive (seen in a real window on the fakes)."""
    with FakeRtde() as fake:
        robot = open_robot(fake, reconnect_after_s=0.3)
        try:
            for _ in range(2):  # twice: the fresh link must survive the next silence too
                fake.send("stall")
                assert robot.wait_for_state("reconnecting", WAIT_S)
                fake.send("resume")
                assert robot.wait_for_state("connected", 4 * WAIT_S), (robot.state, robot.last_error)
                n = robot.samples
                assert robot.wait_for_samples(n + 5, WAIT_S)
            assert robot.reconnects == 2
        finally:
            robot.close()


def test_lost_link_reconnects_with_backoff() -> None:
    with FakeRtde() as fake:
        robot = open_robot(fake)
        try:
            fake.send("refuse")  # the controller's RTDE server goes away ...
            fake.send("drop")
            assert robot.wait_for_state("reconnecting", WAIT_S)
            assert fake.wait_for("DISCONNECTED")
            deadline = time.monotonic() + WAIT_S
            while "refused" not in robot.last_error and time.monotonic() < deadline:
                time.sleep(0.01)
            assert "refused" in robot.last_error.lower()
            n = robot.samples
            fake.send("listen")  # ... and comes back
            assert robot.wait_for_state("connected", WAIT_S)
            assert robot.wait_for_samples(n + 1, WAIT_S)
            assert robot.reconnects == 1 and fake.wait_for("CONNECTED", 2)
        finally:
            robot.close()


def test_non_finite_pose_is_passed_to_the_watchdog() -> None:
    with FakeRtde() as fake:
        robot = open_robot(fake)
        try:
            fake.send("nan")
            deadline = time.monotonic() + WAIT_S
            while not math.isnan(robot.read_pose().position_m[0]) and time.monotonic() < deadline:
                robot.wait_for_samples(robot.samples + 1, WAIT_S)
            pose = robot.read_pose()
            assert math.isnan(pose.position_m[0]) and all(math.isnan(v) for v in pose.rot_base_tip)
        finally:
            robot.close()


def test_closed_port_and_unreachable_host_are_clear_errors_fast() -> None:
    host = f"127.{random.randint(1, 254)}.{random.randint(0, 255)}.{random.randint(1, 254)}"
    t0 = time.monotonic()
    with pytest.raises(DeviceError,
                       match=rf"cannot reach the UR controller at {host}:30004 \(Connection refused\); check the IP"):
        UrRtdeRobot(RtdeLink(host, connect_timeout_s=0.3))
    assert time.monotonic() - t0 < 0.5
    t0 = time.monotonic()
    with pytest.raises(DeviceError, match=r"cannot reach the UR controller at 192\.0\.2\.1:30004"):
        UrRtdeRobot(RtdeLink("192.0.2.1", connect_timeout_s=0.3))
    assert time.monotonic() - t0 < 1.0
    with pytest.raises(ValueError, match=r"frequency_hz = 2000: must be -1 \(automatic\) or in \(0, 500\]"):
        RtdeLink(host, frequency_hz=2000)
