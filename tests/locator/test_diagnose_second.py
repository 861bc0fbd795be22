"""The locator's second edition, honest answers (docs/recordings.md section 7): the two gates
(omnibus or targeted, alpha/2 each), whether the chosen effects explain the mismatch (p_after,
explained, where the rest concentrates), gross outliers before physics, and the noise level."""

import dataclasses
import math

import numpy as np
import pytest

from cmmwb.xlfuncs.locator import diagnose as dg
from cmmwb.xlfuncs.locator import simulate as sm

from tests.helpers.clouds import MPE1, PAIR
from tests.helpers.locator import iso, u_effect

SIGMAS = ("sigma_R_um", "sigma_S_ppm", "sigma_Sa_ppm", "sigma_Q_ppm", "sigma_PQ_um", "sigma_ET_um",
          "sigma_ER_urad", "sigma_P0_um", "sigma_P_um")


# -- the F tail used when the scale of the covariance is estimated ------------------------------

@pytest.mark.parametrize("F,d1,d2", [(0.3, 1, 10), (1.0, 3, 50), (4.2, 2, 104), (25.0, 1, 100), (900.0, 3, 300)])
def test_f_tail_agrees_with_scipy(F, d1, d2):
    from scipy import stats

    assert math.isclose(dg.f_logsf(F, d1, d2), stats.f.logsf(F, d1, d2), rel_tol=1e-9, abs_tol=1e-12)


# -- two gates ------------------------------------------------------------------------------------

def test_pure_noise_passes_both_gates_and_chooses_nothing():
    L, model = iso()
    j = dg.diagnose(sm.simulate(L, MPE1, {}, seed=4), model).to_json()
    assert j["gate"] is None and j["mismatch"] is False
    assert j["p_before"] >= 0.005 and j["p_targeted"] >= 0.005
    assert j["effects"] == [] and j["outliers"] == [] and j["noise_scale"] is None


def test_a_small_effect_the_omnibus_test_misses_is_found_by_the_targeted_gate():
    """squareness_xy at 5.5 standard uncertainties on 105 lengths: the omnibus chi-square passes
    (p = 0.14), the test aimed at the candidates fires."""
    L, model = iso()
    rec = sm.simulate(L, MPE1, {"squareness_xy": 5.5 * u_effect(L, model, "squareness_xy")}, seed=7)
    j = dg.diagnose(rec, model).to_json()
    assert j["p_before"] > 0.01
    assert j["gate"] == "targeted" and j["mismatch"] is True and j["p_targeted"] < 0.005
    assert [e["name"] for e in j["effects"]] == ["squareness_xy"]
    assert j["explained"] is True


def test_the_targeted_p_value_is_the_bonferroni_adjusted_best_candidate():
    L, model = iso()
    rec = sm.simulate(L, MPE1, {"squareness_xy": 5.5 * u_effect(L, model, "squareness_xy")}, seed=7)
    j = dg.diagnose(rec, model).to_json()
    first = j["steps"][0]
    assert math.isclose(j["p_targeted"], min(1.0, min(r["p_value"] for r in first) * len(first)), rel_tol=1e-9)


# -- explained? ---------------------------------------------------------------------------------------

def test_explained_is_the_remaining_chi_square_passing():
    L, model = iso()
    rec = sm.simulate(L, MPE1, {"squareness_xy": 12 * u_effect(L, model, "squareness_xy")}, seed=3)
    j = dg.diagnose(rec, model).to_json()
    assert j["explained"] == (j["p_after"] >= j["alpha"])
    assert j["explained"] is True and j["unexplained"] is None


def periodic_x_lengths():
    """ISO 10360-2 lengths (three repeats, one probe) with a periodic scale error along x of
    1.5 µm amplitude and 53 mm pitch, outside the linear library."""
    L, model = iso()
    rec = sm.simulate(L, MPE1, {}, seed=5)
    na = rec.X2_mm - rec.X1_mm
    na /= np.linalg.norm(na, axis=1)[:, None]
    f = lambda x: 1.5 * np.sin(2 * np.pi * x / 53.0)
    rec.measured_mm += na[:, 0] * (f(rec.X2_mm[:, 0]) - f(rec.X1_mm[:, 0])) / 1000.0
    return rec, model


def test_an_error_outside_the_library_is_not_called_explained_and_is_located():
    """A periodic scale error along x (1.5 µm, pitch 53 mm: not in the linear library): the
    nearest linear effect takes part of it, and the answer says the rest still fails and where."""
    rec, model = periodic_x_lengths()
    j = dg.diagnose(rec, model).to_json()
    assert j["mismatch"] is True and j["effects"]
    assert j["explained"] is False and j["p_after"] < 0.01 and j["noise_scale"] is None
    g = j["unexplained"]["groups"][0]
    assert g["flagged"] and (g["by"], g["group"]) in {("direction", "+x"), ("group", "X")}   # the x lengths
    assert "not the whole story" in j["summary"]


# -- outliers -----------------------------------------------------------------------------------------

def test_a_gross_length_outlier_is_named_and_no_effect_is_chosen_because_of_it():
    L, model = iso()
    rec = sm.simulate(L, MPE1, {}, seed=1)
    rec.measured_mm[7] += 0.008            # 8 µm, about 20 standard uncertainties
    j = dg.diagnose(rec, model).to_json()
    assert [o["id"] for o in j["outliers"]] == [rec.ids[7]]
    o = j["outliers"][0]
    assert o["p_adjusted"] < 0.01 and o["z"] > 10
    assert abs(o["estimate_um"] - 8.0) <= 3 * o["u_um"] + 1.0    # the gross error less the record's own noise
    assert j["effects"] == [] and j["explained"] is True
    assert j["with_outliers"] is not None and "chi2_after" in j["with_outliers"]


def test_a_gross_point_outlier_is_named_with_its_coordinates():
    L = sm.layout("ballplate", PAIR, grid=4)
    model = dg.Model(MPE1, PAIR, True)
    rec = sm.simulate(L, MPE1, {}, seed=2)
    rec.X_mm[5] += np.array([0.004, -0.003, 0.002])
    j = dg.diagnose(rec, model).to_json()
    assert j["outliers"][0]["id"] == rec.ids[5]
    assert j["outliers"][0]["axes"] == ["x", "y", "z"] and len(j["outliers"][0]["estimate_um"]) == 3
    assert j["effects"] == []


def test_many_gross_looking_records_are_a_structure_not_outliers():
    """The periodic error of the test above makes a dozen lengths look gross one by one: more than
    isolated outliers can be, so none is called an outlier and the effects are searched on all."""
    rec, model = periodic_x_lengths()
    j = dg.diagnose(rec, model).to_json()
    assert j["outliers"] == [] and j["outliers_not_isolated"] is True and j["with_outliers"] is None


def test_records_that_agree_report_no_outliers():
    L, model = iso()
    j = dg.diagnose(sm.simulate(L, MPE1, {}, seed=4), model).to_json()
    assert j["outliers"] == []


# -- noise level --------------------------------------------------------------------------------------

def test_uniformly_inflated_noise_gives_a_noise_scale_and_no_effect():
    L, model = iso(5)
    worse = dataclasses.replace(MPE1, **{k: getattr(MPE1, k) * 1.6 for k in SIGMAS})
    j = dg.diagnose(sm.simulate(L, worse, {}, seed=8), model).to_json()
    ns = j["noise_scale"]
    assert j["mismatch"] is True and ns is not None
    assert abs(ns["estimate"] - 1.6) <= 3 * ns["u"]
    assert math.isclose(ns["estimate"] ** 2, j["chi2_after"] / j["dof_after"], rel_tol=1e-12)
    assert j["effects"] == [] and j["outliers"] == []
    assert j["explained"] is False
    assert "too small by a factor" in j["summary"] and "no physical effect is chosen" in j["summary"]


def test_an_effect_with_correct_noise_gives_no_noise_scale():
    L, model = iso()
    rec = sm.simulate(L, MPE1, {"squareness_xy": 12 * u_effect(L, model, "squareness_xy")}, seed=3)
    assert dg.diagnose(rec, model).to_json()["noise_scale"] is None


# -- the structured covariance (large point records) ------------------------------------------------

def test_the_structured_path_gives_the_same_gates_and_skips_the_outlier_search():
    rec = sm.simulate(sm.scan(PAIR, points=400), MPE1, {"scale": 5.0, "probe_radius": 2.0}, seed=3)
    model = dg.Model(MPE1, PAIR, True)
    s = dg.diagnose(rec, model, structured=True).to_json()
    d = dg.diagnose(rec, model, structured=False).to_json()
    assert s["gate"] == d["gate"] == "both"
    assert math.isclose(math.log(s["p_targeted"] or 1e-300), math.log(d["p_targeted"] or 1e-300), rel_tol=1e-6)
    assert s["outliers"] is None and isinstance(d["outliers"], list)
    assert s["explained"] == d["explained"]


# -- naming a cause: adjusted p below alpha/100; between that and alpha only indicated -----------

def weak_squareness():
    """ISO 10360-2 lengths, one probe, a squareness of 6 µrad (about 4.7 of its u = 1.28 µrad):
    the targeted gate fires (adjusted p = 0.0007, about 7 times from either end of the window
    1e-4 ... alpha/2, so that a few more candidates in the Bonferroni count do not move it out)
    but the omnibus test passes."""
    L, model = iso(repeats=1)
    return sm.simulate(L, MPE1, {"squareness_xy": 6.0}, seed=7), model


def test_an_effect_between_alpha_name_and_alpha_is_indicated_not_chosen():
    rec, model = weak_squareness()
    j = dg.diagnose(rec, model).to_json()
    assert j["mismatch"] is True and j["gate"] == "targeted"
    assert j["effects"] == [] and j["alpha_name"] == pytest.approx(1e-4)
    (ind,) = j["indicated"]
    assert ind["name"] == "squareness_xy" and 1e-4 <= ind["p_adjusted"] < 0.01
    assert abs(ind["estimate"] - 6.0) < 3 * ind["u"] and ind["unit"] == "urad"
    status = {c["name"]: c["status"] for c in j["candidates"]}
    assert status["squareness_xy"] == "indicated"
    assert "indicated" in j["summary"] and "not named" in j["summary"]


def test_the_indicated_effect_is_not_applied_in_the_refit():
    rec, model = weak_squareness()
    j = dg.diagnose(rec, model).to_json()
    assert j["chi2_after"] == pytest.approx(j["chi2_before"], rel=1e-12)


def test_with_alpha_name_equal_to_alpha_the_same_effect_is_chosen():
    rec, model = weak_squareness()
    j = dg.diagnose(rec, model, alpha_name=0.01).to_json()
    assert [e["name"] for e in j["effects"]] == ["squareness_xy"] and j["indicated"] == []
    assert j["effects"][0]["estimate"] == pytest.approx(dg.diagnose(rec, model).to_json()["indicated"][0]["estimate"],
                                                        rel=1e-9)


@pytest.mark.parametrize("alpha_name", [0.0, 0.02, -1e-3])
def test_alpha_name_outside_zero_to_alpha_is_refused(alpha_name):
    rec, model = weak_squareness()
    with pytest.raises(dg.ModelError, match="alpha_name"):
        dg.diagnose(rec, model, alpha_name=alpha_name)
