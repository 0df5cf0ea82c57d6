#!/usr/bin/env python3
"""Print a report to PDF with headless Chromium and check that no column of its test tables is lost.

    python scripts/check_report_print.py REPORT_DIR [--pdf OUT.pdf]

Printing is where wide tables lose their right-hand columns (the page clips
what does not fit).  For every row of every test table (``table.stats``) of
``REPORT_DIR/report.html`` this finds one line of the PDF's text
(``pdftotext -layout``) holding all of the row's cells, in order, and checks
every column heading appears.  Exit status 0 when all are there, 1 (naming
what is missing) otherwise, 2 when Chromium or pdftotext is not installed.
"""

from __future__ import annotations

import argparse
import html.parser
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

#: Headings of the row-label columns of the test tables.
LABEL_HEADINGS = ("measure", "target")
CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
#: Flags for a headless, offline, throwaway browser (nothing is fetched, nothing is kept).
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--no-pdf-header-footer")


def find_chromium() -> str | None:
    """The first Chromium-like browser on PATH, or None."""
    return next((p for p in map(shutil.which, CHROMIUM_NAMES) if p), None)


class _Tables(html.parser.HTMLParser):
    """Headings and cell texts of every ``<table class="stats">`` (superscript note marks left out)."""

    def __init__(self) -> None:
        super().__init__()
        self.tables: list[tuple[list[str], list[list[str]]]] = []
        self._in_table = False
        self._cell: list[str] | None = None
        self._row: list[str] = []
        self._sup = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        if tag == "table" and "stats" in (dict(attrs).get("class") or "").split():
            self._in_table = True
            self.tables.append(([], []))
        elif self._in_table and tag in ("td", "th"):
            self._cell = []
        elif self._in_table and tag == "tr":
            self._row = []
        elif tag == "sup":
            self._sup = True

    def handle_endtag(self, tag: str) -> None:
        if tag == "table":
            self._in_table = False
        elif tag == "sup":
            self._sup = False
        elif self._in_table and tag in ("td", "th") and self._cell is not None:
            text = " ".join("".join(self._cell).split())
            (self.tables[-1][0] if tag == "th" else self._row).append(text)
            self._cell = None
        elif self._in_table and tag == "tr" and self._row:
            self.tables[-1][1].append(self._row)

    def handle_data(self, data: str) -> None:
        if self._cell is not None and not self._sup:
            self._cell.append(data)


def print_to_pdf(html_path: Path, pdf_path: Path, chromium: str) -> None:
    """Print a page with headless Chromium (a fresh profile, deleted afterwards)."""
    with tempfile.TemporaryDirectory(prefix="report-print-") as profile:
        subprocess.run([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"--print-to-pdf={pdf_path}",
                        html_path.resolve().as_uri()], check=True, capture_output=True, timeout=180)
    if not pdf_path.is_file() or pdf_path.stat().st_size == 0:
        raise RuntimeError(f"Chromium wrote no PDF to {pdf_path}")


def missing_cells(page_html: str, pdf_text: str) -> list[str]:
    """What of the test tables is not in the PDF's text: one line per missing row or heading."""
    parser = _Tables()
    parser.feed(page_html)
    lines = [" ".join(line.split()) for line in pdf_text.splitlines()]
    pieces = set(re.split(r"[\s/]+", " ".join(lines)))
    problems = []
    if not parser.tables:
        return ["no test table (table.stats) in the page"]
    for k, (head, rows) in enumerate(parser.tables, 1):
        for h in head:
            # a heading may wrap inside its cell, also after a '/'
            lost = [w for w in re.split(r"[\s/]+", h) if w and w not in pieces]
            if lost:
                problems.append(f"table {k}: heading {h!r} is not in the PDF (missing {' '.join(lost)!r})")
        # the row labels (left-most, never clipped) may sit on a line of their own in pdftotext's layout:
        # match the cells from the first numeric column on
        skip = sum(1 for h in head if h in LABEL_HEADINGS)
        for row in rows:
            cells = row[skip:]
            if not any(_in_order(cells, line) for line in lines):
                problems.append(f"table {k}: no line of the PDF holds the cells {cells} of row {row[:skip]}")
    return problems


def _in_order(cells: list[str], line: str) -> bool:
    at = 0
    for c in cells:
        i = line.find(c, at)
        if i < 0:
            return False
        at = i + len(c)
    return True


def check(report: Path, pdf: Path | None = None) -> list[str]:
    """Print ``report`` (a report folder or its report.html) and return what is missing (empty: all there)."""
    page = report / "report.html" if report.is_dir() else report
    chromium, pdftotext = find_chromium(), shutil.which("pdftotext")
    if chromium is None or pdftotext is None:
        raise FileNotFoundError("needs Chromium and pdftotext (Debian: apt-get install chromium poppler-utils)")
    with tempfile.TemporaryDirectory(prefix="report-pdf-") as tmp:
        out = pdf if pdf is not None else Path(tmp) / "report.pdf"
        print_to_pdf(page, out, chromium)
        text = subprocess.run([pdftotext, "-layout", str(out), "-"], check=True, capture_output=True,
                              text=True).stdout
    return missing_cells(page.read_text(encoding="utf-8"), text)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("report", type=Path, help="report folder (or its report.html)")
    ap.add_argument("--pdf", type=Path, default=None, help="keep the printed PDF here")
    args = ap.parse_args(argv)
    try:
        problems = check(args.report, args.pdf)
    except FileNotFoundError as exc:
        print(f"check_report_print: {exc}", file=sys.stderr)
        return 2
    for p in problems:
        print(p)
    if not problems:
        print(f"every column of the test tables of {args.report} is in the printed PDF"
              + (f" ({args.pdf})" if args.pdf else ""))
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
