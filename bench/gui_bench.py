"""``haptic-study bench gui``: does the GUI disturb the 1 kHz loop, and does the GUI itself ever stall?

One run, real clock, the loop in its study-engine process as the app runs it:

1. **Without the GUI**: the engine process alone (this process only reads its
   events, no Qt loaded yet), loop timing over ``seconds``.
2. **With the GUI**: the experimenter window opens (start-up timed to a usable
   window and to a connected engine), runs the recommended calibration, then
   an experiment session driven by the simulated participant while the window
   plots at 30 Hz and the participant screen and rig view are shown; loop
   timing over ``seconds`` of that session.

Loop timing is the engine's own: the ``period_ns`` of every loop record,
|period − 1 ms| quantiles and the share of periods over 2 ms.  With
``explain=True`` (``--explain``) the engine also names the cause of every tick
starting over 100 µs late (:mod:`pipeline.runtime.jitter_trace`: another thread of the
engine holding the GIL, a garbage-collector pass, the loop's own work, or the
machine -- nothing in the process); the tracing costs the loop ~25 µs per tick,
so it is off by default.  The share of CPU time the hypervisor stole during
each measurement is reported either way (a shared VM's noise the process cannot
cause or cure).  GUI stalls are
measured by a 5 ms timer in the GUI's event loop: the longest gap beyond its
interval, per phase (connect, calibration, session).  The window is rendered
offscreen when no display is available (the same painting work, no compositor).
"""

from __future__ import annotations

import os
import platform
import tempfile
import time
from collections.abc import Callable
from typing import Any

from bench.machine import cpu_times, engine_loop_health, format_late_ticks, load_average, steal_percent
from study_app.engine import messages as m
from study_app.engine.setup import HostConfig

__all__ = ["format_gui_bench", "run_gui_bench"]

_STALL_TIMER_MS = 5
#: Stalls at least this long are attributed to a callback (sampled stacks of the GUI thread).
_STALL_THRESHOLD_MS = 30.0


def _loop_figures(h: m.Health, cpu_before: list[int] | None = None) -> dict[str, Any]:
    out: dict[str, Any] = {
        "ticks": h.ticks,
        "abs_dev_p50_us": h.abs_dev_p50_us,
        "abs_dev_p99_us": h.abs_dev_p99_us,
        "period_max_us": h.period_max_us,
        "periods_over_2ms": h.periods_over_2ms,
        "fraction_over_2ms": h.periods_over_2ms / h.ticks if h.ticks else float("nan"),
        "steal_percent": steal_percent(cpu_before, cpu_times()),
        "load_average": load_average(),
    }
    if h.late_periods is not None:
        out["late_ticks"] = h.late_periods
    return out


def _measure_without_gui(seconds: float, explain: bool) -> dict[str, Any]:
    _, last, cpu0 = engine_loop_health(seconds, explain)
    return _loop_figures(last, cpu0)


def _run_until(app: Any, pred: Callable[[], bool], timeout_s: float) -> None:
    """Run Qt's event loop until ``pred()`` holds, or raise after ``timeout_s``."""
    end = time.monotonic() + timeout_s
    while not pred():
        app.processEvents()
        time.sleep(0.001)
        if time.monotonic() > end:
            raise RuntimeError("bench gui: a step did not complete in time")


def _stall_figures(recorder: Any) -> dict[str, Any]:
    """The GUI event loop's stalls: the worst per phase, the count over the threshold and the longest eight."""
    return {
        "gui_stall_ms": {k: round(v, 1) for k, v in recorder.worst_ms.items()},
        "gui_worst_stall": {
            ph: (None if (w := recorder.worst(ph)) is None else {"ms": w.gap_ms, "callback": w.culprit})
            for ph in ("connect", "calibration", "session")
        },
        "gui_stalls_over_threshold": len(recorder.stalls),
        "gui_longest_stalls": [
            {"phase": st.phase, "ms": st.gap_ms, "callback": st.culprit}
            for st in sorted(recorder.stalls, key=lambda st: -st.gap_ms)[:8]
        ],
    }


def run_gui_bench(seconds: float = 20.0, *, explain: bool = False) -> dict[str, Any]:
    """Measure; returns plain data (see :func:`format_gui_bench`); ``explain`` traces late ticks' causes."""
    without = _measure_without_gui(seconds, explain)

    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    t0 = time.perf_counter()
    from PySide6.QtCore import QSettings
    from PySide6.QtWidgets import QApplication

    from study_app.gui.main_window import ExperimenterWindow
    from study_app.gui.stall import StallDetector

    app = QApplication.instance() or QApplication(["haptic-study-bench"])
    tmp = tempfile.TemporaryDirectory(prefix="haptic-study-bench-")
    settings = QSettings(os.path.join(tmp.name, "settings.ini"), QSettings.Format.IniFormat)
    win = ExperimenterWindow(HostConfig(clock="real", trace_jitter=explain), settings,
                             os.path.join(tmp.name, "bench.db"))
    win.session_actions.confirm = lambda title, text: True
    win.show()
    app.processEvents()
    t_usable = time.perf_counter() - t0

    detector = StallDetector(win, _STALL_TIMER_MS, threshold_ms=_STALL_THRESHOLD_MS)
    detector.start("connect")
    health: list[m.Health] = []
    def keep_health(ev: object) -> None:
        if isinstance(ev, m.Health):
            health.append(ev)

    win.bridge.event_received.connect(keep_health)

    try:
        _run_until(app, lambda: win.model.session.state == "ready", 60.0)
        t_ready = time.perf_counter() - t0
        detector.set_phase("calibration")
        win.calibration_wizard.show()
        win.calibration_wizard.run_button.click()
        _run_until(app, lambda: win.model.calibration.state in ("accepted", "refused"), 120.0)
        win.calibration_wizard.hide()
        detector.set_phase("session")
        win.participant_window.show()
        win.rig_window.show()
        win.model.setup.update(code="BENCH01")
        win.start_button.click()
        _run_until(app, lambda: win.model.session.trial is not None, 30.0)
        win.bridge.send(m.ResetStats())
        cpu0 = cpu_times()
        t_end = time.monotonic() + seconds
        _run_until(app, lambda: time.monotonic() >= t_end, seconds + 30.0)
        n = len(health)
        _run_until(app, lambda: len(health) > n + 1, 10.0)  # a Health event entirely after the window
        with_gui = _loop_figures(health[-1], cpu0)
        trials = win.trial_table.rowCount()
    finally:
        detector.stop()
        win.close()
        tmp.cleanup()
    return {
        "seconds": seconds,
        "without_gui": without,
        "with_gui": with_gui,
        **_stall_figures(detector.recorder),
        "load_average": load_average(),
        "startup_s": {"window_usable": round(t_usable, 2), "engine_ready": round(t_ready, 2)},
        "trials_during_measurement": trials,
        "qt_platform": QApplication.platformName(),
        "host": f"{platform.python_implementation()} {platform.python_version()}, {os.cpu_count()} CPUs",
    }


def format_gui_bench(r: dict[str, Any]) -> str:
    """Human-readable summary."""
    def loop(d: dict[str, Any]) -> str:
        steal = "" if d.get("steal_percent") is None else f", CPU stolen by the hypervisor {d['steal_percent']:.1f} %"
        load = "" if "load_average" not in d else f", load {d['load_average'][0]:.2f}"
        text = (f"p50 / p99 |period − 1 ms| {d['abs_dev_p50_us']:.0f} / {d['abs_dev_p99_us']:.0f} µs, "
                f"periods > 2 ms {d['periods_over_2ms']} of {d['ticks']} ({100 * d['fraction_over_2ms']:.3f} %), "
                f"max period {d['period_max_us'] / 1000:.1f} ms{load}{steal}")
        late = d.get("late_ticks")
        if late:
            text += "\n" + format_late_ticks(late)
        return text

    s = r["gui_stall_ms"]
    return (
        f"1 kHz loop in the study-engine process, real clock, {r['seconds']:g} s each ({r['host']}):\n"
        f"  without GUI          {loop(r['without_gui'])}\n"
        f"  with GUI, 30 Hz plot {loop(r['with_gui'])}\n"
        f"GUI event-loop stalls (longest gap beyond a {_STALL_TIMER_MS} ms timer, Qt platform {r['qt_platform']}):\n"
        f"  connect {s['connect']:.1f} ms · calibration {s['calibration']:.1f} ms · session {s['session']:.1f} ms\n"
        + "".join(
            f"  worst in {ph}: {w['ms']:.1f} ms in {w['callback']}\n"
            for ph, w in r["gui_worst_stall"].items() if w is not None
        )
        + f"  {r['gui_stalls_over_threshold']} stalls ≥ {_STALL_THRESHOLD_MS:g} ms in all; load average "
        f"{' '.join(f'{x:.2f}' for x in r['load_average'])} (1/5/15 min, at the end)\n"
        f"start-up: usable window {r['startup_s']['window_usable']:.2f} s, engine connected "
        f"{r['startup_s']['engine_ready']:.2f} s"
    )
