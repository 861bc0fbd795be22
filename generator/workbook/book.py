"""Common parts of every generated workbook: the instruction sheet, named and validated
input cells, formula cells with notes, text cells that never become formulas, charts, the
``Results`` sheet of the contract, sheet protection without password, and atomic saving.  The
styles it applies are in :mod:`generator.workbook.styles`, how the sheets print (column widths,
page setup, charts sized to the page) in :mod:`generator.workbook.pagesetup`.

Writers lay out arrays with :class:`Book`; they never touch openpyxl styles directly.
"""

from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Sequence

from openpyxl import Workbook
from openpyxl.comments import Comment
from openpyxl.styles import Alignment, Font, PatternFill, Protection
from openpyxl.workbook.defined_name import DefinedName
from openpyxl.worksheet.cell_range import MultiCellRange
from openpyxl.worksheet.datavalidation import DataValidation
from openpyxl.worksheet.worksheet import Worksheet

from .. import __version__
from .atomic import replacing
from .cache import fill, referred
from .pagesetup import FIT_WIDTH_MAX_CELLS, fit_widths, page_setup, size_to_page
from .sharedstrings import share_strings
from .styles import (
    BOX,
    DEFAULT_FILL,
    HEADER_FONT,
    INPUT_FILL,
    INPUT_FONT,
    NUMBER_FORMAT,
    TITLE_FONT,
    VALUE_FILL,
)
from .tasksheet import write_task_sheet
from .xlref import Block, array_formula, block, cell, check_name

PARA_WIDTH = 95
RESULTS = "Results"
INSTRUCTIONS = "Instructions"


@dataclass(frozen=True)
class BookAdditions:
    """What a build adds to the workbook of its task, given to the kind's ``write_book`` and by it
    to :meth:`Book.save`: ``info``, the task description stored on the hidden sheet ``_task`` (see
    :meth:`Book.task_info`; ignored when the writer stored its own), and ``sheets``, writers
    ``writer(book)`` of the sheets every book of a build gets (Decision, Summary), called in
    order before the column widths and print setup are finished."""

    info: dict | None = None
    sheets: tuple[Callable[["Book"], None], ...] = ()
    #: which formula cells get cached values (generator.workbook.cache: results, all, none)
    cache: str = "results"


def _finite(value: float, what: str) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{what}: {value!r} is not a finite number")
    return value


class Book:
    """A workbook under construction.

    ``kind`` and ``name`` go to the instruction sheet and the document properties.
    """

    def __init__(self, kind: str, name: str, title: str):
        self.wb = Workbook()
        self.kind = kind
        self.name = name
        ws = self.wb.active
        ws.title = INSTRUCTIONS
        self.instructions = ws
        self._instr_row = 1
        self.text(ws, 1, 1, title, font=TITLE_FONT)
        self.text(ws, 2, 1, f"cmmwb {__version__} — task kind '{kind}', task '{name}'")
        self._instr_row = 4
        ws.column_dimensions["A"].width = 100
        self.wb.properties.creator = f"cmmwb {__version__}"
        self.wb.properties.title = title
        self._validations: dict[tuple[str, float | None, float | None], DataValidation] = {}
        # cells of each validation rule, given to the rule once at save time (openpyxl's
        # DataValidation.add is O(n) per cell: 12,000 cells took 30 s)
        self._validation_cells: dict[tuple[str, float | None, float | None], list[tuple[int, int]]] = {}
        self._task_info: dict | None = None
        #: sheet title -> print settings given by the writer (see :meth:`print_setup`)
        self._print: dict[str, dict] = {}
        #: charts sized to their printed page at save time (see :meth:`fill_page`)
        self._page_charts: list[tuple[str, object]] = []
        #: cached values of formula cells, given when they were written: {sheet: {coordinate: value}}
        self._values: dict[str, dict[str, object]] = {}
        #: the footer's size (pt) of every sheet whose print setup gives none (None: 8 pt); the
        #: footer prints scaled with its page, 11 pt at 0.73 is 8 pt
        self.footer_pt: float | None = None

    # -- sheets ------------------------------------------------------------------------------
    def sheet(self, title: str, *, protect: bool = True) -> Worksheet:
        """A new sheet; formula cells are protected (no password), input cells stay editable."""
        ws = self.wb.create_sheet(title)
        if protect:
            ws.protection.sheet = True
            ws.protection.formatColumns = False
            ws.protection.formatRows = False
        return ws

    def para(self, *paragraphs: str, bold: bool = False) -> None:
        """Paragraphs on the instruction sheet, wrapped into rows of at most ``PARA_WIDTH``
        characters (a wrapped cell's row height is not recomputed by every program, so one
        long cell would overlap the rows below it)."""
        for paragraph in paragraphs:
            lines = textwrap.wrap(paragraph, PARA_WIDTH, subsequent_indent="   ") or [""]
            for line in lines:
                self.text(self.instructions, self._instr_row, 1, line, font=HEADER_FONT if bold else None)
                self._instr_row += 1

    def gap(self) -> None:
        self._instr_row += 1

    # -- cells -------------------------------------------------------------------------------
    @staticmethod
    def text(ws: Worksheet, row: int, column: int, value: str, *, font: Font | None = None,
             wrap: bool = False):
        """A text cell.  Text is stored as a string even when it starts with ``=``, ``+``,
        ``-`` or ``@``: it never becomes a formula."""
        c = ws.cell(row=row, column=column)
        c.value = str(value)
        c.data_type = "s"
        if font is not None:
            c.font = font
        if wrap:
            c.alignment = Alignment(wrap_text=True, vertical="top")
        return c

    @staticmethod
    def align_top(ws: Worksheet, row: int, columns: int) -> None:
        """Every cell of ``row`` (columns 1 .. ``columns``) aligned at the top, wrapping kept: in a
        row a wrapped text makes high, the other cells stand level with its first line (at the
        default bottom they read as belonging to the row below)."""
        for c in range(1, columns + 1):
            cell_ = ws.cell(row=row, column=c)
            al = cell_.alignment
            cell_.alignment = Alignment(horizontal=al.horizontal, vertical="top", wrap_text=al.wrap_text,
                                        indent=al.indent)

    def header(self, ws: Worksheet, row: int, column: int, labels: Sequence[str],
               notes: Sequence[str | None] | None = None) -> None:
        """A row of bold column headers (each label carries its unit, e.g. ``u_um``)."""
        for k, label in enumerate(labels):
            c = self.text(ws, row, column + k, label, font=HEADER_FONT)
            c.border = BOX
            if notes and notes[k]:
                self.note(c, notes[k])

    def number(self, ws: Worksheet, row: int, column: int, value: float, *,
               fmt: str | None = NUMBER_FORMAT, computed: bool = False):
        """A plain number (an input without a name, e.g. a coordinate in a table).

        ``computed=True`` marks a value computed by the core (grey), used only where a block is
        too large for native formulas; the block's note says what produced it.
        """
        c = ws.cell(row=row, column=column)
        c.value = _finite(value, f"{ws.title}!{cell(row, column, absolute=False)}")
        if fmt:
            c.number_format = fmt
        if computed:
            c.fill = VALUE_FILL
        else:
            self._style_input(ws, c)
        return c

    def _style_input(self, ws: Worksheet, c, lo: float | None = None, hi: float | None = None):
        c.fill = INPUT_FILL
        c.font = INPUT_FONT
        c.border = BOX
        c.protection = Protection(locked=False)
        key = (ws.title, lo, hi)
        dv = self._validations.get(key)
        if dv is None:
            if lo is not None and hi is not None:
                dv = DataValidation(type="decimal", operator="between", formula1=repr(lo), formula2=repr(hi))
            elif lo is not None:
                dv = DataValidation(type="decimal", operator="greaterThanOrEqual", formula1=repr(lo))
            else:
                dv = DataValidation(type="decimal", operator="between", formula1="-1E+307", formula2="1E+307")
            dv.error = "Enter a number" + (f" >= {lo}" if lo is not None else "") + (
                f" and <= {hi}" if hi is not None else "") + "."
            dv.errorTitle = "cmmwb input"
            dv.showErrorMessage = True
            ws.add_data_validation(dv)
            self._validations[key] = dv
            self._validation_cells[key] = []
        self._validation_cells[key].append((c.column, c.row))

    def _flush_validations(self) -> None:
        """Give every validation rule its cells as column runs (``B2:B53 E2:G53 ...``)."""
        for key, cells in self._validation_cells.items():
            runs: list[str] = []
            for column, rows in _by_column(cells):
                start = prev = rows[0]
                for r in rows[1:] + [None]:
                    if r is not None and r == prev + 1:
                        prev = r
                        continue
                    runs.append(block(start, column, prev - start + 1, 1, absolute=False))
                    if r is not None:
                        start = prev = r
            self._validations[key].sqref = MultiCellRange(" ".join(runs))

    def input(self, ws: Worksheet, row: int, column: int, name: str | None, value: float, *,
              lo: float | None = None, hi: float | None = None, note: str | None = None,
              fmt: str | None = "General"):
        """A named, validated, editable input cell bound to the workbook-level name ``name``."""
        c = ws.cell(row=row, column=column)
        c.value = _finite(value, name or cell(row, column, ws.title))
        if fmt:
            c.number_format = fmt
        self._style_input(ws, c, lo, hi)
        if name:
            self.define(name, cell(row, column, ws.title))
        if note:
            self.note(c, note)
        return c

    def default(self, ws: Worksheet, row: int, column: int, name: str, formula: str, *,
                lo: float | None = None, hi: float | None = None, note: str | None = None):
        """An editable input whose default is a formula (e.g. a per-probe sigma defaulting to the
        task-wide value): styled, unlocked and validated like :meth:`input`; typing a number
        overrides it."""
        c = self.formula(ws, row, column, formula, fmt="General", name=name)
        self._style_input(ws, c, lo, hi)
        c.fill = DEFAULT_FILL
        inherited = formula.lstrip("=")
        self.note(c, f"Default: inherits {inherited} (formula {formula}). Type a number to override "
                     f"it for this cell only; the link to {inherited} is then cut."
                  + (f" {note}" if note else ""))
        return c

    def formula(self, ws: Worksheet, row: int, column: int, formula: str, *, note: str | None = None,
                fmt: str | None = NUMBER_FORMAT, name: str | None = None, value=None):
        """A single-cell formula (plain, non-array).  ``value``: its result as the core computed
        it, cached in the saved file for programs that do not calculate (:meth:`cache`)."""
        if not formula.startswith("="):
            raise ValueError("a formula starts with '='")
        c = ws.cell(row=row, column=column)
        c.value = formula
        if fmt:
            c.number_format = fmt
        if note:
            self.note(c, note)
        if name:
            self.define(name, cell(row, column, ws.title))
        if value is not None:
            self.cache(ws, row, column, value)
            hop = referred(formula, value, ws.title)
            if hop is not None:          # a formula that merely refers to a cell: that cell's value too
                self._values.setdefault(hop[0], {}).setdefault(hop[1], value)
        return c

    def cache(self, ws: Worksheet, row: int, column: int, value) -> None:
        """The cached value of the formula cell (row, column) of ``ws`` (an array formula's top-left
        cell included), written into the file by :meth:`save`."""
        self._values.setdefault(ws.title, {})[cell(row, column, absolute=False)] = value

    def cache_cells(self, ws: Worksheet, values: dict[str, object]) -> None:
        """Cached values of formula cells of ``ws`` by coordinate (``{"C8": 90.012}``)."""
        self._values.setdefault(ws.title, {}).update(values)

    @property
    def cached_values(self) -> dict[str, dict[str, object]]:
        """The cached values given so far: {sheet: {coordinate: value}} (a copy)."""
        return {s: dict(v) for s, v in self._values.items()}

    def array(self, target: Block, formula: str, *, note: str | None = None,
              fmt: str | None = NUMBER_FORMAT) -> None:
        """A legacy array formula filling ``target`` (also for single cells that do array
        arithmetic, e.g. SUMPRODUCT over a product of ranges)."""
        ws = self.wb[target.sheet]
        ws.cell(row=target.row, column=target.column).value = array_formula(target, formula)
        if fmt:
            for r in target.rows():
                for c in target.columns():
                    ws.cell(row=r, column=c).number_format = fmt
        if note:
            self.note(ws.cell(row=target.row, column=target.column), note)

    def define(self, name: str, ref: str) -> None:
        """A workbook-level defined name for a cell or range (``ref`` includes the sheet)."""
        check_name(name)
        if name in self.wb.defined_names:
            raise ValueError(f"defined name {name!r} used twice")
        self.wb.defined_names[name] = DefinedName(name, attr_text=ref)

    @staticmethod
    def note(c, text: str) -> None:
        """A cell note (comment): where the formula comes from (paper and equation)."""
        cm = Comment(text, "cmmwb")
        cm.width = 320
        cm.height = 120
        c.comment = cm

    # -- charts ------------------------------------------------------------------------------
    @staticmethod
    def scatter(ws: Worksheet, anchor: str, title: str, x_title: str, y_title: str,
                series: Sequence["ChartSeries"], *, width: float = 16, height: float = 9,
                x_min: float | None = None, y_min: float | None = None,
                page: "Book | None" = None):
        """A native XY chart with explicit colours (LibreOffice draws unstyled markers white),
        visible axes at the lower and left edges of the plot (not crossing at zero), the legend
        below.  Every series stays visible where series coincide: marker series get distinct
        symbols and colours, hollow, growing in size (see the comment below); line series get
        distinct dash patterns.  ``page`` = the book: the chart stands alone on its printed page
        and is sized to it when the book is saved (:meth:`fill_page`)."""
        from openpyxl.chart import ScatterChart, Series  # noqa: F811

        chart = ScatterChart()
        # ECMA-376 requires c:scatterStyle as the first child of c:scatterChart (openpyxl leaves it
        # out unless it is set; Excel may repair or drop a drawing without it).  How each series
        # is drawn (markers, lines, no smoothing) is set per series below, so the style is the
        # one Excel writes itself.
        chart.scatterStyle = "lineMarker"
        chart.title = title
        chart.style = 13
        chart.x_axis.title = x_title
        chart.y_axis.title = y_title
        for axis, lo in ((chart.x_axis, x_min), (chart.y_axis, y_min)):
            axis.delete = False
            axis.number_format = "General"
            axis.majorTickMark = "out"
            axis.tickLblPos = "low"          # labels at the edge of the plot, never across the data
            axis.crosses = "min"
            if lo is not None:
                axis.scaling.min = lo
        chart.legend.position = "b"
        n_marker = 0
        n_line = 0
        for k, cs in enumerate(series):
            colour = cs.colour or PALETTE[k % len(PALETTE)]
            if cs.title_from_data:
                s = Series(cs.y, cs.x, title_from_data=True)
            else:
                s = Series(cs.y, cs.x, title=cs.title)
            if cs.symbol is not None:
                # one filled mark per point and no line: limits that belong to separate items
                # (the Decision chart) must not be joined into a curve across them
                s.marker.symbol = cs.symbol
                s.marker.size = 14
                s.marker.graphicalProperties.solidFill = colour
                s.marker.graphicalProperties.line.solidFill = colour
                s.graphicalProperties.line.noFill = True
            elif cs.markers:
                s.marker.symbol = MARKERS[n_marker % len(MARKERS)]
                # LibreOffice draws the FIRST series on top and fills every marker; Excel draws the
                # last on top and honours hollow markers.  Sizes growing by 3 points + hollow
                # markers keep coinciding series visible in both: small filled ones on top of
                # larger ones in LibreOffice (with a step of 2 points the step gauge's LL hid
                # inside RR), nested outlines in Excel.
                s.marker.size = min(5 + 3 * n_marker, 17)
                s.marker.graphicalProperties.noFill = True
                s.marker.graphicalProperties.line.solidFill = colour
                s.marker.graphicalProperties.line.width = 15875  # 1.25 pt
                s.graphicalProperties.line.noFill = True
                n_marker += 1
            else:
                s.marker.symbol = "none"
                s.graphicalProperties.line.solidFill = colour
                s.graphicalProperties.line.width = 28575 if cs.bold else 19050  # 2.25 / 1.5 pt
                s.graphicalProperties.line.dashStyle = cs.dash or DASHES[n_line % len(DASHES)]
                n_line += 1
            s.smooth = False
            chart.series.append(s)
        chart.width, chart.height = width, height
        ws.add_chart(chart, anchor)
        if page is not None:
            page.fill_page(ws, chart)
        return chart

    @staticmethod
    def tolerance_bar(ws: Worksheet, anchor: str, series: Sequence["ChartSeries"], *, width: float, height: float,
                      x_range: tuple[float, float] = (-2.0, 2.0), y_range: tuple[float, float] = (0.0, 1.0)):
        """A small XY chart with no text (no title, legend, axes or grid lines), made by
        :meth:`scatter`: a row's tolerance bar on a report page (value ± U against its limits,
        drawn in coordinates of its own tolerance), which prints at the size of its cells."""
        chart = Book.scatter(ws, anchor, None, None, None, series, width=width, height=height)
        chart.title = None
        chart.legend = None
        for axis, (lo, hi) in ((chart.x_axis, x_range), (chart.y_axis, y_range)):
            axis.delete = True
            axis.title = None
            axis.majorGridlines = None
            axis.scaling.min, axis.scaling.max = lo, hi
        return chart

    @staticmethod
    def bars(ws: Worksheet, anchor: str, title: str, y_title: str, categories, values: Sequence,
             *, titles_from_data: bool = True, width: float = 16, height: float = 7.5,
             horizontal: bool = True, page: "Book | None" = None) -> None:
        """A native bar chart (one bar series per entry of ``values``: a column Reference whose
        first cell is the title, or (title, Reference)), categories from ``categories``, value
        axis at the edge, explicit colours."""
        from openpyxl.chart import BarChart

        chart = BarChart()
        chart.type = "bar" if horizontal else "col"
        chart.title = title
        chart.style = 10
        chart.y_axis.title = y_title
        for axis in (chart.x_axis, chart.y_axis):
            axis.delete = False
            axis.majorTickMark = "out"
            axis.tickLblPos = "low"
        chart.y_axis.number_format = "General"
        if horizontal:
            chart.x_axis.scaling.orientation = "maxMin"   # first category on top
        from openpyxl.chart import Series

        for ref in values:
            if isinstance(ref, tuple):   # (title, values in a row or column)
                chart.series.append(Series(ref[1], title=ref[0]))
            else:
                chart.add_data(ref, titles_from_data=titles_from_data)
        chart.set_categories(categories)
        for k, s in enumerate(chart.series):
            s.graphicalProperties.solidFill = PALETTE[k % len(PALETTE)]
            s.graphicalProperties.line.solidFill = PALETTE[k % len(PALETTE)]
        chart.legend.position = "b"
        if len(values) == 1:
            chart.legend = None
        chart.width, chart.height = width, height
        ws.add_chart(chart, anchor)
        if page is not None:
            page.fill_page(ws, chart)

    def fill_page(self, ws: Worksheet, chart) -> None:
        """Size ``chart`` (anchored in column A, alone on its printed page) to the printed page
        of ``ws`` when the book is saved: as wide as the sheet's columns print across one page
        (the sheet is scaled to the page width, so a fixed 24 cm chart on a 60 cm wide sheet
        printed on a quarter of the page), as high as the page's proportions allow."""
        self._page_charts.append((ws.title, chart))

    # -- printing and column widths --------------------------------------------------------------
    def print_setup(self, ws: Worksheet, *, landscape: bool | None = None,
                    title_rows: int | tuple[int, int] | None = -1,
                    area: str | None = None, row_breaks: Sequence[int] = (), fit_widths: bool = True,
                    matrix: tuple[int, int] | None = None, caption: str | None = None,
                    one_page: bool = False, title_columns: str | None = None,
                    min_scale: float | None = None, footer_pt: float | None = None,
                    corner: tuple[int, int] = (24, 12), chart_row: int | None = None,
                    blocks: Sequence[tuple[int, int]] = ()) -> None:
        """How ``ws`` prints (applied by :meth:`save`; sheets without a call get the defaults).

        Every sheet a person reads prints on A4, scaled to the page width, with the sheet name and
        page number in the footer.  ``landscape`` None chooses by the width of the used columns;
        ``title_rows`` = the last header row repeated on every page (-1: row 1 when it holds bold
        headers, None: none; (first, last): those rows only, a table's header below a title); ``area`` a print area; ``row_breaks`` rows that start a new page
        (e.g. one budget per page); ``one_page``: scaled to fit one page (the Summary).  ``matrix``
        = (rows, columns) of a large matrix at B2: only its top-left corner prints, with
        ``caption`` in the page header saying so (a 156 x 156 V_X would otherwise fill 60 pages).
        With an ``area``, only its columns count for the width (landscape, pages across).
        ``min_scale``: print at this scale (0.8: 11 pt text at 8.8 pt) instead of fitting the page
        width, as many pages across and down as that needs; ``title_columns`` (``"A:B"``) are
        repeated on every page across.  ``footer_pt``: the footer's font size (default 8; the
        footer prints scaled with the page).  ``corner``: the (rows, columns) of a ``matrix`` that
        print.  ``chart_row`` (with ``min_scale``): the row from which a chart anchored in column A
        stands below the table: its rows print as a range of their own, once, not on every page
        across.  ``blocks``: (first row, last row) of blocks (a matrix with its caption) that are
        not split across pages where they fit on one (page breaks before them)."""
        self._print[ws.title] = dict(landscape=landscape, title_rows=title_rows, area=area,
                                     row_breaks=tuple(row_breaks), fit_widths=fit_widths, matrix=matrix,
                                     caption=caption, one_page=one_page, title_columns=title_columns,
                                     min_scale=min_scale, footer_pt=footer_pt, corner=corner,
                                     chart_row=chart_row, blocks=tuple(blocks))

    def _finish_layout(self) -> None:
        """Column widths that fit what each column shows, and the print setup of every sheet."""
        for ws in self.wb.worksheets:
            if ws.sheet_state != "visible":
                continue
            opts = self._print.get(ws.title, {})
            if opts.get("fit_widths", True) and not opts.get("matrix") \
                    and ws.max_row * ws.max_column <= FIT_WIDTH_MAX_CELLS:
                fit_widths(ws)
            kw = {k: v for k, v in opts.items() if k != "fit_widths"}
            if kw.get("footer_pt") is None and self.footer_pt is not None:
                kw["footer_pt"] = self.footer_pt
            page_setup(ws, **kw)
        for title, chart in self._page_charts:
            size_to_page(self.wb[title], chart)

    # -- the Results sheet ---------------------------------------------------------------------
    def results(self, columns: Sequence[str], rows: Iterable[Sequence[str | float]],
                notes: Sequence[str | None] | None = None,
                formats: Sequence[str | None] | None = None) -> Worksheet:
        """The contract's ``Results`` sheet: first row column names, one row per JSON entry.

        Entries that are :class:`Formula` are formulas (the computed columns; a Formula's value is
        cached); any other string is written as text (labels such as point ids), numbers as
        numbers.  ``formats``: the display
        format of each column's formulas (None: :data:`NUMBER_FORMAT`).
        """
        ws = self.sheet(RESULTS)
        self.header(ws, 1, 1, columns, notes)
        for r, row in enumerate(rows, start=2):
            for c, value in enumerate(row, start=1):
                if isinstance(value, Formula):
                    fmt = formats[c - 1] if formats and formats[c - 1] else NUMBER_FORMAT
                    self.formula(ws, r, c, value, fmt=fmt, value=value.value)
                elif isinstance(value, str):
                    self.text(ws, r, c, value)
                else:
                    ws.cell(row=r, column=c).value = value
        for k in range(len(columns)):
            ws.column_dimensions[ws.cell(row=1, column=k + 1).column_letter].width = 12
        ws.freeze_panes = "A2"
        return ws

    @staticmethod
    def flag_unless(ws: Worksheet, ref: str, ok: str) -> None:
        """Cells of ``ref`` (e.g. ``G2:G8``) show in red, bold, whenever their value is not the
        text ``ok``: a state a person must not overlook (conditional formatting, live in Excel
        and LibreOffice)."""
        from openpyxl.formatting.rule import CellIsRule

        escaped = ok.replace('"', '""')
        ws.conditional_formatting.add(ref, CellIsRule(
            operator="notEqual", formula=[f'"{escaped}"'], font=Font(bold=True, color="9C0006"),
            fill=PatternFill(start_color="FFC7CE", end_color="FFC7CE", fill_type="solid")))

    # -- the way back (`cmmwb read`) -------------------------------------------------------------
    def task_info(self, info: dict) -> None:
        """Store the task this workbook was built from, for ``cmmwb read``.

        ``info`` = ``{"kind", "name", "doc"}`` with ``doc`` the task file as a dict (the structure:
        distances, characteristics, notes ...).  :meth:`save` writes it as JSON on the hidden sheet
        ``_task`` together with a snapshot of every input cell's value
        (:func:`generator.workbook.tasksheet.write_task_sheet`); ``cmmwb read`` takes the structure from there
        and every value from the named input cells and input tables.
        """
        self._task_info = dict(info)

    # -- saving --------------------------------------------------------------------------------
    def save(self, path: Path, additions: BookAdditions | None = None) -> Path:
        """Write the workbook atomically (temporary file in the same folder, then rename), with
        the ``additions`` of the build (:class:`BookAdditions`)."""
        path = Path(path)
        additions = additions or BookAdditions()
        for writer in additions.sheets:
            writer(self)
        self._flush_validations()
        self._finish_layout()
        info = self._task_info if self._task_info is not None else additions.info
        if info is not None:
            write_task_sheet(self, info)
        self.wb.move_sheet(INSTRUCTIONS, offset=-self.wb.sheetnames.index(INSTRUCTIONS))
        self.wb.active = 0
        save_atomic(self.wb, path)
        fill(path, self._values, additions.cache)
        return path


def _by_column(cells: list[tuple[int, int]]):
    """(column, sorted unique rows) for a list of (column, row) cells."""
    cols: dict[int, set[int]] = {}
    for column, row in cells:
        cols.setdefault(column, set()).add(row)
    return [(c, sorted(rows)) for c, rows in sorted(cols.items())]


PALETTE = ("1F77B4", "FF7F0E", "2CA02C", "D62728", "9467BD", "8C564B", "E377C2", "7F7F7F")
MARKERS = ("circle", "square", "diamond", "triangle", "x", "star", "dash", "plus")
DASHES = ("solid", "dash", "sysDot", "dashDot", "lgDash", "sysDash", "lgDashDot", "sysDashDot")


@dataclass(frozen=True)
class ChartSeries:
    """One series of :meth:`Book.scatter`: y (and x) as openpyxl ``Reference``s; the title is
    text, or the first cell of ``y`` when ``title_from_data``."""

    title: str | None
    x: object
    y: object
    markers: bool = True
    title_from_data: bool = False
    colour: str | None = None     #: e.g. "000000" for a reference line such as the MPE
    dash: str | None = None       #: a DrawingML dash style; default: distinct per line series
    bold: bool = False            #: a thicker line (the reference line of the chart)
    symbol: str | None = None     #: a fixed, filled marker (e.g. "dash": a limit drawn per item, no line)


class Formula(str):
    """A string that *is* a formula: only these become formulas in :meth:`Book.results`.

    Plain ``str`` values are always written as text, so a point label ``=SUM(A1)`` stays text.
    ``value``: the formula's result as the core computed it (cached in the file), or None.
    """

    value: object

    def __new__(cls, text: str, value: object = None):
        obj = super().__new__(cls, text)
        obj.value = value
        return obj


def save_atomic(wb: Workbook, path: Path) -> Path:
    """Save ``wb`` atomically, its text cells as shared strings (:mod:`.sharedstrings`: the form
    Excel writes, so Excel does not rewrite a book it only opened)."""
    with replacing(path, ".xlsx.tmp") as tmp:
        written = tmp.with_name(tmp.name + ".openpyxl")
        try:
            wb.save(written)
            share_strings(written, tmp)
        finally:
            written.unlink(missing_ok=True)
    return Path(path)
