"""Sites pooled into one study: the ON-vs-OFF tests within each site, and whether the effect differs between sites.

A multi-site study pools its participants into the report's tests (every participant one pair); a reviewer then
asks whether the sites agree.  :func:`site_tests` answers per site with the report's own tests (paired Wilcoxon,
Holm across the primary measures within the site) and :func:`site_differences` per measure with a Kruskal–Wallis
test (:func:`scipy.stats.kruskal`) of the participants' differences ON − OFF between sites: does the effect of
feedback depend on the site?  The models have a fixed effect per site (:func:`analysis.stats.models.site_terms`).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from analysis.stats.aggregate import TESTED_METRICS, by_mode, mode_tests

__all__ = ["SITE_DIFFERENCE_COLUMNS", "site_differences", "site_of", "site_tests", "sites_in"]

#: The columns of :func:`site_differences`.
SITE_DIFFERENCE_COLUMNS = ("metric", "n_sites", "n_participants", "medians_by_site", "h_statistic", "df", "p_value",
                           "computable", "note")


def sites_in(trials: pd.DataFrame) -> list[str]:
    """The named sites of the analysed trials, in order of first appearance (empty: no sites named)."""
    if "site" not in trials.columns:
        return []
    return [s for s in dict.fromkeys(str(v) for v in trials["site"]) if s]


def site_of(trials: pd.DataFrame) -> pd.Series:
    """Each participant's site, by participant code."""
    return trials.drop_duplicates("participant_code").set_index("participant_code")["site"].astype(str)


def site_tests(per_part: pd.DataFrame, trials: pd.DataFrame, *, zero_method: str = "wilcox",
               confidence: float = 0.95) -> pd.DataFrame:
    """The ON-vs-OFF tests within each site (:func:`analysis.stats.aggregate.mode_tests`), a ``site`` column first."""
    where = site_of(trials)
    frames = []
    for site in sites_in(trials):
        mine = per_part[per_part["participant_code"].map(where) == site]
        _, frame = mode_tests(mine, zero_method=zero_method, confidence=confidence)
        frame.insert(0, "site", site)
        frames.append(frame)
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def site_differences(per_part: pd.DataFrame, trials: pd.DataFrame) -> pd.DataFrame:
    """Per tested measure, the Kruskal–Wallis test of the participants' ON − OFF differences between sites."""
    from scipy.stats import kruskal

    where = site_of(trials)
    sites = sites_in(trials)
    rows = []
    for m in (name for name in TESTED_METRICS if name in per_part.columns):
        wide = by_mode(per_part, m)
        diff = (wide["on"] - wide["off"]).dropna()
        groups = [diff[diff.index.map(where) == s].to_numpy(float) for s in sites]
        medians = "; ".join(f"{s}: {np.median(g):.4g} (n = {len(g)})" if len(g) else f"{s}: none"
                            for s, g in zip(sites, groups, strict=True))
        row = {"metric": m, "n_sites": len(sites), "n_participants": int(sum(len(g) for g in groups)),
               "medians_by_site": medians, "h_statistic": math.nan, "df": len(sites) - 1, "p_value": math.nan,
               "computable": False, "note": ""}
        if len(sites) < 2 or any(len(g) < 2 for g in groups):
            row["note"] = "not tested: each site needs at least two participants with both modes"
        elif np.ptp(np.concatenate(groups)) == 0:
            row["note"] = "not tested: every participant has the same ON − OFF difference"
        else:
            res = kruskal(*groups)
            row.update(h_statistic=float(res.statistic), p_value=float(res.pvalue), computable=True)
        rows.append(row)
    return pd.DataFrame(rows, columns=list(SITE_DIFFERENCE_COLUMNS))
