"""The cached values of a saved workbook, read straight from its XML.

What an engine computed is in the ``<v>`` of each cell of the ``.xlsx`` it saves (LibreOffice,
Gnumeric, Excel).  openpyxl reads them too (``data_only=True``) but builds a cell object with its
style for each of them: 4 s for the 180,000 cells of a step-gauge book Gnumeric recalculated,
where :func:`read_values` takes a fraction of it.  Values come back as openpyxl gives them for
cmmwb's books: numbers (int when written without a point or exponent), text (shared, inline or a
formula's string result), booleans, error values as their text (``#NAME?``); no cell is a date
(cmmwb writes none).  :func:`sheet_parts` maps sheet titles to their parts.
"""

from __future__ import annotations

import html
import posixpath
import re
import zipfile
from pathlib import Path
from typing import Any

from .sharedstrings import texts

_SHEET = re.compile(rb'<sheet\b[^>]*?\bname="([^"]*)"[^>]*?\br:id="([^"]*)"')
_REL = re.compile(rb"<Relationship\b[^>]*>")
_ID = re.compile(rb'\bId="([^"]*)"')
_TARGET = re.compile(rb'\bTarget="([^"]*)"')
_CELL = re.compile(rb"<c\b([^>]*?)(?:/>|>(.*?)</c>)", re.S)
_R = re.compile(rb'\br="([A-Z]+[0-9]+)"')
_T = re.compile(rb'\bt="([^"]*)"')
_V = re.compile(rb"<v(?:\s[^>]*)?>(.*?)</v>", re.S)
_IS_T = re.compile(rb"<t\b[^>]*>(.*?)</t>", re.S)


def sheet_parts(z: zipfile.ZipFile) -> dict[str, str]:
    """Sheet title -> part name (``xl/worksheets/sheet3.xml``), in the workbook's order."""
    rels = z.read("xl/_rels/workbook.xml.rels")
    targets = {}
    for m in _REL.finditer(rels):
        i, t = _ID.search(m.group(0)), _TARGET.search(m.group(0))
        if i and t:
            targets[i.group(1)] = t.group(1).decode()
    out = {}
    for name, rid in _SHEET.findall(z.read("xl/workbook.xml")):
        t = targets.get(rid)
        if t is not None:
            out[_unescape(name.decode("utf-8"))] = (t.lstrip("/") if t.startswith("/")
                                                    else posixpath.normpath(posixpath.join("xl", t)))
    return out


def read_values(path: str | Path) -> dict[str, dict[str, Any]]:
    """``{sheet title: {coordinate: value}}`` of every cell of the workbook that holds a value."""
    with zipfile.ZipFile(path) as z:
        shared = texts(z)
        return {title: _sheet_values(z.read(part), shared) for title, part in sheet_parts(z).items()}


def _sheet_values(xml: bytes, shared: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for m in _CELL.finditer(xml):
        body = m.group(2)
        if not body:
            continue
        r = _R.search(m.group(1))
        if r is None:
            continue
        t = _T.search(m.group(1))
        kind = t.group(1) if t else b"n"
        if kind == b"inlineStr":
            text = "".join(_unescape(x.decode("utf-8")) for x in _IS_T.findall(body))
            if text:
                out[r.group(1).decode()] = text
            continue
        v = _V.search(body)
        if v is None:
            continue
        raw = v.group(1).decode("utf-8")
        value: Any
        if kind == b"s":
            value = shared[int(raw)]
        elif kind in (b"str", b"e"):
            value = _unescape(raw)
        elif kind == b"b":
            value = raw.strip() in ("1", "true")
        else:
            raw = raw.strip()
            if not raw:
                continue
            value = float(raw) if any(ch in raw for ch in ".eE") else int(raw)
        if value == "":
            continue
        out[r.group(1).decode()] = value
    return out


def _unescape(s: str) -> str:
    return html.unescape(s) if "&" in s else s
