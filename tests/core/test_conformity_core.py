"""Conformity decisions (xlfuncs.conformity): JCGM 106:2012 with a normal PDF, ISO 14253-1:2017.

Sources of the numbers: JCGM 106:2012, 7.3 Table 1 (z = (T_U - y)/u for a one-sided tolerance
interval at the probability of conformance p_c; printed to two decimals), 7.3-7.4 (p_c for one-
and two-sided intervals), 7.6 (measurement capability index C_m), 8.2-8.3 (acceptance intervals,
guard band w = r·U).  Where a number is derived from a clause rather than printed in it, the
test says so.
"""

from __future__ import annotations

import numpy as np
import pytest

from cmmwb.xlfuncs.conformity import (
    ACCEPTED,
    CONFORMITY_PROVEN,
    CONFORMS,
    DOES_NOT_CONFORM,
    NEITHER_PROVEN,
    NONCONFORMITY_PROVEN,
    REJECTED,
    UNDECIDED,
    DecisionRule,
    Tolerance,
    acceptance_limits,
    decide,
    measurement_capability_index,
    norm_cdf,
    norm_ppf,
    probability_of_conformance,
)
from cmmwb.xlfuncs.errors import ModelError


def printed(value: float, table_value: float, decimals: int) -> bool:
    return abs(value - table_value) <= 0.5 * 10 ** -decimals + 1e-12


# -- the normal distribution function, numpy only ---------------------------------------------

def test_norm_cdf_matches_erfc_identities_in_both_tails():
    # Φ(-z) = 1 - Φ(z) and Φ(0) = 1/2; Φ(-6) = 9.8659e-10 (a tail that 1 - Φ(6) would lose)
    assert norm_cdf(0.0) == 0.5
    assert abs(norm_cdf(1.3) + norm_cdf(-1.3) - 1.0) < 1e-15
    assert abs(norm_cdf(-6.0) / 9.865876450376946e-10 - 1) < 1e-12


@pytest.mark.parametrize("p", [1e-12, 0.001, 0.02, 0.3, 0.5, 0.8, 0.95, 0.999, 1 - 1e-10])
def test_norm_ppf_inverts_norm_cdf_to_double_precision(p):
    z = norm_ppf(p)
    back = norm_cdf(z) if p <= 0.5 else 1 - norm_cdf(z)
    assert abs(back - (p if p <= 0.5 else 1 - p)) <= 1e-13 * min(p, 1 - p) + 1e-17


# -- JCGM 106:2012, 7.3 Table 1: one-sided interval, z for given p_c ----------------------------

@pytest.mark.parametrize("p_c, z_printed", [(0.80, 0.84), (0.90, 1.28), (0.95, 1.64), (0.99, 2.33), (0.999, 3.09)])
def test_table1_z_for_a_one_sided_interval(p_c, z_printed):
    """JCGM 106:2012, 7.3 Table 1: a measured value z standard uncertainties below T_U has
    probability of conformance p_c; the table prints z to two decimals."""
    assert printed(norm_ppf(p_c), z_printed, 2)
    # and the other way round: y = T_U - z u gives p_c (7.3.2, eq. (10): p_c = Φ((T_U - y)/u))
    tol = Tolerance(usl_mm=10.0)
    u_um = 2.0
    y = 10.0 - norm_ppf(p_c) * u_um / 1000
    assert abs(probability_of_conformance(y, u_um, tol) - p_c) < 1e-12


def test_lower_limit_is_the_mirror_of_the_upper():
    """JCGM 106:2012, 7.3.1 eq. (9): p_c = 1 - Φ((T_L - y)/u) = Φ((y - T_L)/u)."""
    lo = probability_of_conformance(5.003, 1.5, Tolerance(lsl_mm=5.0))
    hi = probability_of_conformance(4.997, 1.5, Tolerance(usl_mm=5.0))
    assert abs(lo - hi) < 1e-15
    assert abs(lo - norm_cdf(2.0)) < 1e-12   # (5.003 - 5.0) mm is 3 µm to 1e-13


def test_two_sided_p_c_is_the_difference_of_the_one_sided_tails():
    """JCGM 106:2012, 7.4 eq. (12): p_c = Φ((T_U - y)/u) - Φ((T_L - y)/u)."""
    tol = Tolerance(9.990, 10.010)
    y, u = 10.004, 2.5
    want = norm_cdf((10.010 - y) * 1000 / u) - norm_cdf((9.990 - y) * 1000 / u)
    assert abs(probability_of_conformance(y, u, tol) - want) < 1e-15
    # the value of this case: z_U = 2.4, z_L = -5.6
    assert printed(probability_of_conformance(y, u, tol), 0.99180, 5)


def test_measurement_capability_index_and_p_c_at_the_midpoint():
    """JCGM 106:2012, 7.6: C_m = (T_U - T_L)/(4u); a value at the midpoint of the interval has
    p_c = 2Φ(2 C_m) - 1 (derived from eq. (12)); C_m = 1 (tolerance = 4u) gives 0.9545."""
    tol = Tolerance(-0.004, 0.004)
    cm = measurement_capability_index(tol, 2.0)
    assert cm == pytest.approx(1.0, rel=1e-14)
    assert printed(probability_of_conformance(0.0, 2.0, tol), 0.9545, 4)
    assert abs(probability_of_conformance(0.0, 2.0, tol) - (2 * norm_cdf(2 * cm) - 1)) < 1e-15


def test_p_c_broadcasts_over_arrays():
    tol = Tolerance(usl_mm=1.0)
    p = probability_of_conformance(np.array([0.999, 1.0, 1.001]), 1.0, tol)
    assert np.allclose(p, [norm_cdf(1.0), 0.5, norm_cdf(-1.0)], rtol=1e-12, atol=0)


# -- JCGM 106:2012, 8: acceptance intervals and guard bands --------------------------------------

def test_guarded_acceptance_limits_are_the_tolerance_reduced_by_r_U():
    """JCGM 106:2012, 8.3.2: A_L = T_L + w, A_U = T_U - w with w = r·U."""
    tol = Tolerance(24.990, 25.010)
    d = decide(25.000, 2.0, tol, DecisionRule("guarded_acceptance", r=1.0), k=2)
    assert d.w_um == pytest.approx(4.0, rel=1e-15)
    assert d.acceptance_mm[0] == pytest.approx(24.994, abs=1e-12)
    assert d.acceptance_mm[1] == pytest.approx(25.006, abs=1e-12)
    half = decide(25.000, 2.0, tol, DecisionRule("guarded_acceptance", r=0.5), k=2)
    assert half.acceptance_mm[1] == pytest.approx(25.008, abs=1e-12)


def test_at_a_guarded_acceptance_limit_with_w_U_the_item_is_accepted_with_p_c_0_977():
    """JCGM 106:2012, 8.3.2 (w = U, U = 2u, one-sided interval): an item accepted at the limit
    A_U = T_U - 2u has p_c = Φ(2) = 0.977, i.e. a specific false-acceptance risk of at most 2.3 %;
    on the limit of the conformance zone, conformity is proven (ISO 14253-1:2017, 5.2)."""
    tol = Tolerance(usl_mm=50.020)
    d = decide(50.016, 2.0, tol, DecisionRule("guarded_acceptance", r=1.0), k=2)
    assert d.acceptance_mm[1] == pytest.approx(50.016, abs=1e-12)
    assert (d.outcome, d.rule_outcome, d.conformity) == (ACCEPTED, ACCEPTED, CONFORMITY_PROVEN)
    assert printed(d.p_c, 0.977, 3)
    assert printed(1 - d.p_c, 0.023, 3)


def test_guarded_rejection_accepts_beyond_the_tolerance_limit():
    """JCGM 106:2012, 8.3.3: the acceptance interval extends beyond the tolerance interval by w."""
    tol = Tolerance(usl_mm=10.000)
    d = decide(10.001, 1.0, tol, DecisionRule("guarded_rejection", r=1.0), k=2)
    assert d.acceptance_mm[1] == pytest.approx(10.002, abs=1e-12)
    assert d.w_um == pytest.approx(-2.0)
    # accepted under the rule, but outside its tolerance: never said to conform (ISO 14253-1)
    assert d.outcome == ACCEPTED and d.p_c < 0.5
    assert d.conformity == NEITHER_PROVEN and d.conformity_zone == "uncertainty range"


def test_simple_acceptance_uses_the_tolerance_limits():
    """JCGM 106:2012, 8.2: A_L = T_L, A_U = T_U; a value just inside is accepted with p_c near 1/2."""
    tol = Tolerance(9.99, 10.01)
    inside = decide(10.0099, 3.0, tol, DecisionRule("simple"))
    outside = decide(10.0101, 3.0, tol, DecisionRule("simple"))
    assert inside.outcome == ACCEPTED and inside.zone == "acceptance zone"
    assert outside.outcome == REJECTED and outside.zone == "rejection zone"
    # within U of the limits: neither conformity nor non-conformity proven (ISO 14253-1:2017, 5.4)
    assert inside.conformity == outside.conformity == NEITHER_PROVEN
    assert 0.5 < inside.p_c < 0.52


def test_specific_risk_accepts_exactly_when_p_c_reaches_1_minus_max_pfa():
    """JCGM 106:2012, 9.3: specific consumer's risk R_C* = 1 - p_c; accept when R_C* <= max_pfa.
    One-sided interval: the acceptance limit is T_U - z u with z = Φ⁻¹(1 - max_pfa) (Table 1)."""
    tol = Tolerance(usl_mm=1.000)
    rule = DecisionRule("specific_risk", max_pfa=0.05)
    at = decide(1.0 - norm_ppf(0.95) * 2.0e-3 - 1e-9, 2.0, tol, rule)
    assert at.acceptance_mm[1] == pytest.approx(1.0 - 1.6448536269514722 * 2e-3, abs=1e-13)
    assert at.outcome == ACCEPTED and at.p_c >= 0.95
    beyond = decide(at.acceptance_mm[1] + 1e-5, 2.0, tol, rule)
    assert beyond.outcome == REJECTED and beyond.p_c < 0.95
    # rejected inside the tolerance interval: never said not to conform
    assert beyond.value_mm < tol.usl_mm and beyond.conformity == NEITHER_PROVEN


# -- ISO 14253-1:2017: three outcomes -----------------------------------------------------------

@pytest.mark.parametrize("y, outcome, zone", [
    (20.000, CONFORMS, "conformance zone"),
    (20.016, CONFORMS, "conformance zone"),          # on the limit of the conformance zone
    (20.018, UNDECIDED, "uncertainty range"),
    (20.023, UNDECIDED, "uncertainty range"),
    (20.025, DOES_NOT_CONFORM, "non-conformance zone"),
    (19.978, UNDECIDED, "uncertainty range"),
    (19.970, DOES_NOT_CONFORM, "non-conformance zone"),
])
def test_iso14253_zones(y, outcome, zone):
    """ISO 14253-1:2017, 5.2-5.3: conformance zone = specification zone reduced by U, non-
    conformance zone beyond the specification zone enlarged by U, uncertainty range between."""
    tol = Tolerance.symmetric(20.0, 0.020)
    d = decide(y, 2.0, tol, DecisionRule("iso14253"), k=2)
    assert (d.outcome, d.zone) == (outcome, zone)
    assert d.conformity_zone == zone            # the rule is the conformity statement itself
    assert d.conformity == {CONFORMS: CONFORMITY_PROVEN, UNDECIDED: NEITHER_PROVEN,
                            DOES_NOT_CONFORM: NONCONFORMITY_PROVEN}[outcome]
    assert d.acceptance_mm == pytest.approx((19.984, 20.016), abs=1e-12)
    assert d.rejection_mm == pytest.approx((19.976, 20.024), abs=1e-12)


# -- bad input ------------------------------------------------------------------------------------

def test_bad_tolerances_and_rules_say_which_key():
    with pytest.raises(ModelError, match="lsl_mm"):
        Tolerance(10.0, 9.0)
    with pytest.raises(ModelError, match="lower or an upper"):
        Tolerance()
    with pytest.raises(ModelError, match="tol_mm"):
        Tolerance.symmetric(1.0, -0.1)
    with pytest.raises(ModelError, match="unknown decision rule"):
        DecisionRule("lenient")
    with pytest.raises(ModelError, match="max_pfa"):
        DecisionRule("specific_risk", max_pfa=0.7)


def test_a_guard_band_of_half_the_tolerance_or_more_accepts_nothing():
    """JCGM 106:2012, 8.3.2: U too large for the tolerance leaves an empty acceptance interval."""
    lo, hi = acceptance_limits(Tolerance(0.0, 0.004), 2.5)
    assert lo > hi
    d = decide(0.002, 1.25, Tolerance(0.0, 0.004), DecisionRule("guarded_acceptance"), k=2)
    assert d.outcome == REJECTED and d.as_dict()["acceptance_interval_empty"]
    assert d.conformity == NEITHER_PROVEN          # rejected, but inside the tolerance
    iso = decide(0.002, 1.25, Tolerance(0.0, 0.004), DecisionRule("iso14253"), k=2)
    assert iso.outcome == UNDECIDED


@pytest.mark.parametrize("rule", ["simple", "iso14253", "guarded_acceptance", "guarded_rejection", "specific_risk"])
def test_the_conformity_statement_never_contradicts_the_tolerance(rule):
    """ISO 14253-1:2017, ILAC-G8: whatever a rule accepts or rejects, "conformity proven" only
    inside [T_L + U, T_U - U] and "non-conformity proven" only outside [T_L - U, T_U + U]; the
    non-conformance limits R = T -/+ U are the same for every rule (the Decision sheet set R = A
    for the binary rules: R_U = 50.0217 mm > T_U for guarded rejection)."""
    tol = Tolerance(49.98, 50.02)
    for y in np.linspace(49.97, 50.03, 121):
        d = decide(float(y), 1.734, tol, DecisionRule(rule, r=0.5), k=2)
        inside = tol.lsl_mm <= y <= tol.usl_mm
        if d.conformity == CONFORMITY_PROVEN:
            assert tol.lsl_mm + d.U_um / 1000 <= y <= tol.usl_mm - d.U_um / 1000
        if d.conformity == NONCONFORMITY_PROVEN:
            assert not inside and not (tol.lsl_mm - d.U_um / 1000 <= y <= tol.usl_mm + d.U_um / 1000)
        if d.outcome == CONFORMS:
            assert inside
        if d.outcome == DOES_NOT_CONFORM:
            assert not inside
        assert d.rejection_mm == pytest.approx((49.98 - d.U_um / 1000, 50.02 + d.U_um / 1000), abs=1e-12)
