"""Every workbook `cmmwb demo` writes, printed to PDF by a real LibreOffice (one soffice run for
all of them, through `generator.workbook.pdf`, the code behind `cmmwb build --pdf`): readable pages
(no `###`, no error values outside the instruction prose), page counts within the goals of the
print setup, each knuckle budget on one page, units in the headers, cached Results values."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import openpyxl
import pytest

from cmmwb.generator.budget import block as budget_block
from cmmwb.generator.cli import main
from cmmwb.generator.workbook.recalc import soffice

from tests.helpers import EXAMPLES

#: page goals of issue 11 (A4)
PAGE_GOALS = {"stepgauge": 40, "knuckle": 20, "cylinder_bore": 40, "diagnosis": 30}
ERROR_VALUES = ("#VALUE!", "#NAME?", "#REF!", "Err:", "#DIV/0!")
UNIT = re.compile(r"(_mm|_um|_µm|_ppm|_urad|_µrad|_rad|_deg|_pct|/mm)$")


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """{book path: [text of page 1, page 2, ...]} for every workbook of `cmmwb demo --pdf`."""
    if soffice() is None or shutil.which("pdftotext") is None:
        pytest.skip("needs LibreOffice and pdftotext")
    out = tmp_path_factory.mktemp("demo")
    assert main(["demo", "--out", str(out), "--pdf"]) == 0
    pages = {}
    for book in sorted(out.rglob("*.xlsx")):
        pdf = book.with_suffix(".pdf")
        assert pdf.exists(), f"no PDF for {book}"
        text = subprocess.run(["pdftotext", "-layout", str(pdf), "-"], capture_output=True, text=True,
                              check=True).stdout
        pages[book] = text.split("\f")[:-1] if text.endswith("\f") else text.split("\f")
    return pages


def _sheet(page: str) -> str:
    """The sheet a printed page belongs to: the footer's first word (`&A ... page P of N`)."""
    lines = [ln for ln in page.splitlines() if ln.strip()]
    return lines[-1].split()[0] if lines else ""


def _goal(book: Path) -> int:
    return next((n for key, n in PAGE_GOALS.items() if book.stem.startswith(key)), 40)


def test_demo_writes_a_pdf_per_workbook(demo):
    assert len(demo) >= 19


def test_no_cell_shows_hashes(demo):
    bad = [(b.name, k + 1, _sheet(p)) for b, pages in demo.items() for k, p in enumerate(pages) if "###" in p]
    assert not bad, f"pages showing ### (book, page, sheet): {bad[:10]}"


def test_no_error_values_outside_the_instructions(demo):
    bad = [(b.name, k + 1, _sheet(p), e) for b, pages in demo.items() for k, p in enumerate(pages)
           if _sheet(p) != "Instructions" for e in ERROR_VALUES if e in p]
    assert not bad, f"error values printed (book, page, sheet, error): {bad[:10]}"


def test_page_counts_within_the_goals(demo):
    counts = {b.name: len(pages) for b, pages in demo.items()}
    over = {b.name: (len(pages), _goal(b)) for b, pages in demo.items() if len(pages) > _goal(b)}
    assert not over, f"more pages than the goal (pages, goal): {over}; all: {counts}"


def test_every_knuckle_budget_prints_on_one_page(demo):
    """Each budget printed (a characteristic's chosen budget, a position's Table 9 and its two
    distance budgets) has its header row, u_c and U on the page of its heading."""
    pages = next(p for b, p in demo.items() if b.stem == "knuckle")
    results = openpyxl.load_workbook(next(b for b in demo if b.stem == "knuckle"), read_only=True)["Results"]
    names = [r[0] for r in results.iter_rows(min_row=2, values_only=True) if r[0]]
    seen = set()
    for page in pages:
        if _sheet(page) not in names:
            continue
        chunks = re.split(r"(?m)^(?=[ \t]*Budget of )", page)
        for chunk in chunks[1:]:
            heading = chunk.strip().splitlines()[0]
            name = heading.split()[2]
            seen.add(name)
            if "(Table 9)" in heading:
                for key in ("sensitivity_mm/mm", "contribution_um", "u_POS_um", "U_POS_um"):
                    assert key in chunk, f"{heading!r}: {key} not on the same page"
            else:
                for key in (*budget_block.BUDGET_HEADER[1:], "u_c_um", "U_um"):
                    assert key in chunk, f"{heading!r}: {key} not on the same page"
    assert set(names) <= seen, f"characteristics without a printed budget: {set(names) - seen}"


def test_numeric_headers_of_results_and_budgets_carry_units(demo):
    for book in demo:
        wb = openpyxl.load_workbook(book, data_only=True)
        sheets = [wb["Results"]] + ([wb["Budget"]] if "Budget" in wb.sheetnames else [])
        for ws in sheets:
            header = [c.value for c in ws[1]]
            for k, h in enumerate(header):
                values = [r[k] for r in ws.iter_rows(min_row=2, max_row=min(ws.max_row, 40), values_only=True)]
                numeric = any(isinstance(v, (int, float)) for v in values)
                if numeric and not UNIT.search(str(h)):
                    assert "unit" in header, f"{book.name} {ws.title}: numeric column {h!r} without a unit"


def test_knuckle_budget_headers_carry_units():
    assert all(UNIT.search(h) for h in budget_block.BUDGET_HEADER[1:])


def test_no_header_is_cut(demo):
    """Every column header (bold, boxed) fits its column's width."""
    for book in demo:
        wb = openpyxl.load_workbook(book)
        for ws in wb.worksheets:
            if ws.sheet_state != "visible" or ws.max_row * ws.max_column > 250_000:
                continue
            for row in ws.iter_rows(max_row=min(ws.max_row, 400)):
                for c in row:
                    if not (isinstance(c.value, str) and c.data_type != "f" and c.font.b and c.border.left.style):
                        continue   # a header: bold, boxed text (not a formula that shows a word)
                    width = ws.column_dimensions[c.column_letter].width \
                        if c.column_letter in ws.column_dimensions else 8.43
                    # a wrapped header is cut only where one of its words is wider than the column
                    need = max(map(len, c.value.split() or [""])) if c.alignment.wrap_text else len(c.value)
                    assert width >= need, f"{book.name} {ws.title}!{c.coordinate} {c.value!r}: width {width}"


def test_build_pdf_without_libreoffice_says_so_and_writes_nothing(tmp_path, monkeypatch, capsys):
    from cmmwb import generator

    monkeypatch.setattr(generator.workbook.pdf, "soffice", lambda: None)
    out = tmp_path / "out"
    assert main(["build", str(EXAMPLES / "knuckle.toml"), "--out", str(out), "--pdf"]) == 2
    assert "needs LibreOffice" in capsys.readouterr().err
    assert not out.exists()


def test_every_results_value_is_cached(demo):
    """openpyxl data_only=True (no calculation) sees every Results value of every demo book."""
    for book in demo:
        ws = openpyxl.load_workbook(book, data_only=True)["Results"]
        header = [c.value for c in ws[1]]
        for row in ws.iter_rows(min_row=2, values_only=True):
            for h, v in zip(header, row):
                if h in ("u",) and row[0] in ("chi2_before", "dof_before", "p_before", "chi2_after",
                                               "dof_after", "rms_before_um", "rms_after_um",
                                               "p_targeted", "p_after"):
                    continue   # diagnose statistics have no u
                assert v is not None, f"{book.name} Results {row[0]} {h}: no cached value"


# -- the report page and the Decision sheet, legible (issue 32) -----------------------------------------

TASK_KINDS = ("pointcloud", "budget", "feature", "characteristic")
#: the smallest printed text of a Summary or Decision page (points on the paper)
MIN_PT = 8.0


def _task_books(demo) -> list[Path]:
    return [b for b in demo if b.parent.name in TASK_KINDS]


def test_every_task_book_has_the_report_page(demo):
    """Each demo book of the four kinds prints a Summary with the inspection report's columns."""
    books = _task_books(demo)
    assert len(books) >= 18
    for b in books:
        text = "\n".join(p for p in demo[b] if _sheet(p) == "Summary")
        for head in ("characteristic", "nominal", "lower limit", "upper limit", "value", "deviation", "decision",
                     "conformity", "tolerance bar", "coverage probability", "SHA-256"):
            assert head in text, (b.name, head)


def test_the_smallest_printed_text_of_every_summary_and_decision_page_is_8_pt(demo):
    """Measured from the PDF (the size of every text-showing operator, tests/helpers/pdftext.py):
    the Decision sheets printed at 4-5 pt before issue 32."""
    from tests.helpers.pdftext import font_sizes, sheet_of_pages

    small = []
    n = 0
    for b in _task_books(demo):
        pdf = b.with_suffix(".pdf")
        for page, (sizes, sheet) in enumerate(zip(font_sizes(pdf), sheet_of_pages(pdf)), start=1):
            if sheet in ("Summary", "Decision"):
                n += 1
                assert sizes, (b.name, page)
                if min(sizes) < MIN_PT:
                    small.append((b.name, page, sheet, round(min(sizes), 2)))
    assert n >= 40 and not small, small


def test_the_pointcloud_mpe_verdict_is_on_the_report_page(demo):
    """The MPE2 step gauges' C_max = 1.020 violates the MPE: said on their Summary."""
    for b in demo:
        if b.stem.startswith("stepgauge") and b.stem.endswith("MPE2"):
            text = "\n".join(p for p in demo[b] if _sheet(p) == "Summary")
            assert "MPE check" in text and "1.0201" in text and "violates the MPE" in text, b.name
