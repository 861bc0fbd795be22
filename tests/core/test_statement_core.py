"""Rounded result statements (xlfuncs.statement): GUM (JCGM 100:2008) 7.2.6, U to two
significant digits and the value to the same decimal place; full precision is kept elsewhere."""

from __future__ import annotations

import pytest

from cmmwb.xlfuncs.errors import ModelError
from cmmwb.xlfuncs.statement import decimals_for, round_to, round_uncertainty, statement


@pytest.mark.parametrize("U, rounded, decimals", [
    (11.634609795116338, 12.0, 0),      # the knuckle's U_POS: "U_um 11.634610" in the issue
    (3.4449, 3.4, 1),
    (3.45, 3.5, 1),                     # halves away from zero, on the decimal text
    (0.0712, 0.071, 3),
    (0.125, 0.13, 2),
    (134.0, 130.0, -1),
    (9.96, 10.0, 0),                    # carries into a new digit: 10, two significant digits
    (0.0009951, 0.0010, 4),             # "0.0010"
])
def test_U_rounds_to_two_significant_digits(U, rounded, decimals):
    r, dec = round_uncertainty(U)
    assert r == pytest.approx(rounded, rel=1e-15)
    assert dec == decimals


def test_rounding_up_when_asked():
    assert round_uncertainty(3.41, mode="up") == (3.5, 1)
    assert round_uncertainty(3.40, mode="up") == (3.4, 1)


def test_value_to_the_decimal_place_of_U_across_units():
    # U = 3.4 µm is 0.0034 mm: the value in mm gets four decimals
    s = statement("d", 100.012345, "mm", 3.4449, "µm", 2)
    assert s == "d = 100.0123 mm, U = 3.4 µm (k = 2, coverage probability ≈ 95.45 %)"
    # U = 12 µm: the value to 0.001 mm
    assert statement("l", 63.0, "mm", 11.6346, "µm", 2).startswith("l = 63.000 mm, U = 12 µm")
    # same unit on both sides (angles in rad)
    assert statement("a", 0.7853981, "rad", 2.345e-6, "rad", 2, unit_ratio=1) == \
        "a = 0.7853981 rad, U = 0.0000023 rad (k = 2, coverage probability ≈ 95.45 %)"


def test_decimals_for_and_round_to():
    assert decimals_for(0.5) == 2 and decimals_for(5.0) == 1 and decimals_for(50.0) == 0
    assert round_to(-2.345, 2) == -2.35
    with pytest.raises(ModelError, match="positive"):
        decimals_for(0.0)


def test_a_value_that_rounds_to_zero_has_no_minus_sign():
    assert statement("y0_mm", -1.2e-17, "mm", 1.4, "µm", 2).startswith("y0_mm = 0.0000 mm")


def test_a_t_distribution_k_shows_two_decimals():
    """k = t_95.45(ν) of GUM G.6.4 (ν_eff = 8.6 -> ν = 8: 2.3664) states the 95.45 % it was chosen for."""
    assert statement("d", 10.0, "mm", 2.0, "µm", 2.366419499743066, nu=8.6).endswith(
        "(k = 2.37, coverage probability ≈ 95.45 %)")
    assert statement("d", 10.0, "mm", 2.0, "µm", 2.0).endswith("(k = 2, coverage probability ≈ 95.45 %)")


@pytest.mark.parametrize("k, text", [(3, "99.73"), (2.5, "98.76"), (1, "68.27"), (2, "95.45")])
def test_the_coverage_probability_follows_k(k, text):
    """GUM G.1.3: y ± k·u of a normal distribution covers 2Φ(k) - 1 (issue 32: every k printed 95 %)."""
    assert statement("d", 10.0, "mm", 2.0, "µm", k).endswith(f"coverage probability ≈ {text} %)")


def test_a_small_nu_eff_gives_the_t_coverage_probability():
    """k = 2 with ν_eff = 4 (GUM G.3.2: Student's t): 2 F_t(2; 4) - 1 = 0.8839, not 95.45 %."""
    assert statement("d", 10.0, "mm", 2.0, "µm", 2.0, nu=4.7).endswith("(k = 2, coverage probability ≈ 88.39 %)")
