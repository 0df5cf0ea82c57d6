"""The report's "Incomplete sessions" paragraph reads right for one session and for several."""

from __future__ import annotations

from types import SimpleNamespace

import pandas as pd

from analysis.report.report_sections import incomplete_html


def _within(reasons: list[str]) -> SimpleNamespace:
    return SimpleNamespace(incomplete=pd.DataFrame({"reason": reasons}), resumed=pd.DataFrame())


def test_one_session_is_its_and_several_are_their() -> None:
    one = incomplete_html(_within(["P03: stopped at trial 7 of 20"]), included=True)
    assert "1 experiment session did not complete, analysed with its finished trials (report --include-incomplete)" \
        in one
    two = incomplete_html(_within(["P03: stopped at trial 7 of 20", "P05: <killed>"]), included=False)
    assert ("2 experiment sessions did not complete, left out of every analysis (the default; report "
            "--include-incomplete analyses their finished trials)") in two
    assert "<li>P05: &lt;killed&gt;</li>" in two  # a reason is text, never markup
