"""How a workbook's sheets print and how wide their columns are: column widths that fit what each
column shows (no ``###``, no cut header), the A4 page setup of every sheet (orientation by width,
repeated title rows, print area, page breaks, the top-left corner of a large matrix with a caption,
several pages across for very wide tables), and charts sized to their printed page.
:meth:`generator.workbook.book.Book.print_setup` records the wishes; ``Book.save`` applies them here.
"""

from __future__ import annotations

import math
from typing import Sequence

from openpyxl.worksheet.worksheet import Worksheet

from .styles import TITLE_FONT

WIDE_SHEET = 360               # characters of column width beyond which a sheet prints several pages across
FIT_WIDTH_MAX_CELLS = 250_000   # larger sheets (value blocks of large books) keep their widths
MAX_WIDTH = 60


def display_len(value, fmt: str | None) -> int:
    """About how many characters ``value`` (None: a formula, value unknown) shows in ``fmt``."""
    fmt = fmt or "General"
    known = isinstance(value, (int, float)) and not isinstance(value, bool)
    if fmt == "General":
        if known:
            return len(f"{value:.9g}")
        return 11
    if fmt in ("@",):
        return 10
    core = fmt.split(";")[0]
    if "E+" in core.upper():
        return len(core) + 1
    if "%" in core:
        return len(core) + 5
    dec = len(core.split(".", 1)[1]) if "." in core else 0
    whole = len(str(int(abs(value)))) if known and math.isfinite(value) else 5
    return whole + (dec + 1 if dec else 0) + 1   # digits, point and decimals, sign


def fit_widths(ws: Worksheet) -> None:
    """Widen the columns of ``ws`` so that no number shows ``###`` and no header is cut.

    Numbers count with their format (formulas with room for five integer digits), headers (bold)
    with their text, other text only where the cell to its right is filled (it would be cut).
    Columns are never made narrower than the writer set them."""
    from openpyxl.cell.cell import MergedCell
    from openpyxl.utils import get_column_letter
    from openpyxl.worksheet.formula import ArrayFormula

    want: dict[int, float] = {}
    rows = list(ws.iter_rows())
    for row in rows:
        for k, c in enumerate(row):
            v = c.value
            if isinstance(c, MergedCell):
                continue
            if v is None:
                # a cell inside an array formula's block: formatted, its value comes from the array
                if c.number_format in (None, "General"):
                    continue
                n = display_len(None, c.number_format)
            elif isinstance(v, ArrayFormula) or (isinstance(v, str) and c.data_type == "f"):
                n = display_len(None, c.number_format)
            elif isinstance(v, (int, float)) and not isinstance(v, bool):
                n = display_len(v, c.number_format)
            else:
                text = str(v)
                bold = bool(c.font is not None and c.font.b)
                boxed = bool(c.border is not None and c.border.left is not None and c.border.left.style)
                right = row[k + 1].value if k + 1 < len(row) else None
                if not (bold and boxed) and right is None:
                    continue   # free text overflows into the empty cells to its right
                if c.alignment is not None and c.alignment.wrap_text:
                    continue
                n = min(len(text), 40) * (1.1 if bold else 1.0)
            want[c.column] = max(want.get(c.column, 0.0), n)
    for column, n in want.items():
        letter = get_column_letter(column)
        have = ws.column_dimensions[letter].width if letter in ws.column_dimensions else None
        width = min(MAX_WIDTH, n + 2.0)
        if have is None or have < width:
            ws.column_dimensions[letter].width = round(width, 1)


def _used_width(ws: Worksheet, last_column: int | None = None) -> float:
    from openpyxl.utils import get_column_letter

    total = 0.0
    for column in range(1, (last_column or ws.max_column) + 1):
        letter = get_column_letter(column)
        dim = ws.column_dimensions[letter] if letter in ws.column_dimensions else None
        total += dim.width if dim is not None and dim.width else 8.43
    return total


def page_setup(ws: Worksheet, *, landscape: bool | None = None, title_rows: int | tuple[int, int] | None = -1,
                area: str | None = None, row_breaks: Sequence[int] = (),
                matrix: tuple[int, int] | None = None, caption: str | None = None,
                one_page: bool = False, title_columns: str | None = None,
                min_scale: float | None = None, footer_pt: float | None = None) -> None:
    from openpyxl.utils import get_column_letter
    from openpyxl.worksheet.pagebreak import Break

    ws.page_setup.paperSize = ws.PAPERSIZE_A4
    ws.page_setup.fitToWidth = 1
    ws.page_setup.fitToHeight = 1 if one_page else 0
    ws.sheet_properties.pageSetUpPr.fitToPage = True
    ws.print_options.gridLines = False
    ws.page_margins.left = ws.page_margins.right = 0.5
    ws.page_margins.top = ws.page_margins.bottom = 0.6
    ws.oddFooter.left.text = "&A"
    ws.oddFooter.left.size = footer_pt or 8       # scaled with the page (LibreOffice)
    ws.oddFooter.right.text = "page &P of &N"
    ws.oddFooter.right.size = footer_pt or 8
    if matrix is not None:
        n_rows, n_cols = matrix
        rows, cols = min(n_rows, 24), min(n_cols, 12)
        ws.print_area = f"A1:{get_column_letter(1 + cols)}{1 + rows}"
        ws.oddHeader.center.text = caption or (
            f"{ws.title}: top-left {rows} x {cols} of the {n_rows} x {n_cols} matrix; "
            "the whole matrix is in the workbook, not in the printout")
        ws.oddHeader.center.size = 9
        _room_for_caption(ws)
        ws.page_setup.orientation = "landscape"
        return
    if caption:
        ws.oddHeader.center.text = caption
        ws.oddHeader.center.size = 9
        _room_for_caption(ws)
    last_column = None
    if area:                      # only the printed columns count (chart data may lie beyond)
        from openpyxl.utils import range_boundaries

        last_column = range_boundaries(area.replace("$", ""))[2]
    width = _used_width(ws, last_column)
    if landscape is None:
        landscape = width > 100
    ws.page_setup.orientation = "landscape" if landscape else "portrait"
    if width > WIDE_SHEET:
        # a very wide table (the diagnose Records): several pages across, the first column repeated,
        # rather than one page at an unreadable scale
        ws.page_setup.fitToWidth = math.ceil(width / (WIDE_SHEET * 0.75))
        ws.print_title_cols = "A:A"
    if title_rows == -1:
        first = ws.cell(row=1, column=1)
        title_rows = 1 if (first.value is not None and first.font is not None and first.font.b
                           and first.font.sz != TITLE_FONT.sz) else None
    if min_scale is not None:
        # a fixed scale (text stays legible), as many pages across as the width needs
        ws.sheet_properties.pageSetUpPr.fitToPage = False
        ws.page_setup.scale = max(10, min(100, round(100 * min_scale)))
    if title_columns:
        ws.print_title_cols = title_columns
    if isinstance(title_rows, tuple):          # (first, last): a header row below a title block
        ws.print_title_rows = f"{title_rows[0]}:{title_rows[1]}"
    elif title_rows:
        ws.print_title_rows = f"1:{title_rows}"
    if area:
        ws.print_area = area
    for r in row_breaks:
        if r > 1:
            ws.row_breaks.append(Break(id=r - 1))


def _room_for_caption(ws: Worksheet) -> None:
    """A page header (caption) of its own above the sheet's first row: with the default margins
    LibreOffice printed the caption clipped, across the sheet's title."""
    ws.page_margins.header = 0.3
    ws.page_margins.top = 1.0


#: A4 minus the margins of :func:`page_setup` (cm): (width, height) landscape
_PAGE_CM = (29.7 - 2 * 1.27, 21.0 - 2 * 1.52 - 1.5)


#: printed cm per character of column width: Calibri 11 (Excel) gives 0.19, LibreOffice without
#: Calibri or Carlito (its default font falls back to DejaVu Sans) 0.26 (measured on the demo
#: books' PDFs); the larger one, so that the chart spans the page in both (where the columns are
#: narrower than the chart, the page is scaled to the chart)
CM_PER_CHAR = 0.25


def _width_cm(ws: Worksheet) -> float:
    """The width (cm) of what ``ws`` prints across one page: its columns, or a text that runs on
    past the last column (the MPE sheet's notes), whichever reaches further."""
    from openpyxl.utils import get_column_letter

    chars = _used_width(ws)
    longest: dict[int, int] = {}
    # notes sit near the top; a large book's Budget has 10^5 rows, which are not read
    for row in ws.iter_rows(min_row=1, max_row=min(ws.max_row, OVERFLOW_ROWS)):
        for c in row:
            if isinstance(c.value, str) and c.data_type == "s":
                longest[c.column] = max(longest.get(c.column, 0), len(c.value))
    left = 0.0
    for column in range(1, ws.max_column + 1):
        letter = get_column_letter(column)
        dim = ws.column_dimensions[letter] if letter in ws.column_dimensions else None
        chars = max(chars, left + longest.get(column, 0))
        left += dim.width if dim is not None and dim.width else 8.43
    return CM_PER_CHAR * chars / max(1, ws.page_setup.fitToWidth or 1)


OVERFLOW_ROWS = 200   # rows searched for a text running past the last column


def size_to_page(ws: Worksheet, chart) -> None:
    """The chart as wide as one printed page of ``ws`` and at most 80 % of its height (the sheet
    prints scaled to the page width), never smaller than the writer made it."""
    landscape = ws.page_setup.orientation == "landscape"
    page_w, page_h = _PAGE_CM if landscape else _PAGE_CM[::-1]
    width = max(chart.width, 0.97 * _width_cm(ws))
    height = min(0.8 * page_h * width / page_w, 0.62 * width)
    chart.width, chart.height = round(width, 2), round(max(chart.height, height), 2)
