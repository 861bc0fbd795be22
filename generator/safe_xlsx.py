"""Opening a workbook that came from somewhere else, safely.

An ``.xlsx`` file is a zip archive of XML parts.  Before openpyxl sees it, :func:`check` makes
sure that

* it is an Office Open XML zip at all (not an old ``.xls``, an encrypted workbook, an ``.ods``);
* it cannot exhaust memory: at most :data:`MAX_FILE_BYTES` on disk, :data:`MAX_MEMBERS` parts,
  :data:`MAX_UNCOMPRESSED_BYTES` decompressed in total and no part that decompresses more than
  :data:`MAX_RATIO` times (zip bombs).  The sizes checked are the ones the archive declares;
  Python's ``zipfile`` never decompresses a part beyond its declared size (a part that lies
  fails its CRC check instead), so the declared sizes bound what loading can allocate;
* no XML part has a document type declaration (DTD): entity expansion ("billion laughs") and
  external entities are refused before any parser expands them (``defusedxml``, which openpyxl
  also uses for its own parsing);
* it carries no macros (``vbaProject.bin``, macro-enabled content types): cmmwb never runs
  macros and does not read workbooks that have them.

:func:`load` then opens it with openpyxl without external links and without VBA.  Every problem
is an :class:`~generator.errors.InputError` naming the file (and the part at fault).
"""

from __future__ import annotations

import io
import re
import warnings
import zipfile
from pathlib import Path

from defusedxml import DefusedXmlException
from defusedxml.ElementTree import iterparse

from .errors import InputError

MAX_FILE_BYTES = 64 * 2**20
MAX_MEMBERS = 4096
MAX_UNCOMPRESSED_BYTES = 128 * 2**20
MAX_RATIO = 200            # decompressed/compressed, for parts larger than RATIO_FLOOR_BYTES
RATIO_FLOOR_BYTES = 2**20

_XML_SUFFIXES = (".xml", ".rels", ".vml")
_NOT_A_NUMBER = re.compile(r"(?:invalid literal for int\(\) with base 10|could not convert string to float): (.*)$")
_MACRO_TYPES = ("macroEnabled", "vbaProject")


def check(path: Path) -> None:
    """Refuse anything that is not a plain, reasonably sized, macro-free .xlsx (see module doc)."""
    path = Path(path)
    try:
        size = path.stat().st_size
        with open(path, "rb") as fh:
            magic = fh.read(8)
    except OSError as e:
        raise InputError(f"cannot read the workbook: {e.strerror}", file=path) from None
    if path.suffix.lower() in (".xlsm", ".xltm", ".xlam"):
        raise InputError("a macro-enabled workbook: cmmwb never runs macros and reads only .xlsx files "
                         "(save it as 'Excel Workbook (.xlsx)')", file=path)
    if magic.startswith(b"\xd0\xcf\x11\xe0"):
        raise InputError("not an .xlsx file: an old-format .xls or a password-protected (encrypted) "
                         "workbook; save it as an unencrypted .xlsx", file=path)
    if not magic.startswith(b"PK"):
        raise InputError("not an .xlsx file (an .xlsx is a zip archive)", file=path)
    if size > MAX_FILE_BYTES:
        raise InputError(f"larger than {MAX_FILE_BYTES // 2**20} MiB: refused", file=path)
    try:
        zf = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, ValueError) as e:
        raise InputError(f"not a readable .xlsx file (broken zip archive: {e})", file=path) from None
    with zf:
        infos = zf.infolist()
        if len(infos) > MAX_MEMBERS:
            raise InputError(f"{len(infos)} parts in the archive (at most {MAX_MEMBERS}): refused",
                             file=path)
        names = {i.filename for i in infos}
        total = 0
        for info in infos:
            total += info.file_size
            if total > MAX_UNCOMPRESSED_BYTES:
                raise InputError(f"decompresses to more than {MAX_UNCOMPRESSED_BYTES // 2**20} MiB "
                                 "(a zip bomb?): refused", file=path, where=f"part {info.filename}")
            if (info.file_size > RATIO_FLOOR_BYTES and
                    info.file_size > MAX_RATIO * max(info.compress_size, 1)):
                raise InputError(f"part compressed {info.file_size // max(info.compress_size, 1)}:1 "
                                 "(a zip bomb?): refused", file=path, where=f"part {info.filename}")
            if info.flag_bits & 0x1:
                raise InputError("encrypted parts in the archive: refused", file=path,
                                 where=f"part {info.filename}")
        if "mimetype" in names and b"opendocument" in zf.read("mimetype")[:200]:
            raise InputError("an OpenDocument spreadsheet (.ods): save it as .xlsx", file=path)
        if "[Content_Types].xml" not in names or "xl/workbook.xml" not in names:
            raise InputError("not an .xlsx workbook (no xl/workbook.xml in the archive)", file=path)
        if any(n.lower().endswith("vbaproject.bin") for n in names):
            raise InputError("the workbook contains macros (vbaProject.bin): cmmwb never runs macros and "
                             "does not read such files; save it as 'Excel Workbook (.xlsx)'", file=path)
        for info in infos:
            if info.filename.lower().endswith(_XML_SUFFIXES):
                _check_xml_prolog(zf, info, path)
        types = zf.read("[Content_Types].xml")
        if any(t.encode() in types for t in _MACRO_TYPES):
            raise InputError("the workbook is macro-enabled: cmmwb never runs macros and does not read "
                             "such files; save it as 'Excel Workbook (.xlsx)'", file=path)


def _check_xml_prolog(zf: zipfile.ZipFile, info: zipfile.ZipInfo, path: Path) -> None:
    """Parse up to the root element: a DTD (the only place entities can be declared) comes
    before it, so this is enough to refuse entity bombs and external entities."""
    where = f"part {info.filename}"
    try:
        with zf.open(info) as fh:
            for _event, _elem in iterparse(fh, events=("start",), forbid_dtd=True,
                                           forbid_entities=True, forbid_external=True):
                return
    except DefusedXmlException:
        raise InputError("XML with a document type declaration (DTD/entities) is refused "
                         "(entity-expansion and external-entity attacks)", file=path, where=where) from None
    except (zipfile.BadZipFile, EOFError, OSError, ValueError) as e:
        raise InputError(f"broken part in the archive ({type(e).__name__})", file=path, where=where) from None
    except SyntaxError as e:  # ParseError
        raise InputError(f"malformed XML ({e})", file=path, where=where) from None


_EMPTY_SHEET = (b'<worksheet xmlns="http://schemas.openxmlformats.org/spreadsheetml/2006/main">'
                b'<sheetData/></worksheet>')


def _only_sheets(path: Path, keep: set[str]) -> io.BytesIO:
    """An in-memory copy of the workbook in which the worksheets not in ``keep`` are empty (a
    LibreOffice-saved workbook holds every cached value of its 3m x 3m matrices: loading only
    the input sheets is many times faster)."""
    from .cache import sheet_parts

    buf = io.BytesIO()
    with zipfile.ZipFile(path) as z, zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as out:
        try:
            parts = sheet_parts(z)
        except (KeyError, ValueError, zipfile.BadZipFile):
            parts = {}
        drop = {part for title, part in parts.items() if title not in keep}
        for info in z.infolist():
            out.writestr(info.filename, _EMPTY_SHEET if info.filename in drop else z.read(info))
    buf.seek(0)
    return buf


def load(path: Path, sheets: set[str] | None = None):
    """:func:`check`, then openpyxl (formulas as text, no VBA, no external links).  With
    ``sheets``, the other worksheets are loaded empty (their names and defined names stay)."""
    import openpyxl

    path = Path(path)
    check(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            source = _only_sheets(path, sheets) if sheets is not None else path
            return openpyxl.load_workbook(source, data_only=False, keep_vba=False, keep_links=False,
                                          rich_text=False)
    except DefusedXmlException:
        raise InputError("XML with a document type declaration (DTD/entities) is refused", file=path) from None
    except MemoryError:
        raise InputError("too large to read", file=path) from None
    except Exception as e:  # openpyxl raises many kinds of errors on malformed parts
        root = e
        for _ in range(20):   # the underlying error (openpyxl wraps it)
            if (root.__cause__ or root.__context__) is None:
                break
            root = root.__cause__ or root.__context__
        text = str(root).splitlines()[0][:200] if str(root) else ""
        m = _NOT_A_NUMBER.match(text)
        if m:
            raise InputError(f"cannot be read as a workbook: a number cell holds {m.group(1)}, which is not a "
                             "number", file=path) from None
        raise InputError(f"cannot be read as a workbook ({type(root).__name__}{': ' + text if text else ''})",
                         file=path) from None
