"""The engines themselves (docs/engines.md): Gnumeric computes every cell it returns (no cached
value survives), finds no circular reference where there is none and every one where there is,
reads back what LibreOffice reads; `cmmwb recalc` takes the fastest engine installed and says so."""

from __future__ import annotations

import zipfile
from pathlib import Path

import openpyxl
import pytest
from openpyxl.worksheet.formula import ArrayFormula

from cmmwb.generator.cli import main
from cmmwb.generator.workbook import recalc
from cmmwb.generator.workbook.uncached import strip_cached_values

from tests.helpers import ENGINES, close

GNUMERIC = pytest.mark.gnumeric


def _with_stale_values(tmp_path: Path) -> Path:
    """A1 = 2, B1 = A1*3, C1:D2 = an array formula, every formula cell with a wrong cached value."""
    wb = openpyxl.Workbook()
    ws = wb.active
    ws.title = "Results"
    ws["A1"] = 2
    ws["B1"] = "=A1*3"
    ws["C1"] = ArrayFormula("C1:D2", "=MMULT(A1*{1;2},{1,3})")
    plain = tmp_path / "plain.xlsx"
    wb.save(plain)
    stale = tmp_path / "stale.xlsx"
    with zipfile.ZipFile(plain) as z, zipfile.ZipFile(stale, "w") as out:
        for info in z.infolist():
            data = z.read(info)
            if info.filename == "xl/worksheets/sheet1.xml":
                data = data.replace(b"<f>A1*3</f><v></v>", b"<f>A1*3</f><v>999</v>")
                data = data.replace(b"{1,3})</f><v></v></c>", b'{1,3})</f><v>-1</v></c><c r="D1"><v>-1</v></c>')
                data = data.replace(b"</row></sheetData>", b'</row><row r="2"><c r="C2"><v>-1</v></c>'
                                    b'<c r="D2"><v>-1</v></c></row></sheetData>')
            out.writestr(info, data)
    return stale


def test_stripping_removes_every_cached_formula_value_and_keeps_constants(tmp_path):
    stale = _with_stale_values(tmp_path)
    assert recalc.read_cached(stale)["Results"] == {"A1": 2, "B1": 999, "C1": -1, "D1": -1, "C2": -1, "D2": -1}
    assert strip_cached_values(stale, tmp_path / "clean.xlsx") == 5
    assert recalc.read_cached(tmp_path / "clean.xlsx")["Results"] == {"A1": 2}
    assert openpyxl.load_workbook(tmp_path / "clean.xlsx")["Results"]["B1"].value == "=A1*3"


@pytest.mark.parametrize("engine", ENGINES)
def test_no_stale_cached_value_survives_an_engine(tmp_path, engine):
    values = recalc.recalculate(_with_stale_values(tmp_path), engine)["Results"]
    assert [values[c] for c in ("B1", "C1", "D1", "C2", "D2")] == [6, 2, 6, 4, 12]


def _circular(tmp_path: Path, cycle: bool) -> Path:
    wb = openpyxl.Workbook()
    ws = wb.active
    ws.title = "Results"
    ws.append(["name", "u_um"])
    ws.append(["d", "=C2+1"])
    ws["C2"] = "=B2*2" if cycle else "=D2*2"
    ws["D2"] = 1.5
    wb.save(tmp_path / "book.xlsx")
    return tmp_path / "book.xlsx"


@GNUMERIC
def test_gnumeric_iterates_a_cycle_and_the_second_start_finds_it(tmp_path):
    book = _circular(tmp_path, cycle=True)
    values, cycle = recalc.recalculate_checking_cycles(book)
    assert isinstance(values["Results"]["B2"], (int, float))      # Gnumeric gives numbers, no error
    assert cycle == ["Results!B2", "Results!C2"]
    (tmp_path / "no").mkdir()
    values, cycle = recalc.recalculate_checking_cycles(_circular(tmp_path / "no", cycle=False))
    assert cycle == [] and values["Results"]["B2"] == 4


@GNUMERIC
def test_recalc_with_gnumeric_refuses_a_circular_reference(tmp_path, capsys):
    code = main(["recalc", str(_circular(tmp_path, cycle=True)), "--engine", "gnumeric"])
    err = capsys.readouterr().err
    assert code == 2 and "book.xlsx" in err and "circular reference" in err and "Results!B2" in err


@GNUMERIC
@pytest.mark.libreoffice
def test_gnumeric_and_libreoffice_read_back_alike(tmp_path):
    book = _circular(tmp_path, cycle=False)
    g, lo = recalc.recalculate(book, "gnumeric"), recalc.recalculate(book, "libreoffice")
    assert g == lo == {"Results": {"A1": "name", "B1": "u_um", "A2": "d", "B2": 4, "C2": 3, "D2": 1.5}}


def test_the_default_engine_is_the_fastest_installed(monkeypatch):
    assert recalc.FASTEST_FIRST == ("gnumeric", "libreoffice", "formulas")
    monkeypatch.setattr(recalc, "ssconvert", lambda: None)
    assert recalc.default_engine() == ("libreoffice" if recalc.soffice() else "formulas")
    monkeypatch.setattr(recalc, "soffice", lambda: None)
    assert recalc.default_engine() == "formulas"


def test_recalc_says_which_engine_and_refuses_one_not_installed(tmp_path, capsys, monkeypatch):
    book = _circular(tmp_path, cycle=False)
    assert main(["recalc", str(book)]) == 0
    out, err = capsys.readouterr()
    assert err == f"cmmwb recalc: engine {recalc.default_engine()} (the fastest installed; --engine to choose another)\n"
    assert out.splitlines()[1].split("\t")[:2] == ["d", "4"]
    with pytest.raises(SystemExit):
        main(["recalc", "--help"])
    assert "Default: the fastest installed" in " ".join(capsys.readouterr().out.split())
    monkeypatch.setattr(recalc, "ssconvert", lambda: None)
    assert main(["recalc", str(book), "--engine", "gnumeric"]) == 2
    err = capsys.readouterr().err
    assert "book.xlsx" in err and "gnumeric engine is not installed" in err


@pytest.mark.parametrize("engine", ENGINES[1:])
def test_every_number_of_a_built_book_agrees_with_formulas(tmp_path, engine):
    """Not only Results: every number of a point-cloud workbook with every factor and two probes
    (V_X blocks, budget, MPE check) as LibreOffice or Gnumeric computes it equals `formulas`."""
    from cmmwb.generator.cli import build_task

    from tests.helpers import recalc as counted
    from tests.helpers.tasks import write_random_task

    build_task(write_random_task(tmp_path, 3, m=8, probes=2), tmp_path / "out", plots=False)
    book = tmp_path / "out" / "random_3.xlsx"
    other, f = counted(book, engine), counted(book, "formulas")
    n = 0
    for sheet, cells in f.items():
        for ref in cells:
            a = dict.get(cells, ref)
            if isinstance(a, (int, float)) and not isinstance(a, bool):
                assert close(other[sheet][ref], f[sheet][ref], floor=1e-15), f"{engine} {sheet}!{ref}"
                n += 1
    assert n > 5_000
