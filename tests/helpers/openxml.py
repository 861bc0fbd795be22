"""The Open XML validator over the workbooks the tests build (docs/engines.md, *Excel*).

``openxml-audit`` (a port of the Open XML SDK's validation to Python, a test dependency) checks
a package against the ECMA-376 schemas and semantic rules as Microsoft 365 reads them
(``-f microsoft365``).  :func:`problems` lists its findings on one workbook, less the
validator's own false positives (:data:`FALSE_POSITIVES`, each with its reason); a workbook
cmmwb writes has none (``tests/conftest.py`` runs it over every ``.xlsx`` the suite writes).
"""

from __future__ import annotations

import hashlib
import os
import re
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path

from openxml_audit import FileFormat, OpenXmlValidator, ValidationSeverity

from cmmwb.generator.workbook.safe_xlsx import MAX_UNCOMPRESSED_BYTES

from tests.helpers import excel

FORMAT = FileFormat.MICROSOFT_365

#: the children of a SpreadsheetML font (CT_Font)
_FONT_CHILDREN = "b|i|strike|condense|extend|outline|shadow|u|vertAlign|sz|color|name|family|charset|scheme"


@dataclass(frozen=True)
class FalsePositive:
    """A finding the validator makes of a file the schema allows: the part, path and message it
    gives (regular expressions, matched whole) and why it is not an error."""

    part: str
    path: str
    description: str
    reason: str

    def matches(self, finding) -> bool:
        return bool(re.fullmatch(self.part, finding.part_uri or "")
                    and re.fullmatch(self.path, finding.path or "")
                    and re.fullmatch(self.description, finding.description or ""))


FALSE_POSITIVES = (
    FalsePositive(
        part=r"/xl/styles\.xml",
        path=r"/styleSheet\[1\]/fonts\[1\]/font\[[0-9]+\]",
        description=rf"Unexpected element '(?:{_FONT_CHILDREN})' found",
        reason="ECMA-376 Part 1 (sml.xsd) defines CT_Font as <xsd:choice maxOccurs=\"unbounded\"> of its "
               "children, so they may come in any order; the Open XML SDK's data, which openxml-audit "
               "ports, has them as a sequence (sz, color, name, family, scheme). openpyxl writes the "
               "default font as name, family, color, sz, scheme."),
)

_validator: OpenXmlValidator | None = None


def validator() -> OpenXmlValidator:
    global _validator
    if _validator is None:
        _validator = OpenXmlValidator(file_format=FORMAT, max_errors=0)
    return _validator


def problems(path: Path, *, warnings: bool = False) -> list[str]:
    """The validator's errors on the workbook at ``path`` (and its warnings, with ``warnings``),
    false positives left out, each as ``part path: message``."""
    result = validator().validate(path)
    wanted = {ValidationSeverity.ERROR} | ({ValidationSeverity.WARNING} if warnings else set())
    return [f"{f.part_uri} {f.path}: {f.description}" for f in result.errors
            if f.severity in wanted and not any(fp.matches(f) for fp in FALSE_POSITIVES)]


def fingerprint(path: Path) -> str:
    """What two builds of the same task share: every part of the package but its creation time
    (``docProps/core.xml``) and the text of its shared strings (provenance: build time, folder),
    which the schema does not constrain.  One validation per fingerprint is enough."""
    h = hashlib.sha256()
    with zipfile.ZipFile(path) as z:
        for name in sorted(z.namelist()):
            if name == "docProps/core.xml":
                continue
            data = z.read(name)
            if name == "xl/sharedStrings.xml":
                data = re.sub(rb"<t\b([^>]*)>[^<]*</t>", rb"<t\1/>", data)
            h.update(name.encode() + b"\0" + hashlib.sha256(data).digest())
    return h.hexdigest()


class Watch:
    """The ``.xlsx`` files under one folder (a test worker's ``basetemp``) not yet looked at:
    :meth:`check` validates each new or rewritten one (once per :func:`fingerprint`), holds it to
    the Excel list of docs/engines.md (``tests.helpers.excel``) and returns the problems found; with ``skip`` it only marks them seen (a test that writes foreign or
    hostile files on purpose: ``@pytest.mark.foreign_books``)."""

    def __init__(self, root: Path):
        self.root = root
        self.seen: dict[Path, tuple[int, int]] = {}
        #: folder -> (its mtime when listed, its .xlsx files, its subfolders)
        self.listed: dict[Path, tuple[int, list[Path], list[Path]]] = {}
        self.fingerprints: set[str] = set()
        self.validated = self.same = 0
        self.seconds = 0.0

    def _books(self) -> list[Path]:
        """Every ``.xlsx`` under the root; a folder is listed again only when its mtime changed
        (a file written or renamed into it, as every save of cmmwb is)."""
        out: list[Path] = []
        stack = [self.root]
        while stack:
            folder = stack.pop()
            try:
                mtime = folder.stat().st_mtime_ns
            except FileNotFoundError:
                continue
            if folder not in self.listed or self.listed[folder][0] != mtime:
                files, subfolders = [], []
                with os.scandir(folder) as entries:
                    for e in entries:
                        if e.is_dir(follow_symlinks=False):
                            subfolders.append(Path(e.path))
                        elif e.name.endswith(".xlsx") and not e.name.startswith("."):
                            files.append(Path(e.path))
                self.listed[folder] = (mtime, files, subfolders)
            _, files, subfolders = self.listed[folder]
            out.extend(files)
            stack.extend(subfolders)
        return out

    def check(self, skip: bool = False) -> list[str]:
        found = []
        for book in self._books():
            try:
                st = book.stat()
            except FileNotFoundError:
                continue
            key = (st.st_mtime_ns, st.st_size)
            if self.seen.get(book) == key:
                continue
            self.seen[book] = key
            if skip:
                continue
            t0 = time.perf_counter()
            try:
                with zipfile.ZipFile(book) as z:
                    size = sum(i.file_size for i in z.infolist())
                if size > MAX_UNCOMPRESSED_BYTES:     # never a book of cmmwb: not unpacked here
                    found.append(f"{book.relative_to(self.root)}: {size:,} bytes uncompressed, more than "
                                 f"cmmwb reads (safe_xlsx.MAX_UNCOMPRESSED_BYTES)")
                    continue
                fp = fingerprint(book)
                if fp in self.fingerprints:
                    self.same += 1
                    continue
                said = problems(book) + excel.problems(book)
                self.fingerprints.add(fp)
                self.validated += 1
            except (zipfile.BadZipFile, KeyError, OSError) as e:
                said = [f"not a readable workbook: {e}"]
            finally:
                self.seconds += time.perf_counter() - t0
            found.extend(f"{book.relative_to(self.root)}: {p}" for p in said)
        return found

