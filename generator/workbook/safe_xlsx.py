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
* it carries no macros of any kind: no VBA project (``vbaProject.bin`` under any name), no
  Excel 4.0 macro sheets (``xl/macrosheets``), no ActiveX controls, no ``Auto_Open`` /
  ``Auto_Close`` / ``Auto_Activate`` / ``Auto_Deactivate`` defined names, no macro-enabled content
  types: cmmwb never runs macros and does not read workbooks that have them;
* it cannot reach other files or the network: no external links (``xl/externalLinks``, external
  relationships other than hyperlinks, ``[1]Sheet!A1`` or ``'/path/[book.xlsx]Sheet'!A1``
  references in formulas or defined names), no DDE (``=cmd|'/c calc'!A0``, ``ddeLink``), no web
  queries or data connections (``xl/queryTables``, ``xl/connections.xml``, ``WEBSERVICE``), no
  ``INDIRECT`` (a reference built from text could name any file) and no XLM ``CALL``/``REGISTER``/
  ``EXEC``;
* every part is checked whatever its name: each is scanned for a DTD, and formula text is read
  from every part that holds any;
* it is of a size the engines can handle: at most :data:`MAX_CELLS` cells and
  :data:`MAX_SHARED_STRINGS` shared strings (counted, not the counts the file declares), and at
  most :data:`MAX_FORMULAS_ENGINE_CELLS` cells for ``recalc --engine formulas``.

All of this happens in :func:`check`, before openpyxl, ``formulas`` or LibreOffice see the file.

:func:`load` then opens it with openpyxl without external links and without VBA.  Every problem
is an :class:`~generator.errors.InputError` naming the file (and the part at fault).
"""

from __future__ import annotations

import html
import io
import re
import warnings
import zipfile
from pathlib import Path

from defusedxml import DefusedXmlException
from defusedxml.ElementTree import iterparse

from ..errors import InputError
from .guarded import MAX_BYTES, check_regular

MAX_FILE_BYTES = MAX_BYTES["workbook"]
MAX_CELLS = 3_000_000                 # cells in all worksheets together (cmmwb read, recalc)
MAX_SHARED_STRINGS = 500_000          # distinct shared strings
MAX_FORMULAS_ENGINE_CELLS = 250_000   # recalc --engine formulas (pure Python: minutes beyond)
MAX_MEMBERS = 4096
MAX_UNCOMPRESSED_BYTES = 128 * 2**20
MAX_RATIO = 200            # decompressed/compressed, for parts larger than RATIO_FLOOR_BYTES
RATIO_FLOOR_BYTES = 2**20

_XML_SUFFIXES = (".xml", ".rels", ".vml")
_NOT_A_NUMBER = re.compile(r"(?:invalid literal for int\(\) with base 10|could not convert string to float): (.*)$")


def check(path: Path, *, max_cells: int = MAX_CELLS) -> None:
    """Refuse anything that is not a plain, reasonably sized, macro-free, self-contained .xlsx
    (see the module doc).  ``max_cells``: the cap on cells (lower for the ``formulas`` engine)."""
    path = Path(path)
    if path.suffix.lower() in (".xlsm", ".xltm", ".xlam"):
        raise InputError("a macro-enabled workbook: cmmwb never runs macros and reads only .xlsx files "
                         "(save it as 'Excel Workbook (.xlsx)')", file=path)
    check_regular(path, "workbook")          # a regular file (no FIFO/device) within the cap
    try:
        with open(path, "rb") as fh:
            magic = fh.read(8)
    except OSError as e:
        raise InputError(f"cannot read the workbook: {e.strerror}", file=path) from None
    if magic.startswith(b"\xd0\xcf\x11\xe0"):
        raise InputError("not an .xlsx file: an old-format .xls or a password-protected (encrypted) "
                         "workbook; save it as an unencrypted .xlsx", file=path)
    if not magic.startswith(b"PK"):
        raise InputError("not an .xlsx file (an .xlsx is a zip archive)", file=path)
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
        for info in infos:
            _check_part_name(info.filename, path)
        cells = strings = 0
        for info in infos:
            data = _read_part(zf, info, path)
            _check_any_dtd(data, info, path)
            if info.filename.lower().endswith(_XML_SUFFIXES) or _looks_like_xml(data):
                _check_xml_prolog(zf, info, path)
            _check_content(data, info.filename, path, zf)
            cells += len(_CELL.findall(data))
            strings += len(_SHARED_STRING.findall(data))
            if cells > max_cells:
                raise InputError(f"more than {max_cells:,} cells: too large for this command (see "
                                 "docs/input_limits.md)" + (" -- use --engine gnumeric or --engine libreoffice"
                                                            if max_cells < MAX_CELLS else ""),
                                 file=path, where=part_place(zf, info.filename))
            if strings > MAX_SHARED_STRINGS:
                raise InputError(f"more than {MAX_SHARED_STRINGS:,} shared strings: too large to read "
                                 "(see docs/input_limits.md)", file=path, where=f"part {info.filename}")


# -- what a part may not be or hold -----------------------------------------------------------

#: part-name patterns (lower case) that are refused, and what they are
_REFUSED_PARTS = (
    (re.compile(r"vbaproject"), "macros (a VBA project)"),
    (re.compile(r"(^|/)macrosheets?/"), "an Excel 4.0 macro sheet (XLM macros)"),
    (re.compile(r"(^|/)intlmacrosheets?/"), "an Excel 4.0 macro sheet (XLM macros)"),
    (re.compile(r"(^|/)activex/"), "ActiveX controls (code)"),
    (re.compile(r"(^|/)externallinks?/"), "an external link (a reference to another file)"),
    (re.compile(r"(^|/)querytables?/"), "a web or database query (a query table)"),
    (re.compile(r"(^|/)connections\.xml$"), "a data connection (web query, database or file)"),
)

#: relationship and content types (case-insensitive substrings) that are refused
_REFUSED_TYPES = (
    ("vbaproject", "macros (a VBA project)"), ("macroenabled", "macros (a macro-enabled workbook)"),
    ("macrosheet", "an Excel 4.0 macro sheet (XLM macros)"), ("activex", "ActiveX controls (code)"),
    ("externallink", "an external link (a reference to another file)"),
    ("querytable", "a web or database query (a query table)"),
    ("/connections", "a data connection (web query, database or file)"),
    ("spreadsheetml.connections", "a data connection (web query, database or file)"),
    ("ddelink", "a DDE link (a command run by another program)"),
)
_MACRO_HINT = "cmmwb never runs macros and does not read such files; save it as 'Excel Workbook (.xlsx)'"
_LINK_HINT = ("cmmwb reads no other file and no network source; in Excel: Data > Edit Links > Break Link "
              "(or paste the values), then save as .xlsx")

_CELL = re.compile(rb"<(?:[A-Za-z_][\w.-]*:)?c[\s>/]")
_SHARED_STRING = re.compile(rb"<(?:[A-Za-z_][\w.-]*:)?si[\s>/]")
_FORMULA = re.compile(rb"<(?:[A-Za-z_][\w.-]*:)?f(?:\s[^>]*)?>([^<]*)<")
_DEFINED_NAME = re.compile(rb"<(?:[A-Za-z_][\w.-]*:)?definedName\b([^>]*)>([^<]*)<")
_RELATIONSHIP = re.compile(rb"<(?:[A-Za-z_][\w.-]*:)?Relationship\b([^>]*)>")
_ATTR = re.compile(rb"""([\w:]+)\s*=\s*(?:"([^"]*)"|'([^']*)')""")
_DTD = re.compile(rb"<!\s*(?:doctype|entity)", re.IGNORECASE)
_DTD_WIDE = tuple(re.compile(p, re.IGNORECASE) for p in (
    b"\\x00".join(re.escape(bytes([c])) for c in b"<!DOCTYPE") ,
    b"\\x00".join(re.escape(bytes([c])) for c in b"<!ENTITY")))
_AUTO_NAMES = ("auto_open", "auto_close", "auto_activate", "auto_deactivate")


def _read_part(zf: zipfile.ZipFile, info: zipfile.ZipInfo, path: Path) -> bytes:
    try:
        return zf.read(info)
    except (zipfile.BadZipFile, EOFError, OSError, ValueError, NotImplementedError) as e:
        raise InputError(f"broken part in the archive ({type(e).__name__})", file=path,
                         where=f"part {info.filename}") from None


def _check_part_name(name: str, path: Path) -> None:
    low = name.lower()
    for pattern, what in _REFUSED_PARTS:
        if pattern.search(low):
            hint = _MACRO_HINT if "macro" in what or "code" in what else _LINK_HINT
            raise InputError(f"the workbook contains {what}: {hint}", file=path, where=f"part {name}")


def _looks_like_xml(data: bytes) -> bool:
    """XML in any encoding a parser would accept: starts (after a BOM and blanks) with '<', or is
    UTF-16/UTF-32 text."""
    head = data[:8]
    if head.startswith((b"\xfe\xff", b"\xff\xfe", b"\x00\x00\xfe\xff", b"<\x00", b"\x00<")):
        return True
    return data[:512].lstrip(b"\xef\xbb\xbf \t\r\n").startswith(b"<")


def _check_any_dtd(data: bytes, info: zipfile.ZipInfo, path: Path) -> None:
    """A DTD anywhere in any part (whatever its name or encoding) is refused."""
    if _DTD.search(data) or any(p.search(data) for p in _DTD_WIDE):
        raise InputError("XML with a document type declaration (DTD/entities) is refused "
                         "(entity-expansion and external-entity attacks)", file=path,
                         where=f"part {info.filename}")


def _attrs(raw: bytes) -> dict[str, str]:
    return {m.group(1).decode("latin-1").split(":")[-1]: (m.group(2) if m.group(2) is not None else m.group(3))
            .decode("utf-8", "replace") for m in _ATTR.finditer(raw)}


def part_place(zf: zipfile.ZipFile | None, name: str) -> str:
    """Where a part is, for a message: ``sheet Data`` for a worksheet (its name in the workbook,
    through xl/workbook.xml and its relationships), else ``part NAME``."""
    if zf is not None and name.lower().startswith(("xl/worksheets/", "xl/chartsheets/")):
        from .cached_values import sheet_parts

        try:
            for title, part in sheet_parts(zf).items():
                if part == name:
                    return f"sheet {title}"
        except (KeyError, ValueError, UnicodeDecodeError, zipfile.BadZipFile, OSError):
            pass
    return f"part {name}"


def _check_content(data: bytes, name: str, path: Path, zf: zipfile.ZipFile | None = None) -> None:
    """Relationships, content types, defined names and formulas of one part (``zf``: the archive,
    to name a worksheet by its sheet name)."""
    where = f"part {name}"
    low = name.lower()
    if low.endswith(".rels") or low == "[content_types].xml":
        # the declared types of parts and relationships (not targets: a hyperlink may say anything)
        types = " ".join(m.group(1).decode("utf-8", "replace").lower()
                         for m in re.finditer(rb"""(?:Type|ContentType)\s*=\s*["']([^"']*)["']""", data))
        for needle, what in _REFUSED_TYPES:
            if needle in types:
                hint = _MACRO_HINT if "macro" in what or "code" in what else _LINK_HINT
                raise InputError(f"the workbook contains {what}: {hint}", file=path, where=where)
        for m in _RELATIONSHIP.finditer(data):
            a = _attrs(m.group(1))
            if a.get("TargetMode", "").lower() == "external" and not a.get("Type", "").endswith("/hyperlink"):
                raise InputError(f"the workbook refers to another file or address ({a.get('Target', '')[:80]!r}, "
                                 f"relationship {a.get('Type', '').rsplit('/', 1)[-1]}): {_LINK_HINT}",
                                 file=path, where=where)
    if b"ddeLink" in data or b"oleLink" in data:
        raise InputError(f"the workbook contains a DDE/OLE link (a command run by another program): {_LINK_HINT}",
                         file=path, where=part_place(zf, name))
    if b"definedName" in data:
        for m in _DEFINED_NAME.finditer(data):
            a = _attrs(m.group(1))
            dname = a.get("name", "")
            bare = dname.lower().removeprefix("_xlnm.")
            if bare.startswith(_AUTO_NAMES) or a.get("function") in ("1", "true") or a.get("xlm") in ("1", "true") \
                    or a.get("vbProcedure") in ("1", "true"):
                raise InputError(f"the workbook contains macros (the defined name {dname!r} runs a macro): "
                                 f"{_MACRO_HINT}", file=path, where=f"{where}, defined name {dname}")
            problem = formula_problem(html.unescape(m.group(2).decode("utf-8", "replace")))
            if problem:
                raise InputError(f"the defined name {dname!r} {problem}", file=path,
                                 where=f"{where}, defined name {dname}")
    if b"<f" in data or b":f" in data:
        for m in _FORMULA.finditer(data):
            text = html.unescape(m.group(1).decode("utf-8", "replace"))
            problem = formula_problem(text)
            if problem:
                cell = _cell_of(data, m.start())
                raise InputError(f"the formula ={text[:80]} {problem}", file=path,
                                 where=part_place(zf, name) + (f", cell {cell}" if cell else ""))


_CELL_REF = re.compile(rb"""<(?:[A-Za-z_][\w.-]*:)?c\b[^>]*\br\s*=\s*["']([A-Z]+[0-9]+)["']""")


def _cell_of(data: bytes, pos: int) -> str | None:
    """The reference of the cell element that encloses ``pos`` (for messages)."""
    start = max(data.rfind(b"<c ", 0, pos), data.rfind(b":c ", 0, pos))
    if start < 0:
        return None
    m = _CELL_REF.match(data, data.rfind(b"<", 0, start + 1))
    return m.group(1).decode() if m else None


_STRING_LITERAL = re.compile(r'"(?:[^"]|"")*"')
_REFUSED_FUNCTIONS = re.compile(r"(?<![\w.])(INDIRECT|WEBSERVICE|FILTERXML|CALL|REGISTER|REGISTER\.ID|EXEC|"
                                r"RTD|DDE|DDEAUTO|HYPERLINK\.FOLLOW|ENCODEURL)\s*\(", re.IGNORECASE)
_QUALIFIER_STOP = set(" (),;=+-*/^&<>{}\"%")


def formula_problem(formula: str) -> str | None:
    """Why a formula (or defined-name) text may reach another file, program or address, or None.

    Sheet names cannot hold ``[ ] / \\ ? *``, so a sheet qualifier (the text before ``!``) that
    holds one is a reference into another workbook; ``|`` is no operator of Excel's, so outside
    string literals it is DDE (``=cmd|'/c calc'!A0``)."""
    bare = _STRING_LITERAL.sub('""', formula)
    if "|" in bare:
        return "is a DDE call (it would run another program): refused"
    m = _REFUSED_FUNCTIONS.search(bare)
    if m:
        return (f"uses {m.group(1).upper()}, which can reach other files, programs or the network: refused "
                "(cmmwb's workbooks never use it)")
    if "://" in bare or "file:" in bare.lower():
        return "refers to another file or address: refused"
    for k, ch in enumerate(bare):
        if ch != "!":
            continue
        j = k - 1
        if j >= 0 and bare[j] == "'":          # a quoted qualifier: back to its opening quote
            j -= 1
            while j >= 0:
                if bare[j] == "'" and (j == 0 or bare[j - 1] != "'"):
                    break
                j -= 2 if bare[j] == "'" else 1
            qualifier = bare[max(j, 0):k]
        else:
            while j >= 0 and bare[j] not in _QUALIFIER_STOP and bare[j] != "!":
                j -= 1
            qualifier = bare[j + 1:k]
        if any(c in qualifier for c in "[]/\\?*"):
            return f"refers to another workbook ({qualifier[:60]}!...): refused"
    if re.search(r"(?<![\w\]])\[\d+\]", bare):
        return "refers to another workbook (an external link [n]): refused"
    return None


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
    from .cached_values import sheet_parts

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
