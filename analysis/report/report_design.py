"""report.html's account of the design as run: the training the participants had, and the sites pooled.

* :func:`training_methods` -- the methods' sentence on training: what the paper says ("Prior to the experiment,
  users received training in both modes ..."), what this study's training was (each mode in turn, each target
  once, a trial ending at a completed hold or at the cap, the live force aid or not: from the stored protocol and
  the training sessions), and which of it is this tool's choice (the paper gives no duration and no live aid);
* :func:`sites_methods` and :func:`sites_html` -- a study pooled from several sites (``report --site``): each site's
  databases, seeds, protocol and participants, the re-coding, the site term in the models, the tests within each
  site and the test of whether the effect differs between them.

Nothing here computes a statistic.
"""

from __future__ import annotations

import html
import os
from typing import Any

import numpy as np
import pandas as pd

from analysis.reading.load import StudyData
from analysis.report.html_parts import fmt, fmt_p, html_table, plural
from protocol.study.feedback import FEEDBACK_EVENT

__all__ = ["sites_html", "sites_methods", "training_methods"]

_PAPER = ("The paper says only: \u201cPrior to the experiment, users received training in both modes to internalize "
          "how these forces felt haptically and appeared visually\u201d; it gives no duration and no live aid.")


def _one(values: Any, unit: str = "") -> str:
    vals = sorted({float(v) for v in values if pd.notna(v)})
    return " / ".join(f"{v:g}{unit}" for v in vals) if vals else "not stored"


def feedback_methods(study: StudyData) -> str:
    """The methods' sentence on feedback to the trainee ("" when no score card was shown): an intervention."""
    ev = study.events
    cards = ev[ev["kind"] == FEEDBACK_EVENT] if not ev.empty else ev
    if cards.empty:
        return ""
    kinds = study.sessions.set_index(["database", "session_id"])["kind"]
    sessions = cards[["database", "session_id"]].drop_duplicates()
    where = sorted({str(kinds.get((db, sid), "")) for db, sid in zip(sessions["database"], sessions["session_id"],
                                                                      strict=True)} - {""})
    return (f"<p><b>Feedback to the trainee.</b> An intervention the protocol allowed (its <code>[feedback]</code>): "
            "after each block of one haptic mode the participant screen showed a score card -- the block's primary "
            "measures against the participant's own earlier sessions with the same mode, and whether each was "
            f"better -- before the next cue. {plural(len(cards), 'card')} {'was' if len(cards) == 1 else 'were'} "
            f"shown in {plural(len(sessions), 'session')} ({' and '.join(where)}; events of kind feedback, each "
            "with its card). Measures taken after a card are taken with that feedback.</p>")


def training_methods(study: StudyData) -> str:
    """The methods' sentence on training, as run (module docstring)."""
    s = study.sessions
    exp = s[s["kind"] == "experiment"]
    training = s[s["kind"] == "training"]
    t = study.trials[study.trials["session_kind"] == "training"]
    if training.empty:
        asked = bool(exp.get("training_enabled", pd.Series(dtype=bool)).any())
        return (f"<p><b>Training.</b> {_PAPER} In this study no participant had a training session"
                f"{' although the protocol asks for one (see the deviations)' if asked else ' (the protocol has none)'}"
                ".</p>")
    live = bool(training.get("training_live_aid", pd.Series(dtype=bool)).all())
    partly = bool(training.get("training_live_aid", pd.Series(dtype=bool)).any())
    aid = ("with a live force gauge and the target band on the participant's screen (the live force aid; never in "
           "an experiment session)" if live else
           "with the live force aid in some sessions only (sessions.csv, live_force_aid)" if partly else
           "without a live force aid (the participant saw what an experiment trial shows)")
    length = (t["ended_at_s"] - t["started_at_s"]).to_numpy(float)
    ok = int((t["outcome"] == "success").sum())
    per = training["participant_code"].nunique()
    required = "required before the experiment" if bool(exp.get("training_required", pd.Series(dtype=bool)).all()) \
        else "not required before the experiment"
    held = "hold_s" in training.columns  # a task whose trial ends at a completed hold (force regulation's)
    spread = (f"; a training trial lasted {np.median(length):.1f} s in the median ({length.min():.1f}–"
              f"{length.max():.1f} s)" + (f", {ok} of {len(t)} ended in a completed hold" if held else "")
              if len(t) else "")
    end = f"a completed {_one(training['hold_s'], ' s')} hold" if held else "the end of its target's course"
    return (f"<p><b>Training.</b> {_PAPER} This study's training (this tool's choices, from the stored protocol): "
            f"one training session per participant, {required}: each haptic mode in turn, each target once, a "
            f"trial ending at {end} or at a cap of "
            f"{_one(training['max_trial_s'], ' s')} per target and mode, {aid}. "
            f"{plural(len(training), 'training session')} of {plural(per, 'participant')} were run "
            f"({plural(len(t), 'trial')}{spread}); they are not analysed (sessions.csv lists each, with its trials, "
            "successes and time trained).</p>")


def _site_rows(study: StudyData) -> list[str]:
    s = study.sessions
    out = []
    for site in dict.fromkeys(study.sites):
        mine = s[(s["site"] == site) & s["analysed"].astype(bool)]
        dbs = ", ".join(sorted({os.path.basename(str(d)) for d in s.loc[s["site"] == site, "database"]}))
        seeds = ", ".join(str(int(v)) for v in sorted(set(mine["seed"])))
        protos = "; ".join(sorted({f"{n} v{v:g}" if pd.notna(v) else str(n) for n, v in
                                   zip(mine["protocol_name"], mine.get("protocol_version", np.nan), strict=True)}))
        held = {"tolerance_fraction", "hold_s"} <= set(mine.columns)  # force regulation's rule
        rules = "; ".join(sorted({f"band ±{a:.0%}, hold {b:g} s, cap {c:g} s" for a, b, c in
                                  zip(mine["tolerance_fraction"], mine["hold_s"], mine["max_trial_s"], strict=True)}
                                 if held else {f"cap {c:g} s" for c in mine["max_trial_s"]}))
        who = plural(mine["participant_code"].nunique(), "participant")
        out.append(f"{html.escape(site)} ({html.escape(dbs)}: {who}"
                   f", seed {html.escape(seeds or 'none')}, protocol {html.escape(protos)}, {html.escape(rules)})")
    return out


def sites_methods(study: StudyData) -> str:
    """The methods' sentence on the sites ("" for a study of one site, or none named)."""
    named = [x for x in dict.fromkeys(study.sites) if x]
    if len(named) < 2:
        return ""
    seeds = study.sessions[study.sessions["analysed"].astype(bool)].groupby("site")["seed"].unique()
    same = [s for s in named if len(seeds.get(s, [])) and any(
        set(seeds[s]) & set(seeds[o]) for o in named if o != s)]
    seed_words = ("The sites drew their schedules from different seeds, as sites run apart do: a participant's "
                  "schedule depends on the site's seed and the participant's number." if not same else
                  "Sites share a seed: participants of the same number at those sites met the same schedule.")
    return (f"<p><b>Sites.</b> {plural(len(named), 'site')} pooled: " + "; ".join(_site_rows(study)) + ". "
            "Each database's participant codes were re-coded SITE:CODE as they were read (the files are not "
            f"changed). {seed_words} The Wilcoxon tests pool the participants of every site (each one pair); the "
            "models have a fixed effect per site after the first (the Cox model is stratified by participant, which "
            "holds the site); each site's own tests and a Kruskal–Wallis test of whether the ON − OFF differences "
            "differ between the sites are under Sites.</p>")


def sites_html(within: Any, tables: dict[str, pd.DataFrame], study: StudyData) -> str:
    """The per-site tables ("" without sites)."""
    if "stats_by_site.csv" not in tables:
        return ""
    st = tables["stats_by_site.csv"]
    diff = tables["site_differences.csv"]
    rows = "".join(
        f"<tr><td class=\"m\">{html.escape(str(r.metric))}</td><td class=\"wrap\">{html.escape(str(r.medians_by_site))}"
        f"</td><td>{fmt(r.h_statistic)}</td><td>{int(r.df)}</td><td>{fmt_p(r.p_value)}</td>"
        f"<td class=\"wrap\">{html.escape(str(r.note))}</td></tr>" for r in diff.itertuples())
    cols = ["site", "metric", "n", "median_off", "median_on", "hl_estimate", "p_value", "p_holm", "rank_biserial"]
    return ("<h2>Sites</h2><p>" + "; ".join(_site_rows(study)) + ".</p>"
            + html_table(st, "stats_by_site.csv", cols, caption="ON vs OFF within each site (Holm within the site)")
            + '<div class="scroll"><table class="within"><caption>Does the effect differ between the sites? '
            "Kruskal–Wallis test of the participants' ON − OFF differences (site_differences.csv)</caption><thead>"
            "<tr><th>measure</th><th>median ON − OFF by site</th><th>H</th><th>df</th><th>p</th><th>note</th></tr>"
            f"</thead><tbody>{rows}</tbody></table></div>")
