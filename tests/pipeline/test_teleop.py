"""App-side teleoperation on the simulated arm (125 Hz controller, tracking lag), on the virtual clock."""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pipeline.core.clock import VirtualClock
from pipeline.devices.interfaces import TcpServo
from pipeline.devices.teleop import ServoTarget, Stop, TeleopConfig, TeleopController, TeleopDriver, TeleopState
from pipeline.force.frames import mat_vec, transpose
from pipeline.force.framework import DEFAULT_ROT_HAPTIC_BASE
from pipeline.sim.robot import SimRobot
from pipeline.sim.touch import SimTouch

LO, HI = (0.2, -0.1, 0.05), (0.4, 0.1, 0.25)
HOME = (0.3, 0.0, 0.15)
CFG = TeleopConfig(LO, HI, max_speed_m_s=0.1, motion_scale=0.5, period_s=0.008, rot_haptic_base=DEFAULT_ROT_HAPTIC_BASE)
PERIOD_NS = 8_000_000
DEADMAN, CLUTCH = 1, 2
R_BH = transpose(DEFAULT_ROT_HAPTIC_BASE)


class Bench:
    """Stylus → controller → simulated UR, stepped at 1 kHz on a virtual clock."""

    def __init__(self, cfg: TeleopConfig = CFG) -> None:
        self.clock = VirtualClock()
        self.robot = SimRobot(HOME)
        self.touch = SimTouch()
        self.ctl = TeleopController(cfg)
        self.driver = TeleopDriver(self.ctl, self.touch, self.robot, self.robot)
        self.log: list[tuple[int, object]] = []
        self.cycles: list[tuple[float, float, float]] = []  # robot position at each controller cycle

    def tick(self, stylus: tuple[float, float, float] | None = None, buttons: int | None = None,
             fresh: bool = True) -> object:
        self.clock.advance(1_000_000)
        now = self.clock.now_ns()
        if stylus is not None:
            self.touch.stylus_m = stylus
        if buttons is not None:
            self.touch.buttons = buttons
        if fresh:
            self.touch.advance(now, 0.001)
        cmd = self.driver.update(now)
        if cmd is not None:
            self.log.append((now, cmd))
        before = self.robot.read_pose().t_ns
        self.robot.advance(now, 0.001)
        if self.robot.read_pose().t_ns != before:
            self.cycles.append(self.robot.read_pose().position_m)
        return cmd

    def run(self, n: int, **kw: object) -> None:
        for _ in range(n):
            self.tick(**kw)

    def targets(self) -> list[tuple[float, float, float]]:
        return [c.position_m for _, c in self.log if isinstance(c, ServoTarget)]

    def engage(self) -> None:
        self.run(40, buttons=0)  # idle long enough for a fresh pose after the last stop
        self.tick(buttons=DEADMAN)
        assert self.ctl.state is TeleopState.ENGAGED


def expected(stylus_delta: tuple[float, float, float], anchor: tuple[float, float, float] = HOME) -> tuple[float, ...]:
    d = mat_vec(R_BH, stylus_delta)
    return tuple(anchor[i] + 0.5 * d[i] for i in range(3))


def test_sim_robot_is_a_tcp_servo_and_stops_at_its_next_cycle() -> None:
    robot = SimRobot(HOME)
    assert isinstance(robot, TcpServo)
    robot.advance(0, 0.0)
    robot.servo_tcp((0.31, 0.0, 0.15), robot.orientation)
    for k in range(1, 12):
        robot.advance(k * 1_000_000, 0.001)
    robot.stop_servo()
    robot.stop_servo()  # idempotent
    assert robot.servo_stops == 1
    robot.advance(12_000_000, 0.001)
    robot.advance(16_000_000, 0.004)  # the cycle that carries out the stop
    held = list(robot.position_m)
    for k in range(17, 60):
        robot.advance(k * 1_000_000, 0.001)
    assert robot.position_m == held and not robot.servoing and 0.3 < held[0] < 0.31


def test_targets_follow_the_stylus_scaled_and_rotated_into_the_base_frame() -> None:
    b = Bench()
    b.engage()
    assert b.targets()[-1] == HOME  # engaging never moves the robot
    # 2 cm along the Touch's y (up) and 1 cm along x, at a hand speed of 5 cm/s
    for k in range(1, 401):
        s = k / 400
        b.tick(stylus=(0.01 * s, 0.02 * s, 0.0))
    b.run(500)
    want = expected((0.01, 0.02, 0.0))
    assert want == pytest.approx((0.305, 0.0, 0.16), abs=1e-15)  # Touch +y (up) is base +z
    assert b.targets()[-1] == pytest.approx(want, abs=1e-12)
    assert b.robot.position_m == pytest.approx(want, abs=1e-6)


def test_targets_are_clamped_to_the_workspace_and_rate_limited() -> None:
    b = Bench()
    b.engage()
    n0 = len(b.targets())
    # the stylus goes 0.3 m up at 2 m/s (a fast hand, not a glitch): the box top is 0.1 m above HOME
    for k in range(1, 151):
        b.tick(stylus=(0.0, min(0.3, 0.002 * k), 0.0))
    b.run(2000)
    ts = b.targets()[n0 - 1:]
    steps = [math.dist(a, c) for a, c in itertools.pairwise(ts)]
    assert max(steps) == pytest.approx(CFG.max_step_m, rel=1e-9)  # 0.8 mm per 8 ms = 0.1 m/s
    assert all(s <= CFG.max_step_m * (1 + 1e-12) for s in steps)
    assert ts[-1] == pytest.approx((0.3, 0.0, HI[2]), abs=1e-15) and max(t[2] for t in ts) == HI[2]
    cyc = b.cycles
    assert max(math.dist(a, c) for a, c in itertools.pairwise(cyc)) <= CFG.max_step_m * (1 + 1e-12)


def test_clutch_holds_then_reanchors_without_a_jump() -> None:
    b = Bench()
    b.engage()
    for k in range(1, 201):
        b.tick(stylus=(0.0, 0.0001 * k, 0.0))  # 2 cm up over 0.2 s
    b.run(100)
    held = b.targets()[-1]
    assert held == pytest.approx(expected((0.0, 0.02, 0.0)), abs=1e-12)
    n = len(b.targets())
    for k in range(1, 201):  # clutch in, stylus back down 4 cm
        b.tick(stylus=(0.0, 0.02 - 0.0002 * k, 0.0), buttons=DEADMAN | CLUTCH)
    assert b.ctl.state is TeleopState.CLUTCHED
    assert set(b.targets()[n:]) == {held}
    b.tick(buttons=DEADMAN)  # clutch out at stylus y = -0.02
    assert b.targets()[-1] == held
    for k in range(1, 101):
        b.tick(stylus=(0.0, -0.02 + 0.0001 * k, 0.0))  # 1 cm up from the new anchor
    b.run(100)
    assert b.targets()[-1] == pytest.approx(expected((0.0, 0.01, 0.0), held), abs=1e-12)
    ts = b.targets()
    assert all(math.dist(a, c) <= CFG.max_step_m * (1 + 1e-12) for a, c in itertools.pairwise(ts))


def test_deadman_release_stops_at_once_and_the_arm_holds() -> None:
    b = Bench()
    b.engage()
    for k in range(1, 101):
        b.tick(stylus=(0.0, 0.0005 * k, 0.0))  # moving at 0.5 m/s: rate-limited, robot moving
    t_release = b.clock.now_ns() + 1_000_000
    cmd = b.tick(buttons=0)
    assert isinstance(cmd, Stop) and cmd.reason == "deadman released" and b.ctl.state is TeleopState.IDLE
    assert b.log[-1][0] - t_release == 0  # same call, well within one control period
    assert b.robot.servo_stops == 1
    b.run(PERIOD_NS // 1_000_000)  # the controller's next cycle carries out servoStop
    rest = list(b.robot.position_m)
    b.run(200)
    assert b.robot.position_m == rest and b.robot.servo_stops == 1
    # re-engaging anchors at the arm's rest pose: no jump
    b.tick(buttons=DEADMAN)
    assert b.targets()[-1] == pytest.approx(tuple(rest), abs=1e-15)


@pytest.mark.parametrize("what", ["stylus", "pose"])
def test_stale_data_stop_within_one_period_of_the_limit_and_latch(what: str) -> None:
    b = Bench()
    b.engage()
    for k in range(1, 51):
        b.tick(stylus=(0.0, 0.0002 * k, 0.0))
    if what == "stylus":
        t_last = b.touch.read_state().t_ns
        limit_ns = int(CFG.stylus_max_age_s * 1e9)
        while not isinstance(b.tick(fresh=False), Stop):
            assert b.clock.now_ns() - t_last <= limit_ns
    else:
        b.robot.frozen = True
        t_last = b.robot.read_pose().t_ns
        limit_ns = int(CFG.pose_max_age_s * 1e9)
        while not isinstance(b.tick(), Stop):
            assert b.clock.now_ns() - t_last <= limit_ns
    stop_ns = b.log[-1][0]
    assert limit_ns < stop_ns - t_last <= limit_ns + PERIOD_NS
    assert b.ctl.state is TeleopState.FAULT and f"{what if what == 'stylus' else 'robot pose'}" in b.ctl.stop_reason
    assert "stale" in b.ctl.stop_reason
    # fresh data again, deadman still held: stays stopped until released and pressed again
    b.robot.frozen = False
    b.run(50)
    assert b.ctl.state is TeleopState.FAULT and isinstance(b.log[-1][1], Stop)
    b.engage()


def test_engaging_outside_the_workspace_servo_error_and_tracking_error_stop() -> None:
    b = Bench()
    b.robot.teleport((0.45, 0.0, 0.15))
    b.run(20, buttons=0)
    b.tick(buttons=DEADMAN)
    assert b.ctl.state is TeleopState.FAULT and "outside the teleoperation workspace" in b.ctl.stop_reason
    assert b.targets() == []
    b.robot.teleport(HOME)
    b.engage()
    b.robot.fail_servo = "protective stop"
    assert b.tick() == Stop("robot servo: protective stop")
    b.robot.fail_servo = ""
    b.engage()
    b.robot.teleport((0.3, 0.0, 0.22))  # something pushed the arm 7 cm off its target
    b.run(PERIOD_NS // 1_000_000)
    assert b.ctl.state is TeleopState.FAULT and "collision or protective stop" in b.ctl.stop_reason


def test_teleop_config_validation() -> None:
    with pytest.raises(ValueError, match=r"teleop.workspace_min_m\[y\] = 0.1 must be below workspace_max_m\[y\] = 0.1"):
        TeleopConfig((0.0, 0.1, 0.0), (1.0, 0.1, 1.0))
    with pytest.raises(ValueError, match=r"teleop.max_speed_m_s = inf: must be a finite number > 0"):
        TeleopConfig(LO, HI, max_speed_m_s=math.inf)
    with pytest.raises(ValueError, match=r"teleop.clutch_button = 1: must differ from deadman_button"):
        TeleopConfig(LO, HI, clutch_button=1)


wild = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([math.nan, math.inf, -math.inf, 1e300, -1e300, 0.5, -0.5]),
)
velocity = st.floats(-2.0, 2.0)
step = st.tuples(
    st.one_of(  # a hand moving at up to 2 m/s per axis for a while, or a glitch (NaN/inf/huge/jump) for a while
        st.tuples(st.just("move"), st.tuples(velocity, velocity, velocity)),
        st.tuples(st.just("glitch"), st.tuples(wild, wild, wild)),
    ),
    st.sampled_from([DEADMAN, DEADMAN, DEADMAN, DEADMAN | CLUTCH, 0, CLUTCH]),
    st.sampled_from([True, True, True, True, False]),  # stylus sample fresh during this segment
    st.integers(1, 60),  # ticks (ms) the segment lasts
)


@given(st.lists(step, min_size=1, max_size=25), st.floats(0.01, 0.25), st.floats(0.1, 5.0))
def test_property_targets_stay_in_the_box_below_the_speed_limit_whatever_the_stylus_does(
    trajectory: list, speed: float, scale: float
) -> None:
    cfg = TeleopConfig(LO, HI, max_speed_m_s=speed, motion_scale=scale, rot_haptic_base=DEFAULT_ROT_HAPTIC_BASE)
    b = Bench(cfg)
    prev: tuple[float, float, float] | None = None
    hand = [0.0, 0.0, 0.0]
    for (kind, v), buttons, fresh, hold in trajectory:
        for _ in range(hold):
            if kind == "move":
                hand = [max(-0.08, min(0.08, hand[i] + v[i] * 0.001)) for i in range(3)]
                stylus = (hand[0], hand[1], hand[2])
            else:
                stylus = v
            pose_before = b.robot.read_pose().position_m
            cmd = b.tick(stylus=stylus, buttons=buttons, fresh=fresh)
            if isinstance(cmd, ServoTarget):
                t = cmd.position_m
                assert all(math.isfinite(x) for x in t) and cfg.contains(t)
                if prev is None:
                    assert t == pose_before  # every engagement starts where the arm is
                else:
                    assert math.dist(prev, t) <= cfg.max_step_m * (1 + 1e-9)
                prev = t
            elif isinstance(cmd, Stop):
                prev = None
            if not buttons & DEADMAN:
                assert isinstance(cmd, Stop)  # released: stopped in this very call
            assert cfg.contains(tuple(b.robot.position_m))
    cyc = b.cycles
    assert all(math.dist(a, c) <= cfg.max_step_m * (1 + 1e-9) for a, c in itertools.pairwise(cyc))
