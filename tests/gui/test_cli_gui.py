"""``haptic-study gui`` argument handling: one clear line and exit 2, Qt loaded only when a window opens."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from study_app.cli.main import main

REPO = Path(__file__).resolve().parents[2]

ROOT = Path(__file__).resolve().parents[2]


def test_real_rig_with_an_invalid_hardware_file_is_one_clear_line(capsys, tmp_path):
    p = tmp_path / "hw.toml"
    p.write_text('[sensor]\nhost = "10.0.0.1"\nport = 0\n[robot]\nhost = "10.0.0.2"\n[haptic]\n', encoding="utf-8")
    assert main(["gui", "--rig", "real", "--hardware", str(p)]) == 2
    err = capsys.readouterr().err
    assert err == f"haptic-study: error: {p}: sensor.port = 0: must be a whole port number from 1 to 65535\n"
    assert main(["gui", "--rig", "real"]) == 2
    # the template by a path that exists on this machine (the checkout's here; the installed copy from a wheel)
    assert capsys.readouterr().err == ("haptic-study: error: --rig real needs --hardware FILE (the hardware.toml of "
                                       f"the lab; see {REPO / 'hardware.example.toml'})\n")


def test_missing_hardware_file_is_refused(capsys, tmp_path):
    assert main(["gui", "--hardware", str(tmp_path / "nope.toml")]) == 2
    assert capsys.readouterr().err == f"haptic-study: error: --hardware = '{tmp_path / 'nope.toml'}': no such file\n"


def test_refusing_real_rig_does_not_load_qt():
    code = ("import sys; from study_app.cli.main import main; rc = main(['gui', '--rig', 'real']); "
            "print(rc, 'PySide6' in sys.modules, 'pyqtgraph' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert out.stdout.strip() == "2 False False"


def test_no_display_is_one_clear_line_not_a_qt_abort():
    # Qt itself would abort the process (SIGABRT) listing its platform plugins
    code = ("import sys; from study_app.cli.main import main; rc = main(['gui']); "
            "print(rc, 'PySide6' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert out.stdout.strip() == "2 False"
    assert out.stderr == ("haptic-study: error: no display to open the window on (DISPLAY and WAYLAND_DISPLAY are "
                          "unset): run it on the lab PC's desktop, or pass --screenshot DIR to drive it offscreen\n")
