"""Hostile and messy inputs, made at test time (nothing large or special is stored).

Each case is a function ``make(tmp) -> (argv, file_name, words)``: it writes its files into
``tmp`` and returns the ``cmmwb`` arguments to run, the file the message must name and the words
the message must contain.  ``tests/input/test_hostile_files.py`` runs each and requires one clear
message, exit status 2, no traceback and nothing written.

Families (issue 12): silent wrong numbers (field counts, duplicated columns, coordinates outside
the machine range / beyond float64's nanometre), files that reach other files (external links,
DDE, web queries, macros of every kind, a DTD in a part of any name), hangs and exhaustion (FIFO,
devices, folders, oversize files, cell and shared-string counts, memory), internal errors (huge
integers, deep nesting, circular references), names unsafe as file names, unclear messages (BOM,
NUL in [task] name).
"""

from __future__ import annotations

import os
import re
import zipfile
from pathlib import Path

from make_bad_files import POINTCLOUD_CSV, POINTCLOUD_TASK

HERE = Path(__file__).resolve().parent
BASE_BOOK = HERE / "text_in_parameter.xlsx"   # a cmmwb workbook (its problem lies in a cell check() never reads)

CASES: dict[str, object] = {}


def case(fn):
    CASES[fn.__name__] = fn
    return fn


# -- helpers ------------------------------------------------------------------------------------

def task(tmp: Path, toml: str = POINTCLOUD_TASK, csv: str | None = POINTCLOUD_CSV, name: str = "small.toml"):
    (tmp / name).write_text(toml, encoding="utf-8")
    if csv is not None:
        (tmp / "small.csv").write_text(csv, encoding="utf-8")
    return ["build", str(tmp / name), "--out", str(tmp / "out"), "--no-plots"]


def with_name(name: str) -> str:
    return POINTCLOUD_TASK.replace('name = "small"', f"name = {name}")


def csv_with_row(row: str) -> str:
    return POINTCLOUD_CSV + row + "\n"


def parts() -> dict[str, bytes]:
    with zipfile.ZipFile(BASE_BOOK) as z:
        return {i.filename: z.read(i) for i in z.infolist()}


def book(tmp: Path, p: dict[str, bytes], name: str = "hostile.xlsx") -> Path:
    path = tmp / name
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for n, data in p.items():
            z.writestr(n, data)
    return path


def with_formula(formula: str) -> dict[str, bytes]:
    """The base workbook with one more cell (Z1 of the first sheet) holding ``formula``."""
    p = parts()
    sheet = "xl/worksheets/sheet1.xml"
    cell = f'<c r="Z1"><f>{formula}</f><v>0</v></c>'.encode()
    p[sheet] = re.sub(rb"(<row\b[^>]*>)", lambda m: m.group(1) + cell, p[sheet], count=1)
    assert cell in p[sheet]
    return p


def with_part(name: str, data: bytes, rel_type: str | None = None, target: str | None = None,
              external: bool = False) -> dict[str, bytes]:
    p = parts()
    p[name] = data
    if rel_type:
        mode = ' TargetMode="External"' if external else ""
        rel = (f'<Relationship Id="rIdX" Type="http://schemas.openxmlformats.org/officeDocument/2006/'
               f'relationships/{rel_type}" Target="{target or name}"{mode}/>').encode()
        p["xl/_rels/workbook.xml.rels"] = p["xl/_rels/workbook.xml.rels"].replace(b"</Relationships>",
                                                                                  rel + b"</Relationships>")
    return p


def with_defined_name(name: str, text: str = "Inputs!$A$1", attrs: str = "") -> dict[str, bytes]:
    p = parts()
    dn = f'<definedName name="{name}"{attrs}>{text}</definedName>'.encode()
    wb = p["xl/workbook.xml"]
    if b"<definedNames>" in wb:
        wb = wb.replace(b"<definedNames>", b"<definedNames>" + dn, 1)
    else:
        wb = wb.replace(b"</sheets>", b"</sheets><definedNames>" + dn + b"</definedNames>", 1)
    p["xl/workbook.xml"] = wb
    return p


def recalc(path: Path, engine: str = "formulas"):
    return ["recalc", str(path), "--engine", engine]


def read(path: Path, tmp: Path):
    return ["read", str(path), "--out", str(tmp / "out" / "t.toml")]


DOCTYPE = b'<?xml version="1.0"?><!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]><x>&e;</x>'


# -- silent wrong numbers: CSV ------------------------------------------------------------------

@case
def csv_decimal_comma_gives_an_extra_field(tmp):
    return task(tmp, csv=csv_with_row("E,0,5,3,7,0,0,1,P1")), "small.csv", ["line 6", "9 fields", "header has 8",
                                                                             "decimal comma"]


@case
def csv_row_with_a_missing_field(tmp):
    return task(tmp, csv=csv_with_row("E,0,5,0,0,1,P1")), "small.csv", ["line 6", "7 fields"]


@case
def csv_two_columns_named_x(tmp):
    return (task(tmp, csv="id,x,y,z,nx,ny,nz,probe,x\nA,0,0,0,-1,0,0,P1,5\nB,100,0,0,1,0,0,P1,6\n"),
            "small.csv", ["line 1", "'x' appears twice"])


@case
def csv_x_and_x_mm_both_given(tmp):
    return (task(tmp, csv="id,x,y,z,nx,ny,nz,probe,x_mm\nA,0,0,0,-1,0,0,P1,5\nB,100,0,0,1,0,0,P1,6\n"),
            "small.csv", ["line 1", "'x' and 'x_mm' both give x"])


@case
def csv_coordinate_1e12_mm(tmp):
    return (task(tmp, csv=csv_with_row("E,1e12,0,0,1,0,0,P1")), "small.csv",
            ["line 6, column 'x'", "outside the plausible machine range"])


@case
def csv_coordinate_1e15_mm_in_z(tmp):
    return (task(tmp, csv=csv_with_row("E,1,0,1000000000000000,1,0,0,P1")), "small.csv",
            ["line 6, column 'z'", "1e+15 mm"])


@case
def csv_coordinate_just_outside_100_m(tmp):
    return task(tmp, csv=csv_with_row("E,0,-100001,0,1,0,0,P1")), "small.csv", ["line 6, column 'y'", "100000"]


@case
def toml_rows_coordinate_1e13_mm(tmp):
    toml = POINTCLOUD_TASK.replace('file = "small.csv"', 'rows = [{id = "A", x = 1e13, y = 0, z = 0, nx = 1, '
                                   'ny = 0, nz = 0, probe = "P1"}]')
    return task(tmp, toml, csv=None), "small.toml", ["[points] rows #1 key 'x'", "machine range"]


# -- TOML: huge integers, nesting, BOM ----------------------------------------------------------

@case
def toml_400_digit_integer(tmp):
    toml = POINTCLOUD_TASK.replace("sigma_R_um = 0.2", "sigma_R_um = " + "9" * 400)
    return task(tmp, toml), "small.toml", ["parameters.sigma_R_um", "400 digits", "64-bit"]


@case
def toml_5000_digit_integer(tmp):
    toml = POINTCLOUD_TASK.replace("sigma_R_um = 0.2", "sigma_R_um = " + "9" * 5000)
    return task(tmp, toml), "small.toml", ["malformed TOML", "integer too large"]


@case
def toml_arrays_nested_5000_deep(tmp):
    toml = POINTCLOUD_TASK + "\n[extra]\nx = " + "[" * 5000 + "]" * 5000 + "\n"
    return task(tmp, toml), "small.toml", ["nested too deeply"]


@case
def toml_arrays_nested_40_deep(tmp):
    toml = POINTCLOUD_TASK.replace("[parameters]", "deep = " + "[" * 40 + "1" + "]" * 40 + "\n\n[parameters]")
    return task(tmp, toml), "small.toml", ["task.deep", "nested deeper than 16"]


@case
def toml_with_bom_reaches_the_real_error(tmp):
    """The byte-order mark is accepted: the message is about the kind, not 'line 1, column 1'."""
    (tmp / "small.toml").write_bytes(b"\xef\xbb\xbf" + POINTCLOUD_TASK.replace('"pointcloud"', '"cloud"').encode())
    (tmp / "small.csv").write_text(POINTCLOUD_CSV)
    return ["build", str(tmp / "small.toml"), "--out", str(tmp / "out")], "small.toml", ["[task] kind",
                                                                                         "unknown kind 'cloud'"]


# -- names that should not become file names ----------------------------------------------------

@case
def name_with_a_newline(tmp):
    return task(tmp, with_name('"a\\nb"')), "small.toml", ["[task] name", "control character (0x0a)"]


@case
def name_with_a_nul(tmp):
    return task(tmp, with_name('"a\\u0000b"')), "small.toml", ["[task] name", "NUL character"]


@case
def points_file_name_with_a_nul(tmp):
    return (task(tmp, POINTCLOUD_TASK.replace('file = "small.csv"', 'file = "\\u0000"')), "small.toml",
            ["[points] file", "NUL character"])


@case
def name_with_right_to_left_override(tmp):
    return task(tmp, with_name('"report\\u202Excl.exe"')), "small.toml", ["[task] name", "U+202E"]


@case
def name_with_left_to_right_isolate(tmp):
    return task(tmp, with_name('"a\\u2066b"')), "small.toml", ["[task] name", "U+2066"]


@case
def name_con(tmp):
    return task(tmp, with_name('"CON"')), "small.toml", ["[task] name", "reserved device name", "CON"]


@case
def name_nul_with_extension(tmp):
    return task(tmp, with_name('"nul.txt"')), "small.toml", ["[task] name", "reserved device name", "NUL"]


@case
def name_com1_lower_case(tmp):
    return task(tmp, with_name('"com1"')), "small.toml", ["[task] name", "COM1"]


@case
def name_lpt9(tmp):
    return task(tmp, with_name('"LPT9.xlsx"')), "small.toml", ["[task] name", "LPT9"]


@case
def name_of_300_characters(tmp):
    return task(tmp, with_name('"' + "a" * 300 + '"')), "small.toml", ["[task] name", "longer than 100 characters"]


@case
def name_of_270_utf8_bytes(tmp):
    return task(tmp, with_name('"' + "\u20ac" * 90 + '"')), "small.toml", ["[task] name", "180 bytes"]


@case
def name_ending_in_a_dot(tmp):
    return task(tmp, with_name('"results."')), "small.toml", ["[task] name", "ends with '.'"]


# -- not regular files, oversize files ----------------------------------------------------------

@case
def task_file_is_a_fifo(tmp):
    os.mkfifo(tmp / "small.toml")
    return ["build", str(tmp / "small.toml"), "--out", str(tmp / "out")], "small.toml", ["FIFO", "not a regular file"]


@case
def points_file_is_a_fifo(tmp):
    argv = task(tmp, csv=None)
    os.mkfifo(tmp / "small.csv")
    return argv, "small.csv", ["points table", "FIFO"]


@case
def points_file_is_a_folder(tmp):
    argv = task(tmp, csv=None)
    (tmp / "small.csv").mkdir()
    return argv, "small.csv", ["folder"]


@case
def points_file_is_dev_zero(tmp):
    argv = task(tmp, POINTCLOUD_TASK.replace('file = "small.csv"', 'file = "/dev/zero"'), csv=None)
    return argv, "/dev/zero", ["character device"]


@case
def task_file_is_dev_zero(tmp):
    return ["build", "/dev/zero", "--out", str(tmp / "out")], "/dev/zero", ["character device"]


@case
def task_file_of_17_mib(tmp):
    with open(tmp / "small.toml", "wb") as fh:   # sparse: no disk space used
        fh.truncate(17 * 2**20)
    return ["build", str(tmp / "small.toml"), "--out", str(tmp / "out")], "small.toml", ["larger than 16 MiB"]


@case
def points_file_of_300_mib(tmp):
    argv = task(tmp, csv=None)
    with open(tmp / "small.csv", "wb") as fh:
        fh.truncate(300 * 2**20)
    return argv, "small.csv", ["larger than 256 MiB"]


@case
def workbook_is_a_fifo(tmp):
    os.mkfifo(tmp / "book.xlsx")
    return read(tmp / "book.xlsx", tmp), "book.xlsx", ["FIFO"]


@case
def workbook_is_a_fifo_in_recalc(tmp):
    os.mkfifo(tmp / "book.xlsx")
    return recalc(tmp / "book.xlsx"), "book.xlsx", ["FIFO"]


@case
def workbook_of_70_mib(tmp):
    with open(tmp / "big.xlsx", "wb") as fh:
        fh.write(b"PK\x03\x04")
        fh.truncate(70 * 2**20)
    return recalc(tmp / "big.xlsx", "libreoffice"), "big.xlsx", ["larger than 64 MiB"]


@case
def recordings_file_is_a_fifo(tmp):
    os.mkfifo(tmp / "rec.csv")
    return (["diagnose", str(tmp / "rec.csv"), "--sigma-um", "1", "--out", str(tmp / "out")], "rec.csv",
            ["recordings", "FIFO"])


LENGTH_RECORDS = ("id,x1,y1,z1,x2,y2,z2,reference_mm,measured_mm\n"
                  "L1,0,0,0,100,0,0,100,100.0001\nL2,0,0,0,0,100,0,100,99.9999\n"
                  "L3,0,0,0,0,0,100,100,100.0002\n")


@case
def recordings_coordinate_1e13_mm(tmp):
    (tmp / "rec.csv").write_text(LENGTH_RECORDS + "L4,1e13,0,0,1.00000000001e13,0,0,1e10,1e10\n")
    return (["diagnose", str(tmp / "rec.csv"), "--sigma-um", "1", "--out", str(tmp / "out")], "rec.csv",
            ["line 5", "x1", "machine range"])


@case
def recordings_decimal_comma(tmp):
    (tmp / "rec.csv").write_text(LENGTH_RECORDS + "L4,0,0,0,100,0,0,100,100,0002\n")
    return (["diagnose", str(tmp / "rec.csv"), "--sigma-um", "1", "--out", str(tmp / "out")], "rec.csv",
            ["line 5", "10 fields"])


# -- workbooks that would reach other files or run code (both engines: refused before either) ----

@case
def dtd_in_a_part_named_bin(tmp):
    return read(book(tmp, with_part("xl/media/data.bin", DOCTYPE)), tmp), "hostile.xlsx", [
        "part xl/media/data.bin", "document type declaration"]


@case
def dtd_in_an_unnamed_part_before_libreoffice(tmp):
    return recalc(book(tmp, with_part("xl/customData", DOCTYPE)), "libreoffice"), "hostile.xlsx", [
        "part xl/customData", "document type declaration"]


@case
def dtd_in_a_utf16_part(tmp):
    data = DOCTYPE.decode().replace('version="1.0"', 'version="1.0" encoding="UTF-16"').encode("utf-16")
    return recalc(book(tmp, with_part("xl/worksheets/extra.dat", data))), "hostile.xlsx", [
        "part xl/worksheets/extra.dat", "document type declaration"]


@case
def external_link_part(tmp):
    link = (b'<externalLink xmlns="http://schemas.openxmlformats.org/spreadsheetml/2006/main">'
            b'<externalBook r:id="rId1" xmlns:r="http://schemas.openxmlformats.org/officeDocument/2006/'
            b'relationships"/></externalLink>')
    p = with_part("xl/externalLinks/externalLink1.xml", link, "externalLink", "externalLinks/externalLink1.xml")
    return recalc(book(tmp, p)), "hostile.xlsx", ["external link"]


@case
def external_link_relationship_only(tmp):
    p = with_part("xl/other.xml", b"<x/>", "externalLinkPath", "file:///etc/passwd", external=True)
    return read(book(tmp, p), tmp), "hostile.xlsx", ["external link"]


@case
def external_ole_object_relationship(tmp):
    p = with_part("xl/other.xml", b"<x/>", "oleObject", "../../secret.xlsx", external=True)
    return recalc(book(tmp, p), "libreoffice"), "hostile.xlsx", ["another file", "secret.xlsx"]


@case
def formula_with_external_index(tmp):
    return recalc(book(tmp, with_formula("[1]Sheet1!A1"))), "hostile.xlsx", ["cell Z1", "another workbook"]


@case
def formula_with_absolute_path(tmp):
    return recalc(book(tmp, with_formula("'/etc/[passwd.xlsx]Sheet1'!A1"))), "hostile.xlsx", [
        "another workbook", "/etc/"]


@case
def formula_with_relative_path(tmp):
    return recalc(book(tmp, with_formula("'../other/[b.xlsx]Results'!B2*2")), "libreoffice"), "hostile.xlsx", [
        "another workbook"]


@case
def formula_with_windows_path(tmp):
    return read(book(tmp, with_formula("SUM('C:\\data\\[b.xlsx]S'!A1:A3)")), tmp), "hostile.xlsx", [
        "another workbook"]


@case
def dde_formula(tmp):
    return recalc(book(tmp, with_formula("cmd|'/c calc'!A0"))), "hostile.xlsx", ["DDE", "cell Z1"]


@case
def dde_formula_in_libreoffice(tmp):
    return recalc(book(tmp, with_formula("1+msexcel|'\\..\\..\\windows\\system32\\cmd.exe /c calc'!_xlbgnm.A1")),
                  "libreoffice"), "hostile.xlsx", ["DDE"]


@case
def dde_link_part(tmp):
    dde = (b'<externalLink xmlns="http://schemas.openxmlformats.org/spreadsheetml/2006/main">'
           b'<ddeLink ddeService="cmd" ddeTopic="/c calc"/></externalLink>')
    return read(book(tmp, with_part("xl/links/dde1.xml", dde)), tmp), "hostile.xlsx", ["DDE"]


@case
def webservice_formula(tmp):
    return recalc(book(tmp, with_formula('WEBSERVICE("http://example.com/")'))), "hostile.xlsx", ["WEBSERVICE"]


@case
def indirect_formula(tmp):
    return recalc(book(tmp, with_formula("INDIRECT(\"'/etc/[x.xlsx]S'!A1\")"))), "hostile.xlsx", ["INDIRECT"]


@case
def query_table_part(tmp):
    return recalc(book(tmp, with_part("xl/queryTables/queryTable1.xml", b"<queryTable/>"))), "hostile.xlsx", [
        "query"]


@case
def connections_part(tmp):
    return read(book(tmp, with_part("xl/connections.xml", b"<connections/>")), tmp), "hostile.xlsx", [
        "data connection"]


@case
def excel4_macro_sheet(tmp):
    p = with_part("xl/macrosheets/sheet1.xml", b"<xm:macrosheet xmlns:xm='x'/>", "xlMacrosheet",
                  "macrosheets/sheet1.xml")
    return read(book(tmp, p), tmp), "hostile.xlsx", ["Excel 4.0 macro sheet"]


@case
def excel4_macro_sheet_in_recalc(tmp):
    p = with_part("xl/macrosheets/sheet1.xml", b"<xm:macrosheet xmlns:xm='x'/>", "xlMacrosheet",
                  "macrosheets/sheet1.xml")
    return recalc(book(tmp, p), "libreoffice"), "hostile.xlsx", ["Excel 4.0 macro sheet"]


@case
def auto_open_defined_name(tmp):
    return read(book(tmp, with_defined_name("Auto_Open")), tmp), "hostile.xlsx", ["Auto_Open", "macro"]


@case
def xlnm_auto_close_defined_name(tmp):
    return recalc(book(tmp, with_defined_name("_xlnm.Auto_Close"))), "hostile.xlsx", ["Auto_Close", "macro"]


@case
def macro_function_defined_name(tmp):
    return recalc(book(tmp, with_defined_name("Run", attrs=' function="1" xlm="1"'))), "hostile.xlsx", ["macro"]


@case
def defined_name_to_another_workbook(tmp):
    return read(book(tmp, with_defined_name("linked", "[1]Sheet1!$A$1")), tmp), "hostile.xlsx", [
        "defined name linked", "another workbook"]


@case
def vba_project_under_another_name(tmp):
    return recalc(book(tmp, with_part("xl/media/VbaProjectSignature.bin", b"\xd0\xcf\x11\xe0"))), "hostile.xlsx", [
        "VBA project"]


@case
def activex_control(tmp):
    return read(book(tmp, with_part("xl/activeX/activeX1.xml", b"<ax/>")), tmp), "hostile.xlsx", ["ActiveX"]


# -- size: cells and shared strings, counted (not the counts a file declares) -------------------

def _sheet_with_cells(rows: int, cols: int) -> bytes:
    row = "".join(f'<c r="{chr(65 + c)}{{r}}"><v>1</v></c>' for c in range(cols))
    body = "".join(f'<row r="{r}">{row.format(r=r)}</row>' for r in range(1, rows + 1))
    return ('<worksheet xmlns="http://schemas.openxmlformats.org/spreadsheetml/2006/main"><sheetData>'
            f"{body}</sheetData></worksheet>").encode()


@case
def formulas_engine_on_300000_cells(tmp):
    p = parts()
    p["xl/worksheets/sheet1.xml"] = _sheet_with_cells(100_000, 3)
    return recalc(book(tmp, p)), "hostile.xlsx", ["more than 250,000 cells", "--engine libreoffice"]


@case
def six_hundred_thousand_shared_strings(tmp):
    p = parts()
    p["xl/sharedStrings.xml"] = (
        b'<sst xmlns="http://schemas.openxmlformats.org/spreadsheetml/2006/main" count="1" uniqueCount="1">'
        + b"".join(b"<si><t>s%d</t></si>" % k for k in range(600_000)) + b"</sst>")
    return read(book(tmp, p), tmp), "hostile.xlsx", ["more than 500,000 shared strings"]


# -- generated geometry far outside the machine -------------------------------------------------

EXAMPLES = HERE.parents[1] / "generator" / "examples"


@case
def feature_sampling_radius_of_1e13_mm(tmp):
    toml = (EXAMPLES / "feature_cylinder_bore.toml").read_text().replace("r0_mm = 25.0", "r0_mm = 1e13")
    (tmp / "bore.toml").write_text(toml)
    return ["build", str(tmp / "bore.toml"), "--out", str(tmp / "out")], "bore.toml", [
        "[sampling]", "e+12 mm from the origin", "machine range"]


@case
def budget_point_at_1e14_mm(tmp):
    toml = (EXAMPLES / "knuckle.toml").read_text()
    toml2 = re.sub(r"(?m)^(\w+) = \[([-\d.]+),", lambda m: f"{m.group(1)} = [1e14,", toml, count=1)
    assert toml2 != toml
    (tmp / "knuckle.toml").write_text(toml2)
    return ["build", str(tmp / "knuckle.toml"), "--out", str(tmp / "out")], "knuckle.toml", [
        "[points]", "machine range"]
