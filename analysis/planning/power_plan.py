"""A power estimate as a plan: the participants a study needs, in words (``power.txt``) and as the report's table.

:func:`smallest_n` reads :class:`analysis.planning.power.PowerResult`'s frame for the smallest n from which on a test
keeps its power; :func:`summary_text` and :func:`plan_table` give every test's, with and without Holm's correction
(a primary measure's and the family's; a secondary measure has none).
"""

from __future__ import annotations

import pandas as pd

from analysis.planning.power import DIRECTION_TEXT, FAMILY_ANY, PowerResult, holm_applies, is_family_row, metric_label

__all__ = ["plan_table", "smallest_n", "summary_text"]


def smallest_n(frame: pd.DataFrame, scope: str, metric: str, target: float, *,
               holm_adjusted: bool = False) -> int | None:
    """The smallest n tried from which on every larger n tried reaches ``target`` power (None: not reached).

    "From which on" rather than "the first n that reaches it": the discrete
    Wilcoxon test can make power dip between neighbouring n, and a plan needs
    an n that is not followed by a shortfall.
    """
    sel = frame[(frame["scope"] == scope) & (frame["metric"] == metric)].sort_values("n")
    col = "power_holm" if holm_adjusted else "power"
    ok = (sel[col].to_numpy() >= target)
    ns = sel["n"].to_numpy()
    best = None
    for i in range(len(ns) - 1, -1, -1):
        if not ok[i]:
            break
        best = int(ns[i])
    return best


def _reach(frame: pd.DataFrame, scope: str, metric: str, target: float, holm_adjusted: bool) -> str:
    n = smallest_n(frame, scope, metric, target, holm_adjusted=holm_adjusted)
    if n is not None:
        return f"n = {n}"
    last = frame[(frame["scope"] == scope) & (frame["metric"] == metric)].sort_values("n").iloc[-1]
    return f"> {int(last['n'])} ({last['power_holm' if holm_adjusted else 'power']:.0%})"


def summary_text(result: PowerResult) -> str:
    """The plan in words: per metric, the smallest n reaching 80 % and 90 % power, and the notes."""
    f = result.frame
    tct = "over successful trials" if result.options.tct_policy == "successful" else "failures counted at the trial cap"
    lines = [
        f"Source: {result.source}; {result.n_pool} participants with both haptic modes, resampled with replacement "
        f"({result.resamples} studies per n, seed {result.seed}).",
        f"Test: the report's paired Wilcoxon signed-rank test ON vs OFF per metric, two-sided, significant at "
        f"p < {result.alpha:g}; TCT {tct}; RMSE and Max AE from the "
        f"{'cue' if result.options.error_window == 'cue' else 'first contact'}; "
        f"zero differences: {result.zero_method}.",
        "Power: the probability that a study detects the effect in the direction this pool shows (a rejection "
        "counts only when the resampled study's effect lies on the pool's side); the two-sided rejection rate, "
        "which also counts significant effects the other way, is power_two_sided.",
        f"Intervals ({result.interval_level:.0%}, in power.csv and the figure) are the Monte Carlo error of the "
        f"resampling only, not the uncertainty of the {result.n_pool} participants' own effects: a plan from a "
        "small pilot is itself uncertain.",
        f"Participants needed: the smallest n of {', '.join(str(n) for n in result.n_values)} from which on power "
        f"stays at or above the target, for the test alone and with Holm across the {_family_word(f)} primary metrics "
        "(as the report's "
        "significance marks); '> N (x %)': not reached, x = power at the largest n tried.",
        f"  {'':<21s}{'80 % power':<28s}90 % power",
        f"  {'':<21s}{'test':<14s}{'with Holm':<14s}{'test':<14s}with Holm",
    ]
    for scope in dict.fromkeys(f["scope"]):
        if scope != "overall":
            lines.append(f"  within {scope}:")
        for metric in dict.fromkeys(f["metric"]):
            family = is_family_row(metric)
            cells = []
            for target in (0.8, 0.9):
                cells.append("" if family else _reach(f, scope, metric, target, False))
                cells.append(_reach(f, scope, metric, target, True) if holm_applies(metric) else "")
            name = metric_label(metric) if scope == "overall" else f"  {metric_label(metric)}"
            lines.append(f"  {name:<21s}" + "".join(f"{c:<14s}" for c in cells).rstrip())
    lines.append("Power at each n (overall; the two-sided rejection rate in brackets):")
    ns = list(result.n_values)
    lines.append(f"  {'':<21s}{'pool shows':<12s}" + "".join(f"{'n = ' + str(n):<14s}" for n in ns).rstrip())
    overall = f[f["scope"] == "overall"]
    for metric in dict.fromkeys(overall["metric"]):
        if is_family_row(metric):
            continue
        sel = overall[overall["metric"] == metric].set_index("n")
        direction = DIRECTION_TEXT[str(sel["direction"].iloc[0])]
        cells = [f"{sel.at[n, 'power']:.0%} ({sel.at[n, 'power_two_sided']:.0%})" for n in ns]
        lines.append(f"  {metric_label(metric):<21s}{direction:<12s}" + "".join(f"{c:<14s}" for c in cells).rstrip())
    last = max(result.n_values)
    under = [metric_label(m) for m in dict.fromkeys(f["metric"])
             if not is_family_row(m) and smallest_n(f, "overall", m, 0.8) is None]
    if under:
        lines.append(f"Under-powered: {', '.join(under)} do{'es' if len(under) == 1 else ''} not reach 80 % power "
                     f"by n = {last}: a study testing {'it' if len(under) == 1 else 'them'} needs more participants "
                     "(try a larger --n) or a more sensitive definition.")
    if result.notes:
        lines.append("Notes:")
        lines.extend(f"  - {n}" for n in result.notes)
    return "\n".join(lines)


def _family_word(frame: pd.DataFrame) -> str:
    """How many primary metrics the pool's Holm family has, in a word, as its family row names it (``four``)."""
    row = next((m for m in frame["metric"] if is_family_row(m) and m != FAMILY_ANY), "all_no_holm")
    return str(row).removeprefix("all_").removesuffix("_holm")


def plan_table(result: PowerResult) -> pd.DataFrame:
    """The plan as a table, one row per scope × metric (family rows included), for the report's page.

    Columns: ``scope``, ``metric``, ``direction``, ``n80``, ``n90``,
    ``n80_holm``, ``n90_holm`` (text: ``"12"``, ``"> 30 (64%)"`` when not
    reached, ``""`` where it does not apply) and ``power_n{n}`` per n tried
    (directional power, a fraction; NaN where it does not apply).
    """
    f = result.frame
    rows = []
    for scope in dict.fromkeys(f["scope"]):
        for metric in dict.fromkeys(f[f["scope"] == scope]["metric"]):
            family = is_family_row(metric)
            sel = f[(f["scope"] == scope) & (f["metric"] == metric)].set_index("n")
            row: dict[str, object] = {"scope": scope, "metric": metric, "direction": str(sel["direction"].iloc[0])}
            for target in (0.8, 0.9):
                key = f"n{round(target * 100)}"
                row[key] = "" if family else _reach(f, scope, metric, target, False).removeprefix("n = ")
                row[f"{key}_holm"] = (_reach(f, scope, metric, target, True).removeprefix("n = ")
                                      if holm_applies(metric) else "")
            for n in result.n_values:
                row[f"power_n{n}"] = float(sel.at[n, "power_holm" if family else "power"])
            rows.append(row)
    return pd.DataFrame(rows)
