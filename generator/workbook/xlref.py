"""Formula-text helpers: cell and block addresses, sheet quoting, array formulas, defined names.

Every workbook writer builds its formulas with these few functions instead of pasting strings,
so that the rules of ``docs/engines.md`` hold everywhere:

* static addresses (no OFFSET/INDEX), absolute by default;
* array arithmetic only inside array formulas (LibreOffice gives #VALUE! otherwise);
* ``-(x^2)`` rather than ``-x^2`` (Excel precedence);
* sheet names quoted when needed.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from openpyxl.utils import get_column_letter
from openpyxl.worksheet.formula import ArrayFormula

_PLAIN_SHEET = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_NAME = re.compile(r"^[A-Za-z_\\][A-Za-z0-9_.]*$")
_CELL_LIKE = re.compile(r"^[A-Za-z]{1,3}[0-9]+$|^[RrCc][0-9]*$")


def col(c: int) -> str:
    """Column letters of 1-based column index ``c``."""
    return get_column_letter(c)


def quote_sheet(sheet: str) -> str:
    """A sheet name as it must appear in a formula (quoted unless plain)."""
    if _PLAIN_SHEET.match(sheet) and not _CELL_LIKE.match(sheet):
        return sheet
    return "'" + sheet.replace("'", "''") + "'"


def cell(row: int, column: int, sheet: str | None = None, absolute: bool = True) -> str:
    """Address of one cell, e.g. ``cell(2, 3, 'Points') == 'Points!$C$2'``."""
    if row < 1 or column < 1:
        raise ValueError(f"cell ({row}, {column}) outside the sheet")
    d = "$" if absolute else ""
    ref = f"{d}{col(column)}{d}{row}"
    return f"{quote_sheet(sheet)}!{ref}" if sheet else ref


def block(row: int, column: int, n_rows: int, n_cols: int, sheet: str | None = None,
          absolute: bool = True) -> str:
    """Address of the ``n_rows`` x ``n_cols`` block whose top-left cell is (row, column)."""
    if n_rows < 1 or n_cols < 1:
        raise ValueError("a block needs at least one row and one column")
    top = cell(row, column, absolute=absolute)
    if n_rows == 1 and n_cols == 1:
        ref = top
    else:
        ref = f"{top}:{cell(row + n_rows - 1, column + n_cols - 1, absolute=absolute)}"
    return f"{quote_sheet(sheet)}!{ref}" if sheet else ref


@dataclass(frozen=True)
class Block:
    """A rectangular block of cells on a sheet (1-based top-left, size)."""

    sheet: str
    row: int
    column: int
    n_rows: int
    n_cols: int

    @property
    def ref(self) -> str:
        """Absolute address with the sheet, for use from any sheet."""
        return block(self.row, self.column, self.n_rows, self.n_cols, self.sheet)

    @property
    def local(self) -> str:
        """Absolute address without the sheet (the range an array formula occupies)."""
        return block(self.row, self.column, self.n_rows, self.n_cols)

    def sub(self, r: int, c: int, n_rows: int = 1, n_cols: int = 1) -> "Block":
        """The sub-block at 0-based offset (r, c) inside this block."""
        if r < 0 or c < 0 or r + n_rows > self.n_rows or c + n_cols > self.n_cols:
            raise ValueError("sub-block outside the block")
        return Block(self.sheet, self.row + r, self.column + c, n_rows, n_cols)

    def cell(self, r: int, c: int = 0) -> str:
        """Absolute address (with sheet) of the cell at 0-based offset (r, c)."""
        return self.sub(r, c).ref

    def rows(self) -> range:
        return range(self.row, self.row + self.n_rows)

    def columns(self) -> range:
        return range(self.column, self.column + self.n_cols)


def array_formula(target: Block, formula: str) -> ArrayFormula:
    """A legacy (CSE) array formula over ``target``; ``formula`` starts with ``=``."""
    if not formula.startswith("="):
        raise ValueError("a formula starts with '='")
    # the ref attribute must be relative ("B8:D10"): LibreOffice ignores "$B$8:$D$10"
    return ArrayFormula(block(target.row, target.column, target.n_rows, target.n_cols, absolute=False),
                        formula)


def check_name(name: str) -> str:
    """A valid workbook-level defined name (not a cell address, no spaces)."""
    if not _NAME.match(name) or _CELL_LIKE.match(name) or len(name) > 255:
        raise ValueError(f"{name!r} is not a valid defined name")
    return name


def fn(name: str, *args: str) -> str:
    """A function call ``NAME(a, b, ...)`` (no leading ``=``)."""
    return f"{name}({','.join(args)})"


def norm_s_dist(z: str, cumulative: bool = True) -> str:
    """The standard normal distribution Φ(z) (``cumulative``) or density φ(z) of the formula
    text ``z``, as every engine computes it: ``_xlfn.NORM.DIST(z,0,1,TRUE)``.  Excel 2010+ has
    NORM.S.DIST too, but Gnumeric 1.12.55 does not (#NAME?); NORM.DIST with mean 0 and standard
    deviation 1 gives the same numbers as NORM.S.DIST in `formulas` and LibreOffice
    (docs/engines.md)."""
    return f"_xlfn.NORM.DIST({z},0,1,{'TRUE' if cumulative else 'FALSE'})"
