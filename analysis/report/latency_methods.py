"""The methods' paragraph on the end-to-end latency: how long a force at the tip took to reach the participant's hand,
and the hand's motion to reach the tip (:mod:`pipeline.assembly.latency`).

A session on the real clock stores its breakdown, measured when it started (``config_json``'s ``latency``); a
simulated session on the virtual clock stores none -- computing takes no time there, and the breakdown follows from
the pipeline's settings alone, so it is measured here on a twin of the simulated rig with the settings the
sessions ran with.
"""

from __future__ import annotations

import html
import json
import statistics
from typing import Any

from analysis.reading.load import StudyData
from pipeline.assembly.latency import Latency, simulated_stages
from pipeline.force.pipeline_settings import describe, framework_with
from protocol.storage import StorageError, StudyReader

__all__ = ["latency_paragraph"]


def _stored(study: StudyData) -> dict[tuple[str, int], dict[str, Any]]:
    """Per (database, session id): what its ``config_json`` says of the latency and the pipeline's settings."""
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
                                                          "settings": config.get("pipeline_settings") or {}}
        finally:
            reader.close()
    return out


def _ms(values: list[float | None]) -> str:
    vals = [v for v in values if v is not None]
    if not vals:
        return "not measured"
    lo, hi, med = min(vals), max(vals), statistics.median(vals)
    return f"{med:.1f} ms" if hi - lo < 0.05 else f"{med:.1f} ms (median; {lo:.1f}–{hi:.1f})"


def _measured(latencies: list[dict[str, Any]]) -> str:
    """The real clock's sentence: the stored breakdowns, summarised."""
    first = Latency.from_dict(latencies[0])
    stages = html.escape(f"tip → hand: {first.stages_text('force')}; hand → tip: {first.stages_text('motion')}")
    return (f"Measured when each of the {len(latencies)} session{'s' if len(latencies) > 1 else ''} on the real clock "
            f"started, and stored with it: tip → hand {_ms([d.get('force_ms') for d in latencies])}, hand → tip "
            f"{_ms([d.get('motion_ms') for d in latencies])}, round trip {_ms([d.get('total_ms') for d in latencies])}"
            f" for a {latencies[0].get('step_n', 1.0):g} N step of tip force (the first session's stages: {stages}).")


def _simulated(settings: list[dict[str, float]]) -> str:
    """The virtual clock's sentence: the breakdown of the simulated rig with each set of settings the sessions ran."""
    parts = []
    for chosen in settings:
        lat = Latency(simulated_stages(framework_with(chosen)))
        stages = html.escape(f"tip → hand: {lat.stages_text('force')}; hand → tip: {lat.stages_text('motion')}")
        parts.append(f"with {html.escape(describe(chosen))} pipeline settings, {html.escape(lat.summary())}; "
                     f"measured on a twin of the simulated rig, stage by stage: {stages}")
    return ("On the simulated rig, on the virtual clock (computing takes no time there; the real clock adds the "
            "loop's own share and the sensor's transport): " + "; ".join(parts) + ".")


def latency_paragraph(study: StudyData) -> str:
    """The methods' paragraph on the end-to-end latency of the analysed sessions ("" when none is analysed)."""
    s = study.sessions
    analysed = s[s["analysed"].astype(bool)] if "analysed" in s else s
    if analysed.empty:
        return ""
    stored = _stored(study)
    latencies, settings = [], []
    for db, sid in zip(analysed["database"], analysed["session_id"], strict=True):
        got = stored.get((str(db), int(sid)), {"latency": None, "settings": {}})
        if got["latency"]:
            latencies.append(got["latency"])
        elif got["settings"] not in settings:
            settings.append(got["settings"])
    said = []
    if latencies:
        said.append(_measured(latencies))
    if settings:
        said.append(_simulated(settings))
    return (f"<p><b>End-to-end latency</b> (pipeline/assembly/latency.py): the delay from a force at the instrument's "
            f"tip to the force at the participant's hand, and from the hand's motion to the tip's. {' '.join(said)} "
            "Peak forces suffer from delays of the order of 100 ms.</p>")
