"""Bad and hostile files: `cmmwb read` (workbooks) and `cmmwb build` (task files) give one clear
message naming the file and the sheet/cell or line/key, exit status 2, no traceback, and write
nothing.  The corpus is tests/bad_files/ (see make_bad_files.py there for how each file is broken
and the words its message must contain); the zip bomb, the entity bomb and the archive with too
many parts are made here, at test time."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from cmmwb.generator.cli import main
from cmmwb.generator.errors import InputError
from cmmwb.generator.workbook.safe_xlsx import MAX_UNCOMPRESSED_BYTES, check

from tests.helpers import BAD_FILES
from tests.helpers.files import assert_clear_failure

CORPUS = BAD_FILES
sys.path.insert(0, str(CORPUS))
from make_bad_files import CASES, POINTCLOUD_CSV, POINTCLOUD_TASK  # noqa: E402


def run_cli(capsys, *args) -> tuple[int, str]:
    code = main(list(args))
    err = capsys.readouterr().err.strip()
    return code, err


def test_the_corpus_has_at_least_30_bad_files_and_each_has_a_case():
    files = {p.name for p in CORPUS.iterdir() if p.suffix in (".xlsx", ".xlsm", ".toml")}
    assert files == set(CASES), "regenerate with: python tests/bad_files/make_bad_files.py"
    assert len(files) >= 30


@pytest.mark.parametrize("name", [n for n in CASES if not n.startswith("build_")])
def test_read_refuses_a_bad_workbook(tmp_path, capsys, name):
    out = tmp_path / "out"
    code, err = run_cli(capsys, "read", str(CORPUS / name), "--out", str(out / "task.toml"))
    assert_clear_failure(code, err, name, CASES[name][2])
    assert not out.exists()  # nothing written


@pytest.mark.parametrize("name", [n for n in CASES if n.startswith("build_")])
def test_build_refuses_a_bad_task(tmp_path, capsys, name):
    work = tmp_path / "work"
    shutil.copytree(CORPUS, work, ignore=shutil.ignore_patterns("*.xls*", "*.py", "__pycache__"))
    out = tmp_path / "out"
    code, err = run_cli(capsys, "build", str(work / name), "--out", str(out))
    assert_clear_failure(code, err, "", CASES[name][2])
    assert not out.exists()


def test_one_bad_workbook_through_the_real_command_line(tmp_path):
    """The same through `python -m generator`: the process prints one line and exits 2."""
    r = subprocess.run([sys.executable, "-m", "cmmwb.generator", "read", str(CORPUS / "formula_in_parameter.xlsx"),
                        "--out", str(tmp_path / "t.toml")], capture_output=True, text=True)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip() == ("cmmwb: error: " + str(CORPUS / "formula_in_parameter.xlsx") +
                                ", sheet Inputs, cell B2: a formula (=0.1*2) where a number belongs "
                                "(sigma_R_um): type the number itself")
    assert list(tmp_path.iterdir()) == []


# -- hostile archives, made at run time (tiny on disk) -------------------------------------------

def _valid_parts() -> dict[str, bytes]:
    with zipfile.ZipFile(CORPUS / "text_in_parameter.xlsx") as z:
        return {i.filename: z.read(i) for i in z.infolist()}


def _write_zip(path: Path, parts: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in parts.items():
            z.writestr(name, data)
    return path


@pytest.mark.foreign_books       # hostile files, written on purpose
def test_a_zip_bomb_of_1_gb_is_refused_before_decompressing(tmp_path, capsys):
    """A 1 GiB part of zeros compresses to a few MB; its declared size gives it away."""
    book = _write_zip(tmp_path / "bomb.xlsx", _valid_parts())
    block = bytes(2**20)
    with zipfile.ZipFile(book, "a", zipfile.ZIP_DEFLATED, compresslevel=1) as z:
        with z.open("xl/worksheets/sheet99.xml", "w") as fh:
            for _ in range(1024):
                fh.write(block)
    with zipfile.ZipFile(book) as z:
        assert z.getinfo("xl/worksheets/sheet99.xml").file_size == 2**30 > MAX_UNCOMPRESSED_BYTES
    assert book.stat().st_size < 8 * 2**20                 # on disk: a few MB for 1 GiB
    code, err = run_cli(capsys, "read", str(book), "--out", str(tmp_path / "o" / "t.toml"))
    assert_clear_failure(code, err, "bomb.xlsx", ["zip bomb", "refused"])
    assert not (tmp_path / "o").exists()


@pytest.mark.foreign_books       # hostile files, written on purpose
def test_an_xml_entity_bomb_is_refused(tmp_path, capsys):
    """'Billion laughs': ten levels of ten entity references in the shared strings."""
    lol = ['<!ENTITY lol0 "lol">'] + [f'<!ENTITY lol{k} "{("&lol%d;" % (k - 1)) * 10}">' for k in range(1, 10)]
    bomb = ('<?xml version="1.0"?><!DOCTYPE sst [' + "".join(lol) + ']>'
            '<sst xmlns="http://schemas.openxmlformats.org/spreadsheetml/2006/main" count="1" uniqueCount="1">'
            '<si><t>&lol9;</t></si></sst>').encode()
    parts = _valid_parts()
    parts["xl/sharedStrings.xml"] = bomb
    book = _write_zip(tmp_path / "laughs.xlsx", parts)
    code, err = run_cli(capsys, "read", str(book), "--out", str(tmp_path / "o" / "t.toml"))
    assert_clear_failure(code, err, "laughs.xlsx", ["part xl/sharedStrings.xml", "document type declaration"])
    assert not (tmp_path / "o").exists()


@pytest.mark.foreign_books       # hostile files, written on purpose
def test_an_archive_with_too_many_parts_is_refused(tmp_path):
    parts = _valid_parts()
    parts.update({f"xl/media/pad{k}.bin": b"" for k in range(5000)})
    book = _write_zip(tmp_path / "many.xlsx", parts)
    with pytest.raises(InputError, match="parts in the archive"):
        check(book)


def test_a_huge_csv_field_is_a_clear_error(tmp_path, capsys):
    """The CSV module's own limit (128 KiB per field) becomes a message, not a traceback."""
    (tmp_path / "small.toml").write_text(POINTCLOUD_TASK)
    (tmp_path / "small.csv").write_text(POINTCLOUD_CSV + '"' + "x" * 200_000 + '",1,2,3,1,0,0,P1\n')
    code, err = run_cli(capsys, "build", str(tmp_path / "small.toml"), "--out", str(tmp_path / "out"))
    assert_clear_failure(code, err, "small.csv", ["line 6", "malformed CSV", "field larger than field limit"])
    assert not (tmp_path / "out").exists()
