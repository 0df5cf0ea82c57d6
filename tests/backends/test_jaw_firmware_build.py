"""The jaw-actuator sketch compiles for the Uno, warning-free, and fits.

Needs the AVR toolchain, which CI does not install, and the Arduino Servo library, which
Debian does not package; without them the test is skipped and says what to install
(firmware/jaw_actuator/README.md, "Building and flashing").
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from fake_jaw import INO, PROTOCOL_LITERALS

SKETCH_DIR = INO.parent
ARDUINO_DIR = Path("/usr/share/arduino")
BOARDS_TXT = ARDUINO_DIR / "hardware" / "arduino" / "avr" / "boards.txt"
# The Makefile's default; `make` and this test both honour USER_LIB_PATH from the environment.
USER_LIB_PATH = Path(os.environ.get("USER_LIB_PATH", Path.home() / "Arduino" / "libraries"))
APT = "apt-get install arduino-core-avr gcc-avr avr-libc arduino-mk"
# The Arduino IDE warns "Low memory available, stability problems may occur" above 75 % of SRAM
# used by globals: the rest is the stack.
RAM_GLOBALS_MAX_FRACTION = 0.75


def _missing() -> str:
    """Why the firmware cannot be built here, or '' when it can."""
    if shutil.which("avr-g++") is None or not (ARDUINO_DIR / "Arduino.mk").is_file() or not BOARDS_TXT.is_file():
        return f"AVR toolchain not installed (CI does not install it); to build the firmware: {APT}"
    if shutil.which("make") is None:
        return "make not installed"
    if not any((d / "Servo" / "src" / "Servo.h").is_file() for d in (USER_LIB_PATH, ARDUINO_DIR / "libraries")):
        return (f"Arduino Servo library not in {USER_LIB_PATH} (Debian does not package it): "
                "install it with the Arduino IDE Library Manager or `arduino-cli lib install Servo`")
    return ""


def _board(key: str) -> int:
    m = re.search(rf"^uno\.{re.escape(key)}=(\d+)$", BOARDS_TXT.read_text(encoding="utf-8"), re.M)
    assert m, key
    return int(m[1])


def _intel_hex_image(path: Path) -> bytes:
    """The flash image of an Intel HEX file; every record's checksum is verified."""
    image = bytearray()
    ended = False
    for n, line in enumerate(path.read_text(encoding="ascii").split(), 1):
        assert line[0] == ":" and not ended, f"line {n}: {line}"
        rec = bytes.fromhex(line[1:])
        assert len(rec) == rec[0] + 5 and sum(rec) % 256 == 0, f"line {n}: bad length or checksum"
        addr, rtype, data = int.from_bytes(rec[1:3], "big"), rec[3], rec[4:-1]
        if rtype == 0x00:
            image[len(image):addr] = b"\xff" * max(0, addr - len(image))
            image[addr:addr + len(data)] = data
        else:
            assert rtype == 0x01, f"line {n}: record type {rtype} (an Uno image needs no extended addresses)"
            ended = True
    assert ended, "no end-of-file record"
    return bytes(image)


@pytest.mark.skipif(bool(_missing()), reason=_missing() or "toolchain present")
def test_sketch_builds_warning_free_and_fits_the_uno(tmp_path: Path) -> None:
    build = tmp_path / "build-uno"
    proc = subprocess.run(["make", "-C", str(SKETCH_DIR), f"OBJDIR={build}", "-j2"],
                          capture_output=True, text=True, timeout=300, check=False)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log
    # The sketch itself is compiled with -Wextra and warnings as errors ...
    sketch_cmd = [ln for ln in log.splitlines() if ln.rstrip().endswith(f"-o {build}/jaw_actuator.ino.o")]
    assert len(sketch_cmd) == 1 and " -Wall -Wextra -Werror " in sketch_cmd[0], log
    # ... and the whole build (Arduino core and Servo included) is warning-free.
    assert "warning:" not in log, log

    sizes = subprocess.run(["avr-size", "-A", str(build / "jaw_actuator.elf")],
                           capture_output=True, text=True, check=True).stdout
    sec = {m[1]: int(m[2]) for m in re.finditer(r"^(\.\w+)\s+(\d+)\s+\d+$", sizes, re.M)}
    flash_b, ram_b = sec[".text"] + sec[".data"], sec[".data"] + sec[".bss"]
    assert flash_b <= _board("upload.maximum_size"), sizes  # 32256: 32 KiB minus the Optiboot bootloader
    assert ram_b <= RAM_GLOBALS_MAX_FRACTION * _board("upload.maximum_data_size"), sizes

    # What gets flashed is that program: the HEX holds .text then .data's initial values, and the
    # strings the host parses are in it.
    image = _intel_hex_image(build / "jaw_actuator.hex")
    assert len(image) == flash_b
    for literal in PROTOCOL_LITERALS:
        assert literal.encode("ascii") + b"\0" in image, literal
