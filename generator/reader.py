"""``cmmwb read``: a workbook a person filled in (in Excel or LibreOffice) back into a task file,
and the hidden sheet ``_task`` every built workbook carries for it.

What comes from where:

* the structure (kind, name, notes, distances, characteristics, datum system, feature options,
  sampling ...) from the hidden sheet ``_task`` that ``cmmwb build`` writes (``Book.task_info``):
  the task file the workbook was built from, as JSON, and a snapshot of every input cell;
* every value from the workbook: scalar inputs by their workbook-level defined names (= the task
  keys: ``sigma_R_um``, ``A_um``, ``probe1_px_mm``, ``S4_x_mm`` ...), tables (points, probes,
  weights, planning values) row by row until the first empty row, so rows added at the end of a
  table are read too.

Every cell is checked: a number where a number belongs (not text, not a formula, not a date,
finite, inside the cell's data validation range), text or a number where a label belongs, no
merged cells in the input area.  A problem is an :class:`InputError` naming the workbook, sheet
and cell.  The task is then validated by the kind's own ``load`` before anything is written, and
its messages are traced back to the sheet and cell the value came from.

openpyxl stores numbers with 16 significant digits and LibreOffice with 15; a value that still
equals the build-time value to those digits is given back at full precision (the snapshot), so
build -> read -> build is the identity, also through a LibreOffice save.
"""

from __future__ import annotations

import copy
import csv
import datetime as _dt
import io
import json
import math
import re
import tempfile
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from openpyxl.cell.cell import MergedCell
from openpyxl.utils import get_column_letter, range_boundaries
from openpyxl.worksheet.formula import ArrayFormula, DataTableFormula

from xlfuncs.errors import ModelError

from . import __version__
from .errors import InputError
from .jobs import available, job
from .taskfile import KINDS, PARAMETER_KEYS, PROBE_OVERRIDES
from .xlref import block, cell, check_name

TASK_SHEET = "_task"          # hidden: the task file's structure (see write_task_sheet)
TASK_INFO_FORMAT = 1
_CHUNK = 30000                # characters per cell of the _task sheet (Excel's limit is 32767)
SNAPSHOT_MAX = 50_000         # input values kept at full precision in _task

#: the sheets `read` takes values from (the others are not even loaded)
INPUT_SHEETS = {"Instructions", "Inputs", "Points", "Local", "Planning", TASK_SHEET}
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


# -- the task information sheet, written by Book.save ------------------------------------------------

def _input_runs(book) -> dict[tuple[str, int], list[list[int]]]:
    """The input cells, found through their data validations (every input is validated):
    ``{(sheet, column): [[first_row, last_row], ...]}``, contiguous runs."""
    runs: dict[tuple[str, int], list[list[int]]] = {}
    for ws in book.wb.worksheets:
        for dv in ws.data_validations.dataValidation:
            for cr in dv.sqref.ranges:
                for column in range(cr.min_col, cr.max_col + 1):
                    runs.setdefault((ws.title, column), []).append([cr.min_row, cr.max_row])
    for key, spans in runs.items():
        spans.sort()
        merged = [spans[0]]
        for r0, r1 in spans[1:]:
            if r0 <= merged[-1][1] + 1:
                merged[-1][1] = max(merged[-1][1], r1)
            else:
                merged.append([r0, r1])
        runs[key] = merged
    return runs


def _name_input_tables(book, runs: dict[tuple[str, int], list[list[int]]]) -> None:
    """Defined names for the input cells the writer did not name (table columns such as the
    point coordinates): ``<sheet>_<column header>`` over each contiguous run of a column,
    e.g. ``Points_x_mm`` = Points!$B$2:$B$53, so that every input has a name."""
    single: set[tuple[str, int, int]] = set()
    spans: list[tuple[str, int, int, int, int]] = []
    for dn in book.wb.defined_names.values():
        try:
            dests = list(dn.destinations)
        except Exception:
            continue
        for sheet, ref in dests:
            try:
                c0, r0, c1, r1 = range_boundaries(ref.replace("$", ""))
            except (TypeError, ValueError):
                continue
            if (c0, r0) == (c1, r1):
                single.add((sheet, r0, c0))
            else:
                spans.append((sheet, c0, r0, c1, r1))

    def named(sheet: str, r: int, c: int) -> bool:
        return (sheet, r, c) in single or any(
            s == sheet and c0 <= c <= c1 and r0 <= r <= r1 for s, c0, r0, c1, r1 in spans)

    for (sheet, column), merged in sorted(runs.items()):
        ws = book.wb[sheet]
        for r0, r1 in merged:
            if r1 - r0 > 10_000:          # a big table column: one name unless it has one
                if not named(sheet, r0, column):
                    _name_run(book, ws, column, r0, r1)
                continue
            start = None
            for r in range(r0, r1 + 2):
                free = r <= r1 and not named(sheet, r, column)
                if free and start is None:
                    start = r
                elif not free and start is not None:
                    _name_run(book, ws, column, start, r - 1)
                    start = None


def _name_run(book, ws, column: int, first: int, last: int) -> None:
    header = None
    for r in range(first - 1, max(0, first - 4), -1):
        v = ws.cell(row=r, column=column).value
        if isinstance(v, str) and v.strip():
            header = v.strip()
            break
    base = re.sub(r"[^A-Za-z0-9_]", "_", f"{ws.title}_{header}") if header else ""
    for name in (base, f"{re.sub(r'[^A-Za-z0-9_]', '_', ws.title)}_{cell(first, column, absolute=False)}"):
        try:
            check_name(name)
        except ValueError:
            continue
        if name not in book.wb.defined_names:
            book.define(name, block(first, column, last - first + 1, 1, ws.title))
            return


def write_task_sheet(book, info: dict) -> None:
    """The hidden sheet ``_task`` of a :class:`~generator.book.Book` (called by ``Book.save``):
    ``info`` as JSON over cells A2, A3 ... with a snapshot of every input value, defined names for
    the input table columns, and a paragraph on the way back in the instructions."""
    if TASK_SHEET in book.wb.sheetnames:
        return
    runs = _input_runs(book)
    _name_input_tables(book, runs)
    inputs: dict[str, float] = {}
    for (sheet, column), merged in runs.items():
        cells = book.wb[sheet]._cells
        letter = get_column_letter(column)
        for r0, r1 in merged:
            for r in range(r0, min(r1, r0 + SNAPSHOT_MAX) + 1):
                c = cells.get((r, column))
                v = None if c is None else c.value
                if isinstance(v, (int, float)) and not isinstance(v, bool):
                    inputs[f"{sheet}!{letter}{r}"] = v
            if len(inputs) > SNAPSHOT_MAX:
                break
    payload = {"format": TASK_INFO_FORMAT, "generator": f"cmmwb {__version__}", **info,
               "inputs": inputs}
    text = json.dumps(payload, ensure_ascii=False, default=str, separators=(",", ":"))
    ws = book.wb.create_sheet(TASK_SHEET)
    ws.sheet_state = "hidden"
    ws.protection.sheet = True
    book.text(ws, 1, 1, "cmmwb task information for `cmmwb read` (JSON over the cells below); "
                        "do not edit")
    for k in range(0, len(text), _CHUNK):
        book.text(ws, 2 + k // _CHUNK, 1, text[k:k + _CHUNK])
    book.gap()
    book.para("The way back to a task file", bold=True)
    book.para(
        "`cmmwb read THIS.xlsx --out TASK.toml` turns this workbook, with the values typed into the "
        "yellow cells (in Excel or LibreOffice), back into a task file and its points table; "
        "`cmmwb build TASK.toml --out DIR` regenerates the workbook with the same numbers.",
        "Structural changes (more points, another probe, another characteristic) go that way: read, edit "
        "the task file, build. Rows added at the end of an input table (sheets are protected without a "
        "password; unprotect to add rows) are read as well. The hidden sheet '_task' holds the parts of the "
        "task file the sheets do not show; leave it in place.")


# -- reading the task information -------------------------------------------------------------------

def task_info(cells: Cells) -> dict:
    """The JSON stored on the hidden ``_task`` sheet (see ``Book.task_info``)."""
    path = cells.path
    if TASK_SHEET not in cells.wb.sheetnames:
        raise InputError(f"no hidden sheet {TASK_SHEET!r}: not a workbook written by cmmwb (cmmwb read "
                         "needs a workbook from cmmwb build or workbook_templates/)", file=path,
                         where=f"sheet {TASK_SHEET}")
    ws = cells.wb[TASK_SHEET]
    parts = []
    row = 2
    while row <= ws.max_row:
        v = ws.cell(row=row, column=1).value
        if v is None:
            break
        parts.append(str(v))
        row += 1
    try:
        info = json.loads("".join(parts))
        if not isinstance(info, dict):
            raise ValueError
    except (ValueError, RecursionError):
        raise InputError("the task information is damaged (not the JSON cmmwb wrote)", file=path,
                         where=f"sheet {TASK_SHEET}") from None
    if info.get("format") != TASK_INFO_FORMAT:
        raise InputError(f"task information of format {info.get('format')!r}; this cmmwb reads format "
                         f"{TASK_INFO_FORMAT}", file=path, where=f"sheet {TASK_SHEET}")
    kind = info.get("kind")
    if kind not in KINDS:
        raise InputError(f"unknown task kind {kind!r}", file=path, where=f"sheet {TASK_SHEET}")
    if kind not in available():
        raise InputError(f"task kind {kind!r} is not available in this installation", file=path)
    if not isinstance(info.get("doc"), dict) or not isinstance(info.get("name"), str):
        raise InputError("the task information is damaged (no task)", file=path, where=f"sheet {TASK_SHEET}")
    snap = info.get("inputs")
    info["inputs"] = {k: v for k, v in snap.items() if isinstance(v, (int, float))} \
        if isinstance(snap, dict) else {}
    return info


# -- reading ---------------------------------------------------------------------------------------

def read_workbook(path: Path, points_file: str = "points.csv") -> ReadTask:
    """Read a workbook; ``points_file`` names the points table the task will refer to."""
    from .safe_xlsx import load

    path = Path(path)
    wb = load(path, INPUT_SHEETS)
    cells = Cells(path, wb, {})
    info = task_info(cells)
    cells.snapshot = info["inputs"]
    kind = info["kind"]
    rt = ReadTask(kind, info["name"], copy.deepcopy(info["doc"]))
    if kind == "pointcloud":
        _read_pointcloud(cells, rt, points_file)
    elif kind == "budget":
        _read_budget(cells, rt)
    else:
        _read_feature(cells, rt, points_file)
    return rt


class _Section:
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


# -- the point-cloud model (pointcloud and feature) -----------------------------------------------

def _read_parameters(cells: Cells, rt: ReadTask) -> None:
    sec = _Section(cells, rt, rt.doc, "parameters")
    for key in PARAMETER_KEYS:
        sec.scalar(key)


def _read_probes(cells: Cells, rt: ReadTask) -> list[str]:
    """The probes table on 'Inputs', anchored at the cell named ``probe1_px_mm``."""
    ws, r0, c0 = cells.named("probe1_px_mm")
    probes = []
    ids: dict[str, int] = {}
    r = r0
    while r < r0 + MAX_TABLE_ROWS:
        if all(cells.is_empty(ws, r, c) for c in range(c0 - 1, c0 + 3 + len(PROBE_OVERRIDES))):
            break
        pid = cells.label(ws, r, c0 - 1, "probe id")
        if pid is None:
            raise cells.error(ws, r, c0 - 1, "empty probe id")
        if pid in ids:
            raise cells.error(ws, r, c0 - 1, f"probe id {pid!r} is also in row {ids[pid]}")
        ids[pid] = r
        p: dict[str, Any] = {"id": pid,
                             "offset_mm": [cells.number(ws, r, c0 + a, f"probe offset p{'xyz'[a]}_mm")
                                           for a in range(3)]}
        for k, key in enumerate(PROBE_OVERRIDES):
            col = c0 + 3 + k
            c = cells.raw(ws, r, col)
            if cells.is_formula(c) and re.fullmatch(rf"=\s*{key}\s*", cells.formula_text(c), re.I):
                continue   # the task-wide default
            v = cells.number(ws, r, col, f"{key} of probe {pid}", required=False)
            if v is not None:
                p[key] = v
        n = len(probes) + 1
        for key in (f"[[probes]] #{n}", f"[[[probes]] #{n}]"):
            rt.sources[key] = f"sheet {ws.title}, row {r}"
        probes.append(p)
        r += 1
    if not probes:
        raise cells.error(ws, r0, c0 - 1, "no probes in the probes table")
    rt.doc["probes"] = probes
    return list(ids)


def _read_points_table(cells: Cells, probe_ids: list[str]) -> tuple[list[list], list[int]]:
    """The 'Points' table: rows of [id, x, y, z, nx, ny, nz, probe] and their sheet rows."""
    ws = cells.sheet("Points")
    header = [ws.cell(row=1, column=c).value for c in range(1, len(POINT_HEADER) + 1)]
    if header != POINT_HEADER:
        raise InputError(f"the header row must be {', '.join(POINT_HEADER)}; found "
                         f"{', '.join(str(h) for h in header)}", file=cells.path, where="sheet Points, row 1")
    rows, where = [], []
    seen: dict[str, int] = {}
    r = 2
    while r < 2 + MAX_TABLE_ROWS:
        if all(cells.is_empty(ws, r, c) for c in range(1, 9)):
            break
        label = cells.label(ws, r, 1, "point id")
        if label is None:
            raise cells.error(ws, r, 1, "empty point id")
        if label in seen:
            raise cells.error(ws, r, 1, f"point id {label!r} is also in row {seen[label]}")
        seen[label] = r
        names = ("x_mm", "y_mm", "z_mm", "nx", "ny", "nz")
        vals = [cells.number(ws, r, 2 + k, f"{names[k]} of point {label}") for k in range(6)]
        probe = cells.label(ws, r, 8, f"probe of point {label}")
        if probe is None and len(probe_ids) == 1:
            probe = probe_ids[0]
        if probe is None:
            raise cells.error(ws, r, 8, f"no probe given for point {label} and the task has several "
                              f"({', '.join(probe_ids)})")
        if probe not in probe_ids:
            raise cells.error(ws, r, 8, f"unknown probe {probe!r} (the probes table has "
                              f"{', '.join(probe_ids)})")
        rows.append([label, *vals, probe])
        where.append(r)
        r += 1
    if not rows:
        raise InputError("no points", file=cells.path, where="sheet Points, row 2")
    return rows, where


def _points_csv(rows: list[list]) -> str:
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(CSV_HEADER)
    for row in rows:
        w.writerow([row[0], *(repr(float(v)) for v in row[1:7]), row[7]])
    return out.getvalue()


FORMULA_LIKE = ("=", "+", "-", "@")


def _use_points_file(rt: ReadTask, rows: list[list], where: list[int], points_file: str) -> None:
    """Points go to a CSV file beside the task, unless a label starts with = + - @: a spreadsheet
    program opening that CSV would take it for a formula, so those points stay in the task file
    (``[points] rows``), where no program evaluates anything."""
    if any(str(row[0]).startswith(FORMULA_LIKE) or str(row[7]).startswith(FORMULA_LIKE) for row in rows):
        rt.doc["points"] = {"rows": [dict(zip(CSV_HEADER, [row[0], *(float(v) for v in row[1:7]), row[7]]))
                                     for row in rows]}
        for n, r in enumerate(where, start=1):
            rt.sources[f"[points] rows #{n}"] = f"sheet Points, row {r}"
    else:
        rt.files[points_file] = _points_csv(rows)
        rt.doc["points"] = {"file": points_file}
        rt.csv_rows = {line: f"sheet Points, row {r}" for line, r in enumerate(where, start=2)}
    rt.sources["[points]"] = "sheet Points"


def _read_pointcloud(cells: Cells, rt: ReadTask, points_file: str) -> None:
    _read_parameters(cells, rt)
    if "mpe" in rt.doc:
        sec = _Section(cells, rt, rt.doc, "mpe")
        for key in ("A_um", "B_mm", "K", "P_mm", "L_max_mm"):
            sec.scalar(key)
    else:
        _Section(cells, rt, rt.doc, "task").scalar("K")
    probe_ids = _read_probes(cells, rt)
    rows, where = _read_points_table(cells, probe_ids)
    _use_points_file(rt, rows, where, points_file)


# -- budget ------------------------------------------------------------------------------------------

def _read_budget(cells: Cells, rt: ReadTask) -> None:
    doc = rt.doc
    sec = _Section(cells, rt, doc, "mpe")
    for key in ("A_um", "B_mm", "b", "k"):
        sec.scalar(key)
    stored = doc.get("points")
    if not isinstance(stored, dict) or not stored:
        raise InputError("the task information has no points", file=cells.path, where=f"sheet {TASK_SHEET}")
    first = next(iter(stored))
    ws, r0, c0 = cells.named(f"{first}_x_mm")
    points: dict[str, list[float]] = {}
    r = r0
    while r < r0 + MAX_TABLE_ROWS:
        if all(cells.is_empty(ws, r, c) for c in range(c0, c0 + 3)):
            break   # the table ends at the first row without coordinates
        name = cells.label(ws, r, c0 - 1, "point name")
        if name is None:
            raise cells.error(ws, r, c0 - 1, "empty point name")
        if name in points:
            raise cells.error(ws, r, c0 - 1, f"point {name!r} is listed twice")
        points[name] = [cells.number(ws, r, c0 + a, f"{name}_{'xyz'[a]}_mm") for a in range(3)]
        rt.sources[f"[points] {name}"] = f"sheet {ws.title}, row {r}"
        r += 1
    doc["points"] = points
    chars = doc.get("characteristics")
    if isinstance(chars, list):
        for n, ch in enumerate(chars, start=1):
            if isinstance(ch, dict) and ch.get("model") == "position" and isinstance(ch.get("name"), str):
                teds = []
                for i in (1, 2):
                    ws, r, c = cells.named(f"{ch['name']}_ted{i}_mm")
                    teds.append(cells.number(ws, r, c, f"{ch['name']}_ted{i}_mm"))
                    rt.sources[f"[[characteristics]] #{n} key 'ted_mm'"] = Cells.where(ws, r, c)
                ch["ted_mm"] = teds


# -- feature -----------------------------------------------------------------------------------------

def _read_feature(cells: Cells, rt: ReadTask, points_file: str) -> None:
    doc = rt.doc
    _read_parameters(cells, rt)
    probe_ids = _read_probes(cells, rt)
    rows, where = _read_points_table(cells, probe_ids)
    built_rows = sum(1 for k in cells.snapshot if k.startswith("Points!B"))
    unchanged = len(rows) == built_rows and all(
        cells.snapshot.get(f"Points!{get_column_letter(2 + k)}{r}") == row[1 + k]
        for row, r in zip(rows, where) for k in range(6))
    sampling = doc.get("sampling")
    if isinstance(sampling, dict) and unchanged and [row[7] for row in rows] == [
            sampling.get("probe", probe_ids[0])] * len(rows):
        pass  # the sampled points as built: keep the strategy
    else:
        if isinstance(sampling, dict):
            doc.pop("sampling")
            if isinstance(doc.get("planning"), dict):
                doc["planning"].setdefault("pattern", sampling.get("pattern"))
        _use_points_file(rt, rows, where, points_file)
    _read_weights(cells, rt, [row[0] for row in rows])
    if isinstance(doc.get("planning"), dict):
        _read_planning(cells, rt, built_rows)


def _read_weights(cells: Cells, rt: ReadTask, labels: list[str]) -> None:
    """Weights w_i (Forbes 2022 eq. (11)) from column 'w' of the 'Local' sheet, by point id."""
    ws = cells.sheet("Local")
    if [ws.cell(row=1, column=c).value for c in (1, 2)] != ["id", "w"]:
        raise InputError("the header row must start with id, w", file=cells.path, where="sheet Local, row 1")
    wanted = set(labels)
    weights: dict[str, float] = {}
    r = 2
    while r < 2 + MAX_TABLE_ROWS and not (cells.is_empty(ws, r, 1) and cells.is_empty(ws, r, 2)):
        label = cells.label(ws, r, 1, "point id")
        w = cells.number(ws, r, 2, f"weight of point {label}")
        if w < 0:
            raise cells.error(ws, r, 2, f"{w:g} is not allowed here (a weight w is >= 0)")
        if label in wanted and w != 1.0:
            weights[label] = w
        rt.sources[f"[feature] weights.{label}"] = Cells.where(ws, r, 2)
        r += 1
    feature = rt.doc.setdefault("feature", {})
    if weights:
        feature["weights"] = weights
    else:
        feature.pop("weights", None)


def _read_planning(cells: Cells, rt: ReadTask, built_points: int) -> None:
    """Planning geometry and m_points (named cells on 'Planning') and the sweep values."""
    plan = rt.doc["planning"]
    ws = cells.sheet("Planning")
    named: dict[str, float] = {}
    for name, dn in cells.wb.defined_names.items():
        try:
            dests = list(dn.destinations)
        except Exception:
            continue
        # geometry keys and m_points; not the names of input tables (Planning_<column>)
        if len(dests) == 1 and dests[0][0] == "Planning" and ":" not in dests[0][1] and \
                not name.startswith("Planning_"):
            wsn, r, c = cells.named(name)
            named[name] = cells.number(wsn, r, c, name)
            rt.sources[f"[planning] {name}"] = Cells.where(wsn, r, c)
    pairs = {"theta_deg": ("theta_from_deg", "theta_to_deg"), "phi_range_deg": ("phi_from_deg", "phi_to_deg")}
    for key, (a, b) in pairs.items():
        if a in named and b in named:
            plan[key] = [named.pop(a), named.pop(b)]
    if "m_points" in named:
        m = named.pop("m_points")
        ws_m, r, c = cells.named("m_points")
        if not m.is_integer() or m < 1:
            raise cells.error(ws_m, r, c, f"{m:g}: m_points is a whole number >= 1")
        if "m_points" in plan or int(m) != built_points:
            plan["m_points"] = int(m)
    plan.update(named)
    sweep = plan.get("sweep")
    if isinstance(sweep, str):
        top = None
        for r in range(1, min(ws.max_row, 200) + 1):
            b = ws.cell(row=r, column=2).value
            if ws.cell(row=r, column=1).value == sweep and isinstance(b, str) and b.startswith("s("):
                top = r
                break
        if top is None:
            raise InputError(f"no table with the sweep values {sweep!r}", file=cells.path, where="sheet Planning")
        values = []
        r = top + 1
        while r < top + 1 + MAX_TABLE_ROWS and not cells.is_empty(ws, r, 1):
            values.append(cells.number(ws, r, 1, f"{sweep} (planning sweep)"))
            r += 1
        plan["values"] = values
        rt.sources["[planning] values"] = f"sheet Planning, cells A{top + 1}:A{r - 1}"


# -- validation and writing -------------------------------------------------------------------------

def validate(rt: ReadTask, book: Path, toml_name: str = "task.toml") -> None:
    """Load and compute the task as ``cmmwb build`` would (so that what ``read`` writes builds);
    messages point back to the workbook's cells."""
    import warnings

    import tomli_w

    mod = job(rt.kind)
    with tempfile.TemporaryDirectory(prefix="cmmwb_read_") as tmp:
        tmp = Path(tmp)
        for name, text in rt.files.items():
            (tmp / name).write_text(text, encoding="utf-8")
        toml = tmp / toml_name
        try:
            text = tomli_w.dumps(rt.doc)
        except (TypeError, ValueError, RecursionError) as e:
            raise InputError(f"the task information is damaged ({type(e).__name__})", file=book,
                             where=f"sheet {TASK_SHEET}") from None
        toml.write_text(text, encoding="utf-8")
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                mod.compute(mod.load(toml, tomllib.loads(text)))
        except InputError as e:
            raise _traced(e, rt, book, tmp) from None
        except ModelError as e:
            raise InputError(str(e), file=book) from None


def _traced(e: InputError, rt: ReadTask, book: Path, tmp: Path) -> InputError:
    where = e.where or ""
    if e.file and Path(e.file).parent == tmp and Path(e.file).suffix.lower() == ".csv":
        m = re.match(r"line ([0-9]+)(.*)$", where)
        if m and int(m.group(1)) in rt.csv_rows:
            return InputError(e.message, file=book, where=rt.csv_rows[int(m.group(1))] + m.group(2))
        return InputError(e.message, file=book, where="sheet Points")
    src = rt.sources.get(where)
    if src is None:
        for key in sorted(rt.sources, key=len, reverse=True):
            if where.startswith(key):
                src = rt.sources[key]
                break
    loc = f"{src} ({where})" if src else (f"{where} (as read from the workbook)" if where else None)
    return InputError(e.message, file=book, where=loc)


def task_text(rt: ReadTask, book: Path) -> str:
    """The task file: a short header and the TOML."""
    import tomli_w

    head = (f"# cmmwb {__version__}: task read from {Path(book).name} (kind {rt.kind!r}).\n"
            "# Build with:  cmmwb build THIS.toml --out DIR\n\n")
    return head + _ARRAY.sub(_one_line, tomli_w.dumps(rt.doc))


_ARRAY = re.compile(r"\[\n((?:    [^\n\[\]{}]*,\n)+)\]")


def _one_line(m: re.Match) -> str:
    """Short arrays of scalars on one line: ``[0.0, 0.0, -20.0]``."""
    items = [line.strip()[:-1] for line in m.group(1).splitlines()]
    text = "[" + ", ".join(items) + "]"
    return text if len(text) <= 100 else m.group(0)
