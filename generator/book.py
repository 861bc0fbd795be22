"""Common parts of every generated workbook: styles, the instruction sheet, named and validated
input cells, formula cells with notes, text cells that never become formulas, the ``Results``
sheet of the contract, sheet protection without password, and atomic saving.

Writers lay out arrays with :class:`Book`; they never touch openpyxl styles directly.
"""

from __future__ import annotations

import math
import textwrap
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator, Sequence

from openpyxl import Workbook
from openpyxl.comments import Comment
from openpyxl.styles import Alignment, Border, Font, PatternFill, Protection, Side
from openpyxl.workbook.defined_name import DefinedName
from openpyxl.worksheet.cell_range import MultiCellRange
from openpyxl.worksheet.datavalidation import DataValidation
from openpyxl.worksheet.worksheet import Worksheet

from . import __version__
from .atomic import replacing
from .xlref import Block, array_formula, block, cell, check_name

INPUT_FILL = PatternFill("solid", fgColor="FFF2CC")      # pale yellow: type here
VALUE_FILL = PatternFill("solid", fgColor="EDEDED")      # grey: values computed by the core
HEADER_FONT = Font(bold=True)
TITLE_FONT = Font(bold=True, size=14)
INPUT_FONT = Font(color="1F4E79")
THIN = Side(style="thin", color="BFBFBF")
BOX = Border(left=THIN, right=THIN, top=THIN, bottom=THIN)
NUMBER_FORMAT = "0.000000"

PARA_WIDTH = 95
RESULTS = "Results"
INSTRUCTIONS = "Instructions"
#: the task description :meth:`Book.save` stores when the writer did not call task_info itself
#: (set by ``generator.cli.build_task`` around ``write_book`` with :func:`describing`)
_TASK_INFO: ContextVar[dict | None] = ContextVar("cmmwb_task_info", default=None)


@contextmanager
def describing(info: dict) -> Iterator[None]:
    """Every :class:`Book` of kind ``info["kind"]`` saved inside this block stores ``info``
    (see :meth:`Book.task_info`)."""
    token = _TASK_INFO.set(info)
    try:
        yield
    finally:
        _TASK_INFO.reset(token)


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
        c = self.formula(ws, row, column, formula, note=note, fmt="General", name=name)
        self._style_input(ws, c, lo, hi)
        return c

    def formula(self, ws: Worksheet, row: int, column: int, formula: str, *, note: str | None = None,
                fmt: str | None = NUMBER_FORMAT, name: str | None = None):
        """A single-cell formula (plain, non-array)."""
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
        return c

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
                series: Sequence["ChartSeries"], *, width: float = 16, height: float = 9) -> None:
        """A native XY chart with explicit colours (LibreOffice draws unstyled markers white)
        and visible axes (openpyxl 3.1 hides them in Excel unless told otherwise)."""
        from openpyxl.chart import ScatterChart, Series

        chart = ScatterChart()
        chart.title = title
        chart.style = 13
        chart.x_axis.title = x_title
        chart.y_axis.title = y_title
        for axis, fmt in ((chart.x_axis, "General"), (chart.y_axis, "General")):
            axis.delete = False
            axis.number_format = fmt
            axis.majorTickMark = "out"
        for k, cs in enumerate(series):
            colour = PALETTE[k % len(PALETTE)]
            if cs.title_from_data:
                s = Series(cs.y, cs.x, title_from_data=True)
            else:
                s = Series(cs.y, cs.x, title=cs.title)
            if cs.markers:
                s.marker.symbol = MARKERS[k % len(MARKERS)]
                s.marker.size = 6
                s.marker.graphicalProperties.solidFill = colour
                s.marker.graphicalProperties.line.solidFill = colour
                s.graphicalProperties.line.noFill = True
            else:
                s.marker.symbol = "none"
                s.graphicalProperties.line.solidFill = colour
                s.graphicalProperties.line.width = 19050  # 1.5 pt
            s.smooth = False
            chart.series.append(s)
        chart.width, chart.height = width, height
        ws.add_chart(chart, anchor)

    # -- the Results sheet ---------------------------------------------------------------------
    def results(self, columns: Sequence[str], rows: Iterable[Sequence[str | float]],
                notes: Sequence[str | None] | None = None) -> Worksheet:
        """The contract's ``Results`` sheet: first row column names, one row per JSON entry.

        Entries that start with ``=`` are formulas (the computed columns); any other string is
        written as text (labels such as point ids), numbers as numbers.
        """
        ws = self.sheet(RESULTS)
        self.header(ws, 1, 1, columns, notes)
        for r, row in enumerate(rows, start=2):
            for c, value in enumerate(row, start=1):
                if isinstance(value, Formula):
                    self.formula(ws, r, c, value)
                elif isinstance(value, str):
                    self.text(ws, r, c, value)
                else:
                    ws.cell(row=r, column=c).value = value
        for k in range(len(columns)):
            ws.column_dimensions[ws.cell(row=1, column=k + 1).column_letter].width = 14
        ws.freeze_panes = "A2"
        return ws

    # -- the way back (`cmmwb read`) -------------------------------------------------------------
    def task_info(self, info: dict) -> None:
        """Store the task this workbook was built from, for ``cmmwb read``.

        ``info`` = ``{"kind", "name", "doc"}`` with ``doc`` the task file as a dict (the structure:
        distances, characteristics, notes ...).  :meth:`save` writes it as JSON on the hidden sheet
        ``_task`` together with a snapshot of every input cell's value
        (:func:`generator.reader.write_task_sheet`); ``cmmwb read`` takes the structure from there
        and every value from the named input cells and input tables.
        """
        self._task_info = dict(info)

    # -- saving --------------------------------------------------------------------------------
    def save(self, path: Path) -> Path:
        """Write the workbook atomically (temporary file in the same folder, then rename)."""
        path = Path(path)
        self._flush_validations()
        info = self._task_info if self._task_info is not None else _TASK_INFO.get()
        if info is not None and info.get("kind") == self.kind:
            from .reader import write_task_sheet

            write_task_sheet(self, info)
        self.wb.move_sheet(INSTRUCTIONS, offset=-self.wb.sheetnames.index(INSTRUCTIONS))
        self.wb.active = 0
        return save_atomic(self.wb, path)


def _by_column(cells: list[tuple[int, int]]):
    """(column, sorted unique rows) for a list of (column, row) cells."""
    cols: dict[int, set[int]] = {}
    for column, row in cells:
        cols.setdefault(column, set()).add(row)
    return [(c, sorted(rows)) for c, rows in sorted(cols.items())]


PALETTE = ("1F77B4", "FF7F0E", "2CA02C", "D62728", "9467BD", "8C564B", "E377C2", "7F7F7F")
MARKERS = ("circle", "square", "diamond", "triangle", "x", "star", "dash", "plus")


@dataclass(frozen=True)
class ChartSeries:
    """One series of :meth:`Book.scatter`: y (and x) as openpyxl ``Reference``s; the title is
    text, or the first cell of ``y`` when ``title_from_data``."""

    title: str | None
    x: object
    y: object
    markers: bool = True
    title_from_data: bool = False


class Formula(str):
    """A string that *is* a formula: only these become formulas in :meth:`Book.results`.

    Plain ``str`` values are always written as text, so a point label ``=SUM(A1)`` stays text.
    """


def save_atomic(wb: Workbook, path: Path) -> Path:
    with replacing(path, ".xlsx.tmp") as tmp:
        wb.save(tmp)
    return Path(path)
