"""Matrix blocks are not split across printed pages where they fit on one (issue 32): a sheet of
stacked blocks (as V_A of a feature book: a caption, a header and a matrix per factor) printed by
LibreOffice has each block's caption and its last row on the same page, and a feature book's V_A
gets its page breaks before blocks."""

from __future__ import annotations

import shutil
import subprocess

import openpyxl
import pytest

from cmmwb.generator.workbook.book import Book
from cmmwb.generator.workbook.pagesetup import block_breaks
from cmmwb.generator.workbook.pdf import print_books
from cmmwb.generator.workbook.recalc import soffice

BLOCK_ROWS = 11           # caption, header, 9 matrix rows
GAP = 2


def stacked(book: Book, blocks: int, columns: int = 9):
    ws = book.sheet("Blocks")
    spans = []
    r = 1
    for k in range(blocks):
        book.text(ws, r, 1, f"caption {k}")
        book.header(ws, r + 1, 1, [f"c{j}_mm" for j in range(columns)])
        for a in range(BLOCK_ROWS - 2):
            for j in range(columns):
                ws.cell(row=r + 2 + a, column=1 + j).value = float(k + a + j) / 7.0
        book.text(ws, r + BLOCK_ROWS - 1, columns + 1, f"end {k}")
        spans.append((r, r + BLOCK_ROWS - 1))
        r += BLOCK_ROWS + GAP
    return ws, spans


def test_breaks_come_before_blocks_that_do_not_fit_in_what_is_left():
    book = Book("test", "blocks", "blocks")
    ws, spans = stacked(book, 20)
    breaks = block_breaks(ws, spans)
    assert breaks and all(b in {first for first, _ in spans} for b in breaks)
    # between two breaks the blocks fit on a page of 15 pt rows at the page's largest scale
    pages = [1, *breaks, spans[-1][1] + 1]
    assert max(b - a for a, b in zip(pages, pages[1:])) * 15 * 0.03528 <= 29.7 - 2 * 1.52 - 1.5 + 1e-9


@pytest.mark.libreoffice
def test_libreoffice_prints_every_block_on_one_page(tmp_path):
    if soffice() is None or shutil.which("pdftotext") is None:
        pytest.skip("needs LibreOffice and pdftotext")
    book = Book("test", "blocks", "blocks")
    ws, spans = stacked(book, 20)
    book.print_setup(ws, blocks=spans)
    path = book.save(tmp_path / "blocks.xlsx")
    (pdf,) = print_books([path])
    pages = subprocess.run(["pdftotext", "-layout", str(pdf), "-"], capture_output=True, text=True,
                           check=True).stdout.split("\f")
    for k in range(len(spans)):
        where = [p for p, text in enumerate(pages) if f"caption {k}\n" in text or f"caption {k} " in text]
        ends = [p for p, text in enumerate(pages) if f"end {k}\n" in text or f"end {k} " in text]
        assert where and where == ends, (k, where, ends)
    assert len([p for p in pages if p.strip()]) > 2      # the sheet does span pages


def test_a_feature_book_breaks_its_v_a_before_a_block(tmp_path):
    from cmmwb.generator.cli import build_task

    from tests.helpers import EXAMPLES

    build_task(EXAMPLES / "feature_cylinder_bore.toml", tmp_path, plots=False)
    ws = openpyxl.load_workbook(tmp_path / "cylinder_bore.xlsx")["V_A"]
    rows = [b.id + 1 for b in ws.row_breaks.brk]
    # the blocks' captions: one per factor (R ... W) and the total
    captions = {c.row for c in ws["A"] if isinstance(c.value, str)
                and (": V_A," in c.value or c.value.startswith("total: "))}
    assert rows and set(rows) <= captions
