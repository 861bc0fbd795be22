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

#: height (pt) of one wrapped line of 11 pt text (12.8 pt measured in LibreOffice's PDF)
LINE_PT = 13.5
WIDE_SHEET = 360               # characters of column width beyond which a sheet prints several pages across
FIT_WIDTH_MAX_CELLS = 250_000   # larger sheets (value blocks of large books) keep their widths
MAX_WIDTH = 60


def wrapped_lines(text: str, width: float) -> int:
    """How many lines ``text`` takes wrapped in a column ``width`` characters wide (the unit is a
    digit's width; LibreOffice fitted 1.2-1.3 characters of text per unit, Calibri in Excel more: 1.2
    counts a line more where in doubt); the row's height is then ``LINE_PT`` per line."""
    import textwrap

    return max(1, len(textwrap.wrap(text, int(width * 1.2)))) if text else 1


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
                    if not (bold and boxed):
                        continue
                    # a wrapped header: its longest word must fit (the words wrap, a word is cut)
                    text = max(text.split() or [""], key=len)
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
                min_scale: float | None = None, footer_pt: float | None = None,
                corner: tuple[int, int] = (24, 12), chart_row: int | None = None,
                blocks: Sequence[tuple[int, int]] = ()) -> None:
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
        rows, cols = min(n_rows, corner[0]), min(n_cols, corner[1])
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
    if width > WIDE_SHEET and min_scale is None:
        # a very wide table: several pages across, the first column repeated, rather than one page
        # at an unreadable scale
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
    if chart_row is not None and min_scale is not None:
        # a table printed pages across, then a chart anchored at A{chart_row}: two print ranges, so
        # that the chart's rows print once (one page wide) and not once per page across
        scale = ws.page_setup.scale
        page_cm = (_PAGE_CM if landscape else _PAGE_CM[::-1])
        chars = page_cm[0] * 100.0 / scale / CM_PER_CHAR
        last, used = 0, 0.0
        while last < ws.max_column:
            letter = get_column_letter(last + 1)
            dim = ws.column_dimensions[letter] if letter in ws.column_dimensions else None
            w = dim.width if dim is not None and dim.width else 8.43
            if used + w > chars:
                break
            used += w
            last += 1
        rows = int(page_cm[1] * 100.0 / scale / 0.53)      # rows of 15 pt on one page
        ws.print_area = [f"A1:{get_column_letter(ws.max_column)}{chart_row - 1}",
                         f"A{chart_row}:{get_column_letter(max(1, last))}{chart_row + rows - 1}"]
    breaks = sorted(set(row_breaks) | set(block_breaks(ws, blocks, row_breaks, landscape, min_scale, last_column)))
    for r in breaks:
        if r > 1:
            ws.row_breaks.append(Break(id=r - 1))


#: printed cm per character of column width with Calibri (Excel): the narrower font, so the
#: larger scale of a page fitted to its width, the fewer rows on a page
CM_PER_CHAR_NARROW = 0.19
#: height (pt) of a row without one of its own (Excel's 15 pt for Calibri 11; LibreOffice's is smaller)
DEFAULT_ROW_PT = 15.0


def block_breaks(ws: Worksheet, blocks: Sequence[tuple[int, int]], row_breaks: Sequence[int] = (),
                 landscape: bool = False, min_scale: float | None = None, last_column: int | None = None) -> list[int]:
    """Rows that start a new page so that no block (first row, last row) is split across pages
    where it fits on one: the rows a page holds are counted at the largest scale an engine prints
    the sheet at (Calibri's narrow columns, 15 pt rows), so that a break comes early rather than
    late in every engine; a block taller than a page starts on a new page and runs on."""
    if not blocks:
        return []
    # A4 less the margins of page_setup (0.5 in at the sides, 0.6 in top and bottom) and 1.5 cm
    # for the footer and a caption
    page_w, page_h = (29.7 - 2 * 1.27, 21.0 - 2 * 1.52 - 1.5) if landscape else (21.0 - 2 * 1.27, 29.7 - 2 * 1.52 - 1.5)
    if min_scale is not None:
        scale = min_scale
    else:
        scale = min(1.0, page_w / max(1e-9, _used_width(ws, last_column) * CM_PER_CHAR_NARROW))
    room = page_h / scale / 0.03528          # points of rows on one page

    def height(r: int) -> float:
        dim = ws.row_dimensions[r] if r in ws.row_dimensions else None
        return dim.height if dim is not None and dim.height else DEFAULT_ROW_PT

    titles = 0.0
    if ws.print_title_rows:
        a, b = (int(x) for x in str(ws.print_title_rows).replace("$", "").split(":"))
        titles = sum(height(r) for r in range(a, b + 1))
    starts = {first: last for first, last in blocks}
    forced = set(row_breaks)
    out: list[int] = []
    used = 0.0
    for r in range(1, max(ws.max_row, max(last for _, last in blocks)) + 1):
        if r in forced and r > 1:
            used = titles
        if r in starts and r > 1:
            need = sum(height(q) for q in range(r, starts[r] + 1))
            if used + need > room and used > titles:     # it does not fit in what is left: a new page
                out.append(r)
                used = titles
        used += height(r)
        if used > room:                       # the engine breaks here by itself
            used = titles + height(r)
    return out


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
    past the last column (the MPE sheet's notes), whichever reaches further (a wrapped text stays
    in its column)."""
    from openpyxl.utils import get_column_letter

    chars = _used_width(ws)
    longest: dict[int, int] = {}
    # notes sit near the top; a large book's Budget has 10^5 rows, which are not read
    for row in ws.iter_rows(min_row=1, max_row=min(ws.max_row, OVERFLOW_ROWS)):
        for c in row:
            if isinstance(c.value, str) and c.data_type == "s" and not (c.alignment is not None
                                                                       and c.alignment.wrap_text):
                longest[c.column] = max(longest.get(c.column, 0), len(c.value))
    left = 0.0
    for column in range(1, ws.max_column + 1):
        letter = get_column_letter(column)
        dim = ws.column_dimensions[letter] if letter in ws.column_dimensions else None
        chars = max(chars, left + longest.get(column, 0))
        left += dim.width if dim is not None and dim.width else 8.43
    if not ws.sheet_properties.pageSetUpPr.fitToPage and ws.page_setup.scale:
        # a fixed scale: one printed page holds the page's width divided by the scale; a chart in a
        # print range of its own (``chart_row``) as wide as that range's columns
        landscape = ws.page_setup.orientation == "landscape"
        page = (_PAGE_CM if landscape else _PAGE_CM[::-1])[0] * 100.0 / ws.page_setup.scale
        ranges = str(ws.print_area or "").split(",")
        if len(ranges) > 1:
            from openpyxl.utils import range_boundaries

            lo, _, hi, _ = range_boundaries(ranges[-1].split("!")[-1].replace("$", ""))
            chars = sum((ws.column_dimensions[get_column_letter(c)].width or 8.43)
                        if get_column_letter(c) in ws.column_dimensions else 8.43 for c in range(lo, hi + 1))
            return min(page, CM_PER_CHAR * chars)
        return page
    return CM_PER_CHAR * chars / max(1, ws.page_setup.fitToWidth or 1)


OVERFLOW_ROWS = 200   # rows searched for a text running past the last column


def size_to_page(ws: Worksheet, chart) -> None:
    """The chart as wide as one printed page of ``ws`` and at most 80 % of its height (the sheet
    prints scaled to the page width), never smaller than the writer made it."""
    landscape = ws.page_setup.orientation == "landscape"
    # A4 less the margins of page_setup (0.5 in at the sides, 0.6 in top and bottom) and 1.5 cm
    # for the footer and a caption
    page_w, page_h = (29.7 - 2 * 1.27, 21.0 - 2 * 1.52 - 1.5) if landscape else (21.0 - 2 * 1.27, 29.7 - 2 * 1.52 - 1.5)
    width = max(chart.width, 0.97 * _width_cm(ws))
    height = min(0.8 * page_h * width / page_w, 0.62 * width)
    chart.width, chart.height = round(width, 2), round(max(chart.height, height), 2)
