"""The checks of ``haptic-study qualify`` that run the 1 kHz loop as a session runs it (docs/qualify.md).

Both run on one engine: the study engine on the hardware file's rig, on the real clock, the loop alone in its own
process (:class:`study_app.engine.client.EngineClient`, as the GUI and ``run`` start it), for ``seconds``, while the
machine is as the lab uses it (qualify adds no load of its own).

* **latency** -- the end-to-end sensing-to-rendering latency (tip → hand) as a real-rig session measures and stores
  it when it starts (:class:`study_app.engine.latency_report.LatencyReport`: the loop's own share from its records,
  the pipeline's stages on a twin with the file's settings), with the one stage a session cannot time measured
  here: the F/T sensor's sampling and transport, bounded by the box's answer to single-record requests
  (:func:`pipeline.backends.netft_probe.sample_round_trips`), taken before the engine starts.  The bound:
  :data:`LATENCY_BUDGET_MS` for the round trip a press closes (science.md §8: peak forces suffer from delays of the
  order of 100 ms); the motion path (hand → tip) counts where the app knows it (the teleop look-ahead), and the
  motors after the Touch's servo are the tap test's (said in the record).
* **loop-under-load** -- the loop's every period over the run against the product's own bounds: no period over the
  delivery rule's gap limit (:class:`protocol.study.delivery.DeliveryLimits`: a trial it falls in is aborted,
  ``gap``), no fault latched, no ``LOOP_STALLED``, p99 |period − 1 ms| and missed slots within issue 45's targets.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from study_app.cli.qualify_checks import CheckResult, not_checked

#: The round trip a press closes (hand → tip → hand) must stay under this, ms (science.md §8, issue 45: peak forces
#: suffer from delays of the order of 100 ms).
LATENCY_BUDGET_MS = 100.0
#: Issue 45's targets for the loop under load: p99 |period − 1 ms|, µs, and the fraction of 1 ms slots missed.
P99_DEV_US = 100.0
MISSED_FRACTION = 1e-4
#: Seconds the loop runs before the measurement starts (start-up, its first health reports, 2 s of records for
#: the latency's live stages).
WARM_UP_S = 3.0
#: Single-record requests the sensor's transport is measured with.
_ROUND_TRIPS = 20


@dataclass
class EngineRun:
    """What one engine run on the rig gave: its loop's periods, its health, the latency it measured."""

    periods_ns: Any
    seconds: float
    missed_slots: int
    records_lost: int
    faults: list[str] = field(default_factory=list)
    latency: dict[str, Any] | None = None
    scheduling: str = ""
    load_average: float = math.nan


def run_engine(hardware: str, seconds: float, say: Callable[[str], None]) -> EngineRun:
    """The engine on ``hardware``'s rig for :data:`WARM_UP_S` + ``seconds``; :class:`RuntimeError` (the engine's
    own words) when it cannot start."""
    import numpy as np

    from study_app.engine import messages as m
    from study_app.engine.client import EngineClient, EngineStartError
    from study_app.engine.setup import HostConfig

    client = EngineClient(HostConfig(rig="real", hardware_path=hardware, clock="real", health_period_s=0.5))
    try:
        try:
            client.wait_ready(120.0)
        except EngineStartError as exc:
            raise RuntimeError(str(exc)) from None
        ring = client.ring
        if ring is None:
            raise RuntimeError("the engine shares no loop records")
        say(f"the loop runs on the rig: {WARM_UP_S:g} s to settle, then {seconds:g} s measured")
        first = _health_after(client, WARM_UP_S)
        cursor, lost, periods, faults = ring.write_count, 0, [], []
        last, started = first, time.monotonic()
        while time.monotonic() - started < seconds:
            ev = client.get(0.05)
            if isinstance(ev, m.Health):
                last = ev
            elif isinstance(ev, m.EngineFault) and ev.kind == "fault":
                faults.append(ev.detail)
            got = ring.read_since(cursor)
            cursor, lost = got.cursor, lost + got.lost
            if len(got.rows):
                periods.append(np.asarray(got.rows["period_ns"], dtype=np.int64))
        duration = time.monotonic() - started
        last = _health_after(client, 0.6, last)  # the newest breakdown: the live stages of the run's last 2 s
    finally:
        client.shutdown()
    from foundation.platform_support.machine import load_average

    load = load_average()
    return EngineRun(np.concatenate(periods) if periods else np.zeros(0, dtype=np.int64), duration,
                     int(last.missed_slots - first.missed_slots), lost, faults, last.latency, last.scheduling,
                     load[0] if load is not None else math.nan)


def _health_after(client: Any, wait_s: float, newest: Any = None) -> Any:
    """The newest health report after ``wait_s`` (and at least one)."""
    from study_app.engine import messages as m

    end = time.monotonic() + wait_s
    while time.monotonic() < end or newest is None:
        ev = client.get(0.05)
        if isinstance(ev, m.Health):
            newest = ev
        elif ev is None and time.monotonic() > end + 10.0:
            raise RuntimeError("the engine sent no health report")
    return newest


def sensor_transport(arm: Any) -> tuple[float, str]:
    """The F/T sensor's sampling and transport, ms: the median round trip of single-record requests to ``arm``'s
    box (an upper bound on the one way); NaN and why when it cannot be measured."""
    import numpy as np

    from pipeline.backends.netft_probe import sample_round_trips
    from pipeline.devices.interfaces import DeviceError

    try:
        trips = sample_round_trips(arm.sensor.host, arm.sensor.port, _ROUND_TRIPS)
    except DeviceError as exc:
        return math.nan, str(exc)
    return float(np.median(trips)) * 1e3, (f"median of {len(trips)} single-record requests' round trips "
                                           f"(max {max(trips) * 1e3:.1f} ms): an upper bound")


def latency_check(run: EngineRun | None, transport_ms: float, transport_why: str, why_not: str) -> CheckResult:
    """The latency's verdict from the run's breakdown and the sensor's measured transport."""
    name = "latency"
    bound = (f"round trip (hand → tip → hand) <= {LATENCY_BUDGET_MS:g} ms (science.md §8: peak forces suffer from "
             "delays of the order of 100 ms)")
    if run is None or run.latency is None:
        return not_checked(name, why_not or "the engine measured no latency", bound)
    if not math.isfinite(transport_ms):
        return not_checked(name, f"the F/T sensor's transport could not be measured: {transport_why}", bound)
    from pipeline.assembly.latency import Latency, Stage

    lat = Latency.from_dict(run.latency)
    stages = tuple(Stage(s.path, s.name, transport_ms, transport_why) if s.path == "force" and not
                   math.isfinite(s.ms) and s.name.startswith("F/T sensor") else s for s in lat.stages)
    lat = Latency(stages, lat.step_n)
    motion = (f"hand → tip {lat.motion_ms:.1f} ms" if math.isfinite(lat.motion_ms) else
              "hand → tip not measured by software (observe mode: the tap test, docs/hardware-setup.md)")
    measured = (f"tip → hand {lat.force_ms:.1f} ms ({lat.stages_text('force')}; the sensor's: {transport_why}); "
                f"{motion}; round trip {lat.total_ms:.1f} ms; the motors after the servo: the tap test")
    if lat.total_ms <= LATENCY_BUDGET_MS:
        return CheckResult(name, "PASS", measured, bound)
    return CheckResult(name, "FAIL", measured, bound,
                       why=f"the round trip a press closes, {lat.total_ms:.1f} ms, is over the budget")


def loop_check(run: EngineRun | None, why_not: str) -> CheckResult:
    """The loop-under-load verdict from the run's periods against the product's bounds."""
    import numpy as np

    from protocol.study.delivery import DeliveryLimits

    name = "loop-under-load"
    gap_ms = DeliveryLimits().max_gap_s * 1e3
    bound = (f"no period over {gap_ms:g} ms (the delivery rule: a trial it falls in is aborted, gap), no fault "
             f"latched, p99 |period - 1 ms| <= {P99_DEV_US:g} µs, missed slots <= {MISSED_FRACTION:.2%} "
             "(issue 45's targets)")
    if run is None or not len(run.periods_ns):
        return not_checked(name, why_not or "the loop wrote no records", bound)
    p_us = run.periods_ns * 1e-3
    p50, p99, pmax = (float(np.quantile(p_us, q)) for q in (0.5, 0.99, 1.0))
    dev99 = float(np.quantile(np.abs(p_us - 1000.0), 0.99))
    gaps = int(np.count_nonzero(p_us > gap_ms * 1e3))
    over2 = int(np.count_nonzero(p_us > 2000.0))
    missed = run.missed_slots / max(1, len(p_us) + run.missed_slots)
    faults = sorted({f.split(":")[0] for f in run.faults})
    measured = (f"{run.seconds:.0f} s, {len(p_us):,} periods: p50 {p50:.0f} µs, p99 {p99:.0f} µs, max "
                f"{pmax / 1e3:.1f} ms, p99 |period - 1 ms| {dev99:.0f} µs; {over2} over 2 ms, {gaps} over "
                f"{gap_ms:g} ms; missed slots {run.missed_slots} ({missed:.3%}); faults latched: "
                f"{', '.join(faults) or 'none'}; {run.records_lost} records lost by the reader; load average "
                f"{run.load_average:.2f}; {run.scheduling or 'scheduling not said'}")
    why = "; ".join(w for w, bad in (
        (f"{gaps} period(s) over the {gap_ms:g} ms gap limit: each would abort the trial it falls in", gaps > 0),
        (f"a fault latched while it ran ({', '.join(faults)})", bool(faults)),
        (f"p99 |period - 1 ms| {dev99:.0f} µs over {P99_DEV_US:g} µs", dev99 > P99_DEV_US),
        (f"{missed:.3%} of slots missed", missed > MISSED_FRACTION),
        (f"{run.records_lost} records lost", run.records_lost > 0)) if bad)
    return CheckResult(name, "FAIL" if why else "PASS", measured, bound, why)


def engine_checks(hardware: str, arm: Any, names: tuple[str, ...], seconds: float,
                  say: Callable[[str], None]) -> dict[str, CheckResult]:
    """Run the checks of ``names`` among ``latency`` and ``loop-under-load`` on one engine run."""
    transport_ms, transport_why = math.nan, ""
    if "latency" in names:
        say("latency: timing the F/T sensor's answers")
        transport_ms, transport_why = sensor_transport(arm)
    run, why_not = None, ""
    try:
        run = run_engine(hardware, seconds if "loop-under-load" in names else 0.0, say)
    except RuntimeError as exc:
        why_not = f"the rig's loop could not be run: {exc}"
    out = {}
    if "latency" in names:
        out["latency"] = latency_check(run, transport_ms, transport_why, why_not)
    if "loop-under-load" in names:
        out["loop-under-load"] = loop_check(run, why_not)
    return out
