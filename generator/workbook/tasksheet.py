"""The hidden sheet ``_task`` every built workbook carries (written by :meth:`Book.save
<generator.workbook.book.Book.save>`): the task file the workbook was built from, as JSON, and a
snapshot of every input cell, so that ``cmmwb read`` (:mod:`generator.reader`) can turn the
workbook back into a task file.
"""

from __future__ import annotations

import json
import re

from openpyxl.utils import get_column_letter, range_boundaries

from .. import __version__
from .xlref import block, cell, check_name

TASK_SHEET = "_task"          # hidden: the task file's structure (see write_task_sheet)
TASK_INFO_FORMAT = 1
_CHUNK = 30000                # characters per cell of the _task sheet (Excel's limit is 32767)
SNAPSHOT_MAX = 50_000         # input values kept at full precision in _task


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
    """The hidden sheet ``_task`` of a :class:`~generator.workbook.book.Book` (called by ``Book.save``):
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
