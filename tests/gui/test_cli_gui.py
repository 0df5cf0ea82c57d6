"""``haptic-study gui`` argument handling: one clear line and exit 2, Qt loaded only when a window opens."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from study_app.cli import main

ROOT = Path(__file__).resolve().parents[2]


def test_real_rig_without_backends_is_one_clear_line(capsys):
    assert main(["gui", "--rig", "real", "--hardware", "hw.toml"]) == 2
    err = capsys.readouterr().err
    assert err == ("haptic-study: error: real rig: hardware backends are not configured — pass --hardware FILE; "
                   "see docs/hardware-setup.md\n")


def test_missing_hardware_file_is_refused(capsys, tmp_path):
    assert main(["gui", "--hardware", str(tmp_path / "nope.toml")]) == 2
    assert capsys.readouterr().err == f"haptic-study: error: --hardware = '{tmp_path / 'nope.toml'}': no such file\n"


def test_refusing_real_rig_does_not_load_qt():
    code = ("import sys; from study_app.cli import main; rc = main(['gui', '--rig', 'real']); "
            "print(rc, 'PySide6' in sys.modules, 'pyqtgraph' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert out.stdout.strip() == "2 False False"
