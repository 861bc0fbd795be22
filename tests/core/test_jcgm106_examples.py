"""JCGM 106:2012's examples and clauses, reproduced: probability of conformance, acceptance limits
from a required p_c, global consumer's and producer's risks with a prior of the process, and a
guard band from a stated global consumer's risk, in the core and in a built Decision sheet.

What each number is, and where it comes from (docs/errata.md, "JCGM 106:2012 worked examples"):

* 7.3 Table 1 (printed, two decimals): z = (T_U - A_U)/u at p_c = 0.80 ... 0.999.
* 9.5.4, ball bearings: the inputs are the example's (radial error motion below T_U = 2 µm, a
  gamma PDF of the process, a measuring system with standard uncertainty u_m = 0.25 µm, a
  required global consumer's risk of 0.1 %); the gamma parameters α = 4, β = 4 µm⁻¹ (mean
  1 µm, standard deviation 0.5 µm) and the results 4.2 %, 0.8 % and A_U = 1.67 µm are as an
  independent implementation (Sandia's suncal 1.7, scipy quadrature and root finding) states and
  reproduces this example; the printed pages of JCGM 106 9.5.4 themselves could not be read here,
  so those are the reference, to suncal's full printed precision, and the prior's non-conforming
  fraction is also checked against its closed form.
* 7.4 eq. (12) / 9.3, the specific-risk rule's two-sided acceptance limits: the Newton iteration
  of the core and of the Decision sheet against bisection, and p_c = 1 - max_pfa on the limits.
* 9.5 (normal process and measuring system): no printed numbers at hand; checked against
  closed forms (the probability of acceptance) and the other order of integration (JCGM 106:2012,
  9.5: R_C is also the integral over accepted measured values of the specific risk 1 - p_c under
  the posterior).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cmmwb.xlfuncs import conformity as cf
from cmmwb.xlfuncs import global_risk as gr
from cmmwb.xlfuncs.errors import ModelError

from tests.helpers import ENGINES, close, recalc


def printed(value: float, published: float, decimals: int) -> bool:
    """Agreement to the printed precision: |x - printed| <= half a unit of the last decimal."""
    return abs(value - published) <= 0.5 * 10 ** -decimals + 1e-12


# -- 7.3 Table 1 through the acceptance limits for a required p_c ------------------------------

TABLE1 = [(0.80, 0.84), (0.90, 1.28), (0.95, 1.64), (0.99, 2.33), (0.999, 3.09)]


@pytest.mark.parametrize("p_c, z_printed", TABLE1)
def test_one_sided_acceptance_limit_for_a_required_p_c_is_table1_z_below_the_limit(p_c, z_printed):
    """JCGM 106:2012, 7.3 Table 1 / 8.3.2: accepting only with p_c >= p puts A_U z·u below T_U."""
    u_um = 3.0
    lo, hi = cf.acceptance_limits_for_p_c(cf.Tolerance(usl_mm=10.0), u_um, p_c)
    assert lo is None
    z = (10.0 - hi) * 1000 / u_um
    assert printed(z, z_printed, 2), z
    lo, hi = cf.acceptance_limits_for_p_c(cf.Tolerance(lsl_mm=10.0), u_um, p_c)
    assert hi is None and printed((lo - 10.0) * 1000 / u_um, z_printed, 2)


@pytest.mark.parametrize("c_m", [1.0, 1.5, 2.0, 4.0])
def test_two_sided_acceptance_limits_give_exactly_the_required_p_c(c_m):
    """JCGM 106:2012, 7.4 eq. (12): with both limits the far tail adds to 1 - p_c, so the exact
    acceptance limit for p_c = 0.95 lies inside T_U - 1.645u (errata: specific-risk limits)."""
    u_um = 2.0
    tol = cf.Tolerance.symmetric(20.0, 4 * c_m * u_um / 2 / 1000)      # C_m = (T_U - T_L)/(4u)
    assert cf.measurement_capability_index(tol, u_um) == pytest.approx(c_m, rel=1e-12)
    lo, hi = cf.acceptance_limits_for_p_c(tol, u_um, 0.95)
    assert cf.probability_of_conformance(hi, u_um, tol) == pytest.approx(0.95, abs=1e-12)
    assert cf.probability_of_conformance(lo, u_um, tol) == pytest.approx(0.95, abs=1e-12)
    one_sided = tol.usl_mm - cf.norm_ppf(0.95) * u_um / 1000
    assert hi <= one_sided + 1e-15 and lo == pytest.approx(40.0 - hi, abs=1e-12)
    assert cf.specific_consumer_risk(hi, u_um, tol) == pytest.approx(0.05, abs=1e-12)


def test_a_required_p_c_below_one_half_accepts_beyond_the_tolerance_limits():
    """p_min = 0.3 (guarded rejection, 8.3.3): the limits lie outside [T_L, T_U], p_c there = 0.3."""
    tol = cf.Tolerance.symmetric(5.0, 0.004)
    lo, hi = cf.acceptance_limits_for_p_c(tol, 1.0, 0.3)
    assert lo < tol.lsl_mm and hi > tol.usl_mm
    assert cf.probability_of_conformance(hi, 1.0, tol) == pytest.approx(0.3, abs=1e-12)
    assert (hi - tol.usl_mm) * 1000 == pytest.approx(-cf.norm_ppf(0.3), abs=1e-9)   # far tail: Φ(-8.5)


def test_no_acceptance_interval_when_even_the_midpoint_falls_short():
    """C_m = 0.5: at the midpoint p_c = 2Φ(1) - 1 = 0.683 < 0.95, nothing can be accepted."""
    tol = cf.Tolerance.symmetric(0.0, 0.002)
    limits = cf.acceptance_limits_for_p_c(tol, 2.0, 0.95)
    assert cf.empty(limits)
    with pytest.raises(ModelError, match="p_min"):
        cf.acceptance_limits_for_p_c(tol, 2.0, 1.0)


# -- 9.5.4: ball bearings, gamma process PDF ----------------------------------------------------

T_U_UM = 2.0            # radial error motion must be below 2 µm
U_M_UM = 0.25           # the measuring system's standard uncertainty
BEARINGS = gr.gamma_prior(4.0, 4.0)     # α = 4, β = 4 µm⁻¹: mean 1 µm, sd 0.5 µm
SUNCAL = {"nonconforming": 0.04238011199168401, "R_C": 0.008019111884303471,
          "w_um": 0.3281712284559932, "A_U_um": 1.6718287715440068}


def test_bearings_nonconforming_fraction_without_inspection():
    """9.5.4 (as suncal states it): Pr(η > T_U) = 4.2 % of the bearings do not conform.  For integer α
    the gamma tail is e^(-βT) Σ_{j<α} (βT)^j/j!, here 126⅓·e⁻⁸."""
    r = gr.global_risks(BEARINGS, U_M_UM, (None, T_U_UM), (None, T_U_UM))
    exact = math.exp(-8.0) * sum(8.0 ** j / math.factorial(j) for j in range(4))
    assert r.nonconforming == pytest.approx(exact, rel=1e-12)
    assert printed(100 * r.nonconforming, 4.2, 1)
    assert close(r.nonconforming, SUNCAL["nonconforming"], rel=1e-12)


def test_bearings_global_consumers_risk_with_simple_acceptance():
    """9.5.4 (as suncal states it): inspecting every bearing with u_m = 0.25 µm and accepting
    below T_U leaves R_C = 0.8 % (suncal: 0.008019111884303471)."""
    r = gr.global_risks(BEARINGS, U_M_UM, (None, T_U_UM), (None, T_U_UM))
    assert printed(100 * r.consumer, 0.8, 1)
    assert close(r.consumer, SUNCAL["R_C"], rel=1e-9)
    assert 0 < r.producer < 1 - r.nonconforming


def test_bearings_acceptance_limit_for_a_global_consumers_risk_of_0_1_percent():
    """9.5.4 (suncal's result): a required R_C <= 0.1 % moves the acceptance limit to
    A_U = T_U - w = 1.67 µm; the producer's risk grows (more conforming bearings are rejected)."""
    w = gr.guard_band_for_global_risk(BEARINGS, U_M_UM, (None, T_U_UM), 0.001)
    assert abs(w - SUNCAL["w_um"]) <= 1e-9
    assert printed(T_U_UM - w, 1.67, 2) and abs(T_U_UM - w - SUNCAL["A_U_um"]) <= 1e-9
    simple = gr.global_risks(BEARINGS, U_M_UM, (None, T_U_UM), (None, T_U_UM))
    guarded = gr.global_risks(BEARINGS, U_M_UM, (None, T_U_UM), (None, T_U_UM - w))
    assert guarded.consumer == pytest.approx(0.001, rel=1e-9)
    assert guarded.producer > simple.producer


def test_a_guard_band_is_zero_when_simple_acceptance_already_meets_the_risk():
    assert gr.guard_band_for_global_risk(BEARINGS, U_M_UM, (None, T_U_UM), 0.05) == 0.0


# -- 9.5: normal process and measuring system -------------------------------------------

def _bvn_checks(mean, sd0, u_m, tol, acc):
    """R_C, R_P from the core and (1) the probability of acceptance in closed form, (2) R_C as
    the integral over accepted η_m of h(η_m)·(1 - p_c(η_m)) with the normal posterior."""
    prior = gr.normal_prior(mean, sd0)
    r = gr.global_risks(prior, u_m, tol, acc)
    s = math.hypot(sd0, u_m)
    a_lo, a_hi = acc
    p_acc = cf.norm_cdf((a_hi - mean) / s) - cf.norm_cdf((a_lo - mean) / s)
    # accepted = R_C + (conforming and accepted) = R_C + (1 - nonconforming - R_P)
    assert r.consumer + (1 - r.nonconforming - r.producer) == pytest.approx(p_acc, abs=1e-13)
    t_lo, t_hi = tol
    p_conf = cf.norm_cdf((t_hi - mean) / sd0) - cf.norm_cdf((t_lo - mean) / sd0)
    assert r.nonconforming == pytest.approx(1 - p_conf, abs=1e-13)
    # the other order: posterior N(μ_post, σ_post²) of η given η_m (normal-normal)
    x, w = np.polynomial.legendre.leggauss(200)
    eta_m = 0.5 * (a_hi - a_lo) * x + 0.5 * (a_hi + a_lo)
    h = np.exp(-0.5 * ((eta_m - mean) / s) ** 2) / (s * math.sqrt(2 * math.pi))
    mu_post = (sd0 ** 2 * eta_m + u_m ** 2 * mean) / s ** 2
    sd_post = sd0 * u_m / s
    p_c = cf.norm_cdf((t_hi - mu_post) / sd_post) - cf.norm_cdf((t_lo - mu_post) / sd_post)
    r_c_other = float(np.sum(w * h * (1 - p_c)) * 0.5 * (a_hi - a_lo))
    assert r.consumer == pytest.approx(r_c_other, rel=1e-9, abs=1e-15)
    return r


@pytest.mark.parametrize("mean, sd0, u_m, w", [
    (0.0, 1.0, 0.25, 0.0),       # centred process, C_m = 2, simple acceptance
    (0.0, 1.0, 0.25, 0.5),       # guarded acceptance w = 2u_m = U
    (0.7, 0.6, 0.5, 0.0),        # off-centre process, C_m = 1
    (0.7, 0.6, 0.5, -0.5),       # guarded rejection
])
def test_normal_global_risks_agree_with_closed_forms_and_the_other_order(mean, sd0, u_m, w):
    tol = (-1.0 * 2, 1.0 * 2)
    acc = (tol[0] + w, tol[1] - w)
    r = _bvn_checks(mean, sd0, u_m, tol, acc)
    assert 0 < r.consumer < r.nonconforming


def test_guarded_acceptance_lowers_the_consumers_and_raises_the_producers_risk():
    prior = gr.normal_prior(0.0, 1.0)
    risks = [gr.global_risks(prior, 0.25, (-2.0, 2.0), (-2.0 + w, 2.0 - w)) for w in (-0.5, 0.0, 0.5)]
    assert risks[0].consumer > risks[1].consumer > risks[2].consumer
    assert risks[0].producer < risks[1].producer < risks[2].producer


@pytest.mark.parametrize("u_m", [1e-2, 1e-3, 1e-4])
def test_small_u_m_risks_follow_their_two_term_expansion(u_m):
    """For u_m -> 0 each tolerance limit T contributes ∫_0^∞ g₀(T ± t) Φ(-t/u_m) dt
    = g₀(T) u_m/√(2π) ± g₀'(T) u_m²/4 + O(u_m³) (simple acceptance, A = C): with N(0, 1) and
    C = [-2, 2], g₀(±2) = φ(2) and the prior falls away from the centre, so
    R_C ≈ 2φ(2)(u_m/√(2π) - u_m²/2) and R_P ≈ 2φ(2)(u_m/√(2π) + u_m²/2)."""
    r = gr.global_risks(gr.normal_prior(0.0, 1.0), u_m, (-2.0, 2.0), (-2.0, 2.0))
    phi2 = math.exp(-2.0) / math.sqrt(2 * math.pi)
    lead = 2 * phi2 * u_m / math.sqrt(2 * math.pi)
    assert r.consumer == pytest.approx(lead - phi2 * u_m ** 2, rel=2 * u_m ** 2)
    assert r.producer == pytest.approx(lead + phi2 * u_m ** 2, rel=2 * u_m ** 2)


def test_bad_priors_and_uncertainties_are_refused():
    with pytest.raises(ModelError, match="sd > 0"):
        gr.normal_prior(0.0, 0.0)
    with pytest.raises(ModelError, match="shape >= 1"):
        gr.gamma_prior(0.5, 1.0)
    with pytest.raises(ModelError, match="u_m"):
        gr.global_risks(BEARINGS, 0.0, (None, 2.0), (None, 2.0))
    with pytest.raises(ModelError, match="max_consumer_risk"):
        gr.guard_band_for_global_risk(BEARINGS, 0.25, (None, 2.0), 0.0)


# -- the bearing's acceptance limit in a built Decision sheet, four engines -----------------------

@pytest.fixture(scope="module")
def bearing_book(tmp_path_factory):
    """Knuckle characteristics rescaled to the bearing example: one µm of radial error motion is
    u_char/u_m of the characteristic (so every ratio to u is the example's), upper limit T_U,
    guarded acceptance with r = w/(2u_m) (k = 2), values 0.05 µm inside and outside A_U and one
    at T_U.  Returns (results, book, scale per characteristic (mm per µm of the example))."""
    from tests.helpers import EXAMPLES
    from tests.helpers.decision import build

    KNUCKLE = EXAMPLES / "knuckle.toml"

    tmp = tmp_path_factory.mktemp("bearing")
    plain, _ = build(tmp, KNUCKLE, name="plain.toml")
    u = {c["name"]: c["u_um"] for c in plain["characteristics"]}
    w = gr.guard_band_for_global_risk(BEARINGS, U_M_UM, (None, T_U_UM), 0.001)
    names = ["S1_S2_distance", "S3_from_S1S2", "S4_from_ABC"]
    etas = [T_U_UM - w - 0.05, T_U_UM - w + 0.05, T_U_UM]
    scale = {n: u[n] / U_M_UM / 1000 for n in names}

    def edit(doc):
        doc["task"]["name"] = "bearing"
        doc["decision"] = {"rule": "guarded_acceptance", "r": w / (2 * U_M_UM), "tolerances": [
            {"characteristic": n, "measured_mm": 50.0 + eta * scale[n], "usl_mm": 50.0 + T_U_UM * scale[n]}
            for n, eta in zip(names, etas)]}
    results, book = build(tmp, KNUCKLE, edit, name="bearing.toml")
    return results, book, scale, w, etas


def test_bearing_acceptance_limit_in_the_json(bearing_book):
    results, _, scale, w, etas = bearing_book
    for d, eta in zip(results["decisions"], etas):
        a_u_um = (d["acceptance_limits_mm"][1] - 50.0) / scale[d["characteristic"]]
        assert abs(a_u_um - SUNCAL["A_U_um"]) <= 1e-9 and printed(a_u_um, 1.67, 2)
        assert d["p_c"] == pytest.approx(cf.norm_cdf((T_U_UM - eta) / U_M_UM), rel=1e-9)
    assert [d["outcome"] for d in results["decisions"]] == [cf.CONFORMS, cf.DOES_NOT_CONFORM, cf.DOES_NOT_CONFORM]


@pytest.mark.parametrize("engine", ENGINES)
def test_bearing_acceptance_limit_in_the_workbook(bearing_book, engine):

    from tests.helpers.decision import assert_engine_agrees, at

    results, book, scale, w, etas = bearing_book
    assert assert_engine_agrees(book, engine) > 10
    v = recalc(book, engine)["Decision"]
    for i, d in enumerate(results["decisions"]):
        got = v[at(8 + i, "A_U_mm")]
        assert close(got, d["acceptance_limits_mm"][1], rel=1e-9)
        assert printed((got - 50.0) / scale[d["characteristic"]], 1.67, 2)
        assert close(v[at(8 + i, "p_c")], d["p_c"], rel=1e-9)
        assert v[at(8 + i, "outcome")] == d["outcome"]


# -- the specific-risk rule's exact two-sided acceptance limits (7.4 eq. (12), 9.3) ---------------

@pytest.mark.parametrize("max_pfa", [0.4, 0.2, 0.05, 0.01, 1e-3, 1e-4])
@pytest.mark.parametrize("c_m", [0.9, 0.99, 1.0, 1.2, 1.5, 2.0, 4.0, 50.0])
def test_newtons_specific_risk_limit_is_the_bisections_root(c_m, max_pfa):
    """The five Newton steps the Decision sheet repeats (xlfuncs.conformity.specific_risk_iterates)
    land on the root that acceptance_limits_for_p_c finds by bisection, to 1e-9 u, and an item on
    that limit has p_c = 1 - max_pfa; where the interval is empty both say so."""
    u_um = 1.5
    tol = cf.Tolerance.symmetric(50.0, 4 * c_m * u_um / 2 / 1000)
    w = cf.specific_risk_guard_band_um(tol, u_um, max_pfa)
    lo, hi = cf.acceptance_limits_for_p_c(tol, u_um, 1 - max_pfa)
    assert abs(w - (tol.usl_mm - hi) * 1000) <= 1e-9 * u_um
    got = cf.acceptance_limits(tol, w)
    assert cf.empty(got) == cf.empty((lo, hi))
    if not cf.empty(got):
        assert cf.probability_of_conformance(got[1], u_um, tol) == pytest.approx(1 - max_pfa, abs=1e-12)
        assert w >= cf.norm_ppf(1 - max_pfa) * u_um - 1e-12      # never outside the one-sided limit


def test_newton_reaches_the_conditioning_floor_where_the_interval_vanishes():
    """At h = Φ⁻¹((1 + p)/2) the acceptance interval is the midpoint alone (d = 0, a double root in
    d); in s = d² the root is simple, and the iterates reach d = 0 to within the conditioning of the
    problem (p_c is known to 1e-16, so d to about 1e-7)."""
    for p in (0.6, 0.95, 0.999):
        h = cf.norm_ppf((1 + p) / 2)
        s = cf.specific_risk_iterates(h, 1 - p)
        assert math.sqrt(s[-1]) <= 1e-6 and s[0] > 0


@pytest.fixture(scope="module")
def specific_risk_book(tmp_path_factory):
    """Knuckle characteristics with two-sided tolerances of C_m = 0.9 (nothing can be accepted),
    1.0 and 1.5 around 50 mm, specific-risk rule with max_pfa = 0.05, measured values at the
    one-sided limit T_U - z·u (inside the approximate acceptance interval, outside the exact one)."""
    from tests.helpers import EXAMPLES
    from tests.helpers.decision import build

    knuckle = EXAMPLES / "knuckle.toml"
    tmp = tmp_path_factory.mktemp("specific_risk")
    plain, _ = build(tmp, knuckle, name="plain.toml")
    u = {c["name"]: c["u_um"] for c in plain["characteristics"]}
    names = ["S1_S2_distance", "S3_from_S1S2", "S4_from_ABC"]
    c_ms = [0.9, 1.0, 1.5]
    z = cf.norm_ppf(0.95)

    def edit(doc):
        doc["task"]["name"] = "specific"
        doc["decision"] = {"rule": "specific_risk", "max_pfa": 0.05, "tolerances": [
            {"characteristic": n, "nominal_mm": 50.0, "tol_mm": 2 * c_m * u[n] / 1000,
             "measured_mm": 50.0 + (2 * c_m - z) * u[n] / 1000}
            for n, c_m in zip(names, c_ms)]}
    results, book = build(tmp, knuckle, edit, name="specific.toml")
    return results, book, c_ms


def test_specific_risk_limits_in_the_json_are_exact(specific_risk_book):
    results, _, c_ms = specific_risk_book
    d0, d1, d2 = results["decisions"]
    assert d0["acceptance_interval_empty"] and d0["outcome"] == cf.DOES_NOT_CONFORM
    for d in (d1, d2):
        tol = cf.Tolerance(d["lsl_mm"], d["usl_mm"])
        lo, hi = cf.acceptance_limits_for_p_c(tol, d["u_um"], 0.95)
        assert close(d["acceptance_limits_mm"][1], hi, rel=1e-12) and close(d["acceptance_limits_mm"][0], lo, rel=1e-12)
        assert cf.probability_of_conformance(d["acceptance_limits_mm"][1], d["u_um"], tol) == pytest.approx(0.95, abs=1e-9)
        # the value at the one-sided limit T_U - z·u: inside T_U - z·u, beyond the exact limit, p_c < 0.95
        assert d["value_mm"] > d["acceptance_limits_mm"][1] and d["p_c"] < 0.95 and d["outcome"] == cf.DOES_NOT_CONFORM
    assert d1["w_um"] > cf.norm_ppf(0.95) * d1["u_um"] * 1.01      # C_m = 1: the far tail matters


@pytest.mark.parametrize("engine", ENGINES)
def test_specific_risk_limits_in_the_workbook_are_exact(specific_risk_book, engine):

    from tests.helpers.decision import assert_engine_agrees, at

    results, book, _ = specific_risk_book
    assert assert_engine_agrees(book, engine) > 30
    v = recalc(book, engine)["Decision"]
    for i, d in enumerate(results["decisions"]):
        tol = cf.Tolerance(d["lsl_mm"], d["usl_mm"])
        a_l, a_u = v[at(8 + i, "A_L_mm")], v[at(8 + i, "A_U_mm")]
        lo, hi = cf.acceptance_limits_for_p_c(tol, d["u_um"], 0.95)
        assert close(a_u, hi, rel=1e-9) and close(a_l, lo, rel=1e-9)
        if i:
            assert cf.probability_of_conformance(a_u, d["u_um"], tol) == pytest.approx(0.95, abs=1e-6)
        assert v[at(8 + i, "outcome")] == d["outcome"] == cf.DOES_NOT_CONFORM


# -- 9.5: global risks of a normal process in the Decision sheet ---------------------------------

@pytest.mark.parametrize("mean_off_um, sd_um, u_um, w_in_u, side", [
    (0.0, 3.0, 1.0, 0.0, "two"), (0.0, 3.0, 1.0, 2.0, "two"), (2.0, 1.5, 0.5, -1.0, "two"),
    (0.0, 0.5, 1.0, 1.0, "two"), (3.0, 0.5, 1.0, 0.0, "two"), (1.0, 2.0, 2.0, 0.5, "two"),
    (0.0, 3.0, 1.0, 1.0, "up"), (-2.0, 0.7, 1.2, 0.0, "low"), (0.0, 10.0, 0.1, 0.0, "two"),
])
def test_fixed_panel_global_risks_match_the_adaptive_quadrature(mean_off_um, sd_um, u_um, w_in_u, side):
    """global_risks_normal (the Decision sheet's Gauss-Legendre panels) against global_risks
    (adaptive, any prior): the same R_C, R_P and non-conforming fraction to 1e-9 relative (or
    1e-16 absolute for the smallest), for u below and above σ₀, guarded acceptance and rejection,
    one- and two-sided tolerances (a tolerance of ± 5 µm around 50 mm)."""
    half = 5.0
    tol = {"two": cf.Tolerance(50 - half / 1000, 50 + half / 1000), "up": cf.Tolerance(usl_mm=50 + half / 1000),
           "low": cf.Tolerance(lsl_mm=50 - half / 1000)}[side]
    acc = cf.acceptance_limits(tol, w_in_u * u_um)
    mean = 50 + mean_off_um / 1000
    fixed = gr.global_risks_normal(mean, sd_um, u_um, tol, acc)
    um = lambda x: None if x is None else (x - 50) * 1000      # noqa: E731  (µm about 50 mm)
    ref = gr.global_risks(gr.normal_prior(mean_off_um, sd_um), u_um, (um(tol.lsl_mm), um(tol.usl_mm)),
                          (um(acc[0]), um(acc[1])))
    for got, want in ((fixed.consumer, ref.consumer), (fixed.producer, ref.producer),
                      (fixed.nonconforming, ref.nonconforming)):
        assert abs(got - want) <= 1e-9 * abs(want) + 1e-16, (got, want)


@pytest.fixture(scope="module")
def process_book(tmp_path_factory):
    """Knuckle characteristics with tolerances ± 2.5 u and a normal process prior each: u below
    σ₀ (ISO 14253-1 rule's conformance zone accepted), u above σ₀, and an off-centre process."""
    from tests.helpers import EXAMPLES
    from tests.helpers.decision import build

    knuckle = EXAMPLES / "knuckle.toml"
    tmp = tmp_path_factory.mktemp("process")
    plain, _ = build(tmp, knuckle, name="plain.toml")
    u = {c["name"]: c["u_um"] for c in plain["characteristics"]}
    names = ["S1_S2_distance", "S3_from_S1S2", "S4_from_ABC"]
    priors = [(0.0, 3.0), (0.0, 0.5), (1.0, 1.5)]         # (mean offset, σ₀) in units of u

    def edit(doc):
        doc["task"]["name"] = "process"
        doc["decision"] = {"rule": "simple", "tolerances": [
            {"characteristic": n, "nominal_mm": 50.0, "tol_mm": 2.5 * u[n] / 1000, "measured_mm": 50.0,
             "process_mean_mm": 50.0 + off * u[n] / 1000, "process_sd_um": sd * u[n]}
            for n, (off, sd) in zip(names, priors)]}
    results, book = build(tmp, knuckle, edit, name="process.toml")
    return results, book


def test_global_risks_in_the_json(process_book):
    results, _ = process_book
    for d in results["decisions"]:
        tol = cf.Tolerance(d["lsl_mm"], d["usl_mm"])
        g = gr.global_risks_normal(d["process_mean_mm"], d["process_sd_um"], d["u_um"], tol,
                                   tuple(d["acceptance_limits_mm"]))
        assert d["global_consumer_risk"] == g.consumer and d["global_producer_risk"] == g.producer
        assert 0 < d["global_consumer_risk"] < d["process_nonconforming"] < 1
        assert 0 < d["global_producer_risk"] < 1 - d["process_nonconforming"]
        # the probability of acceptance in closed form: Pr(η_m ∈ A), η_m ~ N(μ, σ₀² + u²)
        s = math.hypot(d["process_sd_um"], d["u_um"]) / 1000
        a_l, a_u = d["acceptance_limits_mm"]
        p_acc = cf.norm_cdf((a_u - d["process_mean_mm"]) / s) - cf.norm_cdf((a_l - d["process_mean_mm"]) / s)
        accepted = d["global_consumer_risk"] + (1 - d["process_nonconforming"] - d["global_producer_risk"])
        assert accepted == pytest.approx(p_acc, abs=1e-13)


@pytest.mark.parametrize("engine", ENGINES)
def test_global_risks_in_the_workbook(process_book, engine):

    from tests.helpers.decision import assert_engine_agrees

    results, book = process_book
    assert assert_engine_agrees(book, engine) > 60
    v = recalc(book, engine)["Decision"]
    got = sorted(x for x in v.values() if isinstance(x, float) and 0 < x < 1)
    for d in results["decisions"]:
        for key in ("global_consumer_risk", "global_producer_risk", "process_nonconforming"):
            assert any(close(x, d[key], rel=1e-9) for x in got), key


def test_a_process_prior_typed_in_the_sheet_reads_back_into_the_task(process_book, tmp_path):
    """`cmmwb read`: the risk table's inputs go back into [[decision.tolerances]]."""
    import tomllib

    import openpyxl

    from cmmwb.generator.reader import read_to_files

    results, book = process_book
    wb = openpyxl.load_workbook(book)
    (sheet, coord), = wb.defined_names["tol2_process_sd_um"].destinations
    wb[sheet][coord.replace("$", "")].value = 0.75
    edited = tmp_path / "edited.xlsx"
    wb.save(edited)
    read_to_files(edited, tmp_path / "back.toml")
    doc = tomllib.loads((tmp_path / "back.toml").read_text(encoding="utf-8"))
    tols = doc["decision"]["tolerances"]
    assert tols[1]["process_sd_um"] == 0.75
    assert tols[0]["process_sd_um"] == results["decisions"][0]["process_sd_um"]     # untouched
