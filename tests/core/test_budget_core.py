"""Wojtyła/Płowucha 2023: sensitivity-analysis budgets from E_L,MPE (xlfuncs.budget).

The steering knuckle of section 4 (Fig. 6), with the conventions of docs/errata.md:
E_L,MPE = 3 + L/250 µm with b = 0.577 (what Tables 1-9 use; section 4 states 2 + L/250 and
b = 1/3), the zero x components of CS4, DS4 and DS3 replaced by 0.01 mm (here: S3 and S4 at
x = 0.01 mm), u_POS = 2 sqrt(u_l1^2 + u_l2^2).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cmmwb.xlfuncs.budget import (
    MPE,
    DatumSystem,
    DegenerateGeometryError,
    ModelError,
    distance_budget,
    evaluate,
    position_budget,
    specs_for,
    value_of,
    variants_datum,
    variants_line_line,
    variants_point_line,
    variants_point_plane,
    variants_point_point,
)

from tests.helpers.budget import (
    DATUMS,
    KNUCKLE,
    POSITIONS,
    SECTION4_MPE,
    TABLE9,
    TABLES,
    TABLES_MPE,
    assert_printed,
    numerical_gradient,
    reference_value,
)

# ---------------------------------------------------------------------------------------------
# The paper's data (the knuckle, Tables 1-9 as printed): tests/helpers/budget.py
# ---------------------------------------------------------------------------------------------


def knuckle_distance(point: str, datum: str, variant: str = "auto", points=KNUCKLE,
                     mpe=TABLES_MPE):
    return distance_budget(variants_datum(point, datum, DATUMS), points, mpe, variant)


# ---------------------------------------------------------------------------------------------
# Tables 1-9
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("table", sorted(TABLES))
def test_tables_1_to_8_every_printed_cell(table):
    point, datum, variant, equation, text, u_c = TABLES[table]
    budget = knuckle_distance(point, datum).chosen
    rows = [line.split() for line in text.strip().splitlines()]
    assert list(budget.inputs) == [r[0] for r in rows]
    for (name, x, s, u, c), xv, sv, uv, cv in zip(rows, budget.values_mm, budget.sensitivities,
                                                  budget.u_um, budget.contributions_um):
        assert_printed(xv, x, min_decimals=2, what=f"Table {table} {name} x_i")
        assert_printed(sv, s, min_decimals=3, what=f"Table {table} {name} dl/dx_i")
        assert_printed(uv, u, what=f"Table {table} {name} u_i")
        assert_printed(cv, c, min_decimals=3, what=f"Table {table} {name} contribution")
    assert_printed(budget.u_c_um, u_c, what=f"Table {table} u_c")


@pytest.mark.parametrize("table", sorted(TABLES))
def test_auto_picks_the_papers_variant(table):
    point, datum, variant, equation, _, _ = TABLES[table]
    d = knuckle_distance(point, datum)
    assert d.chosen.label == variant
    assert d.chosen.spec.equation == equation
    # and it really is (one of) the lowest: a tie goes to the first in the paper's order
    assert d.chosen.u_c_um == min(v.u_c_um for v in d.variants)


def test_variant_counts_follow_the_paper():
    """9 variants for the primary datum (eqs. 10-18), 6 for the secondary (27-32), 3 for the
    tertiary (19-21 / 33-35); the values agree, the uncertainties differ."""
    for datum, n in (("primary", 9), ("secondary", 6), ("tertiary", 3)):
        d = knuckle_distance("S4" if datum == "primary" else "S1", datum)
        assert len(d.variants) == n
        values = [v.value_mm for v in d.variants]
        assert max(values) - min(values) < 1e-12 * max(values)
    primary = knuckle_distance("S4", "primary")
    assert [v.spec.equation for v in primary.variants] == [f"eq. ({i})" for i in range(10, 19)]
    assert len({round(v.u_c_um, 9) for v in primary.variants}) > 1


def test_table_1_contributions_show_the_0_01_mm_substitution():
    """0.150 vs 0.151 for z_CA and z_CB in Table 1 exist only because x_CS4 = 0.01 mm: with the
    drawing's x_CS4 = 0 both sensitivities are 1400/9300 = 0.1505 (printed 0.151)."""
    with_sub = knuckle_distance("S4", "primary").chosen
    drawing = dict(KNUCKLE, S4=[0, 89, 63])
    without = knuckle_distance("S4", "primary", points=drawing).chosen
    assert_printed(with_sub.sensitivities[5], "0.150")
    assert_printed(without.sensitivities[5], "0.151")
    assert without.sensitivities[5] == pytest.approx(1400 / 9300, rel=1e-12)


@pytest.mark.parametrize("point", ["S4", "S1", "S2", "S3"])
def test_table_9_position_uncertainty(point):
    datums, ted = POSITIONS[point]
    pos = position_budget(point, datums, ted, DATUMS, KNUCKLE, TABLES_MPE)
    u1, u2, upos = TABLE9[point]
    assert_printed(pos.distances[0].u_um, u1, what=f"{point} u_1")
    assert_printed(pos.distances[1].u_um, u2, what=f"{point} u_2")
    assert_printed(pos.u_um, upos, what=f"{point} u_POS")
    # u_POS = 2 sqrt(u1^2 + u2^2) from the unrounded u1, u2, written as a budget
    assert pos.u_um == pytest.approx(2 * math.hypot(pos.distances[0].u_um, pos.distances[1].u_um),
                                     rel=1e-14)
    assert list(pos.sensitivities) == [2.0, 2.0]
    assert pos.U_um == pytest.approx(2 * pos.u_um, rel=1e-15)


def test_table_9_is_not_eq_26():
    """Eq. (26), u_POS ~ 2 max(u1, u2), gives 4.38 µm for S4, not Table 9's 5.82."""
    pos = position_budget("S4", *POSITIONS["S4"], DATUMS, KNUCKLE, TABLES_MPE)
    assert_printed(pos.u_eq26_um, "4.38")
    assert abs(pos.u_eq26_um - 5.82) > 1


def test_S4_expanded_uncertainty_is_11_63_not_11_5():
    """Section 4 prints U_POS = 11.5 µm for S4; k = 2 times u_POS = 5.817 is 11.63."""
    pos = position_budget("S4", *POSITIONS["S4"], DATUMS, KNUCKLE, TABLES_MPE)
    assert_printed(pos.U_um, "11.63")


def test_S3_text_value_2_86_is_without_the_factor_2():
    """Section 4 says u_POS = 2.86 µm for S3, which is sqrt(u1^2 + u2^2) (Table 9: 5.72)."""
    pos = position_budget("S3", *POSITIONS["S3"], DATUMS, KNUCKLE, TABLES_MPE)
    assert_printed(pos.u_um / 2, "2.86")


def test_conclusions_follow_eq_26_with_the_section_4_mpe():
    """Conclusion 3 (1.656 µm to 1.758 µm; 1.656 and 1.677 for S1 and S3) is eq. (26) with
    u_l = max(u_l1, u_l2) and the section-4 MPE 2 + L/250, b = 1/3."""
    printed = {"S1": "1.656", "S2": "1.656", "S3": "1.677", "S4": "1.758"}
    for point, text in printed.items():
        pos = position_budget(point, *POSITIONS[point], DATUMS, KNUCKLE, SECTION4_MPE)
        assert_printed(pos.u_eq26_um, text, what=point)


def test_tables_do_not_follow_the_section_4_mpe():
    """The stated 2 + L/250 with b = 1/3 gives u_c = 0.76 µm for Table 1 (printed 1.91)."""
    d = knuckle_distance("S4", "primary", mpe=SECTION4_MPE).chosen
    assert abs(d.u_c_um - 1.91) > 1


def test_position_value_is_eq_22():
    pos = position_budget("S3", *POSITIONS["S3"], DATUMS, KNUCKLE, TABLES_MPE)
    # l_S3,1 = 0.01 mm (the substituted x), l_S3,2 = 52 mm: POS = 2 sqrt(0.01^2 + 0)
    assert pos.value_mm == pytest.approx(0.02, rel=1e-9)
    off = dict(KNUCKLE, S1=[45.003, -26.004, -15])
    pos = position_budget("S1", *POSITIONS["S1"], DATUMS, off, TABLES_MPE)
    assert pos.value_mm == pytest.approx(2 * 0.005, rel=1e-9)


def test_input_uncertainty_is_b_times_E_of_each_component():
    """u(x_i) = b E_L,MPE(|x_i|), eq. (5) per coordinate difference: 0.577 (3 + 93/250)."""
    assert TABLES_MPE.u_um(-93.0) == pytest.approx(0.577 * (3 + 93 / 250), rel=1e-15)
    b = knuckle_distance("S4", "primary").chosen
    assert b.u_um == pytest.approx(0.577 * (3 + np.abs(b.values_mm) / 250), rel=1e-15)
    assert b.u_c_um == pytest.approx(math.sqrt(np.sum((b.sensitivities * b.u_um) ** 2)))
    assert b.U_um == pytest.approx(2 * b.u_c_um)


def test_a_named_variant_is_used_as_given():
    d = knuckle_distance("S4", "primary", variant="AS4 · (AB × AC)")
    assert d.chosen.label == "AS4.(ABxAC)"
    assert d.u_um > knuckle_distance("S4", "primary").u_um
    with pytest.raises(ModelError, match=r"unknown variant 'XS4.*CS4\.\(CAxCB\)"):
        knuckle_distance("S4", "primary", variant="XS4.(ABxAC)")


# ---------------------------------------------------------------------------------------------
# Closed-form sensitivities against numerical derivatives of an independent model
# ---------------------------------------------------------------------------------------------


def random_specs(rng: np.random.Generator):
    """Random essential points (a box of 400 mm) and every variant of every model on them."""
    names = ["A", "B", "C", "D", "E", "S"]
    pts = {n: rng.uniform(-200, 200, 3) for n in names}
    ds = DatumSystem(("A", "B", "C"), ("D", "E"))
    specs = (variants_point_point("A", "S") + variants_point_line("S", "A", "B")
             + variants_point_plane("S", "A", "B", "C") + variants_line_line("A", "B", "C", "D")
             + variants_datum("S", "primary", ds) + variants_datum("S", "secondary", ds)
             + variants_datum("S", "tertiary", ds))
    return pts, specs


@pytest.mark.parametrize("seed", range(12))
def test_sensitivities_match_numerical_derivatives(seed):
    rng = np.random.default_rng(20230927 + seed)
    points, specs = random_specs(rng)
    mpe = MPE(A_um=float(rng.uniform(0.5, 5)), B_mm=float(rng.uniform(100, 1000)),
              b=float(rng.uniform(0.3, 0.7)), k=2.0)
    kinds = set()
    for spec in specs:
        budget = evaluate(spec, points, mpe)
        x = budget.values_mm.copy()
        ref = reference_value(spec.kind, x)
        assert budget.value_mm == pytest.approx(ref, rel=1e-12), spec.label
        assert value_of(spec, x) == pytest.approx(ref, rel=1e-12)
        # random points are far from every kink (|l| of several mm), so h = 1e-3 mm is safe
        assert ref > 1e-2
        num = numerical_gradient(lambda y: reference_value(spec.kind, y), x, h=1e-3)
        scale = np.max(np.abs(budget.sensitivities))
        np.testing.assert_allclose(budget.sensitivities, num, rtol=1e-7, atol=1e-7 * scale,
                                   err_msg=f"{spec.kind} {spec.label}")
        kinds.add(spec.kind)
    assert kinds == {"point_point", "point_line", "plane", "line_line", "secondary", "tertiary"}


def test_sensitivities_on_the_knuckle_match_numerical_derivatives():
    for point, (datums, _) in POSITIONS.items():
        for datum in datums:
            for budget in knuckle_distance(point, datum).variants:
                x = budget.values_mm
                num = numerical_gradient(lambda y: reference_value(budget.spec.kind, y), x, 1e-5)
                np.testing.assert_allclose(budget.sensitivities, num, rtol=1e-7, atol=1e-8,
                                           err_msg=budget.label)


# ---------------------------------------------------------------------------------------------
# Generic models (eqs. 1-4) on simple geometry
# ---------------------------------------------------------------------------------------------


SIMPLE = {"A": [0, 0, 0], "B": [100, 0, 0], "C": [0, 100, 0], "D": [0, 100, 50],
          "S": [30, 40, 20]}
MPE_1 = MPE(A_um=2.0, B_mm=250.0, b=1 / 3, k=2.0)


def test_point_point_distance_is_eq_1():
    d = distance_budget(specs_for("point_point", points_used={"from": "A", "to": "S"}),
                        SIMPLE, MPE_1)
    assert d.value_mm == pytest.approx(math.sqrt(30**2 + 40**2 + 20**2))
    assert list(d.chosen.inputs) == ["x_AS", "y_AS", "z_AS"]
    np.testing.assert_allclose(d.chosen.sensitivities, np.array([30, 40, 20]) / d.value_mm)


def test_point_line_has_two_variants_eq_2():
    d = distance_budget(specs_for("point_line", points_used={"point": "S", "line": ("A", "B")}),
                        SIMPLE, MPE_1)
    assert [v.label for v in d.variants] == ["|ASxAB|/|AB|", "|BSxAB|/|AB|"]
    assert d.value_mm == pytest.approx(math.hypot(40, 20))
    # AS is shorter than BS: the AS variant has the lower uncertainty and is chosen
    assert d.chosen.label == "|ASxAB|/|AB|"
    assert d.variants[1].u_c_um > d.variants[0].u_c_um


def test_point_plane_has_nine_variants_eq_3():
    d = distance_budget(specs_for("point_plane", points_used={"point": "S",
                                                             "plane": ("A", "B", "C")}),
                        SIMPLE, MPE_1)
    assert len(d.variants) == 9
    assert d.value_mm == pytest.approx(20.0)
    assert all(v.value_mm == pytest.approx(20.0, rel=1e-12) for v in d.variants)


def test_line_line_has_four_variants_eq_4():
    d = distance_budget(specs_for("line_line", points_used={"line1": ("A", "B"),
                                                           "line2": ("C", "D")}), SIMPLE, MPE_1)
    # AB is the x axis, CD is vertical through (0, 100): common normal along y, length 100
    assert [v.label for v in d.variants] == ["AC.(ABxCD)", "BC.(ABxCD)", "AD.(ABxCD)",
                                             "BD.(ABxCD)"]
    assert d.value_mm == pytest.approx(100.0)
    assert list(d.chosen.inputs[:3]) == ["x_AB", "y_AB", "z_AB"]


# ---------------------------------------------------------------------------------------------
# Degenerate geometry: a clear error or the documented one-sided treatment, never NaN
# ---------------------------------------------------------------------------------------------


def test_collinear_primary_points_are_an_error():
    pts = dict(KNUCKLE, C=[150, -32, 0])
    with pytest.raises(DegenerateGeometryError, match="collinear"):
        knuckle_distance("S4", "primary", points=pts)
    with pytest.raises(DegenerateGeometryError, match="collinear"):
        knuckle_distance("S1", "tertiary", points=pts)


def test_secondary_direction_perpendicular_to_the_primary_is_an_error():
    pts = dict(KNUCKLE, E=[0, 0, 40])          # DE along the primary normal
    with pytest.raises(DegenerateGeometryError, match="perpendicular to the primary"):
        knuckle_distance("S1", "secondary", points=pts)


def test_parallel_lines_are_an_error():
    pts = dict(SIMPLE, D=[50, 100, 0])          # CD parallel to AB
    specs = specs_for("line_line", points_used={"line1": ("A", "B"), "line2": ("C", "D")})
    with pytest.raises(DegenerateGeometryError, match="parallel"):
        distance_budget(specs, pts, MPE_1)


def test_point_on_the_line_is_an_error():
    pts = dict(SIMPLE, S=[30, 0, 0])
    specs = specs_for("point_line", points_used={"point": "S", "line": ("A", "B")})
    with pytest.raises(DegenerateGeometryError, match="lies on the line"):
        distance_budget(specs, pts, MPE_1)


def test_coincident_points_are_an_error():
    pts = dict(SIMPLE, S=[0, 0, 0])
    with pytest.raises(DegenerateGeometryError, match="coincide"):
        distance_budget(specs_for("point_point", points_used={"from": "A", "to": "S"}), pts,
                        MPE_1)


def test_point_on_a_datum_uses_the_one_sided_derivative():
    """S3 exactly on the secondary datum (the drawing's x = 0): l = 0, |l| has a kink.  The
    sensitivities are those from the positive side (finite, no NaN); u_c is the same from both
    sides, and is Table 7's 2.18 µm."""
    on = dict(KNUCKLE, S3=[0, 52, -15])
    d = knuckle_distance("S3", "secondary", points=on)
    assert d.value_mm == 0.0
    assert np.all(np.isfinite(d.chosen.sensitivities))
    assert d.chosen.sensitivities[0] == 1.0
    assert_printed(d.u_um, "2.18")
    for side in (+1e-7, -1e-7):
        near = knuckle_distance("S3", "secondary", points=dict(KNUCKLE, S3=[side, 52, -15]),
                                variant=d.chosen.label)
        assert near.u_um == pytest.approx(d.u_um, rel=1e-8)


def test_non_finite_coordinates_and_unknown_points_are_errors():
    with pytest.raises(ModelError, match="point S4 has a non-finite coordinate"):
        knuckle_distance("S4", "primary", points=dict(KNUCKLE, S4=[0, float("nan"), 63]))
    with pytest.raises(ModelError, match="unknown point 'S9'"):
        knuckle_distance("S9", "primary")
    with pytest.raises(ModelError, match="datum must be one of"):
        variants_datum("S1", "quaternary", DATUMS)


def test_bad_mpe_parameters_are_errors():
    with pytest.raises(ModelError, match="B_mm must be positive"):
        MPE(A_um=3, B_mm=0, b=0.577)
    with pytest.raises(ModelError, match="b must be positive"):
        MPE(A_um=3, B_mm=250, b=-1)
    with pytest.raises(ModelError, match="A_um must be a finite number"):
        MPE(A_um=float("inf"), B_mm=250, b=0.5)


def test_bad_position_definitions_are_errors():
    with pytest.raises(ModelError, match="two different datums"):
        position_budget("S1", ("secondary", "secondary"), (45, 26), DATUMS, KNUCKLE, TABLES_MPE)
    with pytest.raises(ModelError, match="ted_mm must be two finite numbers"):
        position_budget("S1", ("secondary", "tertiary"), (45, float("nan")), DATUMS, KNUCKLE,
                        TABLES_MPE)
