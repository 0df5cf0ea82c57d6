"""``[haptic] dll_dir``: validated like every hardware field, and added to Windows' DLL path before pyOpenHaptics loads.

The order is what matters on Windows (pyOpenHaptics loads ``HD.dll`` by name
as it is imported): a fake ``pyOpenHaptics`` package on ``sys.path`` records
its import, ``os.add_dll_directory`` is faked, ``sys.platform`` set to win32.
No real DLL is loaded.
"""

from __future__ import annotations

import os
import sys
import tomllib
from pathlib import Path

import pytest

import foundation.platform_support as ps
from foundation.platform_support import files
from pipeline.backends import hdapi
from pipeline.devices.interfaces import DeviceError
from pipeline.settings.hardware import HardwareError, load_hardware

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = (ROOT / "hardware.example.toml").read_text(encoding="utf-8")
FAKE_HD = "import foundation.platform_support as ps\nps._test_events.append('import pyOpenHaptics.hd')\n"


def _hardware(tmp_path: Path, line: str) -> Path:
    text = EXAMPLE.replace('[haptic]                      #', f'[haptic]\n{line}\n#', 1)
    assert line in text and tomllib.loads(text)
    path = tmp_path / "hw.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_the_example_names_no_folder(tmp_path):
    assert load_hardware(_hardware(tmp_path, "")).haptic.dll_dir is None


def test_a_relative_folder_is_relative_to_the_hardware_file(tmp_path):
    (tmp_path / "openhaptics" / "bin").mkdir(parents=True)
    hw = load_hardware(_hardware(tmp_path, 'dll_dir = "openhaptics/bin"'))
    assert hw.haptic.dll_dir == str(tmp_path / "openhaptics" / "bin")
    hw = load_hardware(_hardware(tmp_path, f'dll_dir = "{tmp_path}"'))
    assert hw.haptic.dll_dir == str(tmp_path)


@pytest.mark.parametrize(("line", "says"), [
    ('dll_dir = ""', "haptic.dll_dir = '': must be the path of the folder holding OpenHaptics' HD.dll"),
    ("dll_dir = 3", "haptic.dll_dir = 3: must be the path of the folder holding OpenHaptics' HD.dll"),
    ('dll_dir = "C:/OpenHaptics/nowhere"', "haptic.dll_dir = 'C:/OpenHaptics/nowhere': no such folder ("),
    ('dll_dir = "hw.toml"', "haptic.dll_dir = 'hw.toml': is not a folder ("),
    ('dll_dir = "a\\u0000b"', "haptic.dll_dir = 'a\\x00b': a path without NUL characters"),
])
def test_a_bad_folder_is_one_line_naming_field_value_and_what_is_allowed(tmp_path, line, says):
    with pytest.raises(HardwareError) as err:
        load_hardware(_hardware(tmp_path, line))
    assert says in str(err.value) and "\n" not in str(err.value)
    assert str(err.value).startswith(f"{tmp_path / 'hw.toml'}: haptic.dll_dir = ")


@pytest.fixture
def fake_windows(monkeypatch, tmp_path):
    """win32, a fake os.add_dll_directory and a fake pyOpenHaptics: both record into one list, in order."""
    events: list[str] = []
    package = tmp_path / "site" / "pyOpenHaptics"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "hd.py").write_text(FAKE_HD)
    (package / "hd_callback.py").write_text("")
    (package / "hd_define.py").write_text("")
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    names = ("pyOpenHaptics", "pyOpenHaptics.hd", "pyOpenHaptics.hd_callback", "pyOpenHaptics.hd_define")
    real = {name: sys.modules.pop(name) for name in names if name in sys.modules}
    monkeypatch.setattr(ps, "_test_events", events, raising=False)
    monkeypatch.setattr(sys, "platform", "win32")
    monkeypatch.setattr(os, "add_dll_directory", lambda p: events.append(f"add_dll_directory {p}") or p,
                        raising=False)
    monkeypatch.setattr(files, "_DLL_DIRECTORIES", [])
    yield events
    # the fakes out of sys.modules, the real ones (if another test imported them) back: later tests import the real
    for name in names:
        sys.modules.pop(name, None)
    sys.modules.update(real)


def test_the_folder_is_added_before_pyopenhaptics_is_imported(fake_windows, tmp_path):
    hd, _, _ = hdapi.load_pyopenhaptics(str(tmp_path))
    assert hd.__name__ == "pyOpenHaptics.hd"
    assert fake_windows == [f"add_dll_directory {tmp_path}", "import pyOpenHaptics.hd"]


def test_the_touch_passes_its_setting_down_to_the_import(fake_windows, tmp_path, monkeypatch):
    from pipeline.assembly.real_rig import open_haptic
    from pipeline.core.clock import VirtualClock
    from pipeline.settings.hardware import HapticSettings

    monkeypatch.setattr(hdapi.PyOpenHapticsApi, "init_device", lambda self, name: (_ for _ in ()).throw(
        DeviceError("stop after the import")))
    with pytest.raises(DeviceError, match="stop after the import"):
        open_haptic(HapticSettings(dll_dir=str(tmp_path)), VirtualClock())
    assert fake_windows == [f"add_dll_directory {tmp_path}", "import pyOpenHaptics.hd"]


def test_without_a_folder_nothing_is_added(fake_windows):
    hdapi.load_pyopenhaptics(None)
    assert fake_windows == ["import pyOpenHaptics.hd"]


def test_a_missing_dll_names_the_setting(fake_windows, tmp_path):
    (tmp_path / "site" / "pyOpenHaptics" / "hd.py").write_text("raise OSError(\"Could not find module 'HD.dll'\")\n")
    with pytest.raises(DeviceError, match=r"HD\.dll'; on Windows set \[haptic\] dll_dir to the folder holding HD\.dll"):
        hdapi.load_pyopenhaptics(None)
    with pytest.raises(DeviceError, match=f"HD.dll'; not in {tmp_path}"):
        hdapi.load_pyopenhaptics(str(tmp_path))
