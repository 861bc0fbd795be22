"""A copy of a workbook with every cached formula value removed.

A workbook may carry cached values (``generator.workbook.cache``, or an engine's save): the value
each formula had when the file was written.  An engine that is asked to recalculate but keeps a
cached value where it cannot or does not recompute a cell would hand that stale value back as its
own.  :func:`strip_cached_values` copies the package with the ``<v>`` of every formula cell, and
of every cell covered by an array formula, removed (with the cell's value type), so whatever an
engine returns for such a cell it computed itself; constants, text, styles and formulas are kept.
"""

from __future__ import annotations

import re
import zipfile
from pathlib import Path

from openpyxl.utils import get_column_letter, range_boundaries

from .cached_values import sheet_parts

_CELL = re.compile(rb"<c\b([^>]*?)(?:/>|>(.*?)</c>)", re.S)
_ARRAY_F = re.compile(rb"<f\b[^>]*?\bt=\"array\"[^>]*>")
_REF = re.compile(rb'\bref="([A-Z]+[0-9]+(?::[A-Z]+[0-9]+)?)"')
_R = re.compile(rb'\br="([A-Z]+[0-9]+)"')
_T = re.compile(rb'\s+t="[^"]*"')
_V = re.compile(rb"<v\s*/>|<v(?:\s[^>]*)?>.*?</v>", re.S)


def strip_cached_values(src: str | Path, dst: str | Path, seed: float | None = None) -> int:
    """Copy the workbook ``src`` to ``dst`` without cached formula values; returns how many
    cells lost one.  With ``seed`` every formula cell gets that number as its cached value instead
    (another starting point for an engine that iterates circular references:
    ``generator.workbook.gnumeric``)."""
    count = 0
    with zipfile.ZipFile(src) as z, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as out:
        sheets = set(sheet_parts(z).values())
        for info in z.infolist():
            data = z.read(info)
            if info.filename in sheets:
                data, n = strip_sheet(data, seed)
                count += n
            out.writestr(info, data)
    return count


def strip_sheet(xml: bytes, seed: float | None = None) -> tuple[bytes, int]:
    """One worksheet's XML without cached formula values (or each set to ``seed``), and how many
    cells lost one."""
    covered = _array_cells(xml)
    seeded = b"" if seed is None else b"<v>%r</v>" % float(seed)
    count = 0

    def strip(m: re.Match) -> bytes:
        nonlocal count
        attrs, body = m.group(1), m.group(2)
        if body is None or not (seeded or _V.search(body)):
            return m.group(0)
        r = _R.search(attrs)
        if b"<f" not in body and not (r and r.group(1) in covered):
            return m.group(0)       # a constant
        count += 1
        body = _V.sub(b"", body) + seeded
        return b"<c" + _T.sub(b"", attrs) + (b">" + body + b"</c>" if body.strip() else b"/>")

    return _CELL.sub(strip, xml), count


def _array_cells(xml: bytes) -> set[bytes]:
    """The coordinates (``b"B7"``) of every cell covered by an array formula of the sheet."""
    out: set[bytes] = set()
    for m in _ARRAY_F.finditer(xml):
        ref = _REF.search(m.group(0))
        if ref:
            c0, r0, c1, r1 = range_boundaries(ref.group(1).decode())
            out.update(f"{get_column_letter(c)}{r}".encode() for r in range(r0, r1 + 1) for c in range(c0, c1 + 1))
    return out
