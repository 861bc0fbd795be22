"""The printed size of the text on each page of a PDF (LibreOffice's, of a workbook), for the
legibility tests: the font size each text-showing operator uses, in points on the page.

The PDF's page tree gives each page its content streams; a stream is inflated (FlateDecode)
and read operator by operator: ``q``/``Q``/``cm`` keep the current transformation matrix,
``BT``/``Tf``/``Tm``/``Td``/``TD``/``T*`` the text state, and every ``Tj``/``TJ``/``'``/``"``
records the effective size Tf x (the vertical scale of Tm x CTM).  Form XObjects (``Do``: the
charts LibreOffice draws) are followed with their own ``/Matrix``.  Standard library only; the
page's text itself comes from ``pdftotext`` where a test needs it.
"""

from __future__ import annotations

import math
import re
import subprocess
import zlib
from pathlib import Path

_OBJ = re.compile(rb"(\d+)\s+(\d+)\s+obj\b(.*?)\bendobj", re.S)
_STREAM = re.compile(rb"stream\r?\n(.*?)\r?\nendstream", re.S)
_REF = re.compile(rb"(\d+)\s+0\s+R")
_TOKEN = re.compile(rb"""\((?:\\.|[^\\)])*\)|<[0-9A-Fa-f\s]*>|\[|\]|/[^\s/\[\]()<>{}%]+|[^\s/\[\]()<>{}%]+""", re.S)


def _objects(data: bytes) -> dict[int, bytes]:
    return {int(m.group(1)): m.group(3) for m in _OBJ.finditer(data)}


def _stream(obj: bytes) -> bytes:
    m = _STREAM.search(obj)
    if m is None:
        return b""
    raw = m.group(1)
    head = obj[:m.start()]
    if b"/FlateDecode" in head:
        try:
            return zlib.decompress(raw)
        except zlib.error:
            return zlib.decompressobj().decompress(raw)
    return raw


def _mul(a, b):
    """3x2 affine matrices [a b c d e f]: a then b."""
    return [a[0] * b[0] + a[1] * b[2], a[0] * b[1] + a[1] * b[3],
            a[2] * b[0] + a[3] * b[2], a[2] * b[1] + a[3] * b[3],
            a[4] * b[0] + a[5] * b[2] + b[4], a[4] * b[1] + a[5] * b[3] + b[5]]


def _scale(m) -> float:
    """The vertical scale of a matrix (text size factor)."""
    return math.hypot(m[2], m[3])


def _pages(objs: dict[int, bytes]) -> list[int]:
    """Page object numbers in order (the page tree from the catalog's /Pages)."""
    root = next(n for n, o in objs.items() if re.search(rb"/Type\s*/Catalog", o))
    pages_ref = int(re.search(rb"/Pages\s+(\d+)\s+0\s+R", objs[root]).group(1))
    out: list[int] = []

    def walk(n: int) -> None:
        o = objs[n]
        if re.search(rb"/Type\s*/Pages\b", o):
            kids = re.search(rb"/Kids\s*\[(.*?)\]", o, re.S).group(1)
            for k in _REF.findall(kids):
                walk(int(k))
        else:
            out.append(n)

    walk(pages_ref)
    return out


def _xobjects(objs: dict[int, bytes], obj: bytes) -> dict[bytes, int]:
    """Name -> object number of the XObjects in a page's or form's /Resources."""
    res = re.search(rb"/Resources\s*(\d+\s+0\s+R|<<.*)", obj, re.S)
    if res is None:
        return {}
    text = res.group(1)
    m = re.match(rb"(\d+)\s+0\s+R", text)
    if m:
        text = objs.get(int(m.group(1)), b"")
    xo = re.search(rb"/XObject\s*(\d+\s+0\s+R|<<(.*?)>>)", text, re.S)
    if xo is None:
        return {}
    body = xo.group(2)
    if body is None:
        body = objs.get(int(re.match(rb"(\d+)", xo.group(1)).group(1)), b"")
    return {name: int(n) for name, n in re.findall(rb"/([^\s/<>\[\]]+)\s+(\d+)\s+0\s+R", body)}


def _sizes(objs: dict[int, bytes], content: bytes, xobjects: dict[bytes, int], ctm0, depth: int = 0) -> list[float]:
    out: list[float] = []
    ctm = list(ctm0)
    stack: list[list[float]] = []
    tm = [1, 0, 0, 1, 0, 0]
    tlm = [1, 0, 0, 1, 0, 0]
    size = 0.0
    leading = 0.0
    operands: list[bytes] = []
    for tok in _TOKEN.findall(content):
        if tok[:1] in (b"(", b"<", b"/", b"[", b"]") or re.fullmatch(rb"[-+]?[0-9]*\.?[0-9]+", tok):
            operands.append(tok)
            continue
        op = tok
        nums = []
        for o in operands:
            try:
                nums.append(float(o))
            except ValueError:
                pass
        if op == b"q":
            stack.append(list(ctm))
        elif op == b"Q":
            ctm = stack.pop() if stack else list(ctm0)
        elif op == b"cm" and len(nums) >= 6:
            ctm = _mul(nums[-6:], ctm)
        elif op == b"BT":
            tm = [1, 0, 0, 1, 0, 0]
            tlm = list(tm)
        elif op == b"Tf" and nums:
            size = nums[-1]
        elif op == b"TL" and nums:
            leading = nums[-1]
        elif op == b"Tm" and len(nums) >= 6:
            tm = nums[-6:]
            tlm = list(tm)
        elif op in (b"Td", b"TD") and len(nums) >= 2:
            if op == b"TD":
                leading = -nums[-1]
            tlm = _mul([1, 0, 0, 1, nums[-2], nums[-1]], tlm)
            tm = list(tlm)
        elif op == b"T*":
            tlm = _mul([1, 0, 0, 1, 0, -leading], tlm)
            tm = list(tlm)
        elif op in (b"Tj", b"TJ", b"'", b'"'):
            shown = b"".join(o for o in operands if o[:1] in (b"(", b"<"))
            if shown.strip(b"()<> \n"):
                out.append(abs(size) * _scale(_mul(tm, ctm)))
        elif op == b"Do" and operands and depth < 4:
            name = operands[-1].lstrip(b"/")
            n = xobjects.get(name)
            form = objs.get(n, b"") if n is not None else b""
            if re.search(rb"/Subtype\s*/Form", form):
                mm = re.search(rb"/Matrix\s*\[([^\]]*)\]", form)
                matrix = [float(x) for x in mm.group(1).split()] if mm else [1, 0, 0, 1, 0, 0]
                out += _sizes(objs, _stream(form), _xobjects(objs, form) or xobjects, _mul(matrix, ctm), depth + 1)
        operands = []
    return out


def font_sizes(pdf: Path) -> list[list[float]]:
    """The printed font size (pt) of every text shown on each page, page by page."""
    data = Path(pdf).read_bytes()
    objs = _objects(data)
    pages = []
    for n in _pages(objs):
        page = objs[n]
        contents = re.search(rb"/Contents\s*(\[(.*?)\]|(\d+)\s+0\s+R)", page, re.S)
        refs = [int(x) for x in _REF.findall(contents.group(2))] if contents and contents.group(2) is not None \
            else ([int(contents.group(3))] if contents else [])
        stream = b"\n".join(_stream(objs[r]) for r in refs)
        pages.append(_sizes(objs, stream, _xobjects(objs, page), [1, 0, 0, 1, 0, 0]))
    return pages


def sheet_of_pages(pdf: Path) -> list[str]:
    """The sheet each page prints (the footer's first word: ``&A ... page P of N``)."""
    text = subprocess.run(["pdftotext", "-layout", str(pdf), "-"], capture_output=True, text=True,
                          check=True).stdout
    pages = text.split("\f")
    if pages and not pages[-1].strip():
        pages = pages[:-1]
    out = []
    for page in pages:
        lines = [ln for ln in page.splitlines() if ln.strip()]
        out.append(lines[-1].split()[0] if lines else "")
    return out
