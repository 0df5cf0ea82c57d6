"""The load ``bench loop`` runs beside the 1 kHz loop: busy processes, a report of a study, a GUI plotting live.

Each load is a process of its own, started with our interpreter and our tree (it is the machine's load, not the
code measured): ``python bench/loop_load.py busy`` spins; ``… report DB DIR`` writes the report of a study again
and again (each time into a new folder of ``DIR``); ``… gui RING`` plots the engine's ring live at 30 Hz, the way
the experimenter window does (pyqtgraph, offscreen when there is no display: the same painting work) -- two plots
of the newest 10 s, four curves of 10 000 points each, repainted every frame.  :class:`Load` starts and stops them.
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Load", "LoadSpec", "parse_load"]

_HERE = os.path.abspath(__file__)


@dataclass(frozen=True)
class LoadSpec:
    """What load runs beside the loop: busy processes per usable CPU, a report in a loop, a GUI plotting live."""

    busy_per_cpu: int = 2
    report: bool = True
    gui: bool = True

    def describe(self, cpus: int) -> str:
        """In words, for the bench's output."""
        parts = []
        if self.busy_per_cpu:
            parts.append(f"{self.busy_per_cpu * cpus} busy processes ({self.busy_per_cpu} per CPU, {cpus} CPUs: "
                         "pure-Python spin loops at normal priority)")
        if self.report:
            parts.append("haptic-study report of a 10-participant study, over and over")
        if self.gui:
            parts.append("a GUI plotting the live ring at 30 Hz (pyqtgraph, 2 plots × 10 s, 4 curves)")
        return "; ".join(parts) or "none (a quiet machine: the loop's floor)"


def parse_load(text: str) -> LoadSpec:
    """``busy=2,report,gui`` (any of them; ``none``: no load).

    Raises
    ------
    ValueError
        One line naming the part that is not understood.
    """
    if text.strip() in ("", "none"):
        return LoadSpec(0, False, False)
    busy, report, gui = 0, False, False
    for part in (p.strip() for p in text.split(",")):
        if part == "report":
            report = True
        elif part == "gui":
            gui = True
        elif part.startswith("busy="):
            value = part[5:]
            if not value.isdigit() or not 0 <= int(value) <= 16:
                raise ValueError(f"--load busy={value}: a whole number of busy processes per CPU from 0 to 16")
            busy = int(value)
        else:
            raise ValueError(f"--load: {part!r} is not a load; allowed: busy=N (per CPU), report, gui, none")
    return LoadSpec(busy, report, gui)


@dataclass
class Load:
    """The load processes of a :class:`LoadSpec` (``start`` / ``stop``; the GUI's once the ring is known)."""

    spec: LoadSpec
    study_db: str | None
    work_dir: str
    procs: list[subprocess.Popen[bytes]] = field(default_factory=list)

    def start(self, cpus: int) -> None:
        """The busy processes and the report loop."""
        for _ in range(self.spec.busy_per_cpu * cpus):
            self.procs.append(self._spawn("busy"))
        if self.spec.report and self.study_db is not None:
            self.procs.append(self._spawn("report", self.study_db, os.path.join(self.work_dir, "reports")))

    def plot(self, ring_name: str) -> None:
        """The GUI plotting ``ring_name`` live (when the spec asks for it)."""
        if self.spec.gui:
            self.procs.append(self._spawn("gui", ring_name))

    def stop(self) -> None:
        """End every load process."""
        for p in self.procs:
            if p.poll() is None:
                p.terminate()
        for p in self.procs:
            try:
                p.wait(10.0)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(5.0)
        self.procs = []

    def _spawn(self, *args: str) -> subprocess.Popen[bytes]:
        return subprocess.Popen([sys.executable, _HERE, *args], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                cwd=self.work_dir)


def _busy() -> None:
    x = 0
    while True:
        x = (x * 1103515245 + 12345) & 0xFFFFFFFF


def _report(db: str, out: str) -> None:
    from study_app.cli.main import main  # in this process: it ends with it (its workers die with it)

    os.makedirs(out, exist_ok=True)
    k = 0
    while True:
        k += 1
        main(["report", "--db", db, "--out", os.path.join(out, f"r{os.getpid()}_{k}")])


def _gui(ring_name: str) -> None:
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    import numpy as np
    import pyqtgraph as pg
    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication, QVBoxLayout, QWidget

    from pipeline.runtime.ring import RingBuffer

    app = QApplication.instance() or QApplication(["bench-loop-gui"])
    ring = RingBuffer.attach(ring_name)
    win = QWidget()
    win.resize(1100, 700)
    lay = QVBoxLayout(win)
    upper, lower = pg.PlotWidget(), pg.PlotWidget()
    lay.addWidget(upper)
    lay.addWidget(lower)
    curves: list[tuple[Any, str]] = [(upper.plot(pen=pg.mkPen(c, width=1)), f) for c, f in
                                     (("#1f4e9c", "force_n"), ("#14a03c", "render_fy"))]
    curves += [(lower.plot(pen=pg.mkPen(c, width=1)), f) for c, f in (("#dc2828", "raw_fz"), ("#28963c", "comp_fz"))]
    win.show()

    def frame() -> None:
        rows = ring.latest(10_000)
        if len(rows):
            t = rows["t_s"] - rows["t_s"][-1]
            for curve, name in curves:
                curve.setData(t, np.asarray(rows[name], dtype=float))
        win.repaint()

    timer = QTimer()
    timer.timeout.connect(frame)
    timer.start(33)
    app.exec()


if __name__ == "__main__":
    from foundation.platform_support.processes import die_with

    die_with(os.getppid())  # a bench that is killed leaves no load behind
    what = sys.argv[1]
    if what == "busy":
        _busy()
    elif what == "report":
        _report(sys.argv[2], sys.argv[3])
    elif what == "gui":
        _gui(sys.argv[2])
