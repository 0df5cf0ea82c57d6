"""``haptic-study sim``: run the simulated rig with scripted presses and summarise what the pipeline saw."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from pipeline.assembly.engine import EngineConfig, build_sim_engine
from pipeline.assembly.sim_config import sim_rig_config
from pipeline.core.clock import prepare_realtime_thread
from pipeline.devices.interfaces import Fault

__all__ = ["format_summary", "run_scripted_sim"]

#: True contact force above which the tip counts as touching, N.
_CONTACT_N = 0.05


def run_scripted_sim(
    seconds: float = 60.0,
    seed: int = 0,
    clock: str = "virtual",
    haptics_on: bool = True,
    progress: Callable[[float], None] | None = None,
) -> dict[str, Any]:
    """Run the rig for ``seconds`` and return a JSON-ready summary.

    The records are read from the ring buffer in chunks as the run proceeds,
    exactly as a second process (the GUI) would read them.
    """
    wall0 = time.perf_counter()
    eng = build_sim_engine(
        EngineConfig(sim=sim_rig_config(seed), clock=clock, haptics_on=haptics_on, ring_seconds=10.0)
    )
    loop, ring = eng.loop, eng.ring
    assert ring is not None
    total = int(round(seconds * 1000))
    chunk = 1000
    cols = ("t_s", "force_n", "true_fz", "render_fx", "render_fy", "render_fz", "faults", "gain")
    parts: dict[str, list[np.ndarray]] = {c: [] for c in cols}
    cursor = 0
    lost = 0

    def read() -> None:
        nonlocal cursor, lost
        res = ring.read_since(cursor)
        cursor, lost = res.cursor, lost + res.lost
        for c in cols:
            parts[c].append(np.asarray(res.rows[c]))
        if progress is not None:
            progress(min(cursor, total) / 1000.0)

    try:
        if clock == "virtual":
            done = 0
            while done < total:
                n = min(chunk, total - done)
                loop.run_ticks(n)
                done += n
                read()
        else:
            # one uninterrupted run on its own real-time thread (a run ramps the force down when it
            # ends, so it must not be cut into chunks); this thread reads the ring as a GUI would
            failed: list[BaseException] = []

            def run() -> None:
                prepare_realtime_thread()
                try:
                    loop.run(max_ticks=total)
                except BaseException as exc:  # re-raised in the caller's thread
                    failed.append(exc)

            worker = threading.Thread(target=run, name="haptic-loop", daemon=True)
            worker.start()
            while worker.is_alive():
                worker.join(0.1)
                read()
            read()
            if failed:
                raise failed[0]
    finally:
        loop.ramp_down()
        eng.rig.close()
    wall = time.perf_counter() - wall0
    d = {c: np.concatenate(parts[c]) for c in cols}
    ring.close()
    return _summarise(d, eng, seconds, wall, lost, clock, haptics_on, seed, loop.stats.summary())


def _contacts(true_f: np.ndarray) -> list[tuple[int, int]]:
    on = np.flatnonzero(np.diff(np.concatenate(([0], (true_f > _CONTACT_N).astype(np.int8), [0]))))
    return list(zip(on[::2].tolist(), on[1::2].tolist(), strict=True))


def _summarise(
    d: dict[str, np.ndarray], eng: Any, seconds: float, wall: float, lost: int, clock: str, haptics_on: bool,
    seed: int, stats: dict[str, float],
) -> dict[str, Any]:
    cal = eng.calibration
    true_f = np.abs(d["true_fz"])
    force = d["force_n"]
    render = np.sqrt(d["render_fx"] ** 2 + d["render_fy"] ** 2 + d["render_fz"] ** 2)
    contacts = _contacts(true_f)
    in_contact = true_f > _CONTACT_N
    # rest: well away from any contact (the filter's memory and the tissue's release)
    # (the centre of the full convolution, as mode="same" gives it for runs longer than the window: shorter ones too)
    far = np.convolve(in_contact.astype(float), np.ones(201), mode="full")[100:100 + len(in_contact)] == 0
    peaks = [(float(true_f[a:b].max()), float(force[a:b].max())) for a, b in contacts]
    faults = int(np.bitwise_or.reduce(d["faults"])) if len(d["faults"]) else 0
    out: dict[str, Any] = {
        "seed": seed,
        "seconds": seconds,
        "clock": clock,
        "haptics": "on" if haptics_on else "off",
        "calibration": {
            "model": cal.model,
            "mass_kg": cal.mass_kg,
            "com_mm": [1000.0 * v for v in cal.com_m],
            "condition_number": cal.condition_number,
            "rms_force_residual_n": cal.rms_force_residual_n,
            "mount_angle_deg": cal.mount_angle_deg,
        },
        "contacts": len(contacts),
        "peak_true_force_n": max((p[0] for p in peaks), default=0.0),
        "peak_error_n": max((abs(p[1] - p[0]) for p in peaks), default=0.0),
        "contact_rms_error_n": (float(np.sqrt(np.mean((force - true_f)[in_contact] ** 2))) if in_contact.any()
                                else math.nan),
        "rest_rms_force_n": float(np.sqrt(np.mean(force[far] ** 2))) if far.any() else math.nan,
        "max_render_n": float(render.max()) if len(render) else 0.0,
        "faults": Fault(faults).describe(),
        "ticks": int(stats["ticks"]) + 1,
        "lost_records": lost,
        "wall_s": wall,
        "speed_x_real_time": seconds / wall if wall > 0 else math.inf,
    }
    if clock == "real":
        out["loop"] = stats
    return out


def format_summary(s: dict[str, Any]) -> str:
    """One screen of text."""
    c = s["calibration"]
    com = ", ".join(f"{v:.1f}" for v in c["com_mm"])
    lines = [
        f"Simulated rig: seed {s['seed']}, {s['seconds']:g} s on the {s['clock']} clock, "
        f"haptic feedback {s['haptics']}",
        f"Calibration ({c['model']} model, 24 poses): m = {c['mass_kg']:.4f} kg, c = ({com}) mm, "
        f"cond {c['condition_number']:.1f}, residual {1000 * c['rms_force_residual_n']:.1f} mN RMS, "
        f"mount {c['mount_angle_deg']:.2f}°",
        f"Contacts: {s['contacts']} press{'' if s['contacts'] == 1 else 'es'}, peak tissue force "
        f"{s['peak_true_force_n']:.3f} N",
        f"Compensated + filtered force vs true contact force: RMS error {s['contact_rms_error_n']:.4f} N in contact, "
        f"{s['rest_rms_force_n']:.4f} N at rest; worst peak error {s['peak_error_n']:.3f} N",
        f"Rendered force: max {s['max_render_n']:.3f} N (f_max 3 N, Touch peak 3.3 N)",
        f"Faults: {s['faults']}; records lost by the reader: {s['lost_records']}",
    ]
    if "loop" in s:
        lp = s["loop"]
        lines.append(
            f"Loop: p50 {lp['period_p50_us']:.0f} µs, p99 {lp['period_p99_us']:.0f} µs, "
            f"{lp['periods_over_2ms']:.0f} periods over 2 ms"
        )
    lines.append(f"{s['ticks']} ticks in {s['wall_s']:.1f} s of wall time ({s['speed_x_real_time']:.1f}x real time)")
    return "\n".join(lines)
