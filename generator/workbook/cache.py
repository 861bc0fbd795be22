"""Cached values in a generated workbook, for programs that do not calculate.

openpyxl writes formulas without results (``<c><f>..</f><v/></c>``), so a previewer, pandas or
openpyxl with ``data_only=True`` sees empty cells.  A writer gives the value of a formula cell
when it writes the formula (``Book.formula(..., value=...)``, a ``Formula`` with a value in a
``Results`` row: the numbers the core computed, which the tests hold equal to what ``formulas``
and LibreOffice compute, to 1e-9), as XlsxWriter's ``write_formula(..., value)`` does;
``Book.save`` then writes them into the saved file (:func:`fill`), in one of the modes

``results`` (default, fast)
    the values the writers gave, and the cells that a formula with a given value merely refers
    to (``=Budget!$D$5`` -> ``Budget!D5`` gets the same value);
``all``
    every formula cell and every cell of every array formula, as the ``formulas`` engine computes
    them (slow for big workbooks: about 25 s for the m = 52 step gauge);
``none``
    nothing.

Excel recalculates on load anyway (openpyxl sets ``fullCalcOnLoad``); LibreOffice keeps cached
values of formulas it is not told to recompute, which is why the values written here must be
the engines' values and nothing else.  Strings are written as formula *results* (``t="str"``),
never as formulas.  :func:`store` does the same for a saved file from a list of ``Results`` rows
(the diagnosis and calibration books).
"""

from __future__ import annotations

import math
import re
import zipfile
from pathlib import Path
from typing import Any
from xml.sax.saxutils import escape

from openpyxl.utils import column_index_from_string, get_column_letter, range_boundaries

from .atomic import replacing
from .cached_values import sheet_parts
from .sharedstrings import texts

MODES = ("results", "all", "none")
ERRORS = {"#NULL!", "#DIV/0!", "#VALUE!", "#REF!", "#NAME?", "#NUM!", "#N/A", "#GETTING_DATA"}

_ROW = re.compile(rb"<row\b([^>]*?)(/>|>(.*?)</row>)", re.S)
_CELL = re.compile(rb"<c\b([^>]*?)(/>|>(.*?)</c>)", re.S)
_ATTR_R = re.compile(rb'\br="([A-Z]+)([0-9]+)"')
_ATTR_T = re.compile(rb'\s+t="[^"]*"')
_F = re.compile(rb"<f\b([^>]*?)(?:/>|>(.*?)</f>)", re.S)
_V = re.compile(rb"<v\s*/>|<v>.*?</v>|<v\s[^>]*?>.*?</v>", re.S)
_REF_ATTR = re.compile(rb'\bref="([A-Z]+[0-9]+(?::[A-Z]+[0-9]+)?)"')
_ARRAY = re.compile(rb'\bt="array"')
_SINGLE_REF = re.compile(r"^=?(?:(?:'((?:[^']|'')+)'|([A-Za-z_][A-Za-z0-9_.]*))!)?\$?([A-Z]{1,3})\$?([0-9]+)$")
_HEADER_TEXT = re.compile(rb"<t[^>]*>(.*?)</t>", re.S)
_SHARED = re.compile(rb'\bt="s"')
_V_TEXT = re.compile(rb"<v>([0-9]+)</v>")


# -- what the Results sheet holds -------------------------------------------------------------

def results_table(results: dict) -> list[dict[str, Any]]:
    """The rows of a ``Results`` sheet given as ``{"rows": [{column name: value}]}`` (the
    diagnosis and calibration books build them from the numbers of their JSON)."""
    return list(results["rows"])


# -- the xlsx parts ------------------------------------------------------------------------------

def _unescape(s: str) -> str:
    return (s.replace("&lt;", "<").replace("&gt;", ">").replace("&quot;", '"').replace("&apos;", "'")
            .replace("&amp;", "&"))


def _value_xml(value) -> tuple[bytes, bytes] | None:
    """(type attribute, <v> element) of a cached value, or None when there is nothing to write."""
    if value is None:
        return None
    if isinstance(value, bool):
        return b' t="b"', b"<v>%d</v>" % int(value)
    if isinstance(value, (int, float)):
        v = float(value)
        if not math.isfinite(v):
            return b' t="e"', b"<v>#NUM!</v>"
        text = repr(int(value)) if isinstance(value, int) else repr(v)
        return b"", b"<v>" + text.encode() + b"</v>"
    s = str(value)
    if s in ERRORS:
        return b' t="e"', b"<v>" + s.encode() + b"</v>"
    return b' t="str"', b"<v>" + escape(s).encode("utf-8") + b"</v>"


def _set_value(attrs: bytes, body: bytes | None, value) -> bytes:
    """A ``<c>`` element with ``value`` as its cached value (formula, style kept)."""
    vx = _value_xml(value)
    attrs = _ATTR_T.sub(b"", attrs)
    body = _V.sub(b"", body or b"")
    if vx is None:
        return b"<c" + attrs + (b">" + body + b"</c>" if body else b"/>")
    t, v = vx
    return b"<c" + attrs + t + b">" + body + v + b"</c>"


def _rewrite(xml: bytes, values: dict[str, Any], *, arrays: bool) -> tuple[bytes, int]:
    """Write ``values`` (coordinate -> value) into the formula cells of one sheet.  With
    ``arrays`` also into the cells covered by array formulas, creating them when absent."""
    start = xml.find(b"<sheetData")
    end = xml.find(b"</sheetData>")
    if start < 0 or end < 0:
        return xml, 0
    open_end = xml.index(b">", start) + 1
    data = xml[open_end:end]
    covered: set[str] = set()
    if arrays:
        for m in _F.finditer(data):
            ref = _REF_ATTR.search(m.group(1)) if _ARRAY.search(m.group(1)) else None
            if ref:
                c0, r0, c1, r1 = range_boundaries(ref.group(1).decode())
                covered.update(f"{get_column_letter(c)}{r}" for r in range(r0, r1 + 1)
                               for c in range(c0, c1 + 1))
        covered &= set(values)
    rows: dict[int, tuple[bytes, list[tuple[int, bytes]]]] = {}
    count = 0
    for rm in _ROW.finditer(data):
        rattrs = rm.group(1)
        rnum = int(re.search(rb'\br="([0-9]+)"', rattrs).group(1))
        cells: list[tuple[int, bytes]] = []
        for cm in _CELL.finditer(rm.group(3) or b""):
            attrs, body = cm.group(1), cm.group(3)
            am = _ATTR_R.search(attrs)
            coord = (am.group(1) + am.group(2)).decode() if am else ""
            col = column_index_from_string(am.group(1).decode()) if am else 0
            if coord in values and ((body is not None and b"<f" in body) or coord in covered):
                cells.append((col, _set_value(attrs, body, values[coord])))
                count += 1
            else:
                cells.append((col, cm.group(0)))
            covered.discard(coord)
        rows[rnum] = (rattrs, cells)
    for coord in covered:  # array cells openpyxl did not write
        m = re.match(r"([A-Z]+)([0-9]+)$", coord)
        rnum, col = int(m.group(2)), column_index_from_string(m.group(1))
        rattrs, cells = rows.setdefault(rnum, (b' r="%d"' % rnum, []))
        cells.append((col, _set_value(b' r="' + coord.encode() + b'"', None, values[coord])))
        count += 1
    body = b"".join(b"<row" + rows[r][0] + b">" + b"".join(c for _, c in sorted(rows[r][1], key=lambda t: t[0]))
                    + b"</row>" for r in sorted(rows))
    return xml[:open_end] + body + xml[end:], count


def _results_header(xml: bytes, shared: list[str]) -> dict[str, str]:
    """Column name -> column letter of the Results sheet's first row (shared strings, looked up
    in ``shared``, or inline strings)."""
    for rm in _ROW.finditer(xml):
        if re.search(rb'\br="1"', rm.group(1)) is None:
            continue
        out = {}
        for cm in _CELL.finditer(rm.group(3) or b""):
            am = _ATTR_R.search(cm.group(1))
            if not am:
                continue
            if _SHARED.search(cm.group(1)):
                v = _V_TEXT.search(cm.group(3) or b"")
                if v and int(v.group(1)) < len(shared):
                    out[shared[int(v.group(1))]] = am.group(1).decode()
                continue
            t = _HEADER_TEXT.search(cm.group(3) or b"")
            if t:
                out[_unescape(t.group(1).decode("utf-8"))] = am.group(1).decode()
        return out
    return {}


def _formulas_of(xml: bytes, coords: set[str]) -> dict[str, str]:
    out = {}
    for cm in _CELL.finditer(xml):
        am = _ATTR_R.search(cm.group(1))
        if not am or cm.group(3) is None:
            continue
        coord = (am.group(1) + am.group(2)).decode()
        if coord in coords:
            f = _F.search(cm.group(3))
            if f and f.group(2) is not None:
                out[coord] = _unescape(f.group(2).decode("utf-8"))
    return out


# -- entry points --------------------------------------------------------------------------------

def fill(path: Path, values: dict[str, dict[str, Any]], mode: str = "results") -> int:
    """Write cached values into the workbook at ``path`` (rewritten atomically): ``values`` =
    {sheet: {coordinate: value}} of formula cells (mode ``results``), or every formula cell as
    ``formulas`` computes it (mode ``all``), or nothing (``none``).  Returns the number of cells
    that got a value."""
    if mode not in MODES:
        raise ValueError(f"unknown cache mode {mode!r}; choose one of {', '.join(MODES)}")
    if mode == "none":
        return 0
    path = Path(path)
    with zipfile.ZipFile(path) as z:
        parts = sheet_parts(z)
        if mode == "all":
            from .recalc import recalculate

            values = recalculate(path, "formulas")
            per_part = {parts[s]: v for s, v in values.items() if s in parts}
            arrays = True
        else:
            per_part = {}
            for sheet, vals in values.items():
                if sheet in parts:
                    per_part.setdefault(parts[sheet], {}).update(vals)
            arrays = False
        new = {}
        count = 0
        for part, vals in per_part.items():
            if vals:
                new[part], n = _rewrite(z.read(part), vals, arrays=arrays)
                count += n
        if new:
            _replace_parts(path, z, new)
    return count


def referred(formula: str, value: Any, sheet: str) -> tuple[str, str] | None:
    """(sheet, coordinate) of the one cell a formula merely refers to (``=Budget!$D$5``), which
    then holds the same value; None for any other formula."""
    m = _SINGLE_REF.match(formula)
    if not m:
        return None
    return ((m.group(1) or "").replace("''", "'") or m.group(2) or sheet), f"{m.group(3)}{m.group(4)}"


def store(path: Path, kind: str, results: dict, mode: str = "results",
          extra: dict[str, dict[str, Any]] | None = None) -> int:
    """Cached values of a saved workbook whose ``Results`` rows are ``results["rows"]``
    (:func:`results_table`; ``kind`` names the book, it selects nothing), with the values of
    other formula cells in ``extra`` = {sheet: {coordinate: value}}."""
    if mode not in MODES:
        raise ValueError(f"unknown cache mode {mode!r}; choose one of {', '.join(MODES)}")
    if mode != "results":
        return fill(path, {}, mode)
    with zipfile.ZipFile(path) as z:
        parts = sheet_parts(z)
        values = _results_values(z, parts, results)
    for sheet, vals in (extra or {}).items():
        values.setdefault(sheet, {}).update(vals)
    return fill(path, values)


def _results_values(z: zipfile.ZipFile, parts: dict[str, str], results: dict) -> dict[str, dict[str, Any]]:
    if "Results" not in parts:
        return {}
    xml = z.read(parts["Results"])
    header = _results_header(xml, texts(z))
    values: dict[str, Any] = {}
    for r, row in enumerate(results_table(results), start=2):
        for name, value in row.items():
            if name in header:
                values[f"{header[name]}{r}"] = value
    out: dict[str, dict[str, Any]] = {"Results": values}
    # one hop: Results cells that are plain references to one cell give that cell the same value
    for coord, formula in _formulas_of(xml, set(values)).items():
        hop = referred(formula, values[coord], "Results")
        if hop is not None and hop[0] in parts:
            out.setdefault(hop[0], {})[hop[1]] = values[coord]
    return out


def _replace_parts(path: Path, z: zipfile.ZipFile, new: dict[str, bytes]) -> None:
    """Copy the archive with some parts replaced; atomic rename over ``path``."""
    with replacing(path, ".xlsx.tmp") as tmp:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as out:
            for info in z.infolist():
                data = new.get(info.filename)
                if data is None:
                    data = z.read(info)
                zi = zipfile.ZipInfo(info.filename, date_time=info.date_time)
                zi.compress_type = zipfile.ZIP_DEFLATED
                zi.external_attr = info.external_attr
                out.writestr(zi, data)
