"""One measurement of ``bench loop``: the study engine on the real clock, its loop's every period, a session's trials.

Run as a script (``python bench/loop_probe.py …``) in a fresh process whose import path chooses the version
measured -- ours, or a reference tree's (``PYTHONPATH=TREE``, :mod:`bench.source_trees`) -- so it imports nothing
of ``bench`` and only what every version has: :class:`study_app.engine.client.EngineClient`, the engine's
messages and the loop's ring.  It starts the engine (simulated rig, real clock) as the GUI does, writes the ring's
name to ``--ready-file`` (the bench then starts the GUI load on it), lets the loop settle, resets the engine's
timing, then reads every record the loop writes -- its ``period_ns`` -- for ``--seconds`` or, with ``--protocol``,
until a session of that protocol ends (the simulated participant performs it).  One JSON object on stdout.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from typing import Any

#: Seconds the loop runs before the measurement starts (start-up, the first health report).
WARM_UP_S = 3.0


def _abort_cause(record: Any) -> str:
    cause = getattr(record, "abort_cause", None)
    return "" if cause is None else str(getattr(cause, "value", cause))


def measure(seconds: float, protocol: str | None, db: str, ready_file: str, lsl: bool = False) -> dict[str, Any]:
    """Run the engine, read its loop's periods and its session's trials; the figures as plain data.  With ``lsl``
    the engine publishes on the Lab Streaming Layer (``gui --lsl``) and a pylsl inlet records the session's markers,
    which are then held against the stored events (:class:`_Markers`)."""
    import numpy as np

    from study_app.engine import messages as m
    from study_app.engine.client import EngineClient
    from study_app.engine.setup import HostConfig

    client = EngineClient(HostConfig(clock="real", health_period_s=0.5, lsl=lsl))
    markers = _Markers(protocol) if lsl and protocol else None
    try:
        client.wait_ready(180.0)
        ring = client.ring
        assert ring is not None
        with open(ready_file, "w", encoding="utf-8") as fh:
            fh.write(client.ring_name)
        healths: list[Any] = []
        end = time.monotonic() + WARM_UP_S
        while time.monotonic() < end:
            ev = client.get(0.05)
            healths += [ev] if isinstance(ev, m.Health) else []
        client.send(m.ResetStats())
        first = None
        while first is None:  # the missed slots count from start-up: the difference is taken
            ev = client.get(1.0)
            first = ev if isinstance(ev, m.Health) else None
        cursor = ring.write_count
        periods: list[Any] = []
        trials: list[dict[str, Any]] = []
        lost = 0
        started = time.monotonic()
        _start_session(client, protocol, db, markers)
        ended = False
        last = first
        pauses, was_paused, resets, was_latched = 0, False, 0, False
        stalls = 0
        while True:
            ev = client.get(0.05)
            if isinstance(ev, m.Health):
                last = ev
                # what the experimenter does when the session waits (the issue: ten self-pauses in one session):
                if protocol and ev.paused and ev.session_running:  # the runner held it after trials not delivered
                    pauses += 0 if was_paused else 1
                    client.send(m.Resume())
                was_paused = bool(ev.paused)
                latched = protocol is not None and ev.session_running and "latched" in ev.waiting
                if latched:  # a fault latched (LOOP_STALLED after a long stall): no cue until it is reset
                    resets += 0 if was_latched else 1
                    client.send(m.ResetFaults())
                was_latched = latched
            elif isinstance(ev, m.EngineFault) and ev.kind == "fault" and "LOOP_STALLED" in ev.detail:
                stalls += 1
            elif isinstance(ev, m.TrialEnded):
                r = ev.record
                trials.append({"index": int(r.trial_index), "outcome": str(getattr(r.outcome, "value", r.outcome)),
                               "abort_cause": _abort_cause(r), "abort_reason": r.abort_reason or ""})
            elif isinstance(ev, m.SessionEnded):
                ended = True
            elif isinstance(ev, m.CommandRefused):
                raise RuntimeError(f"the engine refused {ev.command}: {ev.message}")
            got = ring.read_since(cursor)
            cursor, lost = got.cursor, lost + got.lost
            if len(got.rows):
                periods.append(np.asarray(got.rows["period_ns"], dtype=np.int64))
            if time.monotonic() - started >= seconds or ended:  # (ended: only with a session)
                break
        duration = time.monotonic() - started
    finally:
        client.shutdown()
    p_us = np.concatenate(periods) * 1e-3 if periods else np.zeros(0)
    out = _figures(p_us, lost, duration, first, last, trials, ended if protocol else None)
    out["loop_stalled"] = stalls
    if out["session"] is not None:
        out["session"].update(self_pauses=pauses, fault_resets=resets)
    if markers is not None:
        out["markers"] = markers.aligned(db)
    return out


class _Markers:
    """A pylsl inlet on the session's marker outlet (found by its source id: this study's session 1 of ``B01``,
    so no other program's streams of the same name), pulled on a thread until the outlet closes; then each marker
    received is held against the stored event it stands for, put on LSL's clock through the run's stored link
    (tests/protocol/test_lsl_session.py's comparison)."""

    def __init__(self, protocol: str) -> None:
        import threading
        import tomllib

        with open(protocol, "rb") as fh:
            name = tomllib.load(fh)["name"]
        self.source_id = f"haptic-study/{name} (seed 1)/B01/session-1/markers"
        self.got: list[tuple[dict[str, Any], float]] = []
        self.correction = float("nan")
        self.error = ""
        self.thread = threading.Thread(target=self._run, daemon=True)

    def start(self) -> None:
        self.thread.start()

    def _run(self) -> None:
        from protocol.lsl.bus import pylsl as lsl_library

        pylsl = lsl_library()  # (quiet: liblsl's INFO lines off, as the product has it)
        found = pylsl.resolve_byprop("source_id", self.source_id, 1, 30.0)
        if not found:
            self.error = "the marker outlet was not found within 30 s"
            return
        inlet = pylsl.StreamInlet(found[0], max_buflen=360, recover=False)
        inlet.open_stream(timeout=30.0)
        self.correction = inlet.time_correction(timeout=30.0)
        while True:
            try:
                chunk, stamps = inlet.pull_chunk(timeout=0.2)
            except pylsl.util.LostError:  # the outlet closed at the session's end
                return
            self.got += [(json.loads(c[0]), float(t) + self.correction) for c, t in zip(chunk, stamps, strict=True)]

    def aligned(self, db: str) -> dict[str, Any]:
        """How many markers were received and matched, and the largest |marker − stored event| on LSL's clock."""
        import sqlite3

        from protocol.storage.lsl_streams import stored_marker_times

        self.thread.join(30.0)
        conn = sqlite3.connect(db)
        try:
            stored = stored_marker_times(conn, 1)
        finally:
            conn.close()
        errors = sorted(abs(t - stored[key]) for marker, t in self.got
                        if (key := (marker["event"], marker.get("trial"))) in stored)
        return {"received": len(self.got), "matched": len(errors), "stored": len(stored), "error": self.error,
                "max_error_us": max(errors) * 1e6 if errors else float("nan"),
                "median_error_us": errors[len(errors) // 2] * 1e6 if errors else float("nan")}


def _start_session(client: Any, protocol: str | None, db: str, markers: _Markers | None) -> None:
    """Start the measured session (with ``protocol``) and the inlet that records its markers (with LSL)."""
    from study_app.engine import messages as m

    if protocol:
        client.send(m.StartSession(db, "B01", "experiment", protocol, 1, 1))
    if markers is not None:  # (only with a session)
        markers.start()


def _figures(p_us: Any, lost: int, duration: float, first: Any, last: Any, trials: list[dict[str, Any]],
             session_ended: bool | None) -> dict[str, Any]:
    import numpy as np

    def q(x: float) -> float:
        return float(np.quantile(p_us, x)) if len(p_us) else float("nan")

    dev = np.abs(p_us - 1000.0)
    edges = [0, 1050, 1100, 1500, 2000, 5000, 10000, 50000, float("inf")]
    hist = np.histogram(p_us, bins=edges)[0].tolist() if len(p_us) else [0] * (len(edges) - 1)
    missed = int(last.missed_slots - first.missed_slots)
    return {
        "seconds": round(duration, 1), "ticks": int(len(p_us)), "records_lost": lost,
        "period_us": {"p50": q(0.5), "p90": q(0.9), "p99": q(0.99), "p99.9": q(0.999),
                      "max": float(p_us.max()) if len(p_us) else float("nan")},
        "abs_dev_p99_us": float(np.quantile(dev, 0.99)) if len(dev) else float("nan"),
        "histogram_us": {"edges": edges[1:-1], "counts": hist},
        "over_2ms": int(np.count_nonzero(p_us > 2000)), "over_gap_5ms": int(np.count_nonzero(p_us > 5000)),
        "missed_slots": missed, "missed_fraction": missed / max(1, len(p_us) + missed),
        "scheduling": getattr(last, "scheduling", ""), "loop_pid": int(getattr(last, "loop_pid", 0) or 0),
        "latency": getattr(last, "latency", None),
        "session": None if session_ended is None else {
            "ended": session_ended, "attempts": len(trials),
            "completed": sum(1 for t in trials if not t["abort_cause"]),
            "aborted": {c: sum(1 for t in trials if t["abort_cause"] == c)
                        for c in sorted({t["abort_cause"] for t in trials if t["abort_cause"]})},
            "gap_aborts": sum(1 for t in trials if t["abort_cause"] == "gap"),
            "gap_reasons": [t["abort_reason"] for t in trials if t["abort_cause"] == "gap"][:10],
        },
    }


def main() -> None:
    ap = argparse.ArgumentParser(prog="loop_probe")
    ap.add_argument("--seconds", type=float, required=True)
    ap.add_argument("--protocol", default=None)
    ap.add_argument("--db", required=True)
    ap.add_argument("--ready-file", required=True)
    ap.add_argument("--lsl", action="store_true")
    args = ap.parse_args()
    from foundation.platform_support.processes import die_with

    die_with(os.getppid())  # a bench that is killed leaves no measurement behind (its engine follows it)
    if args.protocol and os.path.exists(args.db):
        raise SystemExit(f"--db {args.db}: exists (a fresh database per measurement)")
    print(json.dumps(measure(args.seconds, args.protocol, args.db, args.ready_file, args.lsl)))


if __name__ == "__main__":
    main()
