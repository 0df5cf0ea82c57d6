"""``haptic-study bench loop``: the 1 kHz loop beside a defined load, ours and another version's, in the same run.

The load (:mod:`bench.loop_load`): busy processes per CPU, ``haptic-study report`` of a 10-participant study over
and over, a GUI plotting the live ring at 30 Hz.  It starts first and runs throughout, the same for both versions;
each measurement is a fresh engine (:mod:`bench.loop_probe`, the simulated rig on the real clock) of our tree or
of the reference tree (``--reference-tree``: e.g. a git worktree of the code before the loop had its own
process), in turn, ``--rounds`` times.  By default each measurement is a whole experiment session of the paper's
protocol (20 trials, the simulated participant, training not required) and its loop's every period; with
``--no-session``, ``--seconds`` of the loop alone.  Printed: the period distribution, periods over 2 ms, missed
slots, the periods over the 5 ms gap limit (each aborts the trial it falls in), the session's gap aborts, the
load average and the CPU time the hypervisor stole, and each figure against the issue's target.  Beside each
measurement a bare 1 ms timer runs on the loop's CPU (:mod:`bench.loop_floor`): its late periods are the
machine's (a kernel or hypervisor that takes the CPU away), which no design of the loop's process avoids.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from typing import Any

from bench.loop_floor import Floor
from bench.loop_load import Load, LoadSpec
from bench.machine import cpu_times, load_average, steal_percent
from bench.source_trees import check_tree, source_env
from foundation.platform_support.threads import usable_cpu_count, usable_cpus
from pipeline.core.clock import LOOP_CPU_ENV

__all__ = ["PROTOCOL", "format_loop_bench", "probe", "run_loop_bench"]

_PROBE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "loop_probe.py")
#: The paper's protocol (protocol/study/default.toml) with the training not required: an experiment session at once.
PROTOCOL = """name = "bench loop: the paper's protocol"
[[targets]]
label = "GENTLE"
force_n = 0.6
[[targets]]
label = "FIRM"
force_n = 1.2
[design]
modes = ["on", "off"]
trials_per_cell = 5
[trial]
tolerance_fraction = 0.10
hold_s = 1.0
max_trial_s = 12.0
pause_s = 2.0
cue_s = 1.0
[training]
enabled = true
required = false
"""
#: The issue's targets under load (issue 45, "What it must reach").
TARGETS = {"abs_dev_p99_us": 100.0, "missed_fraction": 1e-4, "gap_aborts": 0}
#: Seconds the load builds up before the first measurement (the report's first pass is reading its database).
_LOAD_SETTLE_S = 10.0


def probe(tree: str | None, seconds: float, protocol: str | None, work: str, plot: bool,
          tag: str, lsl: bool = False) -> dict[str, Any]:
    """One measurement in a fresh process of our tree (``tree`` None) or of ``tree``; the GUI load plots its ring;
    ``lsl``: the engine publishes on the Lab Streaming Layer and the session's markers are recorded and aligned."""
    ready = os.path.join(work, f"{tag}.ready")
    args = [sys.executable, _PROBE, "--seconds", repr(seconds), "--db", os.path.join(work, f"{tag}.db"),
            "--ready-file", ready, *(["--lsl"] if lsl else [])]
    if protocol is not None:
        args += ["--protocol", protocol]
    gui = Load(LoadSpec(0, False, plot), None, work)
    floor = Floor(_loop_cpu(), os.path.join(work, f"{tag}.floor.json"))
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, text=True, env=source_env(tree), cwd=work)
    floor_figures = None
    try:
        end = time.monotonic() + 240.0
        while not os.path.exists(ready) and proc.poll() is None and time.monotonic() < end:
            time.sleep(0.1)
        if os.path.exists(ready):
            with open(ready, encoding="utf-8") as fh:
                gui.plot(fh.read().strip())
        out, _ = proc.communicate()
    finally:
        floor_figures = floor.stop()
        gui.stop()
        if proc.poll() is None:
            proc.kill()
    if proc.returncode:
        raise RuntimeError(f"bench loop: the measurement of {tree or 'our tree'} failed (exit {proc.returncode})")
    result: dict[str, Any] = json.loads(out)
    result["load_average"] = load_average()
    result["floor"] = floor_figures
    return result


def _loop_cpu() -> int:
    """The CPU our loop's process runs on (:func:`pipeline.core.clock.pin_loop_process`): where the floor is."""
    raw = os.environ.get(LOOP_CPU_ENV, "").strip()
    cpus = usable_cpus()
    return int(raw) if raw.isdigit() and int(raw) in cpus else cpus[-1]


def run_loop_bench(*, seconds: float, load: LoadSpec, session: bool, reference_tree: str | None = None,
                   rounds: int = 1, study_db: str | None = None,
                   progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """The measurements (see the module's docstring) as plain data."""
    say = progress or (lambda s: None)
    cpus = usable_cpu_count()
    quiet = load_average()
    with tempfile.TemporaryDirectory(prefix="bench-loop-") as work:
        if reference_tree is not None:
            check_tree(reference_tree, work, "--reference-tree")
        db = study_db
        if load.report and db is None:
            say("simulating the 10-participant study the report load reports on (once)")
            db = os.path.join(work, "s10.db")
            subprocess.run([sys.executable, "-m", "study_app.cli", "run", "--participants", "10", "--seed", "0",
                            "--db", db], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=work)
        protocol = None
        if session:
            protocol = os.path.join(work, "protocol.toml")
            with open(protocol, "w", encoding="utf-8") as fh:
                fh.write(PROTOCOL)
        background = Load(LoadSpec(load.busy_per_cpu, load.report, False), db, work)
        runs: dict[str, list[dict[str, Any]]] = {"ours": [], "reference": []}
        cpu0 = cpu_times()
        try:
            background.start(cpus)
            if background.procs:
                say(f"load running; {_LOAD_SETTLE_S:g} s for it to build up")
                time.sleep(_LOAD_SETTLE_S)
            sides = [("ours", None)] + ([("reference", reference_tree)] if reference_tree is not None else [])
            for k in range(rounds):
                for side, tree in sides:
                    what = "a 20-trial session" if session else f"{seconds:g} s of the loop"
                    say(f"round {k + 1} of {rounds}: {side} ({what})")
                    runs[side].append(probe(tree, seconds, protocol, work, load.gui, f"{side}{k}"))
        finally:
            background.stop()
        steal = steal_percent(cpu0, cpu_times())
    return {"load": load.describe(cpus), "cpus": cpus, "load_average_before": quiet, "steal_percent": steal,
            "session": session, "seconds": seconds, "rounds": rounds, "reference_tree": reference_tree,
            "python": sys.version.split()[0], "machine": f"{platform.machine()} {platform.processor() or ''}".strip(),
            "runs": runs}


def _where(r: dict[str, Any]) -> str:
    """Where the version ran its loop: its own process, or a thread of the engine's."""
    place = f"its own process (pid {r['loop_pid']})" if r.get("loop_pid") else "a thread of the engine's process"
    return f"{place}, {r.get('scheduling') or 'scheduling not said'}"


def _session_cells(r: dict[str, Any]) -> tuple[str, str]:
    s = r.get("session")
    if not s:
        return "–", "–"
    aborted = ", ".join(f"{n} {c}" for c, n in s["aborted"].items()) or "none"
    done = f"{s['completed']} of {s['attempts']} attempts ({'ended' if s['ended'] else 'NOT ended: time cap'})"
    return done, f"{s['gap_aborts']} (aborted: {aborted})"


def _held(r: dict[str, Any]) -> str:
    """How often the session waited for the experimenter, who the probe stands in for."""
    s = r.get("session")
    if not s:
        return "–"
    return (f"the runner paused itself {s.get('self_pauses', 0)} time(s) (trials it could not deliver): resumed; "
            f"a fault latched {s.get('fault_resets', 0)} time(s): reset")


def _rows(r: dict[str, Any]) -> list[tuple[str, str]]:
    p = r["period_us"]
    done, gaps = _session_cells(r)
    n = max(1, r["ticks"])
    return [
        ("measured for", f"{r['seconds']:.0f} s, {r['ticks']:,} ticks, load average {r['load_average'][0]:.2f}"),
        ("period p50 / p90 / p99 / p99.9 / max",
         f"{p['p50']:.0f} / {p['p90']:.0f} / {p['p99']:.0f} / {p['p99.9']:.0f} / {p['max']:.0f} µs"),
        ("p99 |period - 1 ms|", f"{r['abs_dev_p99_us']:.0f} µs   (target ≤ {TARGETS['abs_dev_p99_us']:g} µs)"),
        ("missed slots", f"{r['missed_slots']} ({100 * r['missed_fraction']:.3f} %)   "
                         f"(target ≤ {100 * TARGETS['missed_fraction']:g} %)"),
        ("periods over 2 ms", f"{r['over_2ms']} ({100 * r['over_2ms'] / n:.3f} %)"),
        ("periods over 5 ms", f"{r['over_gap_5ms']}   (the gap limit: each in a trial aborts it)"),
        ("session: completed trials", done),
        ("session: gap aborts", f"{gaps}   (target {TARGETS['gap_aborts']})"),
        ("session: held, then resumed / reset", _held(r)),
        ("the machine's floor, same CPU and time", _floor(r)),
        ("LOOP_STALLED (a tick over 50 ms)", str(r.get("loop_stalled", 0))),
        ("records the reader lost", str(r["records_lost"])),
    ]


def _floor(r: dict[str, Any]) -> str:
    """What a bare 1 ms timer suffered beside the loop (:mod:`bench.loop_floor`): the periods no code avoids."""
    f = r.get("floor")
    if not f:
        return "not measured (the bare timer left no figures)"
    return (f"a bare 1 ms timer ({f['scheduling']}): {f['over_2ms']} periods over 2 ms, {f['over_5ms']} over 5 ms, "
            f"max {f['max_ms']:.1f} ms, of {f['periods']:,}")


def _histogram(r: dict[str, Any]) -> str:
    h = r["histogram_us"]
    edges = [0, *h["edges"]]
    labels = [f"{a / 1000:g}–{b / 1000:g}" for a, b in zip(edges, h["edges"], strict=False)]
    labels.append(f">{edges[-1] / 1000:g}")
    return "  ".join(f"{lab} ms: {c}" for lab, c in zip(labels, h["counts"], strict=True))


def _meets(r: dict[str, Any]) -> str:
    s = r.get("session") or {}
    checks = [("p99 |period - 1 ms| ≤ 100 µs", r["abs_dev_p99_us"] <= TARGETS["abs_dev_p99_us"]),
              ("missed slots ≤ 0.01 %", r["missed_fraction"] <= TARGETS["missed_fraction"])]
    if s:
        checks.append(("0 gap aborts", s["gap_aborts"] == 0 and s["ended"]))
    checks.append(("no LOOP_STALLED", not r.get("loop_stalled")))
    return "; ".join(f"{what}: {'yes' if ok else 'NO'}" for what, ok in checks)


def format_loop_bench(res: dict[str, Any]) -> str:
    """Human-readable report of :func:`run_loop_bench`: what ran, under what load, each version's figures."""
    lines = [
        "bench loop: the 1 kHz loop (simulated rig, real clock, as the GUI's engine runs it) beside a load",
        f"  machine      {res['cpus']} CPUs usable, {res['machine']}, Python {res['python']}; load average before "
        f"the load {res['load_average_before'][0]:.2f}"
        + ("" if res["steal_percent"] is None else f"; CPU stolen by the hypervisor {res['steal_percent']:.1f} %"),
        f"  load         {res['load']}",
        "  measured     " + ("each version runs an experiment session of the paper's protocol (20 trials, the "
                             "simulated participant) to its end" if res["session"] else
                             f"{res['seconds']:g} s of each version's loop, no session")
        + f"; {res['rounds']} round(s), ours then the reference, fresh processes, the same load",
    ]
    sides = [("ours", "this tree")] + ([("reference", res["reference_tree"])] if res["reference_tree"] else [])
    for side, what in sides:
        for k, r in enumerate(res["runs"][side]):
            lines += ["", f"{side} ({what}), round {k + 1}: the loop in {_where(r)}"]
            lines += [f"  {name:<38} {value}" for name, value in _rows(r)]
            lines.append(f"  {'period histogram':<38} {_histogram(r)}")
            lines.append(f"  {'meets the targets':<38} {_meets(r)}")
            if r.get("session") and r["session"]["gap_reasons"]:
                lines.append(f"  {'first gap aborts':<38} {'; '.join(r['session']['gap_reasons'][:3])}")
            if r.get("latency"):
                lat = r["latency"]
                lines.append(f"  {'end-to-end latency':<38} tip → hand {lat['force_ms']:.1f} ms, hand → tip "
                             f"{lat['motion_ms']:.1f} ms, round trip {lat['total_ms']:.1f} ms")
    lines += ["", "Rerun on a quiet machine (the figures above are this machine's, with its other programs): "
                  "haptic-study bench loop --load none --no-session --seconds 30 --reference-tree TREE"]
    return "\n".join(lines)
