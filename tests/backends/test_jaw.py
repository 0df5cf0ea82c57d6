"""Jaw actuator: the pyserial host side against a pty-backed fake Arduino running the sketch's logic."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from fake_jaw import INO, PROTOCOL_LITERALS, C, JawFirmware, PtyJaw
from hypothesis import given
from hypothesis import strategies as st
from waits import until

from pipeline.backends.jaw import PROTOCOL_VERSION, JawFault, SerialJawActuator
from pipeline.devices.interfaces import JawActuator

WAIT_S = 2.0  # the jaw's ready timeout and every bounded wait


def test_handshake_and_commands() -> None:
    with PtyJaw() as fake:
        jaw = SerialJawActuator(fake.path, ready_timeout_s=WAIT_S)
        try:
            assert isinstance(jaw, JawActuator)
            s = jaw.status
            assert (s.closed_us, s.open_us, s.pos_us) == (1100, 1900, 1100) and s.fraction_open == 0.0
            jaw.set_position(0.5)
            assert s.pos_us == 1500 and s.fraction_open == 0.5 and not s.at_limit
            assert jaw.open_jaw() == 1900
            assert jaw.close_jaw() == 1100
            assert jaw.step(50) == 1150
            assert jaw.step(-100) == 1100 and s.at_limit  # the firmware clips at its closed limit
            assert jaw.set_pulse_us(2400) == 1900 and s.at_limit
            jaw.set_position(1.7)  # clamped on the host to 1 before it is sent
            assert jaw.ping()
            assert fake.received == ["SET 1500", "OPEN", "CLOSE", "STEP 50", "STEP -100", "SET 2400", "SET 1900",
                                     "PING"]
        finally:
            jaw.close()


def test_bad_arguments_and_refused_commands() -> None:
    with PtyJaw() as fake:
        jaw = SerialJawActuator(fake.path, ready_timeout_s=WAIT_S)
        try:
            with pytest.raises(ValueError, match=r"fraction_open = nan: must be a finite number from 0 to 1"):
                jaw.set_position(float("nan"))
            with pytest.raises(ValueError, match=r"delta_us = 5000: must be a whole number of µs from -1000 to 1000"):
                jaw.step(5000)
            with pytest.raises(ValueError, match=r"pulse_us = 3000"):
                jaw.set_pulse_us(3000)
            with pytest.raises(JawFault, match=r"jaw actuator refused 'JUMP': unknown command JUMP"):
                jaw._command("JUMP")
            assert jaw.status.fault == ""  # a refused command is not a fault
            assert jaw.ping()
        finally:
            jaw.close()


def test_buttons_short_press_steps_long_press_moves_continuously() -> None:
    with PtyJaw() as fake:
        jaw = SerialJawActuator(fake.path, ready_timeout_s=WAIT_S)
        try:
            # short press: one step on the (debounced) rising edge, nothing more
            assert fake.press("open", 100) == ["POS 1150"]
            assert until(lambda: jaw.status.button_moves == 1) and jaw.status.pos_us == 1150
            # 600 ms hold: the step at t=20 ms after the press, continuous from > 300 ms,
            # one 15 µs increment every 20 ms until the release is debounced
            out = fake.press("open", 600)
            assert out == ["POS 1200"] + [f"POS {1200 + 15 * k}" for k in range(1, 15)]
            assert until(lambda: jaw.status.button_moves == 16) and jaw.status.pos_us == 1410
            # hold "close" long enough to reach the closed limit: the firmware stops there
            out = fake.press("close", 2000)
            assert out[-1] == "POS 1100 LIMIT" and all(int(x.split()[1]) >= 1100 for x in out)
            assert until(lambda: jaw.status.at_limit) and jaw.status.pos_us == 1100
        finally:
            jaw.close()


def test_port_disappearing_is_a_visible_fault() -> None:
    with PtyJaw() as fake:
        jaw = SerialJawActuator(fake.path, ready_timeout_s=WAIT_S)
        try:
            jaw.open_jaw()
            fake.unplug()
            assert until(lambda: jaw.status.fault != "")
            assert jaw.status.fault.startswith(f"serial port {fake.path} lost:")
            with pytest.raises(JawFault, match=r"jaw actuator is in fault: serial port .* lost: .*; reconnect it"):
                jaw.set_position(0.2)
            with pytest.raises(JawFault):  # the cable is still out: reconnecting fails with a clear error
                jaw.reconnect()
        finally:
            jaw.close()


def test_no_ready_and_missing_port_are_clear_errors_fast() -> None:
    with PtyJaw(send_ready=False) as fake:
        t0 = time.monotonic()
        with pytest.raises(JawFault,
                           match=rf"no READY from the jaw actuator on {fake.path} within 0\.2 s; check the port, that "
                                 r"firmware/jaw_actuator is flashed and the baud rate \(115200\)"):
            SerialJawActuator(fake.path, ready_timeout_s=0.2)
        assert time.monotonic() - t0 < 1.0
    with pytest.raises(JawFault, match=r"cannot open the jaw actuator port '/dev/no-such-jaw'"):
        SerialJawActuator("/dev/no-such-jaw")


def test_reconnect_after_a_fault_waits_for_ready_again() -> None:
    with PtyJaw() as fake:
        jaw = SerialJawActuator(fake.path, ready_timeout_s=WAIT_S)
        jaw.status.fault = "serial port lost: test"  # as the reader thread sets it
        with pytest.raises(JawFault, match="in fault"):
            jaw.open_jaw()
    with PtyJaw() as fake2:
        jaw.port = fake2.path  # the Uno re-enumerated on another port
        jaw.reconnect()
        try:
            assert jaw.status.fault == "" and jaw.open_jaw() == 1900
        finally:
            jaw.close()


def test_firmware_and_host_agree_on_the_protocol() -> None:
    text = INO.read_text(encoding="utf-8")
    assert C["PROTOCOL_VERSION"] == PROTOCOL_VERSION
    for literal in PROTOCOL_LITERALS:
        assert f'"{literal}"' in text, literal
    assert "Serial.begin(115200)" in text and "writeMicroseconds" in text
    assert 1000 <= C["CLOSED_US"] <= 2000 and 1000 <= C["OPEN_US"] <= 2000  # the PQ12-R's pulse range
    assert C["LONG_PRESS_MS"] == 300
    readme = (Path(INO).parent / "README.md").read_text(encoding="utf-8")
    for cmd in ("READY", "PING", "GET", "OPEN", "CLOSE", "SET", "STEP", "POS", "ERR", "LIMIT"):
        assert f"`{cmd}" in readme, cmd


commands = st.one_of(
    st.sampled_from(["OPEN", "CLOSE", "GET", "PING", "STEP x", "SET", "FLY"]),
    st.integers(-3000, 5000).map(lambda n: f"SET {n}"),
    st.integers(-1200, 1200).map(lambda n: f"STEP {n}"),
)


@given(st.lists(st.one_of(commands, st.tuples(st.sampled_from(["open", "close"]), st.integers(1, 800))), max_size=40))
def test_firmware_never_leaves_its_limits(script: list[object]) -> None:
    fw = JawFirmware()
    t = 0
    for item in script:
        if isinstance(item, str):
            replies = fw.handle_line(item)
            assert len(replies) == 1
        else:
            button, hold = item
            fw.pressed[button] = True
            for _ in range(hold):
                t += 1
                fw.update(t)
            fw.pressed[button] = False
            for _ in range(30):
                t += 1
                fw.update(t)
        assert fw.lo <= fw.pos_us <= fw.hi
