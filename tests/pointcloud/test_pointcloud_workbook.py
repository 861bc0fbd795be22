"""Four engines, one answer: the point-cloud workbooks recomputed by `formulas`, LibreOffice and
Gnumeric agree with the JSON of the Python core to relative 1e-9."""

import json
import math

import openpyxl
import pytest

from cmmwb.generator.cli import build_task
from cmmwb.generator.workbook.recalc import results_rows
from cmmwb.xlfuncs.pointcloud import FACTORS

from tests.helpers import ENGINES, EXAMPLES, close, recalc
from tests.helpers.tasks import WORKPIECE_ALL_TERMS, write_random_task


def expected_rows(results):
    for d in results["distances"]:
        yield d, {"d_mm": d["d_mm"], "u_um": d["u_um"], "U_um": d["U_um"],
                  **{f"u_{f}_um": d["components_um"][f] for f in FACTORS}}


def assert_workbook_matches_json(book, results, engine):
    values = recalc(book, engine)
    rows = results_rows(values)
    assert len(rows) == len(results["distances"])
    for row, (d, exp) in zip(rows, expected_rows(results)):
        assert (row["from"], row["to"]) == (d["from"], d["to"])
        for key, e in exp.items():
            assert close(row[key], e), f"{engine}: {d['from']}-{d['to']} {key}: {row[key]!r} != {e!r}"
    if "mpe_check" in results:
        mpe = values["MPE"]
        assert close(mpe["K1"], results["mpe_check"]["C_max"])
        assert close(mpe["K2"], results["mpe_check"]["d_at_max_mm"])


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("example", ["stepgauge_I_MPE1", "stepgauge_I_MPE2", "stepgauge_II_MPE1", "stepgauge_II_MPE2"])
def test_paper_workbooks_agree_with_json(tmp_path, example, engine):
    results, _ = build_task(EXAMPLES / f"{example}.toml", tmp_path, plots=False)
    assert_workbook_matches_json(tmp_path / f"{example}.xlsx", results, engine)


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("seed,probes", [(1, 2), (2, 3)])
def test_random_clouds_with_every_factor_agree_with_json(tmp_path, seed, probes, engine):
    task = write_random_task(tmp_path, seed, m=8, probes=probes)
    results, _ = build_task(task, tmp_path / "out", plots=False)
    assert_workbook_matches_json(tmp_path / "out" / f"random_{seed}.xlsx", results, engine)


@pytest.mark.parametrize("engine", ENGINES)
def test_the_part_temperature_is_live_in_every_engine(tmp_path, engine):
    """The factor W with every term (docs/workpiece.md): V_W, the Budget's u_W and the Results agree
    with the JSON, and u_W is d u(eps) exactly (23.1 x 1e-6/K, 3.5 K, corrected 1e-6/K off, 0.4 K across)."""
    task = write_random_task(tmp_path, 3, m=6, probes=2, workpiece=WORKPIECE_ALL_TERMS)
    results, _ = build_task(task, tmp_path / "out", plots=False)
    u_eps = math.sqrt((3.5 * 1.0) ** 2 + 23.1**2 * (0.3**2 + 0.4**2 / 12) + (1.0 * 3.5) ** 2)
    for d in results["distances"]:
        assert d["components_um"]["W"] == pytest.approx(d["d_mm"] * u_eps * 1e-3, rel=1e-13)
    assert_workbook_matches_json(tmp_path / "out" / "random_3.xlsx", results, engine)
    values = recalc(tmp_path / "out" / "random_3.xlsx", engine)
    assert close(values["Inputs"][_named(tmp_path / "out" / "random_3.xlsx", "workpiece_u_eps_ppm")], u_eps)


#: the issue's formula without the extra terms: the CMM corrects with the part's own alpha, no
#: temperature difference, so u(eps) = sqrt((T - 20)^2 u^2(alpha) + alpha^2 u^2(T))
WORKPIECE_ISSUE = """[workpiece]
alpha_ppm_per_K = 23.0
u_alpha_ppm_per_K = 1.0
T_degC = 23.5
u_T_K = 0.3
fixture_mm = [40.0, -25.0, 10.0]
"""


@pytest.mark.parametrize("engine", ENGINES)
def test_each_engines_u_W_is_L_times_the_issues_u_eps(tmp_path, engine):
    """Read from the recalculated Results sheet itself, not through the JSON: every distance's
    u_W_um is d_mm x sqrt((T - 20)^2 u^2(alpha) + alpha^2 u^2(T)) (3.5 K, 1e-6/K, 23e-6/K, 0.3 K:
    7.7466 ppm), to rounding (rel 1e-12), in the engine's own d_mm; W off, the column is 0."""
    u_eps_ppm = math.sqrt(3.5**2 * 1.0**2 + 23.0**2 * 0.3**2)
    task = write_random_task(tmp_path, 4, m=6, probes=2, workpiece=WORKPIECE_ISSUE)
    build_task(task, tmp_path / "on", plots=False)
    rows = results_rows(recalc(tmp_path / "on" / "random_4.xlsx", engine))
    assert len(rows) == 15
    for row in rows:
        assert row["d_mm"] > 50.0
        assert close(row["u_W_um"], row["d_mm"] * u_eps_ppm * 1e-3, rel=1e-12, floor=0.0), row
        assert row["u_W_um"] < row["u_um"]
    plain = write_random_task(tmp_path, 4, m=6, probes=2, name="random_4_off")
    build_task(plain, tmp_path / "off", plots=False)
    for row in results_rows(recalc(tmp_path / "off" / "random_4_off.xlsx", engine)):
        assert row["u_W_um"] == 0.0, row


def _named(book, name: str) -> str:
    """The cell (A1 form, no $) a defined name points at."""
    wb = openpyxl.load_workbook(book)
    return next(iter(wb.defined_names[name].destinations))[1].replace("$", "")


def test_workbook_layout_for_people(tmp_path):
    results, files = build_task(EXAMPLES / "stepgauge_II_MPE1.toml", tmp_path)
    wb = openpyxl.load_workbook(tmp_path / "stepgauge_II_MPE1.xlsx")
    assert wb.sheetnames[0] == "Instructions" and "Results" in wb.sheetnames
    assert [c.value for c in wb["Results"][1]] == ["from", "to", "d_mm", "u_um", "U_um", "u_R_um", "u_PQ_um",
                                                   "u_S_um", "u_ET_um", "u_ER_um", "u_P_um", "u_W_um"]
    # inputs are bound to names equal to the task keys
    for name in ("sigma_R_um", "sigma_ET_um", "lambda_ER_mm", "A_um", "B_mm", "K"):
        assert name in wb.defined_names
    # Results cells are formulas, not pasted numbers
    assert str(wb["Results"]["D2"].value).startswith("=")
    # the charts of Figures 4-7
    assert wb["MPE"]._charts and wb["Budget"]._charts
    assert {f.suffix for f in files} == {".xlsx", ".json", ".png"}


@pytest.mark.parametrize("engine", ENGINES)
def test_point_labels_that_look_like_formulas_stay_text(tmp_path, engine):
    labels = ["=SUM(A1)", "+1", "-2", "@x", "Q5", "Q6"]
    task = write_random_task(tmp_path, 7, m=6, probes=1, labels=labels, mpe=False)
    results, _ = build_task(task, tmp_path / "out", plots=False)
    wb = openpyxl.load_workbook(tmp_path / "out" / "random_7.xlsx")
    assert wb["Points"]["A2"].value == "=SUM(A1)" and wb["Points"]["A2"].data_type == "s"
    assert wb["Results"]["A2"].data_type == "s"
    values = recalc(tmp_path / "out" / "random_7.xlsx", engine)
    assert values["Results"]["A2"] == "=SUM(A1)"
    assert_workbook_matches_json(tmp_path / "out" / "random_7.xlsx", results, engine)
    assert json.loads((tmp_path / "out" / "random_7.json").read_text())["distances"][0]["from"] == "=SUM(A1)"
