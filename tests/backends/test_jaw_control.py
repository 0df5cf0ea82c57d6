"""The jaw in the loop: stylus buttons (short press steps, a press over 0.3 s moves until released or at the limit),
the experimenter's controls, and every command reported -- on the simulated jaw with a clock the test moves, and
on the real serial backend against the pty Arduino running the sketch's logic."""

from __future__ import annotations

from fake_jaw import C, PtyJaw

from pipeline.backends.jaw import SerialJawActuator
from pipeline.devices.jaw_control import CONT_STEP_US, STEP_US, JawController, StylusButtons
from pipeline.sim.jaw import SimJaw

MS = 1_000_000
CLOSE, OPEN = 1, 2


def test_the_firmware_and_the_host_agree_on_the_paper_s_button_logic() -> None:
    assert (C["STEP_US"], C["LONG_PRESS_MS"], C["CONT_STEP_US"], C["CONT_PERIOD_MS"]) == (STEP_US, 300, CONT_STEP_US,
                                                                                          20)


def test_stylus_buttons_short_press_steps_long_press_moves_until_released() -> None:
    b = StylusButtons(close_button=CLOSE, open_button=OPEN)
    assert b.update(0, CLOSE) == ["step_close"]  # the rising edge: one step
    assert b.update(100 * MS, CLOSE) == []
    assert b.update(200 * MS, 0) == []  # released before 0.3 s: just the step
    assert b.update(1000 * MS, OPEN) == ["step_open"]
    assert b.update(1300 * MS, OPEN) == []  # exactly 0.3 s: not yet
    assert b.update(1301 * MS, OPEN) == ["move_open"]  # over 0.3 s: continuous
    assert b.update(1400 * MS, OPEN) == []
    assert b.update(1500 * MS, 0) == ["stop"]
    # both at once: nothing moves (as the sketch); the second press stops a continuous move
    assert b.update(2000 * MS, CLOSE) == ["step_close"]
    assert b.update(2400 * MS, CLOSE) == ["move_close"]
    assert b.update(2500 * MS, CLOSE | OPEN) == ["stop"]
    assert b.update(3000 * MS, CLOSE | OPEN) == []


class Clock:
    def __init__(self) -> None:
        self.t = 0

    def __call__(self) -> int:
        return self.t


def run(ctl: JawController, clock: Clock, mask: int, ms: int) -> None:
    """``ms`` milliseconds with the buttons at ``mask``: the loop feeds them every 1 ms, the controller serves."""
    for _ in range(ms):
        clock.t += MS
        ctl.buttons(clock.t, mask)
        ctl.service()


def test_a_long_press_moves_at_15_mm_per_s_until_released_and_every_command_is_reported() -> None:
    clock, jaw = Clock(), SimJaw()
    ctl = JawController(jaw, clock_ns=clock)
    run(ctl, clock, OPEN, 500)  # a step at once, continuous from 0.3 s, 0.2 s of it
    run(ctl, clock, 0, 10)
    moved = jaw.status.pos_us - 1100
    assert STEP_US + 10 * CONT_STEP_US <= moved <= STEP_US + 11 * CONT_STEP_US  # 15 µs per 20 ms for ~0.2 s
    details = [e.detail for e in ctl.events]
    assert details[0] == "step 50 µs toward open → 1150 µs (6% open)"
    assert details[1] == "open continuously (button held over 0.3 s) from 1150 µs"
    assert details[2].startswith("open continuously: stopped (released) at ") and len(details) == 3
    assert all(e.source == "stylus" for e in ctl.events)


def test_a_long_press_stops_at_the_limit_by_itself() -> None:
    clock, jaw = Clock(), SimJaw()
    ctl = JawController(jaw, clock_ns=clock)
    run(ctl, clock, OPEN, 2500)  # 800 µs of stroke at 15 µs / 20 ms takes ~1.1 s after the long-press threshold
    assert jaw.status.pos_us == 1900
    last = ctl.events[-1]
    assert last.detail.startswith("open continuously: stopped (at the limit) at 1900 µs (100% open)")
    n = len(jaw.commands)
    run(ctl, clock, OPEN, 200)  # still held: nothing more is sent
    assert len(jaw.commands) == n


def test_buttons_do_nothing_when_teleoperation_claims_them_but_controls_work() -> None:
    clock, jaw = Clock(), SimJaw()
    ctl = JawController(jaw, stylus=False, clock_ns=clock)
    run(ctl, clock, OPEN, 600)
    assert jaw.status.pos_us == 1100 and not ctl.events
    ctl.submit("open")
    ctl.service()
    assert jaw.status.pos_us == 1900 and ctl.events[-1].detail == "open fully → 1900 µs (100% open)"
    assert ctl.events[-1].source == "experimenter"


def test_the_serial_jaw_over_the_pty_arduino_with_the_controller() -> None:
    with PtyJaw() as fake:
        jaw = SerialJawActuator(fake.path, ready_timeout_s=2.0)
        ctl = JawController(jaw)
        try:
            for action in ("open", "step_close", "step_close", "close", "step_close"):
                ctl.submit(action)
            ctl.service()
            assert fake.received == ["OPEN", "STEP -50", "STEP -50", "CLOSE", "STEP -50"]
            details = [e.detail for e in ctl.events]
            assert details == ["open fully → 1900 µs (100% open)", "step 50 µs toward closed → 1850 µs (94% open)",
                               "step 50 µs toward closed → 1800 µs (88% open)", "close fully → 1100 µs (0% open)",
                               "step 50 µs toward closed → 1100 µs (0% open, at the limit)"]
            fake.unplug()  # the cable is pulled: the command is refused and says why
            ctl.submit("open")
            ctl.service()
            assert ctl.events[-1].detail.startswith("open fully: refused: ")
            assert ctl.events[-1].fault
        finally:
            ctl.close()
            jaw.close()
