"""Print a force-tracking study's ON/OFF sizes from its report's trials.csv: one value per participant per mode.

    python scripts/tracking_summary.py REPORT_DIR

The lag and the gain are force tracking's own metrics (protocol/metrics/definitions.py), columns of trials.csv but
not yet of the report's per-participant tables (docs/tracking.md, "What is not yet done"); this script averages each
participant's trials per mode first (no pseudo-replication), then gives the mean ± SD across participants, the
mean paired difference ON − OFF, how many participants moved in that direction, and the Wilcoxon signed-rank p.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd
from scipy.stats import wilcoxon

MEASURES = (("lag_s", "lag (s)"), ("rmse_N", "RMSE (N)"), ("max_ae_N", "Max AE (N)"), ("gain", "gain"),
            ("time_in_band_s", "time in band (s)"))


def main(argv: list[str]) -> int:
    if len(argv) != 1 or not (Path(argv[0]) / "trials.csv").is_file():
        print("usage: python scripts/tracking_summary.py REPORT_DIR (a folder with a force-tracking trials.csv)")
        return 2
    trials = pd.read_csv(Path(argv[0]) / "trials.csv")
    per = trials.groupby(["participant_code", "haptic_mode"])[[c for c, _ in MEASURES]].mean().unstack()
    print(f"{trials['participant_code'].nunique()} participants, {len(trials)} trials; per participant and mode "
          "(mean of its trials), then across participants:")
    print(f"  {'measure':18} {'haptics OFF':>15} {'haptics ON':>15} {'ON − OFF':>10} {'ON lower':>9} {'p':>7}")
    for col, label in MEASURES:
        off, on = per[(col, "off")], per[(col, "on")]
        d = on - off
        p = wilcoxon(on, off).pvalue if len(d) >= 2 and (d != 0).any() else float("nan")
        print(f"  {label:18} {off.mean():7.3f} ± {off.std():5.3f} {on.mean():7.3f} ± {on.std():5.3f} "
              f"{d.mean():+10.3f} {int((d < 0).sum()):>4}/{len(d):<4} {p:7.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
