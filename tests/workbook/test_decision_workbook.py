"""Conformity decisions in the built outputs: the ``[decision]`` table, the ``decisions`` of the
JSON and the ``Decision`` sheet (live formulas), in all four engines.

The numbers of JCGM 106:2012, 7.3 Table 1 (z for a one-sided tolerance interval: p_c = 0.80,
0.90, 0.95, 0.99, 0.999 at z = 0.84, 1.28, 1.64, 2.33, 3.09) are reproduced in the workbook: a
task whose upper limits lie z standard uncertainties above the measured values.  Every Decision
and Summary cell is recomputed by `formulas` and by LibreOffice and compared with the value the
core computed (cached in the file) at relative 1e-9, text exactly.
"""

from __future__ import annotations

import math
import re

import openpyxl
import pytest

from cmmwb.generator.errors import InputError
from cmmwb.xlfuncs import conformity as cf
from cmmwb.xlfuncs import dof

from tests.helpers import ENGINES, EXAMPLES, close, recalc
from tests.helpers.decision import assert_engine_agrees, at, build

KNUCKLE = EXAMPLES / "knuckle.toml"


# -- the knuckle (budget, ISO 14253-1 rule) ------------------------------------------------------

@pytest.fixture(scope="module")
def knuckle(tmp_path_factory):
    return build(tmp_path_factory.mktemp("knuckle"), KNUCKLE)


def test_each_outcome_of_the_iso14253_rule_in_the_json(knuckle):
    results, _ = knuckle
    got = {d["characteristic"]: (d["outcome"], d["zone"]) for d in results["decisions"]}
    assert got == {"S4_position": ("conforms", "conformance zone"),
                   "S3_position": ("cannot be decided", "uncertainty range"),
                   "S1_S2_distance": ("conforms", "conformance zone"),
                   "S3_from_S1S2": ("does not conform", "non-conformance zone")}
    assert results["decision_rule"]["rule"] == "iso14253"


def test_json_decisions_are_the_core_decisions(knuckle):
    results, _ = knuckle
    chars = {c["name"]: c for c in results["characteristics"]}
    for d in results["decisions"]:
        c = chars[d["characteristic"]]
        tol = cf.Tolerance(d["lsl_mm"], d["usl_mm"])
        assert d["u_task_um"] == c["u_um"]
        want = cf.decide(d["value_mm"], d["u_um"], tol, cf.DecisionRule("iso14253"), d["k"])
        assert d["p_c"] == pytest.approx(want.p_c, rel=1e-12)
        assert d["outcome"] == want.outcome
        if d["u_A_um"] is None:                       # no repeatability: the task's own u and U
            assert (d["u_um"], d["U_um"]) == pytest.approx((c["u_um"], c["U_um"]), rel=1e-12)


def test_a_type_a_repeatability_gives_nu_eff_and_a_t_coverage_factor(knuckle):
    """S1_S2_distance: mean of n = 5 repeats with s = 2.5 µm: u_A = s/√5, ν_A = 4 (GUM 4.2.3, G.3.3);
    u = √(u_task² + u_A²), ν_eff by Welch–Satterthwaite (G.4.1), k = t_95.45(⌊ν_eff⌋) (G.6.4)."""
    results, _ = knuckle
    d = next(x for x in results["decisions"] if x["characteristic"] == "S1_S2_distance")
    u_task = next(c["u_um"] for c in results["characteristics"] if c["name"] == "S1_S2_distance")
    u_a = 2.5 / math.sqrt(5)
    assert d["u_A_um"] == pytest.approx(u_a, rel=1e-15) and d["nu_A"] == 4
    assert d["u_um"] == pytest.approx(math.hypot(u_task, u_a), rel=1e-15)
    assert d["nu_eff"] == pytest.approx(4 * (d["u_um"] / u_a) ** 4, rel=1e-12)
    assert d["distribution"] == "t" and math.floor(d["nu_eff"]) == 64
    assert d["k"] == pytest.approx(dof.coverage_factor(64), rel=1e-12) and 2.03 < d["k"] < 2.05
    assert d["U_um"] == pytest.approx(d["k"] * d["u_um"], rel=1e-15)
    assert "(k = 2.04, coverage probability ≈ 95.45 %)" in d["statement"]
    assert d["coverage_probability"] == pytest.approx(dof.P_K2, abs=1e-12)    # t_95.45(64) covers 95.45 %
    others = [x for x in results["decisions"] if x["characteristic"] != "S1_S2_distance"]
    assert all(x["distribution"] == "normal" and x["k"] == 2 and x["nu_eff"] is None for x in others)


@pytest.fixture(scope="module")
def small_nu(tmp_path_factory):
    """S1_S2_distance measured 3 times with s = 10 µm and k = 2 kept (no k_from_dof): ν_eff is
    small (2.x), so k = 2 covers less than 95 %."""
    def edit(doc):
        doc["decision"]["k_from_dof"] = False
        doc["decision"]["tolerances"][2].update(s_um=10.0, n_repeats=3)
    return build(tmp_path_factory.mktemp("small_nu"), KNUCKLE, edit)


def test_a_small_nu_eff_states_the_t_coverage_probability_of_k(small_nu):
    """GUM G.3.2, G.6.4: k = 2 with ⌊ν_eff⌋ = 2 covers 2 F_t(2; 2) - 1 = 81.65 %, not 95 %: in the
    JSON, on the Decision sheet (live: 1 - TDIST(k, INT(ν_eff), 2)) and in every statement."""
    results, book = small_nu
    d = next(x for x in results["decisions"] if x["characteristic"] == "S1_S2_distance")
    assert d["k"] == 2 and d["distribution"] == "normal" and 2 <= d["nu_eff"] < 3
    assert d["coverage_probability"] == pytest.approx(dof.coverage_probability(2, 2), rel=1e-12)
    assert round(100 * d["coverage_probability"], 2) == 81.65
    assert d["statement"].endswith("(k = 2, coverage probability ≈ 81.65 %)")
    wb = openpyxl.load_workbook(book, data_only=True)
    row = 8 + [x["characteristic"] for x in results["decisions"]].index("S1_S2_distance")
    assert wb["Decision"][at(row, "coverage_probability")].value == pytest.approx(d["coverage_probability"])
    statements = [c.value for r in wb["Summary"].iter_rows() for c in r if isinstance(c.value, str)]
    assert d["statement"] in statements
    assert sum("coverage probability ≈ 95.45 %" in t for t in statements) >= 7     # the other results
    assert assert_engine_agrees(book, "formulas") > 40


@pytest.mark.libreoffice
def test_libreoffice_agrees_on_the_small_nu_eff_book(small_nu):
    assert assert_engine_agrees(small_nu[1], "libreoffice") > 40


def test_a_k_typed_on_the_decision_sheet_changes_the_summary_statement(tmp_path):
    """Issue 32: k was frozen text in the Summary's formula. cylinder_bore (a feature task, U = k·u
    with decision_k): k = 3 typed on 'Decision' makes every statement on 'Summary' say k = 3 and
    99.73 %, the decided ones and the others."""
    _, book = build(tmp_path, EXAMPLES / "feature_cylinder_bore.toml")
    wb = openpyxl.load_workbook(book)
    sheet, ref = next(iter(wb.defined_names["decision_k"].destinations))
    wb[sheet][ref.replace("$", "")].value = 3
    edited = tmp_path / "k3.xlsx"
    wb.save(edited)
    v = recalc(edited, "formulas")["Summary"]
    statements = [t for t in v.values() if isinstance(t, str) and "coverage probability" in t]
    assert len(statements) >= 4
    assert all(t.endswith("(k = 3, coverage probability ≈ 99.73 %)") for t in statements), statements


def test_symmetric_tolerance_is_around_the_nominal_or_the_task_value(knuckle):
    results, _ = knuckle
    d = {d["characteristic"]: d for d in results["decisions"]}
    assert (d["S1_S2_distance"]["lsl_mm"], d["S1_S2_distance"]["usl_mm"]) == pytest.approx((89.98, 90.02))
    assert (d["S3_from_S1S2"]["lsl_mm"], d["S3_from_S1S2"]["usl_mm"]) == pytest.approx((77.98, 78.02))
    assert d["S4_position"]["lsl_mm"] is None and d["S4_position"]["usl_mm"] == 0.05


def test_openpyxl_data_only_shows_the_decisions(knuckle):
    _, book = knuckle
    wb = openpyxl.load_workbook(book, data_only=True)
    ws = wb["Decision"]
    header = [c.value for c in ws[7]]
    col = header.index("outcome") + 1
    assert [ws.cell(r, col).value for r in range(8, 12)] == [
        "conforms", "cannot be decided", "conforms", "does not conform"]
    summary = [c.value for row in wb["Summary"].iter_rows() for c in row if isinstance(c.value, str)]
    assert "S3_from_S1S2 = 78.0270 mm, U = 4.2 µm (k = 2, coverage probability ≈ 95.45 %)" in summary
    assert "does not conform" in summary and "non-conformity proven" in summary


@pytest.mark.parametrize("engine", ENGINES)
def test_every_engine_agrees_on_decision_and_summary(knuckle, engine):
    assert assert_engine_agrees(knuckle[1], engine) > 40


@pytest.mark.parametrize("engine", ENGINES)
def test_a_measured_value_typed_into_the_sheet_changes_the_decision(knuckle, tmp_path, engine):
    """The Decision sheet is live: S4_position measured 0.045 (beyond A_U = 0.0384) is undecided."""
    _, book = knuckle
    wb = openpyxl.load_workbook(book)
    dest = next(iter(wb.defined_names["tol1_measured_mm"].destinations))
    wb[dest[0]][dest[1].replace("$", "")].value = 0.045
    edited = tmp_path / "edited.xlsx"
    wb.save(edited)
    v = recalc(edited, engine)["Decision"]
    assert v[at(8, "outcome")] == "cannot be decided"
    want = cf.probability_of_conformance(0.045, v[at(8, "u_um")], cf.Tolerance(usl_mm=0.05))
    assert close(v[at(8, "p_c")], want, rel=1e-9)


# -- JCGM 106:2012, 7.3 Table 1 in the workbook --------------------------------------------------

TABLE1 = [(0.80, 0.84), (0.90, 1.28), (0.95, 1.64), (0.99, 2.33), (0.999, 3.09)]


@pytest.fixture(scope="module")
def table1(tmp_path_factory):
    """Four knuckle characteristics with an upper limit z_printed·u above the measured value."""
    tmp = tmp_path_factory.mktemp("table1")
    plain, _ = build(tmp, KNUCKLE, name="plain.toml")
    u = {c["name"]: c["u_um"] for c in plain["characteristics"]}
    names = ["S1_S2_distance", "S3_from_S1S2", "S4_from_ABC", "S1S2_to_DE", "S2_position"]

    def edit(doc):
        doc["task"]["name"] = "table1"
        doc["decision"] = {"rule": "simple", "tolerances": [
            {"characteristic": n, "measured_mm": 50.0, "usl_mm": 50.0 + z * u[n] / 1000}
            for n, (_, z) in zip(names, TABLE1)]}
    return build(tmp, KNUCKLE, edit, name="table1.toml")


def test_table1_probabilities_of_conformance_in_the_json(table1):
    results, _ = table1
    for d, (p_c, _) in zip(results["decisions"], TABLE1):
        decimals = len(str(p_c).split(".")[1])
        assert abs(d["p_c"] - p_c) <= 0.5 * 10 ** -decimals, (d["characteristic"], d["p_c"], p_c)


@pytest.mark.parametrize("engine", ENGINES)
def test_table1_probabilities_of_conformance_in_the_workbook(table1, engine):
    results, book = table1
    v = recalc(book, engine)["Decision"]
    for i, (d, (p_c, _)) in enumerate(zip(results["decisions"], TABLE1)):
        got = v[at(8 + i, "p_c")]
        assert close(got, d["p_c"], rel=1e-9)
        decimals = len(str(p_c).split(".")[1])
        assert abs(got - p_c) <= 0.5 * 10 ** -decimals


# -- the other rules, on other kinds ----------------------------------------------------------

RULE_BOOKS = {
    "specific_risk (pointcloud)": "stepgauge_I_MPE1.toml",
    "guarded_acceptance (feature)": "feature_table1_circle_arc.toml",
    "guarded_rejection (feature)": "feature_table7_cone_arc.toml",
    "simple (feature)": "feature_table4_sphere_segment.toml",
}


@pytest.fixture(scope="module")
def rule_books(tmp_path_factory):
    out = {}
    for label, name in RULE_BOOKS.items():
        out[label] = build(tmp_path_factory.mktemp(re.sub(r"\W", "_", label)), EXAMPLES / name)
    return out


def test_guard_bands_of_each_rule(rule_books):
    sr = rule_books["specific_risk (pointcloud)"][0]
    d = sr["decisions"][0]
    assert d["characteristic"] == "L1→L2" and d["w_um"] == pytest.approx(cf.norm_ppf(0.95) * d["u_um"], rel=1e-12)
    assert [x["outcome"] for x in sr["decisions"]] == ["accepted", "rejected", "accepted"]
    for x in sr["decisions"]:
        assert (x["p_c"] >= 0.95) == (x["outcome"] == "accepted")
    ga = rule_books["guarded_acceptance (feature)"][0]["decisions"][0]
    assert ga["w_um"] == pytest.approx(ga["U_um"], rel=1e-15)
    assert ga["U_um"] == pytest.approx(2 * ga["u_um"], rel=1e-15)     # [decision] k = 2
    gr = rule_books["guarded_rejection (feature)"][0]["decisions"][0]
    assert gr["w_um"] == pytest.approx(-0.5 * gr["U_um"], rel=1e-15)
    assert gr["outcome"] == "accepted" and gr["value_mm"] > gr["usl_mm"]   # accepted beyond T_U ...
    assert gr["conformity"] == "neither proven"                           # ... never said to conform
    simple = rule_books["simple (feature)"][0]["decisions"][0]
    assert simple["w_um"] == 0 and simple["outcome"] == "accepted"


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("label", list(RULE_BOOKS))
def test_every_engine_agrees_for_each_rule(rule_books, label, engine):
    assert assert_engine_agrees(rule_books[label][1], engine) > 10


# -- bad input: one message naming the key ---------------------------------------------------

@pytest.mark.parametrize("edit, where, message", [
    (lambda d: d["decision"].update(rule="lenient"), "[decision] rule", "must be one of"),
    (lambda d: d["decision"].update(k=2), "[decision] k", "results give u only"),
    (lambda d: d["decision"].update(r=1.0), "[decision] r", "guarded rules only"),
    (lambda d: d["decision"]["tolerances"][2].update(lsl_mm=89.9), "#3 key 'tol_mm'", "either tol_mm"),
    (lambda d: d["decision"]["tolerances"][0].update(usl_mm="0.05"), "#1 key 'usl_mm'", "finite number"),
    (lambda d: d["decision"]["tolerances"][1].update(characteristic="S9_position"), "#2 key 'characteristic'",
     "no characteristic 'S9_position'"),
    (lambda d: d["decision"]["tolerances"][3].update(tol_mm=-0.02), "#4 key 'tol_mm'", "positive"),
    (lambda d: d["decision"]["tolerances"][0].update(colour="red"), "tolerances #1", "unknown key"),
    (lambda d: d["decision"]["tolerances"].append(dict(d["decision"]["tolerances"][0])), "#5 key 'characteristic'",
     "has a tolerance already"),
    (lambda d: d["decision"].pop("tolerances"), "[decision] tolerances", "no tolerances"),
    (lambda d: d["decision"]["tolerances"][2].pop("n_repeats"), "#3 key 'n_repeats'", "both s_um"),
    (lambda d: d["decision"]["tolerances"][2].update(n_repeats=1), "#3 key 'n_repeats'", ">= 2"),
    (lambda d: d["decision"].update(k_from_dof="yes"), "[decision] k_from_dof", "true or false"),
    (lambda d: d["decision"]["tolerances"][0].update(process_mean_mm=90.0), "#1 key 'process_sd_um'",
     "both process_mean_mm and process_sd_um"),
    (lambda d: d["decision"]["tolerances"][0].update(process_mean_mm=90.0, process_sd_um=0.0),
     "#1 key 'process_sd_um'", "positive"),
    (lambda d: d["decision"]["tolerances"][0].update(process_mean_mm="90", process_sd_um=2.0),
     "#1 key 'process_mean_mm'", "finite number"),
])
def test_bad_decision_input_names_the_key(tmp_path, edit, where, message):
    with pytest.raises(InputError) as e:
        build(tmp_path, KNUCKLE, edit)
    assert where in str(e.value) and message in str(e.value), str(e.value)
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").glob("*.xlsx"))


def test_build_prints_rounded_statements_and_decisions(tmp_path, capsys):
    from cmmwb.generator.cli import main

    assert main(["build", str(KNUCKLE), "--out", str(tmp_path / "out"), "--no-plots"]) == 0
    out = capsys.readouterr().out
    assert "S3_position = 0.041 mm, U = 11 µm (k = 2, coverage probability ≈ 95.45 %): cannot be decided" in out
    assert "S1_S2_distance = 90.0120 mm, U = 4.6 µm (k = 2.04, coverage probability ≈ 95.45 %): conforms" in out
