"""What Excel is known to compute, as docs/engines.md lists it (*Excel: what is known without
Excel*): the functions a workbook may use, as the file stores them (``_xlfn.NORM.DIST``), and
classic array formulas only.  :func:`problems` lists what a workbook uses beyond that."""

from __future__ import annotations

import html
import re
import zipfile
from functools import cache
from pathlib import Path

from cmmwb.generator.pointcloud import large_book
from cmmwb.generator.workbook.cached_values import sheet_parts
from cmmwb.xlfuncs import udf

from tests.helpers import ROOT

_ROW = re.compile(r"^\| ([A-Z][A-Z0-9.]*) \| [^|]+ \| `([A-Za-z_][A-Za-z0-9_.]*)` \|$", re.M)
_F = re.compile(rb"<f\b([^>]*)>(.*?)</f>", re.S)
_STRING = re.compile(r'"(?:[^"]|"")*"')
_QUOTED_SHEET = re.compile(r"'(?:[^']|'')*'!")
_FUNCTION = re.compile(r"(?<![A-Za-z0-9_.!$])((?:_xl[a-z]+\.)*[A-Za-z_][A-Za-z0-9_.]*)\(")
_ERRORS = re.compile(r"#(?:NAME\?|N/A|VALUE!|REF!|DIV/0!|NUM!|NULL!)")
#: what only dynamic-array Excel (365, 2021) understands, besides its functions
DYNAMIC_ONLY = ("_xlfn.SINGLE", "_xlfn.ANCHORARRAY", "_xlfn._xlws.", "_xlfn.LAMBDA", "_xlpm.")


@cache
def functions() -> dict[str, str]:
    """Function name -> how the file stores it, from the table of docs/engines.md."""
    text = (ROOT / "docs" / "engines.md").read_text(encoding="utf-8")
    return {name: stored for name, stored in _ROW.findall(text)}


def addin_functions() -> set[str]:
    """The add-in's functions (``cmmwb.xlfuncs.udf``), allowed on the ``Live_addin`` sheets only."""
    return {name.upper() for name in vars(udf) if name.startswith("cmm_")}


def problems(path: Path) -> list[str]:
    """Every function outside the list (or stored otherwise), and every dynamic-array form, in the
    workbook at ``path``."""
    allowed = set(functions().values())
    addin = addin_functions()
    found: set[str] = set()
    with zipfile.ZipFile(path) as z:
        if "xl/metadata.xml" in z.namelist():
            found.add("an xl/metadata.xml part (dynamic-array metadata)")
        for title, part in sheet_parts(z).items():
            xml = z.read(part)
            if re.search(rb'<c\b[^>]*\bcm="', xml):
                found.add(f"{title}: a cell with dynamic-array metadata (cm=)")
            for m in _F.finditer(xml):
                text = html.unescape(m.group(2).decode("utf-8"))
                bare = _QUOTED_SHEET.sub("S!", _STRING.sub('""', text))
                for f in _FUNCTION.findall(bare):
                    if f in allowed or (title == large_book.LIVE and f.upper() in addin):
                        continue
                    found.add(f"{title}: {f}( is not in the Excel list of docs/engines.md")
                if any(d in bare for d in DYNAMIC_ONLY) or "#" in _ERRORS.sub("", bare) or "@" in bare:
                    found.add(f"{title}: a dynamic-array form in ={text[:80]}")
    return sorted(found)
