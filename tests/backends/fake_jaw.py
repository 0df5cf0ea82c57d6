"""A fake jaw-actuator Arduino behind a pseudo-terminal, running a Python port of the sketch.

:class:`JawFirmware` mirrors ``firmware/jaw_actuator/jaw_actuator.ino`` line by
line (command parser, limits, debounced buttons with the short/long-press
logic) and reads its constants from the ``.ino`` itself, so the two cannot
drift apart silently.  :class:`PtyJaw` serves it on a pty: the host opens the
slave path with pyserial like a real ``/dev/ttyACM0``.  Like the Uno, it
"reboots" when the host opens the port (pyserial sets the baud rate) and
prints READY after a short boot delay; :meth:`PtyJaw.unplug` makes the port
disappear (reads and writes then fail with EIO, as with a pulled USB cable).
"""

from __future__ import annotations

import os
import re
import select
import termios
import threading
import time
import tty
from pathlib import Path

INO = Path(__file__).resolve().parents[2] / "firmware" / "jaw_actuator" / "jaw_actuator.ino"


def ino_constants(path: Path = INO) -> dict[str, int]:
    """``const <type> NAME = <int>;`` definitions of the sketch."""
    text = path.read_text(encoding="utf-8")
    return {m[1]: int(m[2]) for m in re.finditer(r"^const (?:int|unsigned long|uint8_t) (\w+) = (-?\d+);", text, re.M)}


C = ino_constants()

#: String literals of the sketch that are the protocol on the wire (replies and the commands it matches).
PROTOCOL_LITERALS = ("READY ", "PONG", "OK", "LIMIT", "POS ", " LIMIT", "ERR bad number", "ERR unknown command ",
                     "ERR line too long", "SET ", "STEP ", "OPEN", "CLOSE", "GET", "PING")


class _Button:
    def __init__(self, direction: int) -> None:
        self.dir = direction
        self.stable = False
        self.raw = False
        self.raw_since = 0
        self.pressed_at = 0
        self.last_cont = 0
        self.continuous = False


class JawFirmware:
    """The sketch's logic: ``handle_line`` and ``update`` return the lines it would print."""

    def __init__(self) -> None:
        self.closed_us, self.open_us = C["CLOSED_US"], C["OPEN_US"]
        self.lo, self.hi = min(self.closed_us, self.open_us), max(self.closed_us, self.open_us)
        self.open_dir = 1 if self.open_us > self.closed_us else -1
        self.pos_us = C["START_US"]
        self.buttons = {"open": _Button(1), "close": _Button(-1)}
        self.pressed = {"open": False, "close": False}

    def ready_line(self) -> str:
        return f"READY {C['PROTOCOL_VERSION']} {self.closed_us} {self.open_us} {self.pos_us}"

    def move_to(self, target: int) -> bool:
        clipped = False
        if target < self.lo:
            target, clipped = self.lo, True
        if target > self.hi:
            target, clipped = self.hi, True
        self.pos_us = target
        return clipped

    def handle_line(self, s: str) -> list[str]:
        if len(s) > C["LINE_MAX"]:
            return ["ERR line too long"]
        if s == "PING":
            return ["PONG"]
        if s == "GET":
            return [f"OK {self.pos_us}"]
        if s == "OPEN":
            self.move_to(self.open_us)
            return [f"OK {self.pos_us}"]
        if s == "CLOSE":
            self.move_to(self.closed_us)
            return [f"OK {self.pos_us}"]
        if s.startswith("SET ") or s.startswith("STEP "):
            arg = s.split(" ", 1)[1]
            if not re.fullmatch(r"[+-]?\d+", arg):
                return ["ERR bad number"]
            n = int(arg)
            if s.startswith("SET "):
                clipped = self.move_to(n)
            else:
                if not -1000 <= n <= 1000:
                    return ["ERR bad number"]
                clipped = self.move_to(self.pos_us + self.open_dir * n)
            return [f"{'LIMIT' if clipped else 'OK'} {self.pos_us}"]
        return [f"ERR unknown command {s}"]

    def _moved(self, clipped: bool) -> str:
        return f"POS {self.pos_us}" + (" LIMIT" if clipped else "")

    def update(self, now_ms: int) -> list[str]:
        """One pass of ``loop()`` for both buttons at ``now_ms``."""
        out: list[str] = []
        for name, other in (("open", "close"), ("close", "open")):
            b = self.buttons[name]
            other_pressed = self.buttons[other].stable
            raw = self.pressed[name]
            if raw != b.raw:
                b.raw, b.raw_since = raw, now_ms
            if now_ms - b.raw_since < C["DEBOUNCE_MS"] or raw == b.stable:
                if b.stable and not other_pressed:
                    if not b.continuous and now_ms - b.pressed_at > C["LONG_PRESS_MS"]:
                        b.continuous, b.last_cont = True, now_ms
                    if b.continuous and now_ms - b.last_cont >= C["CONT_PERIOD_MS"]:
                        b.last_cont += C["CONT_PERIOD_MS"]
                        before = self.pos_us
                        clipped = self.move_to(self.pos_us + b.dir * self.open_dir * C["CONT_STEP_US"])
                        if self.pos_us != before or clipped:
                            out.append(self._moved(clipped))
                continue
            b.stable = raw
            if raw:
                b.pressed_at, b.continuous = now_ms, False
                if not other_pressed:
                    out.append(self._moved(self.move_to(self.pos_us + b.dir * self.open_dir * C["STEP_US"])))
            else:
                b.continuous = False
        return out


class PtyJaw:
    """Serve :class:`JawFirmware` on a pseudo-terminal; ``path`` is the port to open.

    Parameters
    ----------
    boot_s
        Delay between the host opening the port and READY (the Uno's bootloader).
    send_ready
        False: the "Arduino" never announces itself (wrong sketch, wrong baud).
    """

    def __init__(self, boot_s: float = 0.02, send_ready: bool = True) -> None:
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.path = os.ttyname(self._slave)
        self.fw = JawFirmware()
        self.boot_s = boot_s
        self.send_ready = send_ready
        self.received: list[str] = []
        self.now_ms = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._unplugged = False
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def __enter__(self) -> PtyJaw:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop serving and close the pty."""
        self._stop.set()
        self._thread.join(1.0)
        self.unplug()
        try:
            os.close(self._slave)
        except OSError:
            pass

    def unplug(self) -> None:
        """Pull the cable: the host's port fails from now on."""
        with self._lock:
            if not self._unplugged:
                self._unplugged = True
                os.close(self.master)

    def _write(self, lines: list[str]) -> None:
        with self._lock:
            if not self._unplugged:
                for ln in lines:
                    os.write(self.master, (ln + "\r\n").encode("ascii"))  # Serial.println ends in CR LF

    def _serve(self) -> None:
        # wait for the host to open and configure the port (pyserial sets 115200 baud): that is the reset
        while not self._stop.is_set():
            if termios.tcgetattr(self._slave)[4] == termios.B115200:
                break
            time.sleep(0.002)
        else:
            return
        time.sleep(self.boot_s)
        if self.send_ready:
            self._write([self.fw.ready_line()])
        buf = b""
        while not self._stop.is_set() and not self._unplugged:
            try:
                r, _, _ = select.select([self.master], [], [], 0.02)
                if not r:
                    continue
                data = os.read(self.master, 256)
            except OSError:
                return
            buf += data
            while b"\n" in buf:
                raw, buf = buf.split(b"\n", 1)
                line = raw.decode("ascii", "replace").replace("\r", "")
                if not line:
                    continue
                self.received.append(line)
                if self.send_ready:
                    self._write(self.fw.handle_line(line))

    # -- buttons on a virtual millisecond clock ----------------------------------------------
    def press(self, button: str, hold_ms: int, then_idle_ms: int = 50) -> list[str]:
        """Hold ``button`` for ``hold_ms`` then release; returns (and sends) the lines printed."""
        out: list[str] = []
        self.fw.pressed[button] = True
        for _ in range(hold_ms):
            self.now_ms += 1
            out += self.fw.update(self.now_ms)
        self.fw.pressed[button] = False
        for _ in range(then_idle_ms):
            self.now_ms += 1
            out += self.fw.update(self.now_ms)
        self._write(out)
        return out
