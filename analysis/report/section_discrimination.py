"""Force discrimination's section of the report: the trials and the fits as tidy CSVs, their codebook, and one
psychometric-curve figure per participant (issue 43); the section of its kind (:mod:`analysis.report.task_sections`).

One row of ``discrimination_fits.csv`` per participant per reference (no pooling of trials across participants:
each JND is one participant's, from its own trials, :mod:`analysis.stats.psychometric`).  A simulated block adds each
participant's true Weber fraction and lapse rate, and whether the fitted interval holds the true value.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

from analysis.reading.errors import AnalysisError
from analysis.report.task_sections import SectionInput, SectionOutput
from analysis.stats.psychometric import PsychometricFit

if TYPE_CHECKING:
    from protocol.storage.trial_answers import TrialAnswer

__all__ = ["CODEBOOK", "SECTION", "BlockResult", "discrimination_body", "study_blocks", "write_discrimination"]

#: Every column of the two tables: (file, column, unit, meaning).
CODEBOOK: tuple[tuple[str, str, str, str], ...] = (
    ("discrimination_trials.csv", "participant", "", "participant number (1-based)"),
    ("discrimination_trials.csv", "target_label", "", "the reference's [[targets]] label"),
    ("discrimination_trials.csv", "reference_n", "N", "the reference at the hand (3 N·tanh(tip force / 7 N))"),
    ("discrimination_trials.csv", "trial", "", "the trial's index at its reference (0-based)"),
    ("discrimination_trials.csv", "delta_n", "N", "the comparison minus the reference, as QUEST+ chose it"),
    ("discrimination_trials.csv", "comparison_first", "", "1: the comparison was the first interval"),
    ("discrimination_trials.csv", "first_n", "N", "the force rendered over the first interval's plateau (mean)"),
    ("discrimination_trials.csv", "second_n", "N", "the force rendered over the second interval's plateau (mean)"),
    ("discrimination_trials.csv", "peak_n", "N", "the largest force rendered in the trial (≤ f_max)"),
    ("discrimination_trials.csv", "answer", "", "the interval answered as stronger (1 or 2)"),
    ("discrimination_trials.csv", "correct", "", "1: the answer named the comparison"),
    ("discrimination_fits.csv", "participant", "", "participant number (1-based)"),
    ("discrimination_fits.csv", "target_label", "", "the reference's [[targets]] label"),
    ("discrimination_fits.csv", "reference_n", "N", "the reference at the hand"),
    ("discrimination_fits.csv", "n_trials", "", "the participant's trials at the reference"),
    ("discrimination_fits.csv", "n_correct", "", "of which correct"),
    ("discrimination_fits.csv", "jnd_n", "N", "the JND: Δ at d′ = 1 (76 % correct without lapses), maximum "
                                              "likelihood"),
    ("discrimination_fits.csv", "jnd_lo_n", "N", "the JND's 95 % profile-likelihood interval, lower (empty: open)"),
    ("discrimination_fits.csv", "jnd_hi_n", "N", "the JND's 95 % profile-likelihood interval, upper (empty: open)"),
    ("discrimination_fits.csv", "weber", "", "the Weber fraction: JND / reference"),
    ("discrimination_fits.csv", "weber_lo", "", "its 95 % interval, lower"),
    ("discrimination_fits.csv", "weber_hi", "", "its 95 % interval, upper"),
    ("discrimination_fits.csv", "lapse", "", "the fitted lapse rate (bounded to 0–0.06)"),
    ("discrimination_fits.csv", "true_weber", "", "simulated: the participant's true Weber fraction"),
    ("discrimination_fits.csv", "true_lapse", "", "simulated: the participant's true lapse rate"),
    ("discrimination_fits.csv", "true_inside", "", "simulated: 1 if the true Weber fraction is within the interval"),
)
_DPI = 110
#: Trials are shown binned by Δ: this many log-spaced bins per reference.
_BINS = 8


@dataclass(frozen=True, slots=True)
class BlockResult:
    """One participant's block: its trials (rows of ``discrimination_trials.csv``), its fits by target label and,
    when simulated, its true Weber fraction and lapse rate."""

    participant: int
    trials: Sequence[Mapping[str, Any]]
    fits: Sequence[tuple[str, PsychometricFit]]
    true_weber: float | None = None
    true_lapse: float | None = None


def _fit_row(r: BlockResult, label: str, f: PsychometricFit) -> dict[str, Any]:
    w = r.true_weber
    inside = None if w is None else int(f.weber_lo <= w <= f.weber_hi)
    return {"participant": r.participant, "target_label": label, "reference_n": f.reference_n,
            "n_trials": f.n_trials, "n_correct": f.n_correct, "jnd_n": f.jnd_n, "jnd_lo_n": f.jnd_lo_n,
            "jnd_hi_n": f.jnd_hi_n, "weber": f.weber, "weber_lo": f.weber_lo, "weber_hi": f.weber_hi,
            "lapse": f.lapse, "true_weber": w, "true_lapse": r.true_lapse, "true_inside": inside}


def write_discrimination(results: Sequence[BlockResult], folder: Path) -> list[str]:
    """The tables, the codebook and the figures into ``folder`` (the output policy's temporary folder); the files
    written, relative to it."""
    trials = pd.DataFrame([dict(t) for r in results for t in r.trials])
    for col in ("comparison_first", "correct"):
        trials[col] = trials[col].astype(int)
    fits = pd.DataFrame([_fit_row(r, label, f) for r in results for label, f in r.fits])
    trials.to_csv(folder / "discrimination_trials.csv", index=False, float_format="%.6g")
    fits.to_csv(folder / "discrimination_fits.csv", index=False, float_format="%.6g")
    present = {("discrimination_trials.csv", c) for c in trials.columns} | {("discrimination_fits.csv", c)
                                                                          for c in fits.columns}
    pd.DataFrame([e for e in CODEBOOK if (e[0], e[1]) in present], columns=["file", "column", "unit", "meaning"]
                 ).to_csv(folder / "discrimination_codebook.csv", index=False)
    files = ["discrimination_trials.csv", "discrimination_fits.csv", "discrimination_codebook.csv"]
    (folder / "figures").mkdir(exist_ok=True)
    for r in results:
        name = f"figures/psychometric_P{r.participant:02d}.png"
        psychometric_figure(r).savefig(folder / name, format="png", dpi=_DPI)
        files.append(name)
    return files


def psychometric_figure(r: BlockResult) -> Figure:
    """One participant's psychometric curves, a panel per reference: the proportion correct of its trials binned by
    Δ (marker area ∝ trials), the fitted curve, the JND with its 95 % interval, and the true JND when simulated."""
    fig = Figure(figsize=(4.0 * len(r.fits), 3.2), dpi=_DPI)
    axes = fig.subplots(1, len(r.fits), squeeze=False)[0]
    for ax, (label, f) in zip(axes, r.fits, strict=True):
        mine = [t for t in r.trials if t["target_label"] == label]
        d = np.array([t["delta_n"] for t in mine], dtype=np.float64)
        c = np.array([t["correct"] for t in mine], dtype=np.float64)
        edges = np.geomspace(d.min() * 0.999, d.max() * 1.001, _BINS + 1)
        k = np.clip(np.searchsorted(edges, d, side="right") - 1, 0, _BINS - 1)
        for b in range(_BINS):
            if np.any(k == b):
                ax.scatter([math.sqrt(edges[b] * edges[b + 1])], [c[k == b].mean()], s=12 * np.sum(k == b),
                           color="0.35", alpha=0.6, zorder=3)
        x = np.geomspace(edges[0], max(edges[-1], f.jnd_n * 3.0), 200)
        ax.plot(x, f.curve(x), color="C0", label=f"fit: JND {f.jnd_n * 1000:.1f} mN, W {f.weber:.3f}")
        if math.isfinite(f.jnd_lo_n) and math.isfinite(f.jnd_hi_n):
            ax.axvspan(f.jnd_lo_n, f.jnd_hi_n, color="C0", alpha=0.12, label="JND 95 % interval")
        ax.axvline(f.jnd_n, color="C0", lw=0.8, ls="--")
        if r.true_weber is not None:
            ax.axvline(r.true_weber * f.reference_n, color="C3", lw=1.0, label=f"true JND (W {r.true_weber:.3f})")
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))  # (a decade holds one label alone)
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v * 1000:g}"))
        ax.xaxis.set_minor_formatter(NullFormatter())  # (log minor labels overlap at this width)
        ax.set_ylim(0.4, 1.02)
        ax.set_xlabel("Δ at the hand (mN)")
        ax.set_ylabel("proportion correct")
        ax.set_title(f"P{r.participant:02d} {label}: reference {f.reference_n:.3f} N, {f.n_trials} trials",
                     fontsize=9)
        ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    return fig


def study_blocks(databases: Sequence[str], sessions: Collection[tuple[str, int]] | None = None) -> list[BlockResult]:
    """Each participant's answered experiment trials read from the study databases (``trial_answers`` beside
    ``trials``: aborted trials and trials without an answer left out) and fitted per reference; only the
    ``sessions`` given as (database, session id), when given."""
    from analysis.stats.psychometric import fit_psychometric
    from protocol.storage.schema import connect_readonly
    from protocol.storage.trial_answers import answered_sessions

    out: list[BlockResult] = []
    for db in databases:
        conn = connect_readonly(db)
        try:
            answered = answered_sessions(conn)
        finally:
            conn.close()
        for session in answered:
            if sessions is not None and (str(db), session.session_id) not in sessions:
                continue
            rows = [_answer_row(session.participant_number, label, a) for label, a in session.answers
                    if a.answer is not None]
            refs = dict.fromkeys((str(r["target_label"]), float(r["reference_n"])) for r in rows)
            fits = [(label, fit_psychometric(ref, [float(r["delta_n"]) for r in rows if r["target_label"] == label],
                                             [bool(r["correct"]) for r in rows if r["target_label"] == label]))
                    for label, ref in refs]
            fits.sort(key=lambda lf: lf[1].reference_n)  # the references from the lightest
            if fits:
                out.append(BlockResult(session.participant_number, rows, fits))
    return out


def _answer_row(participant: int, label: str, a: TrialAnswer) -> dict[str, Any]:
    """One answered trial as a row of ``discrimination_trials.csv`` (from a study database: no ``peak_n``)."""
    v = a.values
    return {"participant": participant, "target_label": label, "reference_n": v["reference_n"],
            "trial": a.trial_index, "delta_n": v["delta_n"], "comparison_first": int(v["comparison_first"]),
            "first_n": v["felt_first_n"], "second_n": v["felt_second_n"], "answer": int(str(a.answer)),
            "correct": int(v["correct"])}


def discrimination_body(results: Sequence[BlockResult], files: Sequence[str], methods: str) -> str:
    """The section's HTML below its heading: the methods, a row per participant and reference (JND and Weber
    fraction with their 95 % intervals) and each participant's psychometric figure (``files``: the figures')."""
    import html

    def cell(v: float, fmt: str) -> str:
        return format(v, fmt) if math.isfinite(v) else "open"

    rows = "".join(
        f"<tr><td>P{r.participant:02d}</td><td>{html.escape(label)}</td><td>{f.reference_n:.3f}</td>"
        f"<td>{f.n_trials}</td><td>{f.jnd_n * 1000:.1f} [{cell(f.jnd_lo_n * 1000, '.1f')}, "
        f"{cell(f.jnd_hi_n * 1000, '.1f')}]</td><td>{f.weber:.3f} [{cell(f.weber_lo, '.3f')}, "
        f"{cell(f.weber_hi, '.3f')}]</td><td>{f.lapse:.3f}</td></tr>"
        for r in results for label, f in r.fits)
    figures = "".join(f'<figure><img src="{n}" alt="psychometric curves, {n[-7:-4]}"></figure>'
                      for n in files if n.startswith("figures/"))
    return (f"<p>{html.escape(methods)}</p>"
            "<p>One row per participant and reference, from that participant's answered trials only (no pooling "
            "across participants); trials without an answer and aborted trials are left out.</p>"
            "<table border='1' cellspacing='0' cellpadding='3'><tr><th>participant</th><th>reference</th>"
            "<th>reference (N)</th><th>trials</th><th>JND (mN) [95 %]</th><th>Weber fraction [95 %]</th>"
            f"<th>lapse</th></tr>{rows}</table><h3>Psychometric curves</h3>{figures}"
            "<p>Files: discrimination_trials.csv, discrimination_fits.csv, discrimination_codebook.csv.</p>")


def _line(r: BlockResult) -> str:
    """What the ``report`` command prints of one participant."""
    return f"P{r.participant:02d}  " + "  ".join(
        f"{label} JND {f.jnd_n * 1000:.1f} mN, W {f.weber:.3f} [{f.weber_lo:.3f}, {f.weber_hi:.3f}]"
        for label, f in r.fits)


@dataclass(frozen=True, slots=True)
class _Discrimination:
    """The section (:class:`analysis.report.task_sections.TaskSection`) of force discrimination."""

    kinds: tuple[str, ...] = ("force_discrimination",)

    def build(self, given: SectionInput, folder: Path) -> SectionOutput:
        """Each participant's fits from its sessions' answered trials: the tables, codebook, figures and HTML."""
        results = study_blocks(given.study.databases, given.keys)
        if not results:
            raise AnalysisError(f"{', '.join(given.study.databases)}: no answered discrimination trial to report")
        tasks = given.tasks
        methods = type(tasks[0]).methods(tasks, sorted(set(given.sessions["max_trial_s"])))
        files = write_discrimination(results, folder)
        return SectionOutput("Force discrimination", discrimination_body(results, files, methods),
                             files=tuple(files), lines=tuple(_line(r) for r in results))


#: The section of force discrimination's kind.
SECTION = _Discrimination()
