"""Text cells as shared strings, the form Excel itself writes (a step of every save).

openpyxl 3.1 writes every text cell as an inline string (``<c t="inlineStr"><is><t>..</t></is></c>``).
That is valid SpreadsheetML, but Excel moves inline strings into a shared-strings table the first
time it saves a workbook: a book opened and closed unchanged would be rewritten, and the
Open XML validator (``openxml-audit``, docs/engines.md, *Excel*) warns of it on every sheet.
:func:`share_strings` copies a saved package with every inline string replaced by an index into
``xl/sharedStrings.xml`` (one entry per distinct text, in order of first use; rich text runs kept
as they are; an empty text cell becomes a blank cell), the part registered in ``[Content_Types].xml`` and in the workbook's relationships.
Cells, styles and formulas are untouched: a text cell stays text (``t="s"``), never a formula.
"""

from __future__ import annotations

import html
import re
import zipfile
from pathlib import Path

PART = "xl/sharedStrings.xml"
CONTENT_TYPE = "application/vnd.openxmlformats-officedocument.spreadsheetml.sharedStrings+xml"
RELATIONSHIP = "http://schemas.openxmlformats.org/officeDocument/2006/relationships/sharedStrings"
_WORKSHEET = b"application/vnd.openxmlformats-officedocument.spreadsheetml.worksheet+xml"
_MAIN = b"http://schemas.openxmlformats.org/spreadsheetml/2006/main"

_OVERRIDE = re.compile(rb'<Override\b[^>]*?\bPartName="/?([^"]+)"[^>]*?\bContentType="([^"]+)"[^>]*/>')
_INLINE = re.compile(rb'<c\b([^>]*?)\s+t="inlineStr"([^>]*)>\s*<is>(.*?)</is>\s*</c>', re.S)
_EMPTY = re.compile(rb'<c\b([^>]*?)\s+t="inlineStr"([^>]*?)\s*(?:/>|>\s*</c>)')
_SI = re.compile(rb"<si>(.*?)</si>|<si\s*/>", re.S)
_REL_ID = re.compile(rb'\bId="rId([0-9]+)"')
_T = re.compile(rb"<t\b[^>]*>(.*?)</t>|<t\s*/>", re.S)


def share_strings(src: str | Path, dst: str | Path) -> int:
    """Copy the workbook ``src`` to ``dst`` with its inline strings shared; returns the number of
    text cells rewritten (0: ``dst`` is a plain copy)."""
    with zipfile.ZipFile(src) as z:
        names = z.namelist()
        types = z.read("[Content_Types].xml")
        sheets = [p.decode() for p, t in _OVERRIDE.findall(types) if t == _WORKSHEET and p.decode() in names]
        table = _Table(z.read(PART) if PART in names else None)
        new = {part: _EMPTY.sub(rb"<c\1\2/>", _INLINE.sub(table.cell, z.read(part))) for part in sheets}
        if table.added:
            new[PART] = table.xml()
            if PART not in names:
                new["[Content_Types].xml"] = types.replace(
                    b"</Types>", b'<Override PartName="/%s" ContentType="%s"/></Types>'
                    % (PART.encode(), CONTENT_TYPE.encode()))
                rels = z.read("xl/_rels/workbook.xml.rels")
                rid = 1 + max((int(n) for n in _REL_ID.findall(rels)), default=0)
                new["xl/_rels/workbook.xml.rels"] = rels.replace(
                    b"</Relationships>", b'<Relationship Id="rId%d" Type="%s" Target="sharedStrings.xml"/>'
                    b"</Relationships>" % (rid, RELATIONSHIP.encode()))
        with zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as out:
            for info in z.infolist():
                data = new.pop(info.filename, None)
                out.writestr(info, z.read(info) if data is None else data)
            for name, data in new.items():      # the new shared-strings part
                out.writestr(name, data)
    return table.added


class _Table:
    """The shared-strings table: the entries a package already has, then the new ones."""

    def __init__(self, existing: bytes | None):
        self.items: list[bytes] = [m.group(1) or b"" for m in _SI.finditer(existing or b"")]
        self.index = {item: k for k, item in enumerate(self.items)}
        self.count = len(self.items)
        self.added = 0

    def cell(self, m: re.Match) -> bytes:
        item = m.group(3)
        k = self.index.get(item)
        if k is None:
            k = self.index[item] = len(self.items)
            self.items.append(item)
        self.count += 1
        self.added += 1
        return b'<c%s t="s"%s><v>%d</v></c>' % (m.group(1), m.group(2), k)

    def xml(self) -> bytes:
        return (b'<?xml version="1.0" encoding="UTF-8" standalone="yes"?>\n<sst xmlns="%s" count="%d" '
                b'uniqueCount="%d">' % (_MAIN, self.count, len(self.items))
                + b"".join(b"<si>" + item + b"</si>" for item in self.items) + b"</sst>")


def texts(z: zipfile.ZipFile) -> list[str]:
    """The plain text of each entry of a package's shared-strings table (empty without one), for
    readers of the raw XML that look cells of type ``s`` up by index."""
    if PART not in z.namelist():
        return []
    return ["".join(_unescape((t.group(1) or b"").decode("utf-8")) for t in _T.finditer(m.group(1) or b""))
            for m in _SI.finditer(z.read(PART))]


def _unescape(s: str) -> str:
    return html.unescape(s) if "&" in s else s
