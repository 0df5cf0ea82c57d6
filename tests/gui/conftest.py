"""GUI tests run offscreen; every test must leave no thread, tracked QTimer or child process behind."""

from __future__ import annotations

import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")  # before anything imports Qt

import multiprocessing
import threading
import time

import pytest

SHORT_PROTOCOL = """
name = "short GUI test protocol"
[[targets]]
label = "GENTLE"
force_n = 0.6
[design]
modes = ["on", "off"]
trials_per_cell = 1
[trial]
hold_s = 0.3
max_trial_s = 2.5
pause_s = 0.3
cue_s = 0.3
[training]
enabled = true
seconds_per_target_per_mode = 2.0
live_force_aid = true
# these tests start experiments directly; the training rule has tests of its own (test_gui_study_rules.py)
required = false
"""


@pytest.fixture
def short_protocol(tmp_path):
    """A 2-trial protocol with short hold, cap and pause."""
    p = tmp_path / "short.toml"
    p.write_text(SHORT_PROTOCOL, encoding="utf-8")
    return str(p)


def open_ready_window(qtbot, tmp_path, protocol: str, speed: float, timeout_ms: int = 30_000):
    """The experimenter window on a simulated engine (virtual clock at ``speed``), ``protocol`` chosen, ready,
    the simulated hand on manual; closing it answers every question Yes."""
    from PySide6.QtCore import QSettings

    from study_app.engine.setup import HostConfig
    from study_app.gui.main_window import ExperimenterWindow

    proto = tmp_path / "p.toml"
    proto.write_text(protocol, encoding="utf-8")
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    settings.setValue("setup/protocol_path", str(proto))
    w = ExperimenterWindow(HostConfig(clock="virtual", speed=speed), settings, str(tmp_path / "study.db"))
    qtbot.addWidget(w, before_close_func=lambda win: setattr(win.session_actions, "confirm", lambda title, text: True))
    w.show()
    qtbot.waitUntil(lambda: w.model.session.state == "ready", timeout=timeout_ms)
    w.model.rig_control.set_driver("manual")
    return w


@pytest.fixture(autouse=True)
def no_leaks():
    """Fail a test that leaves a thread, a running tracked QTimer or a child process behind."""
    before = set(threading.enumerate())
    yield
    # give just-finished threads a moment to be reaped (bounded; nothing waits on the engine here)
    end = time.monotonic() + 5.0
    while True:
        threads = [t for t in threading.enumerate() if t not in before and t.is_alive()]
        children = multiprocessing.active_children()
        timers: list[str] = []
        try:
            from study_app.gui.timers import active_timers

            timers = active_timers()
        except ImportError:  # a model-only test never loaded Qt
            pass
        if not (threads or children or timers) or time.monotonic() > end:
            break
        time.sleep(0.02)
    assert not threads, f"threads left running: {[t.name for t in threads]}"
    assert not children, f"child processes left running: {children}"
    assert not timers, f"QTimers left running: {timers}"
