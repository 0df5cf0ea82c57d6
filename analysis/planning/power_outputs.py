"""Power estimates written out: the files of ``haptic-study power`` and the section of ``report --power``.

Apart from :mod:`analysis.planning.power` (the estimate) because these draw
(:mod:`analysis.planning.power_figures`), which needs the estimate's names: the
estimate never imports its figures.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from analysis.planning import power_figures
from analysis.planning.paired_pool import pool_from_trials
from analysis.planning.power import PowerError, PowerResult, estimate_power
from analysis.planning.power_plan import summary_text
from analysis.reading import codebook
from analysis.reading.metrics import MetricOptions

__all__ = ["ReportPower", "power_csv", "report_section", "write_power"]


def power_csv(result: PowerResult, path: Path) -> None:
    """Write ``power.csv`` as the codebook describes it: the measures by their exported names (``rmse_N``, as in
    every other CSV, not the analysis' ``rmse_n``) and each number rounded as its column says (4 decimals)."""
    codebook.export(result.frame, "power.csv").to_csv(path, index=False)


def write_power(result: PowerResult, folder: str | os.PathLike[str]) -> list[str]:
    """Write ``power.csv``, ``power.txt`` (:func:`summary_text`) and ``power.png/.pdf/.svg`` into ``folder``.

    ``haptic-study power`` gives it the temporary folder of
    :func:`foundation.outdir.write_output_folder`, which moves the files into
    ``--out`` under the output-folder policy (marker, ``--force``, the pool kept).

    Returns
    -------
    list of str
        The file names written.
    """
    out = Path(folder)
    power_csv(result, out / "power.csv")
    (out / "power.txt").write_text(summary_text(result) + "\n", encoding="utf-8")
    fig = power_figures.power_curves(result)
    names = ["power.csv", "power.txt"]
    for ext in ("png", "pdf", "svg"):
        meta = {"Date": None} if ext == "svg" else {"CreationDate": None} if ext == "pdf" else {}
        fig.savefig(out / f"power.{ext}", format=ext, dpi=150, metadata=meta)
        names.append(f"power.{ext}")
    return names


@dataclass(frozen=True, slots=True)
class ReportPower:
    """The "what n would a study need?" section of ``report --power``.

    Attributes
    ----------
    result
        The estimate (None when it could not be made).
    notice
        Why it could not be made, in words ("" when it was).
    png
        The power-curve figure (None when not made).
    """

    result: PowerResult | None
    notice: str
    png: bytes | None


def report_section(trials: pd.DataFrame, options: MetricOptions, zero_method: str,
                   out_dir: str | os.PathLike[str]) -> ReportPower:
    """``report --power``: what n a study would need, resampling the reported study's own participants.

    Writes ``power.csv`` and ``figures/power.png`` / ``.svg`` into ``out_dir``
    with the defaults of ``haptic-study power`` (n = 6 … 30, 2000 resamples,
    α = 0.05, seed 0).

    Returns
    -------
    ReportPower
        The estimate and the figure; when the study cannot be resampled
        (fewer than :data:`MIN_PILOT` participants with both modes, ...), no
        estimate and the reason in words, for the page to show.
    """
    from analysis.plots.figures import save
    pool = pool_from_trials(trials, options, source="this study")
    try:
        result = estimate_power(pool, zero_method=zero_method)
    except PowerError as exc:
        return ReportPower(None, f"Not estimated: {exc}.", None)
    out = Path(out_dir)
    power_csv(result, out / "power.csv")
    return ReportPower(result, "", save(power_figures.power_curves(result), out / "figures", "power"))
