"""Degrees of freedom (xlfuncs.dof): Welch–Satterthwaite and t-distribution coverage factors,
against GUM (JCGM 100:2008) Table G.2 (t_p(ν) for p = 95 % and 95.45 %, printed to 2-3 decimals)."""

from __future__ import annotations

import math

import pytest

from cmmwb.xlfuncs import dof
from cmmwb.xlfuncs.dof import coverage_factor, nu_eff, t_cdf, t_quantile
from cmmwb.xlfuncs.errors import ModelError

#: GUM Table G.2: ν, t_95(ν), t_95.45(ν)
TABLE_G2 = [(1, "12.71", "13.97"), (2, "4.30", "4.53"), (3, "3.18", "3.31"), (4, "2.78", "2.87"),
            (5, "2.57", "2.65"), (6, "2.45", "2.52"), (7, "2.36", "2.43"), (8, "2.31", "2.37"),
            (9, "2.26", "2.32"), (10, "2.23", "2.28"), (20, "2.09", "2.13"), (50, "2.01", "2.05"),
            (100, "1.984", "2.025")]


def printed(x: float, text: str) -> bool:
    decimals = len(text.split(".")[1])
    return abs(x - float(text)) <= 0.5 * 10 ** -decimals + 1e-12


@pytest.mark.parametrize("nu, t95, t9545", TABLE_G2)
def test_gum_table_g2(nu, t95, t9545):
    assert printed(coverage_factor(nu, 0.95), t95)
    assert printed(coverage_factor(nu), t9545)


def test_infinite_degrees_of_freedom_is_the_normal_k():
    assert printed(coverage_factor(math.inf), "2.000")     # GUM Table G.2, ν = ∞: k = 2 <-> 95.45 %
    assert printed(coverage_factor(math.inf, 0.95), "1.960")


def test_t_cdf_and_quantile_invert_each_other():
    for nu in (1, 2.5, 7, 30):
        for p in (0.6, 0.975, 0.99977):
            assert t_cdf(t_quantile(p, nu), nu) == pytest.approx(p, rel=1e-12)
    assert t_cdf(1.0, 1) == pytest.approx(0.75, rel=1e-14)      # Cauchy: 1/2 + atan(1)/π


def test_welch_satterthwaite():
    """GUM G.4.1 eq. (G.2b); type B contributions (ν = inf) add to u_c but not to the sum."""
    assert nu_eff([3.0], [9]) == pytest.approx(9.0)
    assert nu_eff([1.0, 1.0], [4, 4]) == pytest.approx(8.0)        # (2)² / (1/4 + 1/4)
    assert nu_eff([2.0, 1.0], [math.inf, 5]) == pytest.approx(25.0 * 5)
    assert nu_eff([2.0], [math.inf]) == math.inf
    # ν_eff is truncated to the next lower integer for the coverage factor (GUM G.6.4)
    assert coverage_factor(9.99) == coverage_factor(9)
    with pytest.raises(ModelError, match="positive"):
        nu_eff([1.0], [0])


@pytest.mark.parametrize("nu", [1, 2, 4, 8.6, 30, 64.2, 1000])
def test_the_coverage_probability_of_the_t_coverage_factor_is_95_45_percent(nu):
    """coverage_probability inverts coverage_factor (GUM G.6.4: ν truncated to ⌊ν⌋ in both)."""
    assert dof.coverage_probability(dof.coverage_factor(nu), nu) == pytest.approx(dof.P_K2, abs=1e-12)


def test_the_coverage_probability_of_a_normal_k():
    """GUM G.1.3: k = 1, 2, 3 cover 68.27 %, 95.45 %, 99.73 % (2Φ(k) - 1)."""
    got = [dof.coverage_probability(k) for k in (1, 2, 3)]
    assert [round(100 * p, 2) for p in got] == [68.27, 95.45, 99.73]
