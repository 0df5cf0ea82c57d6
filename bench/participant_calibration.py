"""Calibrate the simulated participant: whole simulated 10-participant studies, no database.

``python -m bench.participant_calibration --studies 5``

For every participant of every study this builds the simulated rig on a
virtual clock, hands the stylus to a :class:`pipeline.sim.participant.SimulatedParticipant`
and walks the paper's 20-trial random schedule through the real
:class:`protocol.trial.TrialMachine` (so success, TCT, RMSE and Max AE come from
the one definition in :mod:`protocol.metrics`).  Per participant × mode it
aggregates like science.md §6 (success over 10 trials, mean RMSE and Max AE
over trials, mean TCT over successful trials) and prints, per study and as the
mean over studies, the OFF/ON values, the change, the paper's values and the
Wilcoxon signed-rank p of the 10 paired differences, plus the per-target
success rates and TCT with failures censored at 12 s.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing as mp
import statistics
import sys
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.runtime.engine import EngineConfig, build_sim_engine
from pipeline.runtime.loop_messages import AllowBiasRefinement, Mark, SetHaptics
from pipeline.sim.participant import SimulatedParticipant
from pipeline.sim.participant_params import ParticipantParams
from pipeline.sim.rig import SimRigConfig
from protocol.config import ProtocolConfig, default_protocol
from protocol.design import build_schedule
from protocol.trial import PhaseChanged, TrialFinished, TrialMachine, TrialPhase

__all__ = [
    "PAPER", "TrialRow", "driver_cost_us", "format_table", "main", "participant_seeds", "run_participant", "run_study",
    "summarise_study",
]

#: The paper's results (§V-B): OFF, ON.  TCT is only given as a change (−16 %).
PAPER: dict[str, tuple[float | None, float | None]] = {
    "success": (0.27, 0.54),
    "rmse_n": (1.35, 0.86),
    "max_ae_n": (2.12, 1.46),
    "tct_s": (None, None),
}
PAPER_CHANGE = {"success": "x2.0", "rmse_n": "-36 %", "max_ae_n": "-31 %", "tct_s": "-16 %", "tct_cens_s": "n/a"}

_BLOCK_TICKS = 20
_PHASE_ACTIVE = 2
_PHASE_PAUSE = 3


@dataclass(frozen=True, slots=True)
class TrialRow:
    """One trial's outcome."""

    study: int
    participant: int
    index: int
    target: str
    mode: str
    success: bool
    tct_s: float | None
    rmse_n: float
    max_ae_n: float
    peak_n: float


def participant_seeds(study: int, participant: int) -> tuple[int, int, int]:
    """(rig seed, participant seed, schedule seed) of participant ``participant`` (1-based) of ``study``."""
    return 10_000 * study + participant, 1_000_003 * (study + 1) + 7919 * participant, study


def run_participant(study: int, participant: int, protocol: ProtocolConfig | None = None) -> list[TrialRow]:
    """Run one simulated participant through the full schedule; return the trial rows."""
    proto = protocol or default_protocol()
    rig_seed, p_seed, sched_seed = participant_seeds(study, participant)
    eng = build_sim_engine(EngineConfig(clock="virtual", driver="hold", sim=SimRigConfig(seed=rig_seed)))
    loop, ring = eng.loop, eng.ring
    assert ring is not None
    p = SimulatedParticipant(seed=p_seed, tissue=eng.rig.config.tissue, arm=eng.rig.config.arm,
                             motion_scale=eng.rig.config.motion_scale)
    eng.rig.set_driver(p)
    schedule = build_schedule(proto, sched_seed, participant)
    machine = TrialMachine(proto.trial)
    loop.submit(SetHaptics(False))
    loop.run_ticks(200)  # settle on the start pose
    cursor = ring.write_count
    rows: list[TrialRow] = []
    for spec in schedule:
        on = spec.haptic_mode == "on"
        now_ns = eng.clock.now_ns()
        machine.start(spec, now_ns)
        loop.submit(AllowBiasRefinement(False))
        loop.submit(SetHaptics(on))
        loop.submit(Mark(spec.index, _PHASE_ACTIVE))
        p.begin_trial(spec.target_force_n, on, eng.rig.sim_time_s)
        idle = False
        while not idle:
            loop.run_ticks(_BLOCK_TICKS)
            res = ring.read_since(cursor)
            cursor = res.cursor
            r = res.rows
            t_ns = [int(round(x * 1e9)) for x in r["t_s"].tolist()]
            samples = zip(t_ns, r["force_n"].tolist(), [int(x) for x in r["trial_index"].tolist()], strict=True)
            for ev in machine.feed(samples):
                if isinstance(ev, TrialFinished):
                    m = ev.metrics
                    rows.append(TrialRow(study, participant, spec.index, spec.target_label, spec.haptic_mode,
                                         m.success, m.tct_s, m.rmse_n, m.max_ae_n, m.peak_force_n))
                    p.end_trial(eng.rig.sim_time_s)
                    loop.submit(Mark(-1, _PHASE_PAUSE))
                    loop.submit(SetHaptics(False))
                    loop.submit(AllowBiasRefinement(True))
                elif isinstance(ev, PhaseChanged) and ev.new is TrialPhase.IDLE:
                    idle = True
    eng.rig.close()
    ring.close()
    return rows


def _run_participant_args(args: tuple[int, int]) -> list[TrialRow]:
    return run_participant(*args)


def run_study(study: int, participants: int = 10, jobs: int = 1) -> list[TrialRow]:
    """All participants of one study."""
    work = [(study, j) for j in range(1, participants + 1)]
    if jobs > 1:
        with mp.get_context("spawn").Pool(jobs) as pool:
            parts = pool.map(_run_participant_args, work)
    else:
        parts = [_run_participant_args(w) for w in work]
    return [r for part in parts for r in part]


def _wilcoxon_p(off: list[float], on: list[float]) -> float:
    """Two-sided Wilcoxon signed-rank p of the paired differences (NaN when undefined)."""
    from scipy.stats import wilcoxon

    d = [round(a - b, 12) for a, b in zip(off, on, strict=True) if not (math.isnan(a) or math.isnan(b))]
    if len(d) < 2 or all(x == 0 for x in d):
        return math.nan
    try:
        return float(wilcoxon(d).pvalue)
    except ValueError:
        return math.nan


def summarise_study(rows: list[TrialRow], max_trial_s: float = 12.0) -> dict[str, Any]:
    """Per participant × mode aggregates (science.md §6), group means, changes and Wilcoxon p."""
    parts = sorted({r.participant for r in rows})
    per: dict[str, dict[str, list[float]]] = {m: {} for m in ("off", "on")}
    for mode in ("off", "on"):
        agg: dict[str, list[float]] = {k: [] for k in ("success", "rmse_n", "max_ae_n", "tct_s", "tct_cens_s",
                                                        "success_GENTLE", "success_FIRM")}
        for pid in parts:
            mine = [r for r in rows if r.participant == pid and r.mode == mode]
            agg["success"].append(sum(r.success for r in mine) / len(mine))
            agg["rmse_n"].append(statistics.fmean(r.rmse_n for r in mine))
            agg["max_ae_n"].append(statistics.fmean(r.max_ae_n for r in mine))
            tcts = [r.tct_s for r in mine if r.success and r.tct_s is not None]
            agg["tct_s"].append(statistics.fmean(tcts) if tcts else math.nan)
            agg["tct_cens_s"].append(statistics.fmean(r.tct_s if r.success else max_trial_s  # type: ignore[misc]  # a success has its TCT
                                                      for r in mine))
            for lab in ("GENTLE", "FIRM"):
                sub = [r for r in mine if r.target == lab]
                agg[f"success_{lab}"].append(sum(r.success for r in sub) / len(sub) if sub else math.nan)
        per[mode] = agg
    out: dict[str, Any] = {"n_participants": len(parts)}
    for key in ("success", "rmse_n", "max_ae_n", "tct_s", "tct_cens_s", "success_GENTLE", "success_FIRM"):
        off, on = per["off"][key], per["on"][key]
        m_off = float(np.nanmean(off)) if not all(math.isnan(x) for x in off) else math.nan
        m_on = float(np.nanmean(on)) if not all(math.isnan(x) for x in on) else math.nan
        out[key] = {
            "off": m_off,
            "on": m_on,
            "change": (m_on / m_off - 1.0) if m_off else math.nan,
            "p": _wilcoxon_p(off, on),
            "n_pairs": sum(1 for a, b in zip(off, on, strict=True) if not (math.isnan(a) or math.isnan(b))),
        }
    return out


_LABELS = {
    "success": "success",
    "rmse_n": "RMSE (N)",
    "max_ae_n": "Max AE (N)",
    "tct_s": "TCT (s), successes",
    "tct_cens_s": "TCT (s), fail=12 s",
    "success_GENTLE": "success GENTLE",
    "success_FIRM": "success FIRM",
}


def _spread(values: list[float]) -> str:
    v = [x for x in values if not math.isnan(x)]
    if not v:
        return "n/a"
    if len(v) == 1:
        return f"{v[0]:.3g}"
    return f"{statistics.fmean(v):.3g} ±{statistics.stdev(v):.2g} [{min(v):.3g}–{max(v):.3g}]"


def format_table(summaries: list[dict[str, Any]]) -> str:
    """The calibration table: mean ± SD [min–max] over studies."""
    lines = [
        f"{'metric':22s} | {'sim OFF':26s} | {'sim ON':26s} | {'change':26s} | {'paper':16s} | p<0.05 (median p)",
        "-" * 150,
    ]
    for key, label in _LABELS.items():
        off = [s[key]["off"] for s in summaries]
        on = [s[key]["on"] for s in summaries]
        ch = [s[key]["change"] * 100.0 for s in summaries]
        ps = [s[key]["p"] for s in summaries]
        psig = [x for x in ps if not math.isnan(x)]
        sig = f"{sum(x < 0.05 for x in psig)}/{len(ps)} ({statistics.median(psig):.3f})" if psig else "n/a"
        paper = PAPER.get(key)
        ptxt = f"{paper[0]} → {paper[1]} " if paper and paper[0] is not None else ""
        ptxt += PAPER_CHANGE.get(key, "")
        ch_txt = _spread(ch) + " %" if key != "success" and not key.startswith("success_") else (
            "x" + _spread([s[key]["on"] / s[key]["off"] if s[key]["off"] else math.nan for s in summaries]))
        lines.append(f"{label:22s} | {_spread(off):26s} | {_spread(on):26s} | {ch_txt:26s} | {ptxt:16s} | {sig}")
    return "\n".join(lines)


def _constants() -> dict[str, float]:
    """The participant model's fixed constants (its defaults; the drawn ones are in PARAM_RANGES)."""
    import dataclasses

    return {f.name: f.default for f in dataclasses.fields(ParticipantParams) if f.default is not dataclasses.MISSING}


def driver_cost_us(seconds: float = 12.0, repeats: int = 5) -> float:
    """Mean cost of :meth:`SimulatedParticipant.equilibrium_y` per call, µs (best of ``repeats``).

    Observations of one FIRM trial with feedback are recorded from a simple closed loop
    (tip lag 30 ms, Hunt–Crossley tissue, scaled felt force) and replayed to a fresh
    participant with the same seed, so the replay takes the same decisions.
    """
    from pipeline.force.scaling import scale_magnitude
    from pipeline.sim.hand import HandObservation

    def fresh() -> SimulatedParticipant:
        q = SimulatedParticipant(seed=1)
        q.begin_trial(1.2, True, 0.0)
        return q

    p = fresh()
    obs = []
    tip = 0.0
    n = int(seconds * 1000)
    for i in range(n):
        depth = -0.015 - tip
        ind = depth if depth > 0 else 0.0
        felt = scale_magnitude(1.1e4 * ind**1.5)
        o = HandObservation(i * 1e-3, tip, felt, ind, -depth if depth < 0 else 0.0)
        obs.append(o)
        tip += (p.equilibrium_y(o) + felt / 500.0 - tip) * (1.0 - math.exp(-1e-3 / 0.03))
    best = math.inf
    for _ in range(repeats):
        f = fresh().equilibrium_y
        t0 = time.perf_counter()
        for o in obs:
            f(o)
        best = min(best, time.perf_counter() - t0)
    return best / n * 1e6


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--studies", type=int, default=5, help="number of simulated studies (different seeds)")
    ap.add_argument("--participants", type=int, default=10, help="participants per study")
    ap.add_argument("--first-study", type=int, default=0, help="seed index of the first study")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes (participants in parallel)")
    ap.add_argument("--quiet", action="store_true", help="only the final table")
    args = ap.parse_args(argv)
    summaries = []
    t_total = time.perf_counter()
    for k in range(args.first_study, args.first_study + args.studies):
        t0 = time.perf_counter()
        rows = run_study(k, args.participants, args.jobs)
        wall = time.perf_counter() - t0
        s = summarise_study(rows)
        summaries.append(s)
        if not args.quiet:
            print(f"\n== study {k}: {args.participants} participants, {len(rows)} trials, {wall:.1f} s wall ==")
            print(format_table([s]))
            sys.stdout.flush()
    print(f"\n== mean ± SD [min–max] over {len(summaries)} studies "
          f"({time.perf_counter() - t_total:.0f} s wall, jobs={args.jobs}) ==")
    print(format_table(summaries))
    print("\nfixed model constants:", _constants())
    print(f"equilibrium_y cost: {driver_cost_us():.2f} µs per call (replayed observations, this machine, now)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
