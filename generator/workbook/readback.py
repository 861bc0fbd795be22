"""Reading a workbook a person filled in, whatever its task kind: typed, checked access to the
cells (:class:`Cells`), the task read so far (:class:`ReadTask`) and the scalar inputs of one
table of the task file (:class:`Section`).  The kinds' own readers (``generator.<kind>.reader``)
build on these; :mod:`generator.reader` puts them together.

Every cell is checked: a number where a number belongs (not text, not a formula, not a date,
finite, inside the cell's data validation range), text or a number where a label belongs, no
merged cells in the input area.  A problem is an :class:`InputError` naming the workbook, sheet
and cell.

openpyxl stores numbers with 16 significant digits and LibreOffice with 15; a value that still
equals the build-time value to those digits is given back at full precision (the snapshot), so
build -> read -> build is the identity, also through a LibreOffice save.
"""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass, field
from pathlib import Path

from openpyxl.cell.cell import MergedCell
from openpyxl.utils import get_column_letter, range_boundaries
from openpyxl.worksheet.formula import ArrayFormula, DataTableFormula

from ..errors import InputError

POINT_HEADER = ["id", "x_mm", "y_mm", "z_mm", "nx", "ny", "nz", "probe"]
CSV_HEADER = ["id", "x", "y", "z", "nx", "ny", "nz", "probe"]
ERROR_VALUES = {"#NULL!", "#DIV/0!", "#VALUE!", "#REF!", "#NAME?", "#NUM!", "#N/A", "#GETTING_DATA"}
MAX_TABLE_ROWS = 100_000
#: a value this close (relative) to the build-time value of its cell is that value, stored with
#: 16 digits by openpyxl and then possibly 15 by LibreOffice (which rounds the 16-digit decimal)
SNAP_REL = 1e-14


@dataclass
class ReadTask:
    """A task read from a workbook: the task file as a dict and the tables it refers to."""

    kind: str
    name: str
    doc: dict
    files: dict[str, str] = field(default_factory=dict)      # file name -> text (points CSV)
    sources: dict[str, str] = field(default_factory=dict)    # task key -> "sheet S, cell C"
    csv_rows: dict[int, str] = field(default_factory=dict)   # CSV line -> "sheet Points, row r"


# -- cells -----------------------------------------------------------------------------------

class Cells:
    """Typed, checked access to the cells of an untrusted workbook."""

    def __init__(self, path: Path, wb, snapshot: dict[str, float]):
        self.path = Path(path)
        self.wb = wb
        self.snapshot = snapshot
        self._merged: dict[str, dict[str, str]] = {}
        self._dv: dict[str, list] = {}

    # where and errors
    @staticmethod
    def where(ws, row: int, column: int) -> str:
        return f"sheet {ws.title}, cell {get_column_letter(column)}{row}"

    def error(self, ws, row: int, column: int, message: str) -> InputError:
        return InputError(message, file=self.path, where=self.where(ws, row, column))

    def sheet(self, title: str):
        if title not in self.wb.sheetnames:
            raise InputError(f"no sheet named {title!r} (sheets: {', '.join(self.wb.sheetnames)}); "
                             "cmmwb reads the sheets it wrote", file=self.path, where=f"sheet {title}")
        return self.wb[title]

    def named(self, name: str):
        """(worksheet, row, column) of the single cell a workbook-level defined name points at."""
        dn = self.wb.defined_names.get(name)
        if dn is None:
            raise InputError(f"the defined name {name!r} is missing (renamed or deleted?); cmmwb reads "
                             "each input by its name", file=self.path, where=f"name {name}")
        try:
            dests = list(dn.destinations)
        except Exception:
            dests = []
        if len(dests) != 1 or not dests[0][1]:
            raise InputError(f"the defined name {name!r} does not point to one cell ({dn.attr_text!r})",
                             file=self.path, where=f"name {name}")
        sheet, ref = dests[0]
        ws = self.sheet(sheet)
        try:
            c0, r0, c1, r1 = range_boundaries(ref.replace("$", ""))
        except ValueError:
            c0 = r0 = c1 = r1 = None
        if c0 is None or (c0, r0) != (c1, r1):
            raise InputError(f"the defined name {name!r} must point to one cell, not {ref}", file=self.path,
                             where=f"name {name}")
        return ws, r0, c0

    def _merged_at(self, ws, row: int, column: int) -> str | None:
        m = self._merged.get(ws.title)
        if m is None:
            m = {}
            for rng in ws.merged_cells.ranges:
                if rng.size["rows"] * rng.size["columns"] > 10_000:
                    m["*"] = str(rng)
                    continue
                for r in range(rng.min_row, rng.max_row + 1):
                    for c in range(rng.min_col, rng.max_col + 1):
                        m[f"{r},{c}"] = str(rng)
            self._merged[ws.title] = m
        hit = m.get(f"{row},{column}")
        if hit is None and "*" in m:
            for rng in ws.merged_cells.ranges:
                if rng.min_row <= row <= rng.max_row and rng.min_col <= column <= rng.max_col:
                    return str(rng)
        return hit

    def raw(self, ws, row: int, column: int):
        """The cell's content; merged cells in the input area are an error."""
        rng = self._merged_at(ws, row, column)
        if rng is not None:
            raise self.error(ws, row, column, f"merged cells ({rng}) in the input area: unmerge them")
        c = ws.cell(row=row, column=column)
        if isinstance(c, MergedCell):  # pragma: no cover - caught above
            raise self.error(ws, row, column, "merged cell in the input area: unmerge it")
        return c

    @staticmethod
    def is_formula(c) -> bool:
        v = c.value
        return (isinstance(v, (ArrayFormula, DataTableFormula)) or
                (c.data_type == "f" and isinstance(v, str)))

    @staticmethod
    def formula_text(c) -> str:
        v = c.value
        if isinstance(v, ArrayFormula):
            return str(v.text)
        return str(v)

    def is_empty(self, ws, row: int, column: int) -> bool:
        c = ws.cell(row=row, column=column)
        if isinstance(c, MergedCell):
            return False
        v = c.value
        return v is None or (isinstance(v, str) and not v.strip() and not self.is_formula(c))

    def number(self, ws, row: int, column: int, what: str, *, required: bool = True) -> float | None:
        """A finite number typed into the cell (checked against the cell's data validation)."""
        c = self.raw(ws, row, column)
        v = c.value
        if self.is_formula(c):
            raise self.error(ws, row, column, f"a formula ({_short(self.formula_text(c))}) where a number "
                             f"belongs ({what}): type the number itself")
        if v is None or (isinstance(v, str) and not v.strip()):
            if required:
                raise self.error(ws, row, column, f"empty: {what} needs a number")
            return None
        if isinstance(v, bool):
            raise self.error(ws, row, column, f"{'TRUE' if v else 'FALSE'} where a number belongs ({what})")
        if isinstance(v, (_dt.datetime, _dt.date, _dt.time, _dt.timedelta)):
            raise self.error(ws, row, column, f"a date or time ({v}) where a number belongs ({what}); "
                             "format the cell as a number")
        if isinstance(v, str):
            s = v.strip()
            if c.data_type == "e" or s in ERROR_VALUES:
                raise self.error(ws, row, column, f"the error value {s} where a number belongs ({what})")
            try:
                float(s.replace(",", "."))
                looks = True
            except ValueError:
                looks = False
            if looks:
                raise self.error(ws, row, column, f"{_short(s)!r} is text, not a number ({what}): retype it "
                                 "as a number (the cell may be formatted as text)")
            raise self.error(ws, row, column, f"{_short(s)!r} is not a number ({what})")
        if not isinstance(v, (int, float)):
            raise self.error(ws, row, column, f"{type(v).__name__} where a number belongs ({what})")
        x = float(v)
        if not math.isfinite(x):
            raise self.error(ws, row, column, f"{x!r} is not a finite number ({what})")
        snap = self.snapshot.get(f"{ws.title}!{get_column_letter(column)}{row}")
        if isinstance(snap, (int, float)) and snap != x and abs(x - snap) <= SNAP_REL * abs(snap):
            x = float(snap)  # stored with 16 (openpyxl) or 15 (LibreOffice) digits: the build-time value
        self._validate(ws, row, column, x, what)
        return x

    def label(self, ws, row: int, column: int, what: str) -> str | None:
        """A text label (point or probe id); numbers are taken as their text; None when empty."""
        c = self.raw(ws, row, column)
        v = c.value
        if self.is_formula(c):
            raise self.error(ws, row, column, f"a formula ({_short(self.formula_text(c))}) where a label "
                             f"belongs ({what}): labels are text (to start one with =, type an apostrophe "
                             "first)")
        if v is None:
            return None
        if isinstance(v, bool) or isinstance(v, (_dt.datetime, _dt.date, _dt.time, _dt.timedelta)):
            raise self.error(ws, row, column, f"{v!r} where a label belongs ({what})")
        if isinstance(v, (int, float)):
            if not math.isfinite(float(v)):
                raise self.error(ws, row, column, f"{v!r} is not a usable label ({what})")
            return str(int(v)) if float(v).is_integer() and abs(v) < 1e15 else repr(float(v))
        s = str(v)
        if c.data_type == "e":
            raise self.error(ws, row, column, f"the error value {s} where a label belongs ({what})")
        s = s.strip()
        if any(ord(ch) < 32 for ch in s):
            raise self.error(ws, row, column, f"{_short(s)!r}: control characters in a label ({what})")
        return s or None

    # data validation of the workbook itself (Book.input writes ranges such as >= 0)
    def _validate(self, ws, row: int, column: int, x: float, what: str) -> None:
        rules = self._dv.get(ws.title)
        if rules is None:
            rules = []
            for dv in getattr(ws.data_validations, "dataValidation", []) or []:
                if dv.type not in ("decimal", "whole"):
                    continue
                try:
                    lo = float(dv.formula1) if dv.formula1 not in (None, "") else None
                    hi = float(dv.formula2) if dv.formula2 not in (None, "") else None
                except (TypeError, ValueError):
                    continue
                rules.append((dv.sqref, dv.operator or "between", lo, hi, dv.type))
            self._dv[ws.title] = rules
        coord = f"{get_column_letter(column)}{row}"
        for sqref, op, lo, hi, typ in rules:
            if coord not in sqref:
                continue
            ok, text = _dv_ok(op, x, lo, hi)
            if ok and typ == "whole" and not x.is_integer():
                ok, text = False, "a whole number"
            if not ok:
                raise self.error(ws, row, column, f"{x:g} is not allowed here ({what} must be {text})")


def _dv_ok(op: str, x: float, lo: float | None, hi: float | None) -> tuple[bool, str]:
    if lo is None:
        return True, ""
    checks = {
        "between": (hi is None or lo <= x <= hi, f"between {lo:g} and {hi:g}" if hi is not None else ""),
        "notBetween": (hi is None or not lo <= x <= hi, f"outside {lo:g} .. {hi:g}" if hi is not None else ""),
        "equal": (x == lo, f"= {lo:g}"), "notEqual": (x != lo, f"not {lo:g}"),
        "greaterThan": (x > lo, f"> {lo:g}"), "lessThan": (x < lo, f"< {lo:g}"),
        "greaterThanOrEqual": (x >= lo, f">= {lo:g}"), "lessThanOrEqual": (x <= lo, f"<= {lo:g}"),
    }
    ok, text = checks.get(op, (True, ""))
    if op == "between" and hi is not None and lo <= -1e306 and hi >= 1e306:
        return True, ""
    return ok, text


def _short(s: str, n: int = 40) -> str:
    s = str(s)
    return s if len(s) <= n else s[:n - 3] + "..."


class Section:
    """A table of the task file whose keys come from named cells."""

    def __init__(self, cells: Cells, rt: ReadTask, doc: dict, section: str):
        self.cells, self.rt, self.section = cells, rt, section
        tbl = doc.get(section)
        if not isinstance(tbl, dict):
            tbl = doc[section] = {}
        self.tbl = tbl

    def scalar(self, key: str, name: str | None = None, *, always: bool = False) -> float:
        """The value of the cell named ``name`` (default ``key``).  A key the task file did not
        have is written only when its value differs from the build-time one (defaults stay
        defaults)."""
        ws, r, c = self.cells.named(name or key)
        x = self.cells.number(ws, r, c, name or key)
        built = self.cells.snapshot.get(f"{ws.title}!{get_column_letter(c)}{r}")
        if always or key in self.tbl or built is None or x != built:
            self.tbl[key] = x
        self.rt.sources[f"[{self.section}] {key}"] = Cells.where(ws, r, c)
        return x
