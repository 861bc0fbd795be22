"""Field finish (issue 25), messages that name the place: an empty points file name, a full disk
(the output folder), a DDE formula (the sheet's name, not the zip part), TOML nested thousands of
levels deep (the key and line).  Each is one line, exit status 2, nothing written."""

from __future__ import annotations

import errno
import os
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import openpyxl
import pytest

from cmmwb.generator.cli import main

from tests.helpers import BAD_FILES, DATA

sys.path.insert(0, str(BAD_FILES))
from make_bad_files import POINTCLOUD_CSV, POINTCLOUD_TASK  # noqa: E402

from tests.helpers.files import assert_clear_failure  # noqa: E402


def run_cli(capsys, *args) -> tuple[int, str]:
    code = main(list(args))
    return code, capsys.readouterr().err.strip()


def write_task(tmp_path: Path, toml: str = POINTCLOUD_TASK) -> Path:
    (tmp_path / "small.toml").write_text(toml)
    (tmp_path / "small.csv").write_text(POINTCLOUD_CSV)
    return tmp_path / "small.toml"


# -- [points] file ----------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ['""', '"  "'])
def test_an_empty_points_file_name_is_named_as_the_key(tmp_path, capsys, name):
    task = write_task(tmp_path, POINTCLOUD_TASK.replace('file = "small.csv"', f"file = {name}"))
    code, err = run_cli(capsys, "build", str(task), "--out", str(tmp_path / "out"))
    assert_clear_failure(code, err, "small.toml", ["[points] file", "is empty", "name the points table"])
    assert not (tmp_path / "out").exists()


def test_a_points_file_name_that_is_a_folder_is_named_as_the_key(tmp_path, capsys):
    (tmp_path / "tables").mkdir()
    task = write_task(tmp_path, POINTCLOUD_TASK.replace('file = "small.csv"', 'file = "tables"'))
    code, err = run_cli(capsys, "build", str(task), "--out", str(tmp_path / "out"))
    assert_clear_failure(code, err, "small.toml", ["[points] file", "'tables' is a folder"])


# -- a full disk --------------------------------------------------------------------------------------

def test_a_full_disk_names_the_output_folder(tmp_path, capsys, monkeypatch):
    """ENOSPC while the workbook is written into the staging folder: the message names DIR (not
    the hidden staging file), the previous outputs stay."""
    task = write_task(tmp_path)
    out = tmp_path / "results"
    code0, err0 = run_cli(capsys, "build", str(task), "--out", str(out), "--no-plots")
    assert code0 == 0, err0
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    import openpyxl.workbook.workbook as wbmod

    def no_space(self, filename):
        with open(filename, "wb") as fh:
            fh.write(b"PK")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(filename))

    monkeypatch.setattr(wbmod.Workbook, "save", no_space)
    code, err = run_cli(capsys, "build", str(task), "--out", str(out), "--no-plots")
    assert_clear_failure(code, err, str(out), ["cannot write the outputs into this folder", "the disk is full",
                                               "previous output is unchanged"])
    assert err.startswith(f"cmmwb: error: {out}: ") and ".cmmwb-" not in err, err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_a_full_disk_while_committing_names_the_output_folder(tmp_path, capsys, monkeypatch):
    task = write_task(tmp_path)
    out = tmp_path / "results"
    real_replace = os.replace

    def no_space(src, dst, *a, **k):
        if Path(dst).parent == out:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(dst))
        return real_replace(src, dst, *a, **k)

    monkeypatch.setattr(os, "replace", no_space)
    code, err = run_cli(capsys, "build", str(task), "--out", str(out), "--no-plots")
    assert_clear_failure(code, err, str(out), ["cannot write the outputs into this folder", "the disk is full"])
    assert not out.exists()


def _mount_tmpfs(where: Path, size: str) -> bool:
    if os.geteuid() != 0:
        return False
    where.mkdir()
    return subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                          capture_output=True).returncode == 0


def test_a_real_full_disk_names_the_output_folder(tmp_path):
    """A 40 kB tmpfs (where this test may mount one): the workbook does not fit."""
    disk = tmp_path / "disk"
    if not _mount_tmpfs(disk, "40k"):
        pytest.skip("cannot mount a tmpfs here (needs root)")
    try:
        task = write_task(tmp_path)
        out = disk / "out"
        r = subprocess.run([sys.executable, "-m", "cmmwb.generator", "build", str(task), "--out", str(out)],
                           capture_output=True, text=True, timeout=120)
        assert_clear_failure(r.returncode, r.stderr.strip(), str(out), ["the disk is full"])
        assert list(disk.iterdir()) == []
    finally:
        subprocess.run(["umount", str(disk)], capture_output=True)


# -- a DDE formula: the sheet's name ----------------------------------------------------------------

def test_a_dde_formula_is_named_by_its_sheet_not_its_zip_part(tmp_path, capsys):
    """Sheets 'Alpha' and 'Beta' whose parts are swapped (Alpha is xl/worksheets/sheet2.xml): the
    message follows workbook.xml and its relationships to the sheet's name."""
    src = tmp_path / "plain.xlsx"
    wb = openpyxl.Workbook()
    wb.active.title = "Results"
    wb.active["A1"] = "name"
    wb.create_sheet("Alpha")["B2"] = 1.0
    wb.create_sheet("Beta")["C3"] = 2.0
    wb.save(src)
    with zipfile.ZipFile(src) as z:
        parts = {i.filename: z.read(i) for i in z.infolist()}
    rels = parts["xl/_rels/workbook.xml.rels"].decode()
    rels = rels.replace("worksheets/sheet2.xml", "@").replace("worksheets/sheet3.xml", "worksheets/sheet2.xml")
    parts["xl/_rels/workbook.xml.rels"] = rels.replace("@", "worksheets/sheet3.xml").encode()
    parts["xl/worksheets/sheet2.xml"], parts["xl/worksheets/sheet3.xml"] = (parts["xl/worksheets/sheet3.xml"],
                                                                            parts["xl/worksheets/sheet2.xml"])
    # now Alpha (B2) lives in sheet3.xml and Beta (C3) in sheet2.xml; the DDE goes into Beta's C3
    sheet = parts["xl/worksheets/sheet2.xml"].decode()
    sheet, n = re.subn(r'<c r="C3"([^>]*)><v>2</v></c>', r"""<c r="C3"\1><f>cmd|'/c calc'!A0</f><v>0</v></c>""",
                       sheet)
    assert n == 1, sheet
    parts["xl/worksheets/sheet2.xml"] = sheet.encode()
    book = tmp_path / "dde.xlsx"
    with zipfile.ZipFile(book, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in parts.items():
            z.writestr(name, data)
    code, err = run_cli(capsys, "recalc", str(book))
    assert_clear_failure(code, err, "dde.xlsx", ["sheet Beta, cell C3", "DDE"])
    assert "xl/worksheets" not in err


# -- TOML nested thousands deep -----------------------------------------------------------------------

@pytest.mark.parametrize("value", ["{a = " * 3000 + "1" + "}" * 3000, "[\n" + "[" * 3000 + "1" + "]" * 3000 + "]"],
                         ids=["inline tables", "arrays"])
def test_toml_nested_3000_deep_names_the_key_and_line(tmp_path, capsys, value):
    toml = POINTCLOUD_TASK.replace("[parameters]", f'note = "[[[[ not nesting ]]]]"\ndeep = {value}\n\n[parameters]')
    task = write_task(tmp_path, toml)
    code, err = run_cli(capsys, "build", str(task), "--out", str(tmp_path / "out"))
    line = 6 if value.startswith("{") else 7
    assert_clear_failure(code, err, "small.toml", [f"line {line}, key task.deep", "nested too deeply"])


def test_a_table_header_3000_deep_names_its_top_key(tmp_path, capsys):
    task = write_task(tmp_path, POINTCLOUD_TASK + "\n[deep" + ".a" * 3000 + "]\nx = 1\n")
    code, err = run_cli(capsys, "build", str(task), "--out", str(tmp_path / "out"))
    assert_clear_failure(code, err, "small.toml", ["small.toml, deep.a.a", "nested deeper than 16"])


def test_a_full_disk_while_importing_names_the_file_being_written(tmp_path, capsys, monkeypatch):
    """`cmmwb import` writes through generator.workbook.atomic: the message names the output
    file, not the hidden temporary file beside it."""
    from pathlib import Path as _Path

    sample = DATA / "qif" / "QIF_PTS_SAMPLE.QIF"
    real_write = _Path.write_text

    def no_space(self, *a, **k):
        if self.name.startswith(".rec.csv."):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self))
        return real_write(self, *a, **k)

    monkeypatch.setattr(_Path, "write_text", no_space)
    out = tmp_path / "rec.csv"
    code, err = run_cli(capsys, "import", str(sample), "--out", str(out))
    assert_clear_failure(code, err, str(out), ["the disk is full"])
    assert err.startswith(f"cmmwb: error: {out}: ") and ".tmp" not in err, err
    assert list(tmp_path.iterdir()) == []
