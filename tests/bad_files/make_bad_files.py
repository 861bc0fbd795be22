"""The corpus of bad files in this folder, and the message each must give.

Every file here is something a person (or an attacker) could hand to ``cmmwb read`` (the .xlsx
files) or ``cmmwb build`` (the .toml files and their points tables).  Each must give one clear
message naming the file and the sheet/cell (or line/key) at fault, exit status 2, no traceback,
and write nothing.  ``tests/input/test_bad_files.py`` checks that, with the words listed in CASES.

The workbooks are cmmwb's own workbooks of small tasks, broken one way each.  Regenerate them
(after a change of the workbook layout) with

    python tests/bad_files/make_bad_files.py

The 1 GB zip bomb, the XML entity bomb and the archive with too many parts are made at test
time (see the test), not stored.
"""

from __future__ import annotations

import datetime
import json
import re
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path

import openpyxl

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

POINTCLOUD_TASK = """[task]
kind = "pointcloud"
name = "small"

[parameters]
sigma_R_um = 0.2
sigma_S_ppm = 0.7
sigma_PQ_um = 0.2
sigma_ET_um = 0.3
lambda_ET_mm = 150

[[probes]]
id = "P1"
offset_mm = [0.0, 0.0, -20.0]

[[probes]]
id = "P2"
offset_mm = [30.0, 0.0, -20.0]

[points]
file = "small.csv"
"""
POINTCLOUD_CSV = """id,x,y,z,nx,ny,nz,probe
A,0,0,0,-1,0,0,P1
B,100,0,0,1,0,0,P1
C,0,50,0,0,-1,0,P2
D,0,50,80,0,0,1,P2
"""

# -- how each workbook is broken -----------------------------------------------------------


def _named(wb, name):
    (sheet, coord), = wb.defined_names[name].destinations
    return wb[sheet][coord.replace("$", "")]


def _set(name, value):
    def f(wb):
        _named(wb, name).value = value
    return f


def _cell(sheet, coord, value, data_type=None):
    def f(wb):
        c = wb[sheet][coord]
        c.value = value
        if data_type:
            c.data_type = data_type
    return f


def _rename_name(old, new):
    def f(wb):
        dn = wb.defined_names.pop(old)
        dn.name = new
        wb.defined_names[new] = dn
    return f


def _name_to(name, text):
    def f(wb):
        wb.defined_names[name].attr_text = text
    return f


def _delete_sheet(title):
    def f(wb):
        del wb[title]
    return f


def _merge(sheet, rng):
    def f(wb):
        wb[sheet].merge_cells(rng)
    return f


def _task_json(edit):
    def f(wb):
        ws = wb["_task"]
        parts, r = [], 2
        while ws.cell(row=r, column=1).value is not None:
            parts.append(ws.cell(row=r, column=1).value)
            ws.cell(row=r, column=1).value = None
            r += 1
        text = edit("".join(parts))
        ws.cell(row=2, column=1).value = text
        ws.cell(row=2, column=1).data_type = "s"
    return f


def _kind(kind):
    return _task_json(lambda t: json.dumps({**json.loads(t), "kind": kind}))


# XML-level edits of a saved workbook: (part, regex, replacement)
def _xml(part_of_sheet, pattern, repl):
    return ("xml", part_of_sheet, pattern, repl)


# name: (base, edit, words the message must contain)
CASES: dict[str, tuple] = {
    # not a workbook at all
    "not_a_zip.xlsx": ("bytes", b"id,x,y,z\nA,0,0,0\n", ["not an .xlsx file"]),
    "truncated.xlsx": ("truncate", None, ["broken zip archive"]),
    "old_format_or_encrypted.xlsx": ("bytes", b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1" + b"\0" * 504,
                                     ["old-format .xls or a password-protected"]),
    "macro_enabled.xlsm": ("copy", None, ["macro-enabled"]),
    "vba_project_inside.xlsx": ("zip-add", ("xl/vbaProject.bin", b"\xd0\xcf\x11\xe0vba"), ["contains macros"]),
    "opendocument_renamed.xlsx": ("ods", None, ["OpenDocument"]),
    "zip_without_workbook.xlsx": ("zip-only", None, ["no xl/workbook.xml"]),
    # hostile XML
    "external_entity.xlsx": ("zip-edit", ("xl/workbook.xml", rb"^(<\?xml[^>]*\?>)?",
                                          b'<?xml version="1.0"?><!DOCTYPE x [<!ENTITY e SYSTEM '
                                          b'"file:///etc/passwd">]>'),
                             ["part xl/workbook.xml", "document type declaration"]),
    "doctype_in_sheet.xlsx": ("zip-edit", ("xl/worksheets/sheet2.xml", rb"^(<\?xml[^>]*\?>)?",
                                           b'<?xml version="1.0"?><!DOCTYPE worksheet>'),
                              ["part xl/worksheets/sheet2.xml", "document type declaration"]),
    # a workbook, but not one cmmwb wrote, or its task information is damaged
    "plain_workbook.xlsx": ("plain", None, ["no hidden sheet '_task'", "not a workbook written by cmmwb"]),
    "task_info_damaged.xlsx": ("pc", _task_json(lambda t: t[: len(t) // 2]), ["sheet _task", "damaged"]),
    "task_info_unknown_kind.xlsx": ("pc", _kind("spline"), ["sheet _task", "unknown task kind 'spline'"]),
    # missing sheets, renamed or broken names
    "missing_points_sheet.xlsx": ("pc", _delete_sheet("Points"), ["no sheet named 'Points'"]),
    "missing_local_sheet.xlsx": ("feature", _delete_sheet("Local"), ["no sheet named 'Local'"]),
    "renamed_name.xlsx": ("pc", _rename_name("sigma_R_um", "sigma_R"),
                          ["defined name 'sigma_R_um' is missing"]),
    "renamed_probe_name.xlsx": ("pc", _rename_name("probe1_px_mm", "px1"),
                                ["defined name 'probe1_px_mm' is missing"]),
    "name_points_to_ref_error.xlsx": ("pc", _name_to("sigma_ET_um", "#REF!"),
                                      ["defined name 'sigma_ET_um' does not point to one cell"]),
    "name_points_to_range.xlsx": ("pc", _name_to("K", "Inputs!$B$2:$B$5"),
                                  ["defined name 'K' must point to one cell"]),
    "points_header_changed.xlsx": ("pc", _cell("Points", "B1", "x"), ["sheet Points, row 1", "header row"]),
    # wrong types
    "text_in_parameter.xlsx": ("pc", _set("sigma_R_um", "abc"),
                               ["sheet Inputs, cell B2", "'abc' is not a number", "sigma_R_um"]),
    "number_stored_as_text.xlsx": ("pc", _set("sigma_ET_um", "0.25"), ["sheet Inputs, cell B7",
                                                                      "'0.25' is text, not a number"]),
    "boolean_in_parameter.xlsx": ("pc", _set("lambda_ET_mm", True), ["sheet Inputs, cell B8", "TRUE where a number"]),
    "date_in_coordinate.xlsx": ("pc", _cell("Points", "C3", datetime.datetime(2024, 5, 1)),
                                ["sheet Points, cell C3", "a date or time"]),
    "empty_coordinate.xlsx": ("pc", _cell("Points", "D4", None), ["sheet Points, cell D4", "empty", "z_mm of point C"]),
    "text_in_probe_offset.xlsx": ("pc", _set("probe2_px_mm", "thirty"), ["sheet Inputs", "'thirty' is not a number"]),
    "text_in_ted.xlsx": ("budget", _set("S4_position_ted1_mm", "n/a"), ["sheet Inputs", "'n/a' is not a number"]),
    # NaN, infinities, error values (written into the XML as a program other than Excel might)
    "nan_in_parameter.xlsx": ("pc-xml", ("Inputs", "B2", b"NaN"), ["cannot be read as a workbook", "NaN"]),
    "infinite_coordinate.xlsx": ("pc-xml", ("Points", "B3", b"1E999"), ["sheet Points, cell B3", "not a finite number"]),
    "minus_infinite_parameter.xlsx": ("pc-xml", ("Inputs", "B4", b"-1E999"), ["sheet Inputs, cell B4",
                                                                              "not a finite number"]),
    "error_value_in_parameter.xlsx": ("pc", _cell("Inputs", "B5", "#DIV/0!", "e"), ["sheet Inputs, cell B5",
                                                                                  "error value #DIV/0!"]),
    # formulas typed where numbers or labels belong
    "formula_in_parameter.xlsx": ("pc", _set("sigma_R_um", "=0.1*2"),
                                  ["sheet Inputs, cell B2", "a formula (=0.1*2) where a number belongs"]),
    "formula_in_coordinate.xlsx": ("pc", _cell("Points", "C3", "=B3+1"), ["sheet Points, cell C3", "formula"]),
    "formula_in_probe_override.xlsx": ("pc", _cell("Inputs", "E19", "=sigma_PQ_um/2"),
                                       ["sheet Inputs, cell E19", "formula"]),
    "label_formula_equals.xlsx": ("pc", _cell("Points", "A2", "=SUM(B2:D2)"),
                                  ["sheet Points, cell A2", "where a label belongs"]),
    "label_formula_plus.xlsx": ("pc", _cell("Points", "A3", "=+B3"), ["sheet Points, cell A3", "where a label belongs"]),
    "label_formula_minus.xlsx": ("pc", _cell("Points", "A4", "=-B4"), ["sheet Points, cell A4", "where a label belongs"]),
    "label_formula_at.xlsx": ("pc", _cell("Points", "A5", "=@B5"), ["sheet Points, cell A5", "where a label belongs"]),
    "probe_label_formula.xlsx": ("pc", _cell("Inputs", "A19", "=A18"), ["sheet Inputs, cell A19",
                                                                        "where a label belongs"]),
    # merged cells in the input area
    "merged_points.xlsx": ("pc", _merge("Points", "B3:C3"), ["sheet Points, cell B3", "merged cells (B3:C3)"]),
    "merged_parameters.xlsx": ("pc", _merge("Inputs", "B3:B4"), ["sheet Inputs", "merged cells (B3:B4)"]),
    # values outside their range, structure the model rejects
    "negative_sigma.xlsx": ("pc", _set("sigma_R_um", -0.2), ["sheet Inputs, cell B2", "not allowed", ">= 0"]),
    "negative_weight.xlsx": ("feature", _cell("Local", "B3", -1.0),
                             ["sheet Local, cell B3", "-1 is not allowed", ">= 0"]),
    "unknown_probe.xlsx": ("pc", _cell("Points", "H3", "P9"), ["sheet Points, cell H3", "unknown probe 'P9'"]),
    "duplicate_point_id.xlsx": ("pc", _cell("Points", "A4", "A"), ["sheet Points, cell A4", "also in row 2"]),
    "non_unit_normal.xlsx": ("pc", _cell("Points", "F3", 1.0), ["sheet Points, row 3", "not a unit vector"]),
    "coincident_points.xlsx": ("pc", _cell("Points", "B3", 0.0), ["A and B are at the same place"]),
    # task files for `cmmwb build`
    "build_nul_in_points.toml": ("build", ("nul_in_points.csv", "id,x,y,z,nx,ny,nz,probe\nA,0,0,0\0,1,0,0,P1\n"),
                                 ["nul_in_points.csv", "line 2", "column 'z'", "is not a number"]),
    "build_latin1_points.toml": ("build", ("latin1_points.csv", "id,x,y,z,nx,ny,nz,probe\nPunkt\xe9,0,0,0,1,0,0,P1\n"),
                                 ["latin1_points.csv", "not UTF-8"]),
    "build_nan_in_points.toml": ("build", ("nan_points.csv", "id,x,y,z,nx,ny,nz,probe\nA,0,0,0,1,0,0,P1\n"
                                                            "B,nan,0,0,1,0,0,P1\n"),
                                 ["nan_points.csv", "line 3", "not a finite number"]),
    "build_inf_parameter.toml": ("build-toml", "sigma_R_um = inf", ["[parameters] sigma_R_um", "finite"]),
    "build_string_parameter.toml": ("build-toml", 'sigma_R_um = "=1+1"', ["[parameters] sigma_R_um", "number"]),
}


def build_base(folder: Path, kind: str) -> Path:
    """A small cmmwb workbook of each kind (built by cmmwb build)."""
    from cmmwb.generator.cli import build_task

    ex = ROOT / "generator" / "examples"
    if kind == "pc":
        (folder / "small.toml").write_text(POINTCLOUD_TASK)
        (folder / "small.csv").write_text(POINTCLOUD_CSV)
        task = folder / "small.toml"
    elif kind == "budget":
        task = ex / "knuckle.toml"
    else:
        task = ex / "feature_plane_face.toml"
    _, files = build_task(task, folder / f"out_{kind}", plots=False)
    return next(f for f in files if f.suffix == ".xlsx")


def _zip_rewrite(src: Path, dst: Path, edit=None, add=None, only=None) -> None:
    with zipfile.ZipFile(src) as z, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as out:
        for info in z.infolist():
            if only is not None and info.filename not in only:
                continue
            data = z.read(info)
            if edit and info.filename == edit[0]:
                data = re.sub(edit[1], edit[2], data, count=1)
            out.writestr(_info(info.filename), data)
        if add:
            out.writestr(_info(add[0]), add[1])


def _info(name: str) -> zipfile.ZipInfo:
    zi = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
    zi.compress_type = zipfile.ZIP_DEFLATED
    return zi


def _sheet_part(book: Path, title: str) -> str:
    from cmmwb.generator.workbook.cached_values import sheet_parts

    with zipfile.ZipFile(book) as z:
        return sheet_parts(z)[title]


def make(folder: Path = HERE) -> list[Path]:
    folder.mkdir(exist_ok=True)
    made = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        bases = {k: build_base(tmp, k) for k in ("pc", "budget", "feature")}
        pc = bases["pc"]
        for name, (how, arg, _words) in CASES.items():
            dst = folder / name
            if how == "bytes":
                dst.write_bytes(arg)
            elif how == "truncate":
                dst.write_bytes(pc.read_bytes()[: pc.stat().st_size // 2])
            elif how == "copy":
                shutil.copyfile(pc, dst)
            elif how == "zip-add":
                _zip_rewrite(pc, dst, add=arg)
            elif how == "zip-edit":
                _zip_rewrite(pc, dst, edit=arg)
            elif how == "zip-only":
                _zip_rewrite(pc, dst, only={"[Content_Types].xml", "_rels/.rels", "docProps/app.xml"})
            elif how == "ods":
                with zipfile.ZipFile(dst, "w") as z:
                    z.writestr(zipfile.ZipInfo("mimetype", date_time=(1980, 1, 1, 0, 0, 0)),
                               "application/vnd.oasis.opendocument.spreadsheet")
                    z.writestr(zipfile.ZipInfo("content.xml", date_time=(1980, 1, 1, 0, 0, 0)),
                               "<office:document-content/>")
            elif how == "plain":
                wb = openpyxl.Workbook()
                wb.active["A1"] = "sigma_R_um"
                wb.active["B1"] = 0.2
                wb.save(dst)
            elif how == "pc-xml":
                sheet, coord, text = arg
                part = _sheet_part(pc, sheet)
                pat = rb'(<c r="' + coord.encode() + rb'"[^>]*>)<v>[^<]*</v>'
                _zip_rewrite(pc, dst, edit=(part, pat, rb"\g<1><v>" + text + rb"</v>"))
            elif how in ("pc", "budget", "feature"):
                wb = openpyxl.load_workbook(bases[how])
                arg(wb)
                wb.save(dst)
            elif how == "build":
                csv_name, csv_text = arg
                (folder / csv_name).write_bytes(csv_text.encode("latin-1" if "latin1" in csv_name else "utf-8"))
                dst.write_text(POINTCLOUD_TASK.replace('name = "small"', f'name = "{dst.stem}"')
                               .replace('"small.csv"', f'"{csv_name}"'))
                made.append(folder / csv_name)
            elif how == "build-toml":
                (folder / "small.csv").write_text(POINTCLOUD_CSV)
                dst.write_text(POINTCLOUD_TASK.replace("sigma_R_um = 0.2", arg)
                               .replace('name = "small"', f'name = "{dst.stem}"'))
                made.append(folder / "small.csv")
            else:  # pragma: no cover
                raise ValueError(how)
            made.append(dst)
    return made


if __name__ == "__main__":
    for p in sorted(set(make())):
        print(p.relative_to(ROOT))
