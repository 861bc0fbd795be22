"""The add-in formulas of a large workbook evaluated in Python: each call of an ``cmmwb.xlfuncs.udf``
function gets the (recalculated) values of the ranges it names, as Excel would pass them."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import openpyxl
from openpyxl.utils import get_column_letter, range_boundaries
from openpyxl.worksheet.formula import ArrayFormula

from cmmwb.generator.pointcloud import large_book
from cmmwb.xlfuncs import udf

_CALL = re.compile(r"^=(?P<name>[A-Za-z_][A-Za-z0-9_]*)\((?P<args>.*)\)$")


def split_args(text: str) -> list[str]:
    args, depth, quoted, cur = [], 0, False, ""
    for ch in text:
        if ch == '"':
            quoted = not quoted
        elif not quoted and ch == "(":
            depth += 1
        elif not quoted and ch == ")":
            depth -= 1
        if ch == "," and depth == 0 and not quoted:
            args.append(cur)
            cur = ""
        else:
            cur += ch
    return args + [cur]


def _range_values(values: dict, ref: str) -> list[list]:
    sheet, addr = ref.rsplit("!", 1)
    sheet = sheet.strip("'").replace("''", "'")
    c0, r0, c1, r1 = range_boundaries(addr.replace("$", ""))
    cells = values[sheet]
    from openpyxl.utils import get_column_letter
    return [[cells.get(f"{get_column_letter(c)}{r}") for c in range(c0, c1 + 1)] for r in range(r0, r1 + 1)]


def evaluate_addin_formulas(book: Path, values: dict, sheet: str = large_book.LIVE) -> dict:
    """{cell: value} of every add-in array formula on ``sheet``, computed by calling the
    function of cmmwb.xlfuncs.udf with the (recalculated) values of the ranges it names."""
    wb = openpyxl.load_workbook(book)
    out = {}
    for row in wb[sheet].iter_rows():
        for c in row:
            if not isinstance(c.value, ArrayFormula):
                continue
            m = _CALL.match(c.value.text)
            assert m, c.value.text
            fn = udf.UDFS[m.group("name").lower()]
            args = []
            for a in split_args(m.group("args")):
                args.append(a[1:-1] if a.startswith('"') else _range_values(values, a))
            result = np.asarray(fn(*args))
            c0, r0, c1, r1 = range_boundaries(c.value.ref)
            assert result.shape == (r1 - r0 + 1, c1 - c0 + 1)
            for dr in range(result.shape[0]):
                for dc in range(result.shape[1]):
                    out[wb[sheet].cell(row=r0 + dr, column=c0 + dc).coordinate] = float(result[dr, dc])
    return out


def _shape(ref: str) -> tuple[int, int]:
    c0, r0, c1, r1 = range_boundaries(ref)
    return r1 - r0 + 1, c1 - c0 + 1


_UDF = re.compile(r"^=(?P<name>cmm_[a-z_]+)\((?P<args>.*)\)$")

_PAPER = re.compile(r"^=MMULT\(TRANSPOSE\((?P<T>[^)]+)\),MMULT\((?P<V>[^,]+),(?P=T)\)\)\*1E\+12$")


def evaluate_live(book: Path, values: dict) -> dict:
    """{cell: value} of every array formula on 'Live_addin': the add-in calls by calling the
    function of cmmwb.xlfuncs.udf with the recalculated values of the ranges they name, then the
    MMULT formulas over those results (numpy)."""
    ws = openpyxl.load_workbook(book)[large_book.LIVE]
    own = {c.coordinate: c.value for row in ws.iter_rows() for c in row
           if isinstance(c.value, (int, float))}                  # fit options: constants

    def rng(ref: str, live: dict) -> list[list]:
        sheet, addr = ref.rsplit("!", 1) if "!" in ref else (large_book.LIVE, ref)
        cells = {**own, **live} if sheet == large_book.LIVE else values[sheet]
        c0, r0, c1, r1 = range_boundaries(addr.replace("$", ""))
        return [[cells.get(f"{get_column_letter(c)}{r}") for c in range(c0, c1 + 1)]
                for r in range(r0, r1 + 1)]

    def put(out: dict, target: str, result) -> None:
        c0, r0, c1, r1 = range_boundaries(target)
        result = np.asarray(result, dtype=object)
        assert result.shape == (r1 - r0 + 1, c1 - c0 + 1), target
        for dr in range(result.shape[0]):
            for dc in range(result.shape[1]):
                out[f"{get_column_letter(c0 + dc)}{r0 + dr}"] = result[dr, dc]

    formulas = [c.value for row in ws.iter_rows() for c in row if isinstance(c.value, ArrayFormula)]
    out: dict = {}
    for f in formulas:
        m = _UDF.match(f.text)
        if m:
            args = [a[1:-1] if a.startswith('"') else rng(a, out) for a in split_args(m["args"])]
            put(out, f.ref, udf.UDFS[m["name"]](*args))
    for f in formulas:
        m = _PAPER.match(f.text)
        if m:
            T = np.array(rng(m["T"], out), dtype=float)
            put(out, f.ref, T.T @ np.array(rng(m["V"], out), dtype=float) @ T * 1e12)
    assert len(out) == sum(np.prod(_shape(f.ref)) for f in formulas), "a formula not evaluated"
    return out
