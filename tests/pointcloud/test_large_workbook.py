"""Point-cloud workbooks beyond the native-formula limit (generator.pointcloud.large_book): every result
visible in LibreOffice (Gaussian-process blocks as labelled values, the rest native formulas),
and the Excel add-in formulas on 'Live_addin' evaluate -- by calling the add-in's Python
functions with the values of the ranges they name -- to the same numbers."""

import json
import re
from pathlib import Path

import openpyxl
import pytest

from cmmwb.generator.cli import build_task
from cmmwb.generator.errors import InputError
from cmmwb.generator.pointcloud import large_book
from cmmwb.generator.pointcloud.vx_sheets import NATIVE_MAX_POINTS
from cmmwb.generator.workbook.recalc import results_rows

from tests.helpers import ENGINES, close, recalc
from tests.helpers.addin import evaluate_addin_formulas
from tests.helpers.tasks import write_large_task

FACTORS = ("R", "PQ", "S", "ET", "ER", "P")


# -- evaluating the add-in formulas as Excel would (xlwings passes the ranges' values) ---------

def assert_results_match_json(values: dict, results: dict) -> None:
    rows = results_rows(values)
    assert len(rows) == len(results["distances"])
    for row, d in zip(rows, results["distances"]):
        assert (row["from"], row["to"]) == (d["from"], d["to"])
        exp = {"d_mm": d["d_mm"], "u_um": d["u_um"], "U_um": d["U_um"],
               **{f"u_{f}_um": d["components_um"][f] for f in FACTORS}}
        for key, e in exp.items():
            assert close(row[key], e), f"{d['from']}-{d['to']} {key}: {row[key]!r} != {e!r}"
    if "mpe_check" in results:
        assert close(values["MPE"]["K1"], results["mpe_check"]["C_max"])
        assert close(values["MPE"]["K2"], results["mpe_check"]["d_at_max_mm"])


def assert_addin_formulas_reproduce_the_values(book: Path, values: dict, results: dict) -> None:
    live = evaluate_addin_formulas(book, values)
    gp = values[large_book.GP]
    n = len(results["distances"])
    # the GP pair blocks: same cells on GP_blocks (values written at build time) and Live_addin
    for r in range(2, n + 2):
        for c in range(3, 3 + 27):
            key = f"{openpyxl.utils.get_column_letter(c)}{r}"
            assert close(live[key], gp[key], rel=1e-12, floor=1e-15), key
    # d, u and the six components: the JSON
    cols = ["d_mm", "u_um", *(f"u_{f}_um" for f in FACTORS)]
    for q, d in enumerate(results["distances"]):
        exp = [d["d_mm"], d["u_um"], *(d["components_um"][f] for f in FACTORS)]
        for k, e in enumerate(exp):
            key = f"{openpyxl.utils.get_column_letter(30 + k)}{q + 2}"
            assert close(live[key], e), f"{key} {cols[k]}"


@pytest.fixture(scope="module")
def book2000(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("large2000")
    task = write_large_task(tmp, 2000, "plate_m2000")
    results, _ = build_task(task, tmp / "out", plots=False)
    return tmp / "out" / "plate_m2000.xlsx", results


@pytest.mark.parametrize("engine", ENGINES[1:])      # `formulas` would take minutes
def test_m2000_workbook_shows_every_result_in_libreoffice_and_gnumeric(book2000, engine):
    book, results = book2000
    assert len(results["distances"]) == 2000
    values = recalc(book, engine)
    assert_results_match_json(values, results)
    # the add-in cells are #NAME? without the add-in; no other cell shows an error
    live = values[large_book.LIVE]
    addin_cells = [v for k, v in live.items() if re.match(r"^([C-Z]|A[A-K])([2-9]|\d\d+)$", k)]
    assert len(addin_cells) == 2000 * 35 and set(addin_cells) == {"#NAME?"}
    for sheet, cells in values.items():
        if sheet != large_book.LIVE:
            assert not any(isinstance(v, str) and v.startswith("#") for v in cells.values()), sheet
    assert values[large_book.GP]["AI" + str(_snapshot_row(values))] is True
    assert_addin_formulas_reproduce_the_values(book, values, results)


def _snapshot_row(values) -> int:
    gp = values[large_book.GP]
    return next(int(k[2:]) for k, v in gp.items() if k.startswith("AE") and v == "gp_snapshot_ok")


@pytest.fixture(scope="module")
def book130(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("large130")
    task = write_large_task(tmp, NATIVE_MAX_POINTS + 1, "plate_small", star=False, mpe=False,
                            labels=["=SUM(A1)", "+1"] + [f"Q{i}" for i in range(NATIVE_MAX_POINTS - 1)],
                            distances=(("=SUM(A1)", "+1"), ("Q5", "Q77"), ("Q9", "+1")))
    results, _ = build_task(task, tmp / "out", plots=False)
    return tmp / "out" / "plate_small.xlsx", results


@pytest.mark.parametrize("engine", ENGINES)
def test_smallest_large_workbook_in_every_engine(book130, engine):
    book, results = book130
    values = recalc(book, engine)
    assert_results_match_json(values, results)
    assert values[large_book.GP]["AI" + str(_snapshot_row(values))] is True
    assert_addin_formulas_reproduce_the_values(book, values, results)


def test_large_workbook_layout(book130):
    book, results = book130
    wb = openpyxl.load_workbook(book)
    visible = [ws.title for ws in wb.worksheets if ws.sheet_state == "visible"]
    assert visible == ["Instructions", "Inputs", "Points", large_book.GP, "Budget", large_book.LIVE,
                       "Results", "xlwings.conf", "Summary"]
    assert not any(name.startswith("V_") for name in wb.sheetnames)      # no 3m x 3m matrices
    assert [c.value for c in wb["xlwings.conf"][1]] == ["UDF Modules", "cmmwb.xlfuncs.udf"]
    assert str(wb["Results"]["D2"].value).startswith("=Budget!")
    # GP blocks: grey values with a note naming the core function and version
    gp = wb[large_book.GP]
    assert isinstance(gp["C2"].value, float) and gp["C2"].fill.fgColor.rgb.endswith("EDEDED")
    assert "xlfuncs.blocked.pair_blocks" in gp["C1"].comment.text and "cmmwb 0.1.0" in gp["C1"].comment.text
    # Budget GP components are native formulas of n and the GP block cells
    pts = wb["Points"]
    assert pts["B2"].fill.fgColor.rgb.endswith("FFF2CC") and pts["B2"].protection.locked is False
    assert pts["L2"].protection.locked is not False and pts["L2"].value == "=$B$2-$I$2"
    assert "GP_blocks!$C$2" in wb["Budget"]["J2"].value and wb["Budget"]["J2"].value.startswith("=SQRT(")
    # the add-in formulas, and labels that look like formulas stay text everywhere
    live = wb[large_book.LIVE]
    assert live["C2"].value.text.startswith('=cmm_pair_blocks("ET",Points!$A$2:$H$122,Budget!$A$2:$A$4,')
    assert live["AD2"].value.text.startswith("=cmm_distances(")
    for sheet, ref in (("Points", "A2"), ("Budget", "A2"), (large_book.GP, "A2"), (large_book.LIVE, "A2"),
                       ("Results", "A2")):
        assert wb[sheet][ref].value == "=SUM(A1)" and wb[sheet][ref].data_type == "s", sheet
    assert json.loads(book.with_suffix(".json").read_text())["distances"][0]["from"] == "=SUM(A1)"


@pytest.mark.parametrize("engine", ENGINES)
def test_editing_an_input_of_the_gp_values_is_flagged(book130, tmp_path, engine):
    book, results = book130
    wb = openpyxl.load_workbook(book)
    ws = wb["Inputs"]
    row = next(r for r in range(2, 20) if ws.cell(row=r, column=1).value == "lambda_ET_mm")
    ws.cell(row=row, column=2).value = 300.0
    srow = next(r for r in range(2, 20) if ws.cell(row=r, column=1).value == "sigma_S_ppm")
    ws.cell(row=srow, column=2).value = 2 * ws.cell(row=srow, column=2).value
    wb.save(tmp_path / "edited.xlsx")
    values = recalc(tmp_path / "edited.xlsx", engine)
    assert values[large_book.GP]["AI" + str(_snapshot_row(values))] is False
    rows = results_rows(values)
    # the native scale/squareness column follows the edit at once
    assert not close(rows[1]["u_S_um"], results["distances"][1]["components_um"]["S"])


def test_too_many_distances_for_a_workbook_is_one_clear_error(tmp_path, monkeypatch):
    monkeypatch.setattr(large_book, "MAX_BOOK_DISTANCES", 1000)
    task = write_large_task(tmp_path, NATIVE_MAX_POINTS + 5, "all_pairs", star=False)
    with pytest.raises(InputError, match=r"7750 distances: a workbook holds at most 1000 .*\[\[distances\]\]"):
        build_task(task, tmp_path / "out", plots=False)
    assert not (tmp_path / "out").exists()
