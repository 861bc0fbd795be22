"""The `feature` workbook: every element type built from a task, recalculated by `formulas` and by
LibreOffice, agrees with the JSON of the Python core to relative 1e-9 -- parameters, u, the six
components, the covariance and the planning rows (Forbes 2022 Tables 1-8 as live sheets).
Also: bad feature tasks give one clear message naming the file and key, and nothing is written.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import openpyxl
import pytest
from openpyxl.utils import get_column_letter

from cmmwb.generator.cli import build_task, main
from cmmwb.generator.errors import InputError
from cmmwb.generator.feature import book as feature_book
from cmmwb.generator.feature import job as feature_job
from cmmwb.generator.feature import va_sheets
from cmmwb.generator.taskfile import read_toml
from cmmwb.generator.workbook.recalc import results_rows
from cmmwb.xlfuncs.pointcloud import FACTORS

from tests.helpers import ENGINES, EXAMPLES, recalc
from tests.helpers.tasks import SHIPPED, SMALL_TASKS, feature_task_path

REL = 1e-9

CASES = list(SMALL_TASKS) + SHIPPED


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("features")
    out = {}
    for case in CASES:
        results, files = build_task(feature_task_path(case, tmp), tmp / "out", plots=False)
        book = next(f for f in files if f.suffix == ".xlsx")
        on_disk = json.loads(book.with_suffix(".json").read_text())
        out[case] = (on_disk, book)
    return out


_cache: dict = {}


def values_of(book: Path, engine: str):
    key = (str(book), engine)
    if key not in _cache:
        _cache[key] = recalc(book, engine)
    return _cache[key]


def agree(got, ref, floor: float = 1e-15) -> bool:
    return isinstance(got, (int, float)) and math.isfinite(got) and \
        abs(got - ref) <= REL * max(abs(got), abs(ref)) + floor


def block_values(values, blk):
    cells = values[blk.sheet]
    from openpyxl.utils import get_column_letter as L
    return np.array([[cells.get(f"{L(c)}{r}") for c in blk.columns()] for r in blk.rows()],
                    dtype=float)


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("case", CASES)
def test_workbook_agrees_with_the_json(built, case, engine):
    res, book = built[case]
    values = values_of(book, engine)
    errors = [(s, c, v) for s, cells in values.items() for c, v in cells.items()
              if isinstance(v, str) and v.startswith("#")]
    assert not errors, f"{engine}: error cells, e.g. {errors[:3]}"
    fe = res["feature"]
    names = fe["parameter_names"]
    # Results: parameter, value, u
    rows = results_rows(values)
    assert [r["parameter"] for r in rows] == names
    for r in rows:
        n = r["parameter"]
        assert agree(r["value"], fe["parameters"][n]), f"{engine} {n} value {r['value']}"
        assert agree(r["u"], fe["u"][n]), f"{engine} {n} u {r['u']} vs {fe['u'][n]}"
    # Budget: the components per parameter, the six factors and W (Forbes 2025 section 5.6)
    cells = values["Budget"]
    for p, n in enumerate(names):
        scale, _ = feature_book.u_display(n)            # Budget shows u in µm, µrad or 1e-6
        for q, fac in enumerate(FACTORS):
            got = cells[f"{get_column_letter(va_sheets.U_COLUMN + 1 + q)}{2 + p}"] / scale
            # compared as variances u_f^2: a component that is exactly zero (e.g. a rigid probe
            # offset on a radius) is sqrt(rounding) in both engines, ~1e-8 u, not 0
            ref = fe["components"][fac][n]
            # (floor 1e-15 u^2, and (1e-15)^2 for parameters whose u is itself a structural zero)
            assert agree(got ** 2, ref ** 2, floor=1e-15 * fe["u"][n] ** 2 + 1e-30), \
                f"{engine} {n} u_{fac}: {got} vs {ref}"
    # the covariance of the reported parameters
    f_n, g = len(fe["local"]["parameter_names"]), len(names)
    L, Gl = va_sheets.v_a_layout(f_n, g)["total"]
    C = block_values(values, Gl)
    ref = np.array(fe["covariance"])
    assert np.all(np.abs(C - ref) <= REL * np.abs(ref) + 1e-12 * np.abs(ref).max())
    Cl = block_values(values, L)
    refl = np.array(fe["local"]["covariance"])
    assert np.all(np.abs(Cl - refl) <= REL * np.abs(refl) + 1e-12 * np.abs(refl).max())
    # at the fitted values the Gauss-Newton step is zero (the fit is the least-squares solution)
    step = block_values(values, feature_book.gn_step_block(f_n))
    assert np.all(np.abs(step) < 1e-9)
    # the planning rows (analytic approximations, Forbes 2022 Tables 1-8)
    if "planning" in res:
        check_planning(values, res["planning"], engine)


def check_planning(values, pl, engine):
    cells = values["Planning"]
    head = pl["sweep"] or "row"
    top = next(int(k[1:]) for k, v in cells.items() if k.startswith("A") and v == head
               and f"B{k[1:]}" in cells and str(cells[f"B{k[1:]}"]).startswith("s("))
    names = pl["parameter_names"]
    n = len(names)
    from openpyxl.utils import get_column_letter as L
    for q, row in enumerate(pl["rows"]):
        r = top + 1 + q
        for p, nm in enumerate(names):
            s = cells[f"{L(2 + p)}{r}"]
            u = cells[f"{L(2 + n + p)}{r}"]
            assert agree(s, row["s"][nm]), f"{engine} planning row {q} s({nm}) {s} vs {row['s'][nm]}"
            assert agree(u, row["u"][nm]), f"{engine} planning row {q} u({nm})"


@pytest.mark.parametrize("example", ["feature_table3_sphere_band.toml",
                                     "feature_table4_sphere_segment.toml",
                                     "feature_table2_sphere_cap.toml",
                                     "feature_table5_cylinder_patch.toml",
                                     "feature_table7_cone_arc.toml"])
@pytest.mark.parametrize("engine", ENGINES)
def test_table_planning_sheets_recalculate_to_the_json(tmp_path, example, monkeypatch, engine):
    """The remaining table patterns, in every engine.  Built without the V_X sheets (the
    Planning sheet does not use them) to keep the test fast."""
    monkeypatch.setattr(feature_book, "FEATURE_NATIVE_MAX_POINTS", 0)
    res, files = build_task(EXAMPLES / example, tmp_path, plots=False)
    values = recalc(next(f for f in files if f.suffix == ".xlsx"), engine)
    check_planning(values, res["planning"], engine)


@pytest.mark.parametrize("engine", ENGINES)
def test_above_the_native_limit_the_heavy_blocks_are_labelled_values(tmp_path, engine, monkeypatch):
    """With more points than FEATURE_NATIVE_MAX_POINTS the V_X sheets are left out and V_A of
    the factors other than R are values computed by the core, marked and noted as such;
    the workbook still reproduces the JSON."""
    monkeypatch.setattr(feature_book, "FEATURE_NATIVE_MAX_POINTS", 10)
    res, files = build_task(EXAMPLES / "feature_plane_face.toml", tmp_path, plots=False)
    book = next(f for f in files if f.suffix == ".xlsx")
    wb = openpyxl.load_workbook(book)
    assert "V_X" not in wb.sheetnames and "Coords" not in wb.sheetnames
    L, G = va_sheets.v_a_layout(3, 6)["ET"]
    c = wb["V_A"].cell(row=L.row, column=G.column + G.n_cols + 2)
    assert isinstance(c.value, float) and "VALUES, not formulas" in c.comment.text
    assert "x 1e-12" in wb["V_A"].cell(row=L.row, column=L.column).comment.text
    L, _ = va_sheets.v_a_layout(3, 6)["R"]
    assert "sigma_R_um" in str(wb["V_A"].cell(row=L.row, column=L.column).value.text)
    values = recalc(book, engine)
    for r in results_rows(values):
        assert agree(r["u"], res["feature"]["u"][r["parameter"]])


@pytest.mark.parametrize("engine", ENGINES)
def test_the_workbook_is_live(tmp_path, engine):
    """Doubling sigma_R_um on 'Inputs' doubles u_R of every parameter."""
    p = feature_task_path("line_space", tmp_path)
    res, files = build_task(p, tmp_path / "out", plots=False)
    book = next(f for f in files if f.suffix == ".xlsx")
    wb = openpyxl.load_workbook(book)
    ws = wb["Inputs"]
    row = next(r for r in range(1, 30) if ws.cell(row=r, column=1).value == "sigma_R_um")
    ws.cell(row=row, column=2).value = 0.6
    edited = tmp_path / "edited.xlsx"
    wb.save(edited)
    cells = recalc(edited, engine)["Budget"]
    for p_, n in enumerate(res["feature"]["parameter_names"]):
        ref = 2 * res["feature"]["components"]["R"][n] * feature_book.u_display(n)[0]
        assert agree(cells[f"F{2 + p_}"], ref)


def test_point_labels_stay_text(tmp_path):
    src = (EXAMPLES / "feature_plane_face.csv").read_text().replace("F1,", "=SUM(A1),", 1)
    (tmp_path / "feature_plane_face.csv").write_text(src)
    task = (EXAMPLES / "feature_plane_face.toml").read_text()
    (tmp_path / "t.toml").write_text(task)
    _, files = build_task(tmp_path / "t.toml", tmp_path / "out", plots=False)
    wb = openpyxl.load_workbook(next(f for f in files if f.suffix == ".xlsx"))
    assert wb["Local"]["A2"].value == "=SUM(A1)" and wb["Local"]["A2"].data_type == "s"


# ---- bad input: one clear message naming the file and key; exit status 2; nothing written -----

BASE = """
[task]
kind = "feature"
name = "bad"
[feature]
type = "cylinder"
[sampling]
pattern = "cylinder_patch"
r0_mm = 10.0
arc_deg = 360.0
half_height_mm = 10.0
n_theta = 6
n_z = 2
[parameters]
sigma_R_um = 0.2
"""


def load_text(tmp_path, text):
    p = tmp_path / "task.toml"
    p.write_text(text)
    task = feature_job.load(p, read_toml(p))
    return feature_job.compute(task)


@pytest.mark.parametrize("edit,where,message", [
    (('type = "cylinder"', 'type = "torus"'), "[feature] type", "unknown feature type 'torus'"),
    (("[sampling]", "[points]\nfile = 'x.csv'\n[sampling]"), "[points]", "exactly one of them"),
    (('pattern = "cylinder_patch"', 'pattern = "sphere_cap"'), "[sampling] pattern",
     "samples a sphere, the feature is a cylinder"),
    (("n_theta = 6", "n_theta = 6.5"), "[sampling] n_theta", "whole number"),
    (("r0_mm = 10.0", 'r0_mm = "ten"'), "[sampling] r0_mm", "must be a number"),
    (("arc_deg = 360.0", "arc_deg = 400.0"), "[sampling]", "arc_deg must be in"),
    (("[parameters]", "[feature.weights]\nX99 = 1.0\n[parameters]"), "[feature] weights.X99",
     "unknown point 'X99'"),
    (("[parameters]", "[planning]\nsweep = 'r0_mm'\nvalues = [1]\n[parameters]"),
     "[planning] sweep", "must name a number key"),
    (("n_z = 2", "n_z = 1"), "[sampling]", "do not determine rot_"),
])
def test_bad_tasks_name_the_key(tmp_path, edit, where, message):
    text = BASE.replace(*edit)
    if "[feature.weights]" in text:  # a sub-table after [feature] keys
        text = text.replace("[feature]\ntype", "[feature]\ntype", 1)
    with pytest.raises(InputError) as e:
        load_text(tmp_path, text)
    assert e.value.where == where and message in str(e.value), str(e.value)
    assert str(tmp_path / "task.toml") in str(e.value)


def test_too_few_points_and_non_convergence_are_input_errors(tmp_path):
    text = BASE.replace("n_theta = 6\nn_z = 2", "n_theta = 2\nn_z = 2")
    with pytest.raises(InputError, match=r"\[sampling\].*cylinder fit needs at least 5 "
                                         r"points with positive weight, got 4"):
        load_text(tmp_path, text)
    rng = np.random.default_rng(5)
    rows = ["id,x,y,z,nx,ny,nz"] + [
        f"Q{i},{x:.4f},{y:.4f},{z:.7f},0,0,1" for i, (x, y, z) in enumerate(zip(
            rng.uniform(-20, 20, 30), rng.uniform(-20, 20, 30), rng.normal(scale=1e-4, size=30)))]
    (tmp_path / "flat").mkdir()
    (tmp_path / "flat" / "flat.csv").write_text("\n".join(rows) + "\n")
    text = """
[task]
kind = "feature"
name = "flat"
[feature]
type = "cylinder"
axis_hint = [1.0, 0.0, 0.0]
max_iter = 3
[points]
file = "flat.csv"
[parameters]
sigma_R_um = 0.2
"""
    with pytest.raises(InputError, match=r"flat/task.toml, \[points\]: cylinder fit did not "
                                         r"converge"):
        load_text(tmp_path / "flat", text)


def test_cli_exit_status_2_and_nothing_written(tmp_path, capsys):
    p = tmp_path / "task.toml"
    p.write_text(BASE.replace("n_z = 2", "n_z = 1"))
    out = tmp_path / "out"
    assert main(["build", str(p), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(p) in err and "[sampling]" in err and "rank-deficient" in err
    assert not out.exists()


def test_new_task_template_builds(tmp_path, capsys):
    t = tmp_path / "new.toml"
    assert main(["new", "feature", "--out", str(t)]) == 0
    res, files = build_task(t, tmp_path / "out", plots=True)
    assert res["feature"]["type"] == "cylinder" and len(res["planning"]["rows"]) == 6
    assert any(f.name.endswith("_factors.png") for f in files)
