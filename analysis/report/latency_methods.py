"""The methods' paragraphs on the rig: the end-to-end latency -- how long a force at the tip took to reach the
participant's hand, and the hand's motion to reach the tip (measured by :mod:`pipeline.assembly.latency`).

A session on the real clock stores its breakdown, measured when it started (``config_json``'s ``latency``): the
paragraph states what is stored, and reads it as plain data (the analysis imports nothing of the pipeline).  A
simulated session on the virtual clock stores none -- computing takes no time there -- and the paragraph says so
and where the simulated rig's breakdown is measured (``haptic-study bench loop``, docs/science.md §8) -- and the
rig's qualification (``haptic-study qualify``, docs/qualify.md), named when a session stored one (``config_json``'s
``qualification``: each arm's record as it stood when the session started).
"""

from __future__ import annotations

import html
import json
import statistics
from typing import Any

from analysis.reading.load import StudyData
from protocol.storage import StorageError, StudyReader

__all__ = ["latency_paragraph", "qualification_paragraph"]


def _stored(study: StudyData) -> dict[tuple[str, int], dict[str, Any]]:
    """Per (database, session id): what its ``config_json`` says of the latency."""
    out: dict[tuple[str, int], dict[str, Any]] = {}
    for path in study.databases:
        try:
            reader = StudyReader(path, check=False)
        except StorageError:
            continue
        try:
            for info in reader.sessions():
                try:
                    config = json.loads(info.config_json)
                except (TypeError, ValueError):
                    config = {}
                out[(str(path), int(info.session_id))] = {"latency": config.get("latency"),
                                                          "qualification": config.get("qualification")}
        finally:
            reader.close()
    return out


def _ms(values: list[float | None]) -> str:
    vals = [v for v in values if v is not None]
    if not vals:
        return "not measured"
    lo, hi, med = min(vals), max(vals), statistics.median(vals)
    return f"{med:.1f} ms" if hi - lo < 0.05 else f"{med:.1f} ms (median; {lo:.1f}–{hi:.1f})"


def _stages_text(latency: dict[str, Any], path: str) -> str:
    """A stored breakdown's stages of one path in one line: ``moving average (10 samples) 4.0 ms, …``."""
    return ", ".join(f"{s['name']} {s['ms']:.1f} ms" if s.get("ms") is not None else f"{s['name']} –"
                     for s in latency.get("stages", ()) if s.get("path") == path)


def _measured(latencies: list[dict[str, Any]]) -> str:
    """The real clock's sentence: the stored breakdowns, summarised."""
    first = latencies[0]
    stages = html.escape(f"tip → hand: {_stages_text(first, 'force')}; hand → tip: {_stages_text(first, 'motion')}")
    return (f"Measured when each of the {len(latencies)} session{'s' if len(latencies) > 1 else ''} on the real clock "
            f"started, and stored with it: tip → hand {_ms([d.get('force_ms') for d in latencies])}, hand → tip "
            f"{_ms([d.get('motion_ms') for d in latencies])}, round trip {_ms([d.get('total_ms') for d in latencies])}"
            f" for a {latencies[0].get('step_n', 1.0):g} N step of tip force (the first session's stages: {stages}).")


def _simulated(sessions: int) -> str:
    """The virtual clock's sentence: nothing measured, and where the simulated rig's breakdown is."""
    return (f"{sessions} session{'s' if sessions > 1 else ''} ran on the simulated rig on the virtual clock, where "
            "computing takes no time and no latency is stored; the simulated rig's breakdown with the paper's "
            "settings is measured stage by stage by haptic-study bench loop (docs/science.md, section 8).")


def latency_paragraph(study: StudyData) -> str:
    """The methods' paragraph on the end-to-end latency of the analysed sessions ("" when none is analysed)."""
    s = study.sessions
    analysed = s[s["analysed"].astype(bool)] if "analysed" in s else s
    if analysed.empty:
        return ""
    stored = _stored(study)
    latencies, unmeasured = [], 0
    for db, sid in zip(analysed["database"], analysed["session_id"], strict=True):
        got = stored.get((str(db), int(sid)), {"latency": None})
        if got["latency"]:
            latencies.append(got["latency"])
        else:
            unmeasured += 1
    said = []
    if latencies:
        said.append(_measured(latencies))
    if unmeasured:
        said.append(_simulated(unmeasured))
    return (f"<p><b>End-to-end latency</b> (measured by pipeline/assembly/latency.py): the delay from a force at the "
            f"instrument's tip to the force at the participant's hand, and from the hand's motion to the tip's. "
            f"{' '.join(said)} Peak forces suffer from delays of the order of 100 ms.</p>")


def _record_text(arm: str, rec: dict[str, Any]) -> str:
    """One arm's record in words: ``arm right: PARTIAL on DATE (software V): process-death PASS (…), …``."""
    checks = "; ".join(f"{c.get('name')} {c.get('verdict')}"
                       + (f" ({c.get('measured') or c.get('why')})" if c.get("measured") or c.get("why") else "")
                       for c in rec.get("checks", ()))
    return (f"arm {arm}: {rec.get('verdict')} on {rec.get('date', 'an unknown date')} (software "
            f"{rec.get('software_version', 'unknown')})" + (f": {checks}" if checks else f": {rec.get('why', '')}"))


def qualification_paragraph(study: StudyData) -> str:
    """The methods' paragraph on the rig's qualification ("" when no analysed session stored one)."""
    s = study.sessions
    analysed = s[s["analysed"].astype(bool)] if "analysed" in s else s
    stored = _stored(study)
    records: dict[str, str] = {}
    without = 0
    for db, sid in zip(analysed["database"], analysed["session_id"], strict=True):
        got = stored.get((str(db), int(sid)), {}).get("qualification")
        if not got:
            without += 1
            continue
        for arm, rec in got.items():
            text = _record_text(str(arm), rec)
            records[text] = text  # the distinct records, in the order first met
    if not records:
        return ""
    n = len(analysed) - without
    return (f"<p><b>Rig qualification</b> (haptic-study qualify, docs/qualify.md): the record stored with "
            f"{n} session{'s' if n > 1 else ''} when {'they' if n > 1 else 'it'} started: "
            f"{html.escape(' | '.join(records))}."
            + (f" {without} session{'s' if without > 1 else ''} stored no qualification." if without else "")
            + "</p>")
