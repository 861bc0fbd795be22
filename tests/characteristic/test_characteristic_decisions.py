"""Conformity decisions of the ``characteristic`` kind: the tolerances of the characteristics
themselves (no ``[[decision.tolerances]]``) decided by the shared machinery of
``generator.decision`` and ``xlfuncs.conformity``; ISO 14253-1 when the task has no ``[decision]``.

The demo plate shows the three outcomes of ISO 14253-1 (conforms, does not conform, cannot be
decided), a position at MMC decided on its margin, an angle not decided; its Decision and Summary
cells, recomputed by `formulas` and by LibreOffice, equal the core's (relative 1e-9, text exactly).
"""

from __future__ import annotations

import openpyxl
import pytest

from cmmwb.generator import decision
from cmmwb.generator.errors import InputError
from cmmwb.generator.workbook import report_page
from cmmwb.xlfuncs import conformity as cf

from tests.helpers import ENGINES, EXAMPLES, recalc
from tests.helpers.decision import assert_engine_agrees, at, build, cached

PLATE = EXAMPLES / "characteristic_plate.toml"


@pytest.fixture(scope="module")
def plate(tmp_path_factory):
    return build(tmp_path_factory.mktemp("plate"), PLATE)


def by_name(results):
    return {d["characteristic"]: d for d in results["decisions"]}


def test_every_toleranced_characteristic_is_decided_under_iso14253_by_default(plate):
    results, _ = plate
    assert results["decision_rule"]["rule"] == "iso14253"
    d = by_name(results)
    toleranced = [c["name"] for c in results["characteristics"]
                  if any(c[k] is not None for k in ("lsl", "usl", "tolerance_mm"))]
    decided = [n.removesuffix(" margin") for n in d] + [x["characteristic"] for x in results["not_decided"]]
    assert sorted(decided) == sorted(toleranced) and len(d) == 17
    assert {x["outcome"] for x in d.values()} == {cf.CONFORMS, cf.DOES_NOT_CONFORM, cf.UNDECIDED}


def test_the_demo_plate_shows_each_outcome(plate):
    """dia_H1 10.0209 mm in [10, 10.05]; flat_A_LS 12.8 µm > 10 µm + U; cyl_H1_LS 9.17 µm within
    U = 0.64 µm of its 9 µm tolerance, cyl_H1_MZ (7.84 µm) of the same cylinder inside it."""
    d = by_name(plate[0])
    assert d["dia_H1"]["outcome"] == cf.CONFORMS and d["dia_H1"]["zone"] == "conformance zone"
    assert d["flat_A_LS"]["outcome"] == cf.DOES_NOT_CONFORM
    assert d["cyl_H1_LS"]["outcome"] == cf.UNDECIDED and d["cyl_H1_LS"]["zone"] == "uncertainty range"
    assert d["cyl_H1_MZ"]["outcome"] == cf.CONFORMS


def test_a_form_zone_is_one_sided_and_a_size_two_sided(plate):
    results, _ = plate
    d = by_name(results)
    c = {c["name"]: c for c in results["characteristics"]}
    assert (d["flat_A_MZ"]["lsl_mm"], d["flat_A_MZ"]["usl_mm"]) == (None, c["flat_A_MZ"]["tolerance_mm"])
    assert (d["dia_H1"]["lsl_mm"], d["dia_H1"]["usl_mm"]) == (10.0, 10.05)
    assert d["perp_D_A"]["usl_mm"] == 0.02 and d["pos_H2"]["usl_mm"] == 0.05      # RFS: value <= tolerance


def test_a_position_at_mmc_is_decided_on_its_margin_with_the_margins_u(plate):
    """margin = tolerance + bonus - value >= 0; its u includes the size (bonus) correlated with the
    position through V_X, so it is not the position's u."""
    results, _ = plate
    d = by_name(results)
    c = {c["name"]: c for c in results["characteristics"]}["pos_H1_MMC"]
    m = d["pos_H1_MMC margin"]
    assert "pos_H1_MMC" not in d and m["quantity"] == "margin_mm"
    assert (m["lsl_mm"], m["usl_mm"]) == (0.0, None)
    assert m["value_mm"] == c["margin_mm"] and m["u_um"] == c["u_margin_um"] != c["u"]
    want = cf.decide(c["margin_mm"], c["u_margin_um"], cf.Tolerance(0.0, None), cf.DecisionRule(), 2.0)
    assert m["p_c"] == want.p_c and m["outcome"] == want.outcome == cf.CONFORMS


def test_json_decisions_are_the_core_decisions(plate):
    results, _ = plate
    d = by_name(results)
    for c in results["characteristics"]:
        if c["name"] not in d:
            continue
        tol = cf.Tolerance(c["lsl"], c["usl"]) if c["tolerance_mm"] is None else cf.Tolerance(None, c["tolerance_mm"])
        want = cf.decide(c["value"], c["u"], tol, cf.DecisionRule("iso14253"), 2.0)
        got = d[c["name"]]
        assert (got["value_mm"], got["U_um"], got["p_c"], got["outcome"]) == \
            (want.value_mm, want.U_um, want.p_c, want.outcome), c["name"]


def test_an_angle_is_named_as_not_decided(plate):
    results, book = plate
    assert [x["characteristic"] for x in results["not_decided"]] == ["angle_B_C"]
    assert "not decided yet" in results["not_decided"][0]["reason"]
    ws = openpyxl.load_workbook(book)["Summary"]
    row = next(r for r in range(1, ws.max_row + 1) if ws.cell(r, 1).value == "angle_B_C")
    assert ws.cell(row, report_page.C["decision"]).value == "not decided (see below)"
    below = [ws.cell(r, 1).value for r in range(row + 2, row + 6)]
    assert any(isinstance(t, str) and t.startswith("tolerance not decided: an angle tolerance") for t in below)


def test_openpyxl_data_only_shows_the_decisions(plate):
    results, book = plate
    ws = openpyxl.load_workbook(book, data_only=True)["Decision"]
    for i, d in enumerate(results["decisions"]):
        r = decision.FIRST_ROW + i
        assert ws[at(r, "characteristic")].value == d["characteristic"]
        assert ws[at(r, "outcome")].value == d["outcome"]


@pytest.mark.parametrize("engine", ENGINES)
def test_engines_agree_on_decision_and_summary(plate, engine):
    assert assert_engine_agrees(plate[1], engine) > 300


@pytest.mark.parametrize("engine", ENGINES)
def test_a_tolerance_typed_on_characteristics_changes_the_decision(plate, tmp_path, engine):
    """cyl_H1_LS: its tolerance on 'Characteristics' from 0.009 to 0.010 mm: the Decision sheet's
    upper limit follows and the value (9.17 µm, U 0.64 µm) now conforms."""
    results, book = plate
    wb = openpyxl.load_workbook(book)
    ws = wb["Characteristics"]
    row = next(r for r in range(2, ws.max_row + 1) if ws.cell(r, 1).value == "cyl_H1_LS")
    ws.cell(row, 11).value = 0.010
    edited = tmp_path / "edited.xlsx"
    wb.save(edited)
    v = recalc(edited, engine)["Decision"]
    r = decision.FIRST_ROW + [d["characteristic"] for d in results["decisions"]].index("cyl_H1_LS")
    assert v[at(r, "usl_mm")] == 0.010
    assert v[at(r, "outcome")] == cf.CONFORMS


def test_a_decision_table_sets_the_rule_and_k(tmp_path):
    """Simple acceptance with k = 3: cyl_H1_LS (9.17 µm against 9 µm), undecided by ISO 14253-1,
    is rejected; U = 3u, and every statement names the coverage probability of k = 3, 99.73 %
    (2Φ(3) - 1, GUM G.1.3), on the Summary too (it said 95 % for every k)."""
    def edit(doc):
        doc["decision"] = {"rule": "simple", "k": 3.0}
    results, book = build(tmp_path, PLATE, edit)
    d = by_name(results)
    assert results["decision_rule"] == {"rule": "simple", "text": cf.DecisionRule("simple").text, "k": 3.0}
    assert d["cyl_H1_LS"]["outcome"] == cf.REJECTED and d["cyl_H1_LS"]["k"] == 3.0
    assert d["cyl_H1_LS"]["conformity"] == cf.NEITHER_PROVEN        # 9.17 µm, U = 0.96 µm, T = 9 µm
    assert d["cyl_H1_LS"]["U_um"] == 3.0 * d["cyl_H1_LS"]["u_um"]
    assert {x["outcome"] for x in d.values()} == {cf.ACCEPTED, cf.REJECTED}
    assert all(x["statement"].endswith("(k = 3, coverage probability ≈ 99.73 %)") for x in d.values())
    assert all(x["coverage_probability"] == pytest.approx(0.9973002039367398, rel=1e-12) for x in d.values())
    summary = [v for v in cached(book)["Summary"].values() if isinstance(v, str) and " = " in v]
    assert summary and all("(k = 3, coverage probability ≈ 99.73 %)" in v for v in summary)
    for engine in ("formulas",):
        assert assert_engine_agrees(book, engine) > 300


@pytest.mark.parametrize("table, where, message", [
    ({"tolerances": [{"characteristic": "dia_H1", "tol_mm": 0.1}]}, "[decision] tolerances",
     "lsl/usl/nominal/tolerance_mm of its"),
    ({"k_from_dof": True}, "[decision] k_from_dof", "type A"),
    ({"k": 0.0}, "[decision] k", "coverage factor"),
])
def test_bad_decision_input_names_the_key(tmp_path, table, where, message):
    def edit(doc):
        doc["decision"] = table
    with pytest.raises(InputError, match=message) as err:
        build(tmp_path, PLATE, edit)
    assert where in str(err.value) and "characteristic_plate.toml" in str(err.value)


def test_a_k_typed_in_the_decision_sheet_goes_back_to_the_task_file(plate, tmp_path):
    """The plate has no [decision]: cmmwb read of its book with k = 3 typed on 'Decision' writes
    [decision] k = 3; an untouched book writes no [decision]."""
    import tomllib

    from cmmwb.generator.reader import read_to_files

    _, book = plate
    same = read_to_files(book, tmp_path / "same" / "task.toml")
    assert "decision" not in tomllib.loads(same[0].read_text(encoding="utf-8"))
    wb = openpyxl.load_workbook(book)
    ws, coord = next(iter(wb.defined_names["decision_k"].destinations))
    wb[ws][coord.replace("$", "")].value = 3.0
    edited = tmp_path / "edited.xlsx"
    wb.save(edited)
    files = read_to_files(edited, tmp_path / "back" / "task.toml")
    assert tomllib.loads(files[0].read_text(encoding="utf-8"))["decision"] == {"k": 3.0}


def test_crossed_size_limits_name_the_characteristic(tmp_path):
    def edit(doc):
        c = next(c for c in doc["characteristics"] if c["name"] == "dia_H2")
        c["lsl"], c["usl"] = 10.05, 10.0
    with pytest.raises(InputError, match="must be below") as err:
        build(tmp_path, PLATE, edit)
    assert "[[characteristics]] #2 lsl (line" in str(err.value) and "dia_H2: the lower limit" in str(err.value)
